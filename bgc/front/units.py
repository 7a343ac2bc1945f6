"""Stage: units.  Graph (flat) -> Graph with the unit of every quantity it can tell, after every
law is checked for dimensional consistency (docs/units.md).

Each quantity of the model has a dimension: a vector of exponents of the SI base dimensions
(m, kg, s, A, K, mol, cd, and rad, which is carried for display but not checked: an angle is a
number).  Some are known: declared (`unit "kg"` on a parameter, a signal, an input; a port's
unit is its effort's), from a port's domain (electrical V and A, translational N and m/s,
rotational N*m and rad/s, hydraulic Pa and m^3/s, thermal K and W, planar (N, N, N*m) and
(m/s, m/s, rad/s)), time in s.  The others are unknowns: each bond's effort and flow, each
parameter and signal not declared.  Every law is an equation between dimensions, linear in
the exponents: a product adds them, a power multiplies them, the terms of a sum and the two
sides of a relation are equal, a function's argument (sin, exp, log, ...) is dimensionless.
A number written in the model takes any dimension (a fresh unknown per occurrence: `2*x`
adds nothing to what is known of x, `x - y` says x and y agree; `Se(12)` is 12 V).

The equations are solved by propagation (a worklist: an equation with one unknown left gives
it; one with none is checked), which is linear in the model's size.  An equation that does not
hold is a located error naming both units, with a note for each unit it inferred and where
from; what stays unknown is not guessed.  A declared unit with a scale (mm, kN, deg) is a
warning: bgc does not convert, the number enters the equations as it is written.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from fractions import Fraction

import sympy as sp

from ..base import si
from ..base.diagnostics import Collector, Note, Span
from .graph import TIME, Graph, part_name, variable_name, written

N_DIMS = len(si.BASE)  # the last, rad, is not checked
CHECKED = N_DIMS - 1
# exponents are kept as integers times SCALE (exact for every denominator up to 10: Pa^0.5,
# x^(1/3)); arithmetic on them is Python's int, a Fraction only where a division needs it
SCALE = 2520
ZERO = (0,) * N_DIMS
MAX_NOTES = 6  # of an error: the declarations and laws that led to the units it names
MAX_TRACE = 200  # quantities followed back to find them
MAX_ELIMINATION = 64  # unknowns of a loop solved by elimination (beyond: left unknown)

_EFFORT_FLOW = {  # domain -> (effort units, flow units), one per component of a vector port
    "electrical": (("V",), ("A",)),
    "translational": (("N",), ("m/s",)),
    "rotational": (("N*m",), ("rad/s",)),
    "hydraulic": (("Pa",), ("m^3/s",)),
    "thermal": (("K",), ("W",)),
    "planar": (("N", "N", "N*m"), ("m/s", "m/s", "rad/s")),
}
DOMAINS = {name: (tuple(si.parse(u).dims for u in e), tuple(si.parse(u).dims for u in f))
           for name, (e, f) in _EFFORT_FLOW.items()}

# dimensionless argument, dimensionless value
_PLAIN_FUNCTIONS = (sp.sin, sp.cos, sp.tan, sp.asin, sp.acos, sp.atan, sp.sinh, sp.cosh,
                    sp.tanh, sp.asinh, sp.acosh, sp.atanh, sp.exp, sp.log)
_SAME_FUNCTIONS = (sp.Abs, sp.floor, sp.ceiling)  # the value has the argument's dimension


@dataclass
class _Form:
    """A dimension as a linear form: sum of coefficient * unknown, plus a constant vector."""

    terms: dict
    const: tuple

    def plus(self, other: "_Form", k=1) -> "_Form":
        terms = dict(self.terms)
        for i, c in other.terms.items():
            v = terms.get(i, 0) + k * c
            if v:
                terms[i] = v
            else:
                del terms[i]
        if other.const == ZERO:
            return _Form(terms, self.const)
        return _Form(terms, tuple(a + k * b for a, b in zip(self.const, other.const)))

    def times(self, k) -> "_Form":
        if not k:
            return _Form({}, ZERO)
        return _Form({i: k * c for i, c in self.terms.items()},
                     self.const if self.const == ZERO else tuple(_exact(k * a)
                                                                 for a in self.const))


def _exact(v):
    """v as an int where it is one (a Fraction's arithmetic is slow)."""
    return int(v) if not isinstance(v, int) and v.denominator == 1 else v


def _subtract(coef: dict, const, pivot, row: dict, row_const):
    """coef (in place) and const less the multiple of row that clears coef's pivot entry;
    the new const."""
    c = coef.get(pivot)
    if not c:
        return const
    f = _div(c, row[pivot])
    for i, v in row.items():
        coef[i] = coef.get(i, 0) - f * v
        if not coef[i]:
            del coef[i]
    return [a - f * b for a, b in zip(const, row_const)]


def _div(a, c):
    """a / c, exactly."""
    if c == 1:
        return a
    if c == -1:
        return -a
    return _exact(Fraction(a) / c)


def _known(dims) -> _Form:
    return _Form({}, tuple(_exact(Fraction(d) * SCALE) for d in dims))


_SECOND = _known(si.s.dims)
_PER_SECOND = _known((si.ONE / si.s).dims)
_ONE = _known(ZERO)


@dataclass(frozen=True)
class _Where:
    span: Span | None
    what: str  # "the law of 'r'"
    note: Note | None = None  # where the unit it holds to is declared (a port)


@dataclass
class _Equation:
    lhs: _Form
    rhs: _Form
    where: _Where
    lhs_text: str
    rhs_text: str


class _Units:
    def __init__(self, g: Graph, diags: Collector):
        self.g = g
        self.diags = diags
        self.names: list = []  # id -> the quantity's name (None: a number's or an event's)
        self.by_name: dict = {}
        self.value: dict = {}  # id -> its dimension vector, once known
        self.declared: dict = {}  # id -> the unit as declared (display)
        self.why: dict = {}  # id -> the equation that gave it
        self.equations: list[_Equation] = []
        self.alias: dict = {}  # model variable name -> its form over the bonds' unknowns
        self.declarations = 0  # units declared, ports of a known domain
        self.same: dict = {}  # name -> a name it is merged with (merge)

    # ------------------------------------------------------------ unknowns
    def merge(self, a: str, b: str):
        """a and b are one quantity (a junction's bonds share its effort and its flow): one
        unknown for both, before any equation is written (union-find over the names)."""
        ra, rb = self.rep(a), self.rep(b)
        if ra != rb:
            self.same[rb] = ra
        self.same.setdefault(a, a)
        self.same.setdefault(b, b)

    def rep(self, name: str) -> str:
        same = self.same
        while same.get(name, name) != name:
            same[name] = same.get(same[name], same[name])
            name = same[name]
        return name

    def unknown(self, name: str | None) -> int:
        if name is not None:
            name = self.rep(name)
            if name in self.by_name:
                return self.by_name[name]
        i = len(self.names)
        self.names.append(name)
        if name is not None:
            self.by_name[name] = i
        return i

    def form_of(self, name: str) -> _Form:
        if name in self.alias:
            return self.alias[name]
        return _Form({self.unknown(name): 1}, ZERO)

    def declare(self, name: str, unit: str | None, span: Span | None, what: str):
        """name's unit as declared (a bad string was refused by the parser)."""
        if not unit:
            return
        self.declarations += 1
        u = si.parse(unit)
        if u.scale != 1.0:
            self.diags.warning(span, f"unit '{unit}' of {what} is {u.scale:g} {si.show(u)}: bgc "
                                     "does not convert units, the value enters the equations as "
                                     f"the number written (write it in {si.show(u)})")
        self.equal(self.form_of(name), _known(u.dims), _Where(span, f"the unit of {what}"),
                   f"'{name}'", f"the declared '{unit}'")
        if name in self.by_name:
            self.declared.setdefault(self.by_name[name], unit)

    def equal(self, lhs: _Form, rhs: _Form, where: _Where, lhs_text: str, rhs_text: str):
        self.equations.append(_Equation(lhs, rhs, where, lhs_text, rhs_text))

    # ------------------------------------------------------------ expressions
    def form(self, expr, where: _Where) -> _Form | None:
        """expr's dimension (None for a condition), its inner equations added (the terms of
        a sum, a function's argument, a relation's sides).  Post-order with a stack."""
        done: list = []
        todo: list = [(False, expr)]
        while todo:
            ready, node = todo.pop()
            if not ready:
                if isinstance(node, sp.MatrixBase):
                    done.append(self.wild())
                    continue
                todo.append((True, node))
                todo.extend((False, a) for a in reversed(self._operands(node)))
                continue
            k = len(self._operands(node))
            args = done[len(done) - k:] if k else []
            del done[len(done) - k:]
            done.append(self._combine(node, args, where))
        (value,) = done
        return value

    @staticmethod
    def _operands(node):
        if isinstance(node, sp.Piecewise):
            return [x for pair in node.args for x in pair]
        if isinstance(node, (sp.Symbol, sp.Number, sp.MatrixBase)) or not node.args:
            return []
        if isinstance(node, sp.Pow) and node.exp.is_Number:
            return [node.base]
        return list(node.args)

    def wild(self) -> _Form:
        return _Form({self.unknown(None): 1}, ZERO)

    def _combine(self, node, args, where: _Where):
        if isinstance(node, sp.Symbol):
            if node == TIME:
                return _SECOND
            name = node.name
            if name in self.alias or name in self.by_name:
                return self.form_of(name)
            return self.wild()  # an event's value, a table's piece, an input's segment
        if isinstance(node, sp.Number):
            return self.wild()
        if isinstance(node, (sp.logic.boolalg.BooleanAtom,)):
            return None
        if isinstance(node, sp.Mul):
            out = _Form({}, ZERO)
            for a, f in zip(node.args, args):
                if a == -1 or f is None:  # a minus sign
                    continue
                out = out.plus(f)
            return out
        if isinstance(node, sp.Add):
            return self._same(node.args, args, where, "the terms of a sum")
        if isinstance(node, sp.Pow):
            if node.exp.is_Number:
                return args[0].times(Fraction(str(node.exp)) if node.exp.is_Float
                                     else Fraction(int(node.exp.p), int(node.exp.q)))
            base, exp = args
            self._plain(node.base, base, where, "the base of a power with a variable exponent")
            self._plain(node.exp, exp, where, "an exponent")
            return _ONE
        if isinstance(node, sp.Piecewise):
            values = args[0::2]
            return self._same(node.args and [v for v, _ in node.args], values, where,
                              "the values of the branches of an if")
        if isinstance(node, sp.core.relational.Relational):
            self._same(node.args, args, where, "the two sides of a relation")
            return None
        if isinstance(node, sp.logic.boolalg.Boolean):
            return None
        if isinstance(node, (sp.Min, sp.Max)):
            return self._same(node.args, args, where, f"the arguments of {_fname(node)}()")
        if isinstance(node, sp.atan2):
            self._same(node.args, args, where, "the arguments of atan2()")
            return _ONE
        if isinstance(node, sp.sign):
            return _ONE
        if isinstance(node, _PLAIN_FUNCTIONS):
            for a, f in zip(node.args, args):
                self._plain(a, f, where, f"the argument of {_fname(node)}()")
            return _ONE
        if isinstance(node, _SAME_FUNCTIONS):
            return args[0]
        return self.wild()  # a table, a guard: its value's dimension is not known here

    def _same(self, exprs, forms, where, what):
        first = None
        for e, f in zip(exprs, forms):
            if f is None:
                continue
            if first is None:
                first = (e, f)
                continue
            self.equal(first[1], f, _Where(where.span, f"{what} in {where.what}"),
                       _Quote(first[0]), _Quote(e))
        return first[1] if first is not None else None

    def _plain(self, expr, f, where, what):
        if f is not None:
            self.equal(f, _ONE, _Where(where.span, f"{what} in {where.what}"),
                       _Quote(expr), "a number (dimensionless)")

    def law(self, lhs_name: str, expr, where: _Where, lhs_text: str | None = None):
        """lhs_name's dimension is that of expr (an Expr or a SymPy value)."""
        value = getattr(expr, "value", expr)
        f = self.form(value, where)
        if f is not None:
            self.equal(self.form_of(lhs_name), f, where, lhs_text or f"'{lhs_name}'",
                       _Quote(value))

    # ------------------------------------------------------------ solving
    def solve(self):
        """Propagation: each equation with one unknown left gives it; one with none is
        checked (linear in the total size of the equations).  Where it stalls, on loops whose
        equations each hold two unknowns or more (a motor's gyrator between an electrical and
        a mechanical side), elimination over the small loops that remain gives the unknowns
        they determine, and propagation goes on from them."""
        self.residual = [eq.lhs.plus(eq.rhs, -1) for eq in self.equations]
        self.uses: dict = {}
        for k, r in enumerate(self.residual):
            for i in r.terms:
                self.uses.setdefault(i, []).append(k)
        # one error for the mismatches of a connected part (they follow from one another)
        parent = list(range(len(self.names)))
        self._parent = parent
        for r in self.residual:
            ids = list(r.terms)
            for i in ids[1:]:
                a, b = self._find(ids[0]), self._find(i)
                if a != b:
                    parent[max(a, b)] = min(a, b)
        self.failed: set = set()
        self.reported: dict = {}
        self._propagate([k for k, r in enumerate(self.residual) if len(r.terms) <= 1])
        # (elimination only where there is something to check against: a model that declares
        # no unit gets what propagation gives it, time's s)
        for _ in range(len(self.names) + 1 if self.declarations else 0):
            found = self._eliminate()
            if not found:
                break
            self._propagate(found)
        if self.declarations:
            for k, more in self.reported.values():
                self._report(k, more)
        elif self.reported:
            self.diags.error(None, "units: the laws do not agree")  # (not checked: dropped)

    def _propagate(self, ready):
        # (a junction's bonds are one unknown already, merged: a conflict shows at a law or
        # a declaration, where it is, not at a bond that merely joins two laws)
        queue = list(ready)
        residual = self.residual
        head = 0
        while head < len(queue):
            k = queue[head]
            head += 1
            r = residual[k]
            open_ = [i for i in r.terms if i not in self.value]
            if len(open_) > 1:
                continue
            if not open_:
                if k not in self.failed and self._value(r)[:CHECKED] != ZERO[:CHECKED]:
                    self.failed.add(k)
                    root = self._root(r) if r.terms else ("alone", k)
                    if root not in self.reported:
                        self.reported[root] = [k, 0]
                    else:
                        self.reported[root][1] += 1
                continue
            (x,) = open_
            c = r.terms[x]
            rest = _Form({i: v for i, v in r.terms.items() if i != x}, r.const)
            self._set(x, tuple(_div(-a, c) for a in self._value(rest)), k)
            for j in self.uses[x]:
                queue.append(j)

    def _set(self, x: int, value: tuple, k: int):
        self.value[x] = value
        self.why[x] = k

    def _eliminate(self) -> list:
        """The unknowns that the equations still open determine together: the open ones
        peeled of every unknown that only one of them holds (it takes whatever they need:
        a number's), the rest eliminated exactly (fractions), each connected part of at most
        MAX_ELIMINATION unknowns; the equations to propagate from next."""
        open_eqs = [k for k, r in enumerate(self.residual)
                    if sum(i not in self.value for i in r.terms) >= 2]
        count: dict = {}
        for k in open_eqs:
            for i in self.residual[k].terms:
                if i not in self.value:
                    count[i] = count.get(i, 0) + 1
        alive = set(open_eqs)
        stack = [k for k in open_eqs
                 if any(count.get(i) == 1 for i in self.residual[k].terms)]
        while stack:
            k = stack.pop()
            if k not in alive:
                continue
            alive.discard(k)
            for i in self.residual[k].terms:
                if i in count:
                    count[i] -= 1
                    if count[i] == 1:
                        stack.extend(j for j in self.uses[i] if j in alive)
        parts: dict = {}
        for k in sorted(alive):
            parts.setdefault(self._find(next(iter(self.residual[k].terms))), []).append(k)
        found = []
        for rows in parts.values():
            unknowns = sorted({i for k in rows for i in self.residual[k].terms
                               if i not in self.value})
            if len(unknowns) > MAX_ELIMINATION:
                continue
            for x, value, k in self._solve_part(rows, unknowns):
                self._set(x, value, k)
                found.extend(self.uses[x])
        return found

    def _solve_part(self, rows, unknowns):
        """Gauss-Jordan over the fractions: (unknown, its value, an equation it came from) for
        each unknown the rows determine (a pivot row with no other unknown left).  A row
        that reduces to a mismatch is left for propagation to report where it is."""
        reduced = []  # (pivot, coefficients, constant, equation)
        for k in rows:
            r = self.residual[k]
            coef = {i: c for i, c in r.terms.items() if i not in self.value}
            const = list(r.const)
            for i, c in r.terms.items():
                if i in self.value:
                    const = [a + c * b for a, b in zip(const, self.value[i])]
            for pivot, pc, pconst, _ in reduced:
                const = _subtract(coef, const, pivot, pc, pconst)
            if not coef:
                continue  # (0 = const: a mismatch, reported by propagation at an equation)
            pivot = min(coef)
            for j, (p2, c2, k2, e2) in enumerate(reduced):
                reduced[j] = (p2, c2, _subtract(c2, k2, pivot, coef, const), e2)
            reduced.append((pivot, coef, const, k))
        out = []
        for pivot, coef, const, k in reduced:
            if len(coef) == 1:
                out.append((pivot, tuple(_div(-a, coef[pivot]) for a in const), k))
        return out

    def _find(self, i: int) -> int:
        parent = self._parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def _root(self, r: _Form):
        return self._find(next(iter(r.terms)))

    def _value(self, f: _Form, known_only: bool = False) -> tuple:
        """f's dimension; known_only: of its known terms (an unknown that both sides of an
        equation hold alike cancels, `z = integral(-z)`)."""
        out = list(f.const)
        for i, c in f.terms.items():
            if known_only and i not in self.value:
                continue
            v = self.value[i]
            for d in range(N_DIMS):
                out[d] += c * v[d]
        return tuple(out)

    def _report(self, k: int, more: int):
        """The error of equation k, with notes tracing each unit it inferred back to the
        declarations it came from (breadth first, a few steps)."""
        eq = self.equations[k]
        lhs, rhs = self._value(eq.lhs, True), self._value(eq.rhs, True)
        declared, laws, seen = [], [], set()
        todo = sorted(set(eq.lhs.terms) | set(eq.rhs.terms))
        while todo and len(seen) < MAX_TRACE:
            i = todo.pop(0)
            if i in seen or i not in self.why or self.names[i] is None:
                continue
            seen.add(i)
            source = self.equations[self.why[i]]
            if i in self.declared:
                declared.append(Note(source.where.span, f"{self._label(i)} is declared "
                                                        f"'{self.declared[i]}' here"))
                continue
            laws.append(Note(source.where.span, f"{self._label(i)} is "
                                                    f"{show(self.value[i])}, from "
                                                    f"{source.where.what}"))
            todo += sorted(j for j in set(source.lhs.terms) | set(source.rhs.terms) if j != i)
        notes = ([eq.where.note] if eq.where.note else []) + (declared + laws)[:MAX_NOTES]
        if more:
            notes.append(Note(None, f"{more} more unit mismatch{'es' if more > 1 else ''} "
                                    "of the same quantities follow from it"))
        self.diags.error(eq.where.span, f"unit mismatch in {eq.where.what}: {eq.lhs_text} is "
                                        f"{show(lhs)} but {eq.rhs_text} is {show(rhs)}", *notes)

    def _label(self, i: int) -> str:
        name = self.names[i]
        if name.startswith("bond "):
            label, what = name[5:].rsplit(".", 1)
            return f"the {dict(e='effort', f='flow')[what]} of bond '{label}'"
        return f"'{name}'"

    def units(self) -> tuple:
        """(name, unit) of every named quantity whose dimension is known: the declared
        spelling, else the one shown for its dimension; sorted by name."""
        out = {}
        for i, name in enumerate(self.names):
            if name is not None and not name.startswith("bond ") and i in self.value:
                out[name] = self.declared.get(i) or show(self.value[i])
        for name in self.same:  # (merged names: their representative's)
            i = self.by_name.get(self.rep(name))
            if not name.startswith("bond ") and i is not None and i in self.value:
                out[name] = self.declared.get(i) or show(self.value[i])
        for name, f in self.alias.items():
            if all(i in self.value for i in f.terms):
                out[name] = show(self._value(f))
        return tuple(sorted(out.items()))


def _fname(node) -> str:
    return {"Abs": "abs", "Min": "min", "Max": "max"}.get(type(node).__name__,
                                                          type(node).__name__)


class _Quote:
    """An expression quoted in a message, written only if the message is (str())."""

    __slots__ = ("expr", "before", "after")

    def __init__(self, expr, before: str = "", after: str = ""):
        self.expr, self.before, self.after = expr, before, after

    def __str__(self) -> str:
        return f"{self.before}'{_text(self.expr)}'{self.after}"


def _text(expr) -> str:
    text = written(expr)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------- display

_NAMED = ["V", "A", "N", "N*m", "W", "J", "Pa", "Ohm", "F", "H", "S", "Wb", "T", "kg",
          "m", "s", "K", "mol", "cd", "A*s", "m/s", "m/s^2", "rad/s", "rad/s^2", "rad", "m^2", "m^3",
          "m^3/s", "kg*m^2", "N*s", "N/m", "N*s/m", "N*m/rad", "N*m*s", "N*m*s/rad", "V*s/rad", "Pa*s/m^3",
          "J/K", "W/K", "1/s", "Hz"]
_SHOWN = {}
for _u in _NAMED:
    _SHOWN.setdefault(_known(si.parse(_u).dims).const, _u)


def ratio(num: str | None, den: str | None) -> str | None:
    """The unit of a quotient of quantities in units num and den (a gain: V/A shows as
    Ohm), None if either is unknown."""
    if not num or not den:
        return None
    try:
        a, b = si.parse(num), si.parse(den)
    except si.UnitError:
        return None
    return show(_known(tuple(x - y for x, y in zip(a.dims, b.dims))).const)


def show(dims) -> str:
    """A dimension (exponents times SCALE) as a unit: a named one where there is one (V,
    N*m, Ohm), else in base units; `1` for a number."""
    dims = tuple(dims)
    if dims in _SHOWN:
        return _SHOWN[dims]
    if not any(dims):
        return "1"
    return si.show(si.Unit(tuple(_exact(Fraction(d) / SCALE) for d in dims)))


# ---------------------------------------------------------------- the model's equations

_PART = re.compile(r"(.*)\[([0-9]+)\]")


def check_units(g: Graph) -> Graph:
    """g with its units (Graph.units: (name, unit) of every quantity whose unit is known),
    after every law is checked; a mismatch is a ModelError."""
    diags = Collector()
    u = _Units(g, diags)
    incident = g.incident
    for el in g.elements:  # a junction's bonds: its effort and its flow (one unknown each)
        if el.is_junction:
            e, f = variable_name(el.name, "e"), variable_name(el.name, "f")
            for k in incident[el.name]:
                label = g.bonds[k].label
                u.merge(e, f"bond {label}.e")
                u.merge(f, f"bond {label}.f")
    _bond_unknowns(u, g)
    _declarations(u, g)
    _elements(u, g)
    _signals_and_events(u, g)
    u.solve()
    if not u.declarations:  # nothing to check against but time: not checked (docs/units.md)
        return g if diags.errors else replace(g, units=u.units())
    diags.raise_if_errors()
    return replace(g, units=u.units(), units_checked=True, warnings=g.warnings + diags.warnings)


def _bond_unknowns(u: _Units, g: Graph):
    for b in g.bonds:
        u.unknown(f"bond {b.label}.e")
        u.unknown(f"bond {b.label}.f")
        for domain, unit, span, port in b.ports:
            where = _Where(b.span, f"bond '{b.label}' through port '{port}'"
                                   + (f" ({domain})" if domain in DOMAINS else ""),
                           Note(span, f"port '{port}' is declared here"))
            if domain in DOMAINS:
                u.declarations += 1
                efforts, flows = DOMAINS[domain]
                k = b.part if len(efforts) > 1 and b.part is not None else 0
                if k < len(efforts):
                    u.equal(_effort(u, b), _known(efforts[k]), where,
                            f"its effort", f"the {domain} effort")
                    u.equal(_flow(u, b), _known(flows[k]), where,
                            f"its flow", f"the {domain} flow")
            if unit:
                u.declarations += 1
                u.equal(_effort(u, b), _known(si.parse(unit).dims), where, "its effort",
                        f"the port's unit '{unit}'")


def _effort(u: _Units, b) -> _Form:
    return u.form_of(f"bond {b.label}.e")


def _flow(u: _Units, b) -> _Form:
    return u.form_of(f"bond {b.label}.f")


def _declarations(u: _Units, g: Graph):
    for p in g.parameters:
        u.unknown(p.name)
    for s in g.signals:
        u.unknown(s.name)
    for d in g.discretes:
        u.unknown(d.name)
    for p in g.parameters:
        u.declare(p.name, p.unit, p.span, f"parameter '{p.name}'")
    for s in g.signals:
        u.declare(s.name, s.unit, s.span, f"signal '{s.name}'")
    for i in g.inputs:
        u.declare(i.name, i.unit, i.span, f"input '{i.name}'")
    for p in g.parameters:
        if not isinstance(p.expr.value, sp.MatrixBase):
            u.law(p.name, p.expr, _Where(p.expr.span, f"the definition of '{p.name}'"))


def _elements(u: _Units, g: Graph):
    incident = g.incident
    for el in g.elements:
        bonds = [g.bonds[i] for i in incident[el.name]]
        if el.is_junction:
            _junction(u, g, el, bonds)
        elif el.spec.ports == 1 and bonds:
            _one_port(u, g, el, bonds[0])
    for el in g.elements:
        if not el.is_junction and el.spec.ports == 2:
            bonds = [g.bonds[i] for i in incident[el.name]]
            ins = [b for b in bonds if b.dst == el.name]
            outs = [b for b in bonds if b.src == el.name]
            if len(ins) == 1 and len(outs) == 1:
                _two_port(u, el, ins[0], outs[0])
        if el.init is not None:
            field, expr = el.init
            u.law(variable_name(el.name, field), expr,
                  _Where(expr.span, f"the initial value of '{el.name}'"))


def _junction(u: _Units, g: Graph, el, bonds):
    e, f = variable_name(el.name, "e"), variable_name(el.name, "f")  # (its bonds': merged)
    c = el.constraint
    if c is None:
        return
    u.alias[variable_name(el.name, "lambda")] = u.form_of(e)
    phi = u.form_of(f).plus(_SECOND)
    u.alias[variable_name(el.name, "residual")] = phi
    where = _Where(c.span, f"the constraint of '{el.origin or el.name}'")
    if c.annotation is not None:
        value = c.annotation[1].value
        if not isinstance(value, sp.MatrixBase):
            form = u.form(value, where)
            if form is not None:
                u.equal(phi, form, where, "its Phi (the flow balance integrated)",
                        _Quote(value))
    if c.kind in ("diode", "switch", None, "holonomic", "nonholonomic", "unilateral"):
        for gain in c.gains:
            value = gain.value
            form = u.form(value, where)
            if form is not None and c.corrector in ("pid", "pd"):
                u.equal(form, _PER_SECOND, _Where(gain.span, f"the corrector of "
                                                             f"'{el.origin or el.name}'"),
                        _Quote(value, "the gain "), "a rate (1/s)")
    if c.kind == "friction":
        for gain in c.gains:
            form = u.form(gain.value, where)
            if form is not None:
                u.equal(form, u.form_of(e), _Where(gain.span, f"the friction of '{el.name}'"),
                        _Quote(gain.value, "the friction force "), "the bond's effort")
    if c.restitution is not None:
        form = u.form(c.restitution.value, where)
        if form is not None:
            u.equal(form, _ONE, _Where(c.restitution.span, f"the restitution of '{el.name}'"),
                    _Quote(c.restitution.value), "a number (dimensionless)")


def _one_port(u: _Units, g: Graph, el, b):
    e, f = _effort(u, b), _flow(u, b)
    u.alias[variable_name(el.name, "e")] = e
    u.alias[variable_name(el.name, "f")] = f
    spec = el.spec
    if spec.state == "p":
        u.alias[variable_name(el.name, "p")] = e.plus(_SECOND)
    if spec.state == "q":
        u.alias[variable_name(el.name, "q")] = f.plus(_SECOND)
    where = _Where(el.span, f"the law of '{el.origin or el.name}'")
    if spec.role == "source":
        side = "e" if spec.fixed == "effort" else "f"
        if el.value is not None:
            u.law(variable_name(el.name, side), el.value, where,
                  f"its {'effort' if side == 'e' else 'flow'}")
        return
    if el.law is not None:
        side, expr = el.law
        u.law(variable_name(el.name, side), expr, where,
              f"its {dict(e='effort', f='flow')[side]}")
        return
    if el.value is None:
        return
    # p = I f, q = C e, e = R f (a matrix: row i of the multiport's parts)
    out, into = {"I": ("p", "f"), "C": ("q", "e"), "R": ("e", "f")}[el.kind]
    value = el.value.value
    if isinstance(value, sp.MatrixBase):
        m = _PART.fullmatch(el.name)
        if m is None:
            return
        base, i = m.group(1), int(m.group(2))
        for j in range(value.cols):
            entry = value[i, j]
            if entry == 0:
                continue
            other = part_name(base, j)
            form = u.form(entry, where)
            if form is not None:
                u.equal(u.form_of(variable_name(el.name, out)),
                        form.plus(u.form_of(variable_name(other, into))), where,
                        f"'{variable_name(el.name, out)}'",
                        _Quote(entry, "", f" times '{variable_name(other, into)}'"))
        return
    form = u.form(value, where)
    if form is not None:
        u.equal(u.form_of(variable_name(el.name, out)),
                form.plus(u.form_of(variable_name(el.name, into))), where,
                {"p": "its momentum", "q": "its displacement", "e": "its effort"}[out],
                _Quote(value, "", f" times its {dict(e='effort', f='flow')[into]}"))


def _two_port(u: _Units, el, a, b):
    where = _Where(el.span, f"the law of '{el.origin or el.name}'")
    n = u.form(el.value.value, where) if el.value is not None else None
    if n is None:
        return
    value = el.value.value
    if el.spec.role == "transformer":  # e_in = n e_out, f_out = n f_in
        u.equal(_effort(u, a), n.plus(_effort(u, b)), where, "its input effort",
                _Quote(value, "", " times its output effort"))
        u.equal(_flow(u, b), n.plus(_flow(u, a)), where, "its output flow",
                _Quote(value, "", " times its input flow"))
    else:  # e_in = r f_out, e_out = r f_in
        u.equal(_effort(u, a), n.plus(_flow(u, b)), where, "its input effort",
                _Quote(value, "", " times its output flow"))
        u.equal(_effort(u, b), n.plus(_flow(u, a)), where, "its output effort",
                _Quote(value, "", " times its input flow"))


def _signals_and_events(u: _Units, g: Graph):
    for s in g.signals:
        where = _Where(s.expr.span, f"signal '{s.name}'")
        if s.is_integral:
            f = u.form(s.expr.value, where)
            if f is not None:
                u.equal(u.form_of(s.name), f.plus(_SECOND), where, f"'{s.name}'",
                        _Quote(s.expr.value, "the integral of ", " over time"))
            u.law(s.name, s.init, _Where(s.init.span, f"the initial value of '{s.name}'"))
        elif not isinstance(s.expr.value, sp.MatrixBase):
            u.law(s.name, s.expr, where)
    for d in g.discretes:
        if d.init is not None:
            u.law(d.name, d.init, _Where(d.span, f"the initial value of '{d.name}'"))
    for r in g.relations:
        u.form(r.relation, _Where(r.span, f"'{r.text}'"))
    for sq in (s for s in g.squares if getattr(s, "kind", None) == "square"):
        where = _Where(sq.span, f"'{sq.text}'")
        for value, dim, what in ((sq.period, _SECOND, "its period"),
                                 (sq.t0, _SECOND, "its start"),
                                 (sq.duty, _ONE, "its duty cycle")):
            f = u.form(value, where)
            if f is not None:
                u.equal(f, dim, where, _Quote(value, f"{what} "),
                        "a time (s)" if dim is _SECOND else "a number (dimensionless)")
    for w in g.whens:
        for a in w.actions:
            u.law(a.symbol.name, a.expr, _Where(a.span, f"'{a.name} = ...'"))
    for sc in g.scenes:
        for name, expr, span in sc.sets:
            if name in u.by_name:
                u.law(name, expr, _Where(span, f"'set {name}' of scene '{sc.name}'"))
