"""Stage 2b, flatten: a graph with multiports (vector bonds) -> a graph of scalar bonds.

Every later stage sees scalar elements and scalar bonds only; the multiports are remembered
(Graph.vectors, Graph.multibonds) for what the user reads: outputs written `q` or `rod.lambda`
expand into columns `q[0]`, `rod.lambda[0]`, ..., and `bgc check` reports causality per vector
bond.

- A junction array `0[n]` / `1[n]` becomes n junctions NAME[0] .. NAME[n-1]; a constraint array
  `0[m] constraint ...` becomes m constraint junctions, row i taking component i of vector gains
  and of a vector `init`/`phi` annotation (a scalar applies to every row).
- A one-port `KIND[n](V)` becomes n one-ports NAME[i]: V a scalar (V times the identity for I, C,
  R; the same value for each source), a vector of n, or a diagonal n x n matrix.
- A two-port `MTF[n->m](T)` (T an m x n matrix, f_out = T f_in, e_in = T^T e_out) becomes the
  standard network of scalar parts: a 1-junction NAME.in[j] per input component (its common flow
  f_in_j), a 0-junction NAME.out[i] per output component (its common effort e_out_i) and a
  transformer NAME[i,j] of modulus T_ij from in[j] to out[i] for every entry that is not
  identically zero.  Summing at the junctions gives exactly f_out = T f_in and e_in = T^T e_out,
  and the network admits only the causality the matrix allows: flow enters at the input side.
  `MGY[n->m](G)` (e_out = G f_in, e_in = G^T f_out) is the same with gyrators and a 1-junction
  per output component.  `TF[n](k)`/`MTF[n](T)` with a scalar k is k times the identity.
- A bond between two ports of dimension n becomes n scalar bonds LABEL[i] between their parts; a
  bond between ports of different dimensions is an error naming both.
- A vector signal `q[n]` becomes n signals q[0] .. q[n-1].

The stage is linear in the number of scalar parts it makes.
"""
from __future__ import annotations

from dataclasses import replace

import sympy as sp

from ..symbolic.algebra import is_zero
from ..base.diagnostics import Collector, ModelError, fail
from .graph import Bond, Element, Expr, Graph, Multibond, Signal, Vector, part_name
from ..base.resources import max_statements, too_large

TWO_PORT_JUNCTIONS = {"transformer": ("1", "0"), "gyrator": ("1", "1")}


def _is_matrix(v) -> bool:
    return isinstance(v, sp.MatrixBase)


def _part(e: Expr | None, value) -> Expr | None:
    return None if e is None else Expr(value, e.refs, e.span)


def _scalar(e: Expr | None, what: str) -> Expr | None:
    if e is not None and _is_matrix(e.value):
        fail(e.span, f"{what} is a scalar element's value, but this is a vector or a matrix "
                     f"(write the element as KIND[n] for a multiport)")
    return e


def _scalar_element(el: Element) -> None:
    """A scalar element's value, law and initial value are scalars."""
    _scalar(el.value, f"'{el.name}'")
    for what, given in (("law", el.law), ("initial value", el.init)):
        if given is not None and _is_matrix(given[1].value):
            fail(given[1].span, f"the {what} of '{el.name}' is a scalar, but this is a vector "
                                "or a matrix")


def _one_row(el: Element) -> Element:
    """A scalar constraint junction (also 0[1]) whose annotation or gains are written as
    vectors of one row: their entry."""
    c = el.constraint
    if c is None:
        return el
    gains = [_part(g, _rows(g, 1, f"a gain of '{el.name}'", False)[0]) for g in c.gains]
    ann = c.annotation
    if ann is not None:
        which, e = ann
        ann = (which, _part(e, _rows(e, 1, f"the '{which}' of '{el.name}'", False)[0]))
    return replace(el, constraint=replace(c, gains=tuple(gains), annotation=ann))


def _rows(e: Expr, n: int, what: str, diagonal_ok: bool) -> list:
    """The n component values of a multiport's value: a scalar broadcast, a vector of n, or
    (diagonal_ok) a diagonal n x n matrix."""
    v = e.value
    if not _is_matrix(v):
        return [v] * n
    if v.shape == (n, 1):
        return list(v)
    if diagonal_ok and v.shape == (n, n):
        off = [v[i, j] for i in range(n) for j in range(n) if i != j and v[i, j] != 0]
        if off:
            fail(e.span, f"{what}: a coupled (non-diagonal) matrix is not supported for this "
                         "element yet; only a scalar, a vector or a diagonal matrix")
        return [v[i, i] for i in range(n)]
    shape = f"{v.rows}x{v.cols}" if v.cols > 1 else f"a vector of {v.rows}"
    fail(e.span, f"{what} has dimension {n}, but its value is {shape}")


def _one_port(el: Element, n: int) -> list[Element]:
    spec = el.spec
    if el.law is not None:
        fail(el.span, f"'{el.name}': a multiport {el.kind} takes a value, not a law (a law "
                      "per component: declare scalar elements)")
    storage_like = spec.role in ("storage", "resistor")
    v = el.value.value
    if el.kind in ("I", "C", "R") and _is_matrix(v) and v.shape == (n, n) and any(
            v[i, j] != 0 for i in range(n) for j in range(n) if i != j):
        return _coupled_field(el, n)
    values = _rows(el.value, n, f"'{el.name}' ({el.kind}[{n}])", storage_like)
    inits = None
    if el.init is not None:
        inits = _rows(el.init[1], n, f"the initial value of '{el.name}'", False)
    return [replace(el, name=part_name(el.name, i), value=_part(el.value, values[i]),
                    init=None if inits is None else (el.init[0], _part(el.init[1], inits[i])),
                    dim=None, origin=el.name)
            for i in range(n)]


def _coupled_field(el: Element, n: int) -> list[Element]:
    """A field with a full matrix (I: M f = p, C: K e = q, R: e = R f): n parts that each keep
    all of it (the equations stage couples them; the storage fields' solves are made in the
    generated code)."""
    v = el.value.value
    what = {"I": "mass matrix", "C": "capacitance matrix", "R": "resistance matrix"}[el.kind]
    for i in range(n):
        for j in range(i):
            d = v[i, j] - v[j, i]
            if el.kind != "R" and d != 0 and not is_zero(d):
                fail(el.value.span, f"the {what} of '{el.name}' is not symmetric: entries "
                                    f"[{i}][{j}] and [{j}][{i}] differ")
    inits = None
    if el.init is not None:
        state = el.spec.state
        if el.init[0] != state:
            fail(el.init[1].span, f"'{el.name}' is a coupled field: give its states "
                                  f"('init {state} = [...]')")
        inits = _rows(el.init[1], n, f"the initial value of '{el.name}'", False)
    return [replace(el, name=part_name(el.name, i), dim=None, origin=el.name,
                    init=None if inits is None else (el.init[0], _part(el.init[1], inits[i])))
            for i in range(n)]


def _junction(el: Element, n: int) -> list[Element]:
    c = el.constraint
    if c is not None:
        gains = [_rows(g, n, f"a gain of '{el.name}'", False) for g in c.gains]
        if c.annotation is not None:
            which, e = c.annotation
            values = _rows(e, n, f"the '{which}' of '{el.name}'", False)
    parts = []
    for i in range(n):
        ci = None
        if c is not None:
            ann = None if c.annotation is None else (which, _part(e, values[i]))
            ci = replace(c, gains=tuple(_part(g, rows[i]) for g, rows in zip(c.gains, gains)),
                         annotation=ann)
        parts.append(replace(el, name=part_name(el.name, i), constraint=ci, dim=None,
                             origin=el.name))
    return parts


def _two_port(el: Element, n: int, m: int) -> tuple[list[Element], list[Bond]]:
    """The scalar network of a multiport transformer or gyrator (see the module docstring)."""
    v = el.value.value
    if not _is_matrix(v):
        if n != m:
            fail(el.value.span, f"'{el.name}' maps {n} to {m}: its modulus is a {m}x{n} "
                                "matrix, not a scalar")
        entries = [(i, i, v) for i in range(n)] if v != 0 else []
    elif v.shape != (m, n):
        fail(el.value.span, f"'{el.name}' ({el.kind}[{n}->{m}]) takes a {m}x{n} matrix; this "
                            f"one is {v.rows}x{v.cols}")
    else:  # a matrix written out (or made by diag()): its entries are bounded by the text
        entries = [(i, j, v[i, j]) for i in range(m) for j in range(n) if v[i, j] != 0]
    left, right = TWO_PORT_JUNCTIONS[el.spec.role]
    scalar_kind = "MTF" if el.spec.role == "transformer" else "MGY"
    common = dict(value=None, law=None, init=None, constraint=None, dim=None, origin=el.name)
    ins = [replace(el, name=f"{el.name}.in[{j}]", kind=left, **common) for j in range(n)]
    outs = [replace(el, name=f"{el.name}.out[{i}]", kind=right, **common) for i in range(m)]
    parts, bonds = ins + outs, []
    for i, j, value in entries:
        name = f"{el.name}[{i},{j}]"
        parts.append(replace(el, name=name, kind=scalar_kind, law=None, init=None,
                             value=_part(el.value, value), dim=None, origin=el.name))
        bonds.append(Bond(ins[j].name, name, f"{ins[j].name}->{name}", el.span))
        bonds.append(Bond(name, outs[i].name, f"{name}->{outs[i].name}", el.span))
    return parts, bonds


def _check_size(g: Graph):
    """Refuse, before making them, more scalar parts than a compile can take (max_statements;
    a two-port counts its junctions and its entries, a bond its components)."""
    total = 0
    most = max_statements()
    for item in list(g.elements) + list(g.signals) + list(g.bonds):
        dim = getattr(item, "dim", None)
        if isinstance(item, Bond):
            total += _port(g.by_name[item.src], True)[0]
        elif isinstance(item, Element) and dim is not None and not item.is_junction \
                and item.spec.ports == 2:
            n, m = dim
            v = item.value.value
            total += n + m + (len(v) if _is_matrix(v) else n)
        elif dim is not None:
            total += dim[0] if isinstance(dim, tuple) else dim
        else:
            total += 1
        if total > most:
            fail(item.span, too_large(f"the more than {most} scalar elements, signals and "
                                      "bonds of its multiports once split", total))


def _port(el: Element, as_source: bool) -> tuple[int, bool]:
    """(dimension, expanded?) of the element's port that a bond leaves (as_source) or enters."""
    if el.dim is None:
        return 1, False
    n, m = el.dim
    if not el.is_junction and el.spec.ports == 2:
        return (m if as_source else n), True
    return n, True


def _end(el: Element, as_source: bool, i: int) -> str:
    if el.dim is None:
        return el.name
    if not el.is_junction and el.spec.ports == 2:
        return f"{el.name}.out[{i}]" if as_source else f"{el.name}.in[{i}]"
    return part_name(el.name, i)


def _describe(el: Element) -> str:
    if el.dim is None:
        return el.kind
    n, m = el.dim
    return f"{el.kind}[{n}->{m}]" if n != m else f"{el.kind}[{n}]"


def flatten(g: Graph) -> Graph:
    """The scalar graph of g (g itself when it has no multiport and no vector signal)."""
    diags = Collector()
    if not any(el.dim for el in g.elements) and not any(s.dim for s in g.signals):
        elements = []
        for el in g.elements:
            try:
                _scalar_element(el)
                elements.append(_one_row(el))
            except ModelError as exc:
                diags.items.extend(exc.diagnostics)
        diags.raise_if_errors()
        return replace(g, elements=tuple(elements)) if elements != list(g.elements) else g
    _check_size(g)
    elements: list[Element] = []
    bonds: list[Bond] = []
    vectors: list[Vector] = []
    for el in g.elements:
        try:
            if el.dim is None:
                _scalar_element(el)
                elements.append(_one_row(el))
                continue
            n, m = el.dim
            vectors.append(Vector(el.name, "element", m, el.kind, el.constraint is not None))
            if el.is_junction:
                elements += _junction(el, n)
            elif el.spec.ports == 2:
                parts, inner = _two_port(el, n, m)
                elements += parts
                bonds += inner
            else:
                elements += _one_port(el, n)
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    by_name = g.by_name
    multibonds = []
    for b in g.bonds:
        a, c = by_name[b.src], by_name[b.dst]
        (na, va), (nc, vc) = _port(a, True), _port(c, False)
        if na != nc:
            diags.error(b.span, f"bond '{b.src} -> {b.dst}' joins a port of dimension {na} "
                                f"('{b.src}', {_describe(a)}) to one of dimension {nc} "
                                f"('{b.dst}', {_describe(c)})")
            continue
        if not va and not vc:
            bonds.append(b)
            continue
        parts = []
        for i in range(na):
            label = b.label if na == 1 else f"{b.label}[{i}]"
            bonds.append(Bond(_end(a, True, i), _end(c, False, i), label, b.span, b.ports, i))
            parts.append(label)
        multibonds.append(Multibond(b.label, b.src, b.dst, na, tuple(parts), b.span))
    signals = []
    for s in g.signals:
        if s.dim is None:
            signals.append(s)
            continue
        vectors.append(Vector(s.name, "signal", s.dim, "signal"))
        values = list(s.expr.value)
        inits = None if s.init is None else _rows(s.init, s.dim, f"the initial value of "
                                                                 f"'{s.name}'", False)
        for i in range(s.dim):
            signals.append(Signal(part_name(s.name, i), _part(s.expr, values[i]),
                                  None if inits is None else _part(s.init, inits[i]), s.span,
                                  unit=s.unit, order=s.order))
    diags.raise_if_errors()
    return replace(g, elements=tuple(elements), bonds=tuple(bonds), signals=tuple(signals),
                   vectors=tuple(vectors), multibonds=tuple(multibonds))


__all__ = ["flatten"]
