"""`bgc equations --format latex`: the reduced equations as a modeller writes them.

Names become the paper's notation: a momentum is p with a subscript (`mx.p` is p_{x} when
the signal x integrates mx's flow, as the paper's p_x for the coordinate x; else p_{mx}),
likewise q, e and f; a multiplier is λ with its junction as subscript (λ_{rod}), a
constraint's residual Φ_{rod}; a parameter named after a Greek letter is that letter
(alpha → α, theta0 → θ_0), trailing digits and what follows a first underscore become a
subscript; a state's derivative is dotted (\\dot{p}_{x}).  Any name that two symbols would
share falls back to the names as written, so the map from symbols to LaTeX names is one to one
(`LatexSystem.names`).  Every piece of a name from the model text is escaped.

Each right side is tidied by bounded, targeted rewrites only (sin² + cos² = 1, c − c cos² =
c sin², then SymPy's factor_terms), never by a general simplifier, and only for expressions
within the symbolic limits of bgc/base/resources.py; anything larger is printed as it is.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import sympy as sp

from ..base import resources
from ..front.graph import variable_name
from ..middle.reduce import BlockInfo, explicit_forms, shown_steps

GREEK = frozenset(
    "alpha beta gamma delta epsilon zeta eta theta iota kappa lambda mu nu xi pi rho sigma "
    "tau upsilon phi chi psi omega Gamma Delta Theta Lambda Xi Pi Sigma Upsilon Phi Psi "
    "Omega".split())
_ALIASES = {"eps": r"\varepsilon"}
VARIABLES = {"p": "p", "q": "q", "e": "e", "f": "f", "lambda": r"\lambda", "residual": r"\Phi",
             "balance": "B"}

# the nodes of an expression (as resources.fits walks it) up to which the rewrites are tried
TIDY_MAX_NODES = 5_000

_ESCAPES = {"\\": r"\text{\textbackslash}", "_": r"\_", "{": r"\{", "}": r"\}", "$": r"\$",
            "%": r"\%", "#": r"\#", "&": r"\&", "^": r"\text{\textasciicircum}",
            "~": r"\text{\textasciitilde}"}
_SAFE = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789"
                  " .,;:()[]+-*/=<>!?'|@")


def escape(text: str) -> str:
    """text safe inside \\mathrm{...} in math mode: LaTeX's special characters escaped, any
    other character outside plain ASCII punctuation and letters written as '?'."""
    return "".join(_ESCAPES.get(c) or (c if c in _SAFE else "?") for c in text)


def _word(w: str) -> str:
    if w in GREEK:
        return "\\" + w
    if w in _ALIASES:
        return _ALIASES[w]
    if len(w) == 1 or w.isdigit():
        return escape(w)
    return r"\mathrm{" + escape(w) + "}"


_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_DIGITS = re.compile(r"([A-Za-z]+?)([0-9]+)")
_INDEXED = re.compile(r"([A-Za-z][A-Za-z0-9_]*)\[([0-9]+)\]")
_ELEMENT_VAR = re.compile(r"([A-Za-z][A-Za-z0-9_]*)\.([a-z]+)(?:\[([0-9]+)\])?")
_DER = re.compile(r"der\((.*)\)")
_BOND = re.compile(r"([ef])\[(.+)->(.+)\]")


@dataclass(frozen=True)
class _Name:
    base: str
    sub: str | None = None

    def text(self) -> str:
        return self.base if self.sub is None else f"{self.base}_{{{self.sub}}}"

    def dot(self) -> str:
        return rf"\dot{{{self.base}}}" + ("" if self.sub is None else f"_{{{self.sub}}}")

    def indexed(self, index: str) -> _Name:
        return _Name(self.base, index if self.sub is None else f"{self.sub},{index}")


def identifier(name: str) -> _Name:
    """A model identifier: theta0 -> θ_0, tau_load -> τ_load, x -> x, Ra -> Ra upright."""
    if not _IDENT.fullmatch(name):
        return _Name(r"\mathrm{" + escape(name) + "}")
    head, sep, tail = name.partition("_")
    if sep and tail:
        return _Name(_word(head), _word(tail))
    m = _DIGITS.fullmatch(name)
    if m and not (name in GREEK or name in _ALIASES):
        return _Name(_word(m.group(1)), m.group(2))
    return _Name(_word(name))


def _subscript(name: str) -> str:
    """An element or signal name as a subscript (its index after a comma)."""
    m = _INDEXED.fullmatch(name)
    if m:
        return f"{identifier(m.group(1)).text()},{m.group(2)}"
    return identifier(name).text()


def _primary(name: str, coordinates: dict) -> _Name:
    """The modeller's name of a symbol named `name` (see the module's doc)."""
    m = _DER.fullmatch(name)
    if m:  # (printed dotted by the caller; here only as a symbol inside an expression)
        return _Name(_primary(m.group(1), coordinates).dot())
    if name in coordinates:
        return _Name("p", _subscript(coordinates[name]))
    m = _BOND.fullmatch(name)
    if m:  # a bond's effort or flow: e_{src -> dst}
        return _Name(m.group(1), rf"{_subscript(m.group(2))} \to {_subscript(m.group(3))}")
    m = _ELEMENT_VAR.fullmatch(name)
    if m and m.group(2) in VARIABLES:
        sub = identifier(m.group(1)).text()
        if m.group(3) is not None:
            sub += "," + m.group(3)
        return _Name(VARIABLES[m.group(2)], sub)
    m = _INDEXED.fullmatch(name)
    if m:
        return identifier(m.group(1)).indexed(m.group(2))
    return identifier(name)


def _fallback(name: str) -> _Name:
    m = _DER.fullmatch(name)
    if m:
        return _Name(_fallback(m.group(1)).dot())
    return _Name(r"\mathrm{" + escape(name) + "}")


def coordinates(graph) -> dict[str, str]:
    """{momentum symbol name: coordinate signal}: an I element on a 1-junction whose flow one
    integral signal integrates (signal x = integral(vx.f)) has the momentum p_x."""
    neighbours: dict[str, list[str]] = {}
    for b in graph.bonds:
        neighbours.setdefault(b.src, []).append(b.dst)
        neighbours.setdefault(b.dst, []).append(b.src)
    integrating: dict[str, list[str]] = {}  # flow symbol name -> integral signals of it
    for s in graph.signals:
        value = s.expr.value if s.is_integral else None
        if isinstance(value, sp.Symbol):
            integrating.setdefault(value.name, []).append(s.name)
    out = {}
    for el in graph.elements:
        ends = neighbours.get(el.name, [])
        if el.kind != "I" or len(ends) != 1:
            continue
        junction = graph.by_name.get(ends[0])
        flows = [variable_name(el.name, "f")]
        if junction is not None and junction.kind == "1":
            flows.append(variable_name(junction.name, "f"))
        signals = [s for f in flows for s in integrating.get(f, ())]
        if len(signals) == 1:
            out[variable_name(el.name, "p")] = signals[0]
    return out


def tex_names(names, coords: dict) -> dict[str, _Name]:
    """A one-to-one map from symbol names to LaTeX names: each its primary name unless two
    share one, those then as written (upright, escaped)."""
    primary = {n: _primary(n, coords) for n in names}
    count: dict[str, int] = {}
    for t in primary.values():
        count[t.text()] = count.get(t.text(), 0) + 1
    out = {n: (t if count[t.text()] == 1 else _fallback(n)) for n, t in primary.items()}
    if len({t.text() for t in out.values()}) < len(out):  # (cannot happen; but never merge)
        out = {n: _fallback(n) for n in names}
    return out


# ---------------------------------------------------------------- targeted trigonometry


def _square_of_trig(factor):
    if factor.is_Pow and factor.exp == 2 and isinstance(factor.base, (sp.sin, sp.cos)):
        return factor.base.func, factor.base.args[0]
    return None


def _pythagoras_add(add: sp.Add) -> sp.Expr:
    """In a sum: r sin²a + r cos²a -> r; r cos²a - r -> -r sin²a; r sin²a - r -> -r cos²a."""
    terms = list(add.args)
    squares = {}  # (func, arg, rest) -> index of the term rest * func(arg)**2
    for i, term in enumerate(terms):
        factors = sp.Mul.make_args(term)
        for j, f in enumerate(factors):
            trig = _square_of_trig(f)
            if trig is not None:
                rest = sp.Mul(*(factors[:j] + factors[j + 1:]))
                squares.setdefault((trig[0], trig[1], rest), i)
                break
    if not squares:
        return add
    used, new = set(), []
    index = {t: i for i, t in reversed(list(enumerate(terms)))}
    for (func, arg, rest), i in squares.items():
        if i in used:
            continue
        other = sp.cos if func is sp.sin else sp.sin
        j = squares.get((other, arg, rest))
        if j is not None and j not in used:
            used.update((i, j))
            new.append(rest)
            continue
        k = index.get(-rest)
        if k is not None and k not in used and k != i:
            used.update((i, k))
            new.append(-rest * other(arg) ** 2)
    if not used:
        return add
    return sp.Add(*[t for i, t in enumerate(terms) if i not in used], *new)


def _negated_sum(e) -> bool:
    """-(a + b) as factor_terms leaves it unevaluated (printed "- (a + b)"): to be a - b."""
    return e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and e.args[1].is_Add


def tidy(expr):
    """expr with its sums of squared sines and cosines reduced and common factors pulled out
    (factor_terms); as it is when it is past the limits."""
    if not isinstance(expr, sp.Basic) or not resources.fits(expr, TIDY_MAX_NODES):
        return expr
    if expr.has(sp.sin, sp.cos):
        expr = expr.replace(lambda e: e.is_Add, _pythagoras_add)
    expr = sp.factor_terms(expr).replace(_negated_sum, lambda e: sp.Mul(*e.args))
    if expr.has(sp.sin, sp.cos):
        expr = expr.replace(lambda e: e.is_Add, _pythagoras_add)
    return expr


# ---------------------------------------------------------------- the system


@dataclass(frozen=True)
class Row:
    """One line of the align environment: `lhs &= rhs` (rhs the expression printed), or, when
    rhs is None, lhs as it is (a block's heading)."""
    lhs: str
    rhs: object


@dataclass(frozen=True)
class LatexSystem:
    header: str
    rows: tuple[Row, ...]
    names: dict  # symbol name -> its LaTeX name, one to one

    def row(self, lhs: str) -> Row:
        (found,) = [r for r in self.rows if r.lhs == lhs]
        return found

    def text(self) -> str:
        symbol_names = {}
        for r in self.rows:
            if r.rhs is not None:
                for s in r.rhs.free_symbols:
                    symbol_names[s] = self.names[s.name]
        lines = [r.lhs if r.rhs is None else
                 f"{r.lhs} &= {sp.latex(r.rhs, symbol_names=symbol_names)}" for r in self.rows]
        body = " \\\\\n".join(lines)
        return f"% {self.header}\n\\begin{{align}}\n{body}\n\\end{{align}}\n"


def latex_system(compiled, header: str) -> LatexSystem:
    """The rows of `bgc equations --format latex`: the state equations, the multipliers and
    the other outputs, each right side in the states, parameters and t; or, when blocks are
    solved in the generated code, the program in its evaluation order (a block headed by a
    row `& \\text{block k, ...}`)."""
    r = compiled.reduced
    multipliers = [k.multiplier for k in r.constraints]
    states = {st.symbol for st in r.states}
    shown = [o.expr for o in r.outputs
             if isinstance(o.expr, sp.Symbol) and o.expr not in states
             and o.expr not in multipliers]
    forms = explicit_forms(r, list(r.rates) + multipliers + shown)
    pairs = []  # (lhs symbol, rhs), or (text, None)
    if forms is not None:
        pairs += [(d, forms[d]) for d in r.rates]
        pairs += [(m, forms[m]) for m in multipliers + shown if forms[m] != m]
    else:
        for step in shown_steps(r):
            if isinstance(step, BlockInfo):
                how = "LU" if step.method == "lu" else "Newton's method"
                pairs.append(((step.index, how, step.unknowns), None))
                pairs += [(0, e) for e in step.residuals]
                pairs += [(a.target, a.expr) for a in step.body]
            else:
                pairs.append((step.target, step.expr))
    relations = {q.symbol: q.relation for q in getattr(compiled.graph, "relations", ())}
    pairs = [(lhs, tidy(rhs.xreplace(relations)) if rhs is not None else None)
             for lhs, rhs in pairs]  # (a relation as written, not its frozen value)
    symbols = set()
    for lhs, rhs in pairs:
        if isinstance(lhs, sp.Symbol):
            symbols.add(lhs.name)
        elif rhs is None:
            symbols.update(lhs[2])
        if rhs is not None:
            symbols.update(s.name for s in rhs.free_symbols)
    names = tex_names(sorted(symbols), coordinates(compiled.graph))
    tex = {n: t.text() for n, t in names.items()}
    rows = []
    for lhs, rhs in pairs:
        if rhs is None:
            index, how, unknowns = lhs
            rows.append(Row(rf"& \text{{block {index}, solved numerically ({how}), for }} "
                            + ", ".join(tex[u] for u in unknowns) + ":", None))
        elif isinstance(lhs, sp.Symbol):
            rows.append(Row(tex[lhs.name], rhs))
        else:
            rows.append(Row("0", rhs))
    return LatexSystem(header.replace("\n", " "), tuple(rows), tex)
