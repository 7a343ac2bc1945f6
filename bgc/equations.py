"""Stage 5, equations: the causal bond graph as assignments `variable = expression`.

Every bond k has symbols e[k] and f[k]; each node contributes an assignment for each variable
its causality makes it compute.  States (I, C, integral signals) are leaves with a derivative
expression; storage in derivative causality and constraint multipliers leave unknowns that the
reduce stage determines.  Each assignment carries the span of the declaration it came from.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .causality import Causality
from .diagnostics import Span, fail
from .resolve import Element, Graph, var
from .scene import Settings


@dataclass(frozen=True)
class Assignment:
    target: sp.Symbol
    expr: sp.Expr
    origin: str  # the element or signal that computes it
    span: Span


@dataclass(frozen=True)
class State:
    symbol: sp.Symbol
    name: str  # as shown to users: "mx.p", "c1.q", "x"
    derivative: sp.Expr
    init: sp.Expr  # the state's initial value (parameters and t only)
    origin: str
    span: Span


@dataclass(frozen=True)
class DerivativeStore:
    """A storage element in derivative causality: output = sign * d/dt(state_expr)."""

    element: str
    output: sp.Symbol  # the bond variable it sets (an unknown for the reduce stage)
    state_symbol: sp.Symbol  # X.p / X.q, here a dependent quantity
    state_expr: sp.Expr  # in terms of other variables (its input through the law)
    sign: int
    span: Span
    given_init: sp.Expr | None = None  # an init clause, which derivative causality overrides


@dataclass(frozen=True)
class ConstraintEq:
    junction: str
    kind: str | None  # declared kind
    multiplier: sp.Symbol
    balance: sp.Expr  # flows in - flows out (0) / efforts in - efforts out (1)
    corrector: str
    gains: tuple[sp.Expr, ...]
    annotation: tuple | None  # ("init" | "phi", sympy expr, span)
    span: Span
    element: Element


@dataclass(frozen=True)
class EquationSystem:
    graph: Graph
    causality: Causality
    settings: Settings
    assignments: tuple[Assignment, ...]
    states: tuple[State, ...]
    stores: tuple[DerivativeStore, ...]
    constraints: tuple[ConstraintEq, ...]
    warnings: tuple = ()


def bond_effort(label: str) -> sp.Symbol:
    return var(f"e[{label}]")


def bond_flow(label: str) -> sp.Symbol:
    return var(f"f[{label}]")


class _Builder:
    def __init__(self, graph: Graph, causality: Causality):
        self.g, self.c = graph, causality
        self.assignments: list[Assignment] = []
        self.states: list[State] = []
        self.stores: list[DerivativeStore] = []
        self.constraints: list[ConstraintEq] = []
        self.warnings: list = []

    def emit(self, target, expr, el_or_name, span):
        origin = el_or_name if isinstance(el_or_name, str) else el_or_name.name
        self.assignments.append(Assignment(target, expr, origin, span))

    def incident(self, name):
        return [(i, b) for i, b in enumerate(self.g.bonds) if name in (b.src, b.dst)]

    # ------------------------------------------------------------ one-ports
    def one_port(self, el: Element):
        ((i, b),) = self.incident(el.name)
        e, f = bond_effort(b.label), bond_flow(b.label)
        s = 1 if b.dst == el.name else -1  # orientation: the element's own flow is s*f
        self.emit(var(f"{el.name}.e"), e, el, el.span)
        self.emit(var(f"{el.name}.f"), f, el, el.span)
        sets_effort = self.c.effort_by[i] == el.name
        role = el.spec.role
        if role == "source":
            self.emit(e if el.spec.fixed == "effort" else f, el.value.value, el, el.span)
        elif role == "resistor":
            self.resistor(el, e, f, s, sets_effort)
        else:
            self.storage(el, e, f, s, sets_effort)

    def _own(self, el, e, f, s):
        return {var(f"{el.name}.e"): e, var(f"{el.name}.f"): s * f}

    def resistor(self, el, e, f, s, sets_effort):
        own_e, own_f = sp.Symbol("_E", real=True), sp.Symbol("_F", real=True)
        if el.law is None:
            lhs, rhs = own_e, el.value.value * own_f
        else:
            which, expr = el.law
            law = expr.value.xreplace({var(f"{el.name}.e"): own_e, var(f"{el.name}.f"): own_f})
            lhs, rhs = (own_e, law) if which == "e" else (own_f, law)
        want = own_e if sets_effort else own_f
        sol = rhs if lhs == want else _invert(lhs - rhs, want, el)
        sol = sol.xreplace({own_e: e, own_f: s * f})
        if sets_effort:
            self.emit(e, sol, el, el.span)
        else:
            self.emit(f, s * sol, el, el.span)

    def storage(self, el, e, f, s, sets_effort):
        st = el.spec.state  # "p" (I) or "q" (C)
        state = var(f"{el.name}.{st}")
        partner = sp.Symbol("_V", real=True)  # f for I, e for C
        if el.law is None:
            law = state / el.value.value  # f = p/m, e = q/c
        else:
            law = el.law[1].value
        integral = sets_effort == (el.spec.preferred == "effort")
        bond_partner = e if st == "q" else s * f
        if integral:
            out = law
            if st == "p":
                self.emit(f, s * out, el, el.span)
                deriv = e
            else:
                self.emit(e, out, el, el.span)
                deriv = s * f
            self.states.append(State(state, f"{el.name}.{st}", deriv, self._init(el, law, state),
                                     el.name, el.span))
        else:
            dep = _invert(partner - law, state, el).xreplace({partner: bond_partner})
            output = e if st == "p" else f
            sign = 1 if st == "p" else s
            self.emit(state, dep, el, el.span)
            given = self._init(el, law, state) if el.init is not None else None
            self.stores.append(DerivativeStore(el.name, output, state, dep, sign, el.span, given))

    def _init(self, el, law, state):
        if el.init is None:
            return sp.Integer(0)
        which, expr = el.init
        if which == el.spec.state:
            return expr.value
        partner = sp.Symbol("_V", real=True)
        return _invert(partner - law, state, el).xreplace({partner: expr.value})

    # ------------------------------------------------------------ two-ports
    def two_port(self, el: Element):
        (ia, a), = [(i, b) for i, b in self.incident(el.name) if b.dst == el.name]
        (ib, b), = [(i, b) for i, b in self.incident(el.name) if b.src == el.name]
        ea, fa, eb, fb = bond_effort(a.label), bond_flow(a.label), bond_effort(b.label), \
            bond_flow(b.label)
        n = el.value.value
        if el.spec.role == "transformer":
            if self.c.effort_by[ia] == el.name:  # e_in = n e_out, f_out = n f_in
                self.emit(ea, n * eb, el, el.span)
                self.emit(fb, n * fa, el, el.span)
            else:
                self.emit(eb, ea / n, el, el.span)
                self.emit(fa, fb / n, el, el.span)
        else:
            if self.c.effort_by[ia] == el.name:  # e_in = r f_out, e_out = r f_in
                self.emit(ea, n * fb, el, el.span)
                self.emit(eb, n * fa, el, el.span)
            else:
                self.emit(fb, ea / n, el, el.span)
                self.emit(fa, eb / n, el, el.span)

    # ------------------------------------------------------------ junctions
    def junction(self, el: Element):
        bonds = self.incident(el.name)
        sigma = {i: (1 if b.dst == el.name else -1) for i, b in bonds}
        common, through = (bond_effort, bond_flow) if el.kind == "0" else (bond_flow, bond_effort)
        field = "e" if el.kind == "0" else "f"
        if el.constraint is not None:
            lam = var(f"{el.name}.lambda")
            for i, b in bonds:
                self.emit(common(b.label), lam, el, el.span)
            self.emit(var(f"{el.name}.{field}"), lam, el, el.span)
            balance = sp.Add(*[sigma[i] * through(b.label) for i, b in bonds])
            c = el.constraint
            ann = None
            if c.annotation is not None:
                ann = (c.annotation[0], c.annotation[1].value, c.annotation[1].span)
            self.constraints.append(ConstraintEq(el.name, c.kind, lam, balance, c.corrector,
                                                 tuple(g.value for g in c.gains), ann, el.span, el))
            return
        if not bonds:
            return
        # the odd bond: at a 0-junction the one that sets the effort, at a 1-junction the one
        # whose effort the junction computes (equivalently, that sets the common flow).
        if el.kind == "0":
            (k, kb), = [(i, b) for i, b in bonds if self.c.effort_by[i] != el.name]
        else:
            (k, kb), = [(i, b) for i, b in bonds if self.c.effort_by[i] == el.name]
        for i, b in bonds:
            if i != k:
                self.emit(common(b.label), common(kb.label), el, el.span)
        others = sp.Add(*[sigma[i] * through(b.label) for i, b in bonds if i != k])
        self.emit(through(kb.label), -sigma[k] * others, el, el.span)
        self.emit(var(f"{el.name}.{field}"), common(kb.label), el, el.span)

    def signal(self, s):
        if s.is_integral:
            self.states.append(State(var(s.name), s.name, s.expr.value, s.init.value, s.name,
                                     s.span))
        else:
            self.emit(var(s.name), s.expr.value, s.name, s.span)


def _invert(equation, unknown, el: Element):
    """Solve equation == 0 for unknown; the law must have exactly one solution."""
    if not equation.has(unknown):
        fail(el.span, f"the law of '{el.name}' does not involve the variable its causality asks for")
    if sp.degree(equation, unknown) == 1 if equation.is_polynomial(unknown) else False:
        a = equation.diff(unknown)
        return sp.cancel(-(equation - a * unknown) / a) if a.free_symbols else \
            -(equation - a * unknown) / a
    sols = sp.solve(equation, unknown, dict=True)
    if len(sols) != 1:
        fail(el.span, f"the law of '{el.name}' cannot be inverted uniquely for the causality "
                      f"it is in ({len(sols)} solutions); write it the other way round")
    return sols[0][unknown]


def build_equations(graph: Graph, causality: Causality, settings: Settings) -> EquationSystem:
    b = _Builder(graph, causality)
    for item in sorted(list(graph.elements) + list(graph.signals),
                       key=lambda d: (d.span.line, d.span.col)):
        if not hasattr(item, "kind"):
            b.signal(item)
        elif item.is_junction:
            b.junction(item)
        elif item.spec.ports == 2:
            b.two_port(item)
        else:
            b.one_port(item)
    return EquationSystem(graph, causality, settings, tuple(b.assignments), tuple(b.states),
                          tuple(b.stores), tuple(b.constraints), tuple(b.warnings))
