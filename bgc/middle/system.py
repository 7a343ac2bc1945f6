"""Stage 5, equations (bgc.middle.system, so that `bgc.equations` is the API's function and no
module of the same name shadows it): CausalGraph -> EquationSystem, the causal bond graph as
equations.

Every bond k has symbols e[k] and f[k]; each node contributes one equation for each variable
its causality makes it compute.  An equation is *explicit*, `target = expr`, or *implicit*,
`0 = expr`, which determines its target without giving it (a law that has no clean inverse in
the causality it is in; the reduce stage adds those of the constraint multipliers).  States
(I, C, integral signals) are leaves: each has one explicit equation for its derivative
`der(x)`.  Storage in derivative causality computes its state from its input and its output
from that state's derivative `der(X.q)`, which the reduce stage derives.

The system carries nothing of the graph: names, spans and the numbers of the run, so that the
later stages cannot reach back into it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp

from ..symbolic.algebra import solve_for
from .causality import CausalGraph
from ..base.diagnostics import Collector, ModelError, Span, did_you_mean, fail
from ..symbolic.differentiate import partial
from ..front.graph import TIME, Element, Graph, part_name, var, variable_name
from ..base.run_settings import RunSettings
from .scene import parameter_values


def der(symbol: sp.Symbol) -> sp.Symbol:
    """The symbol of the time derivative of a variable: der(mx.p)."""
    return var(f"der({symbol.name})")


def _signed(sign: int, symbol: sp.Symbol) -> sp.Expr:
    """sign * symbol (sign 1 or -1), the same expression as SymPy's product, built without
    converting the Python number and flattening a product of two factors."""
    return symbol if sign == 1 else -symbol


def bond_effort(label: str) -> sp.Symbol:
    return var(f"e[{label}]")


def bond_flow(label: str) -> sp.Symbol:
    return var(f"f[{label}]")


@dataclass(frozen=True)
class Equation:
    target: sp.Symbol
    expr: sp.Expr
    explicit: bool  # target = expr; else 0 = expr determines target
    origin: str  # the element, signal or junction it comes from
    span: Span


@dataclass(frozen=True)
class StateVar:
    symbol: sp.Symbol
    name: str  # as shown to users: "mx.p", "c1.q", "x"
    init: sp.Expr  # the initial value (parameters only; t is t0)
    kind: str  # "I", "C" or "integral signal"
    span: Span


@dataclass(frozen=True)
class ConstraintDef:
    junction: str
    kind: str | None  # declared: holonomic | nonholonomic | None (detect)
    corrector: str  # pid | pd | none
    gains: tuple[sp.Expr, ...]
    annotation: tuple | None  # ("init" | "phi", sympy expr, span)
    multiplier: sp.Symbol  # X.lambda: its equation comes from the reduce stage
    balance: sp.Symbol  # X.balance = flows in - flows out (efforts, on a 1 junction)
    residual: sp.Symbol  # X.residual: Phi (holonomic) or the balance (nonholonomic)
    span: Span
    name_span: Span
    restitution: sp.Expr | None = None  # unilateral: E (0 when not given)
    dual: bool = False  # on a 1 junction: the multiplier a flow, the balance of efforts


@dataclass(frozen=True)
class Store:
    """A storage element in derivative causality (its state is a dependent variable)."""

    element: str
    state: sp.Symbol
    given_init: sp.Expr | None  # an init clause, which derivative causality overrides
    init_span: Span | None


@dataclass(frozen=True)
class OutputDef:
    name: str  # the CSV column
    expr: sp.Expr  # over model symbols
    span: Span | None


@dataclass(frozen=True)
class ParameterDef:
    name: str
    expr: sp.Expr  # default, the scene's `set` applied; earlier parameters only
    span: Span



@dataclass(frozen=True)
class EquationSystem:
    name: str
    parameters: tuple[ParameterDef, ...]
    states: tuple[StateVar, ...]
    equations: tuple[Equation, ...]
    constraints: tuple[ConstraintDef, ...]
    stores: tuple[Store, ...]
    outputs: tuple[OutputDef, ...]
    run: RunSettings  # the scene's
    warnings: tuple = ()
    fields: tuple = ()  # (field, coordinates of the Hamiltonian correction) of coupled I fields
    momenta: tuple = ()  # (p, f, sign) of each I state in integral causality: its velocity
    #                      is sign * f, f a bond flow (the projection's kinetic metric)
    events: tuple = ((), (), (), ())  # bgc.front.events: relations, squares, discretes, whens
    tables: tuple = ()  # bgc.front.tables.TableData, as Table(k, ...) numbers them
    inputs: tuple = ()  # graph.InputInfo, in declaration order


class _Builder:
    def __init__(self, cg: CausalGraph):
        self.g: Graph = cg.graph
        self.effort_by = cg.effort_by
        self.sets = cg.settings.sets
        self._defaults = None
        self.equations: list[Equation] = []
        self.states: list[StateVar] = []
        self.stores: list[Store] = []
        self.constraints: list[ConstraintDef] = []
        self.fields: dict[str, None] = {}  # coupled I fields, in order
        self.hamiltonian: dict[str, list[str]] = {}  # ... whose M depends on own coordinates
        self.momenta: list = []
        self._field_entries: dict = {}
        self._integrals = None

    def emit(self, target, expr, el: Element | str, span, explicit=True):
        origin = el if isinstance(el, str) else el.name
        self.equations.append(Equation(target, expr, explicit, origin, span))

    def incident(self, name):
        bonds = self.g.bonds
        return [(i, bonds[i]) for i in self.g.incident[name]]

    # ------------------------------------------------------------ one-ports
    def one_port(self, el: Element):
        ((i, b),) = self.incident(el.name)
        e, f = bond_effort(b.label), bond_flow(b.label)
        s = 1 if b.dst == el.name else -1  # orientation: the element's own flow is s*f
        self.emit(var(variable_name(el.name, "e")), e, el, el.span)
        self.emit(var(variable_name(el.name, "f")), f, el, el.span)
        sets_effort = self.effort_by[i] == el.name
        role = el.spec.role
        if role == "source":
            self.emit(e if el.spec.fixed == "effort" else f, el.value.value, el, el.span)
        elif role == "resistor":
            self.resistor(el, e, f, s, sets_effort)
        else:
            self.storage(el, e, f, s, sets_effort)

    def _parts(self, el):
        """(index of el, [(sign, bond) of every part]) of a part of a coupled field."""
        n, origin = el.value.value.rows, el.origin
        out = []
        for j in range(n):
            part = part_name(origin, j)
            ((_, b),) = self.incident(part)
            out.append((1 if b.dst == part else -1, b))
        return int(el.name[len(origin) + 1:-1]), out

    def resistor(self, el, e, f, s, sets_effort):
        if el.value is not None and isinstance(el.value.value, sp.MatrixBase):
            # a resistance matrix: e_i = sum_j R_ij f_j over the parts' own flows
            R = el.value.value
            i, parts = self._parts(el)
            law = sp.Add(*[R[i, j] * sj * bond_flow(b.label) for j, (sj, b) in enumerate(parts)])
            if sets_effort:
                self.emit(e, law, el, el.span)
            else:
                self.emit(f, law - e, el, el.span, explicit=False)
            return
        own_e, own_f = sp.Symbol("_E", real=True), sp.Symbol("_F", real=True)
        if el.law is None:
            lhs, rhs = own_e, el.value.value * own_f
        else:
            which, expr = el.law
            law = expr.value.xreplace({var(variable_name(el.name, "e")): own_e,
                                       var(variable_name(el.name, "f")): own_f})
            lhs, rhs = (own_e, law) if which == "e" else (own_f, law)
        want = own_e if sets_effort else own_f
        target = e if sets_effort else f
        bond = {own_e: e, own_f: s * f}
        if lhs == want and not rhs.has(want):
            sol = rhs
        else:
            sol = _invert(lhs - rhs, want, el)
        if sol is None:  # no clean inverse: the law itself determines the variable
            self.emit(target, (lhs - rhs).xreplace(bond), el, el.span, explicit=False)
        elif sets_effort:
            self.emit(e, sol.xreplace(bond), el, el.span)
        else:
            self.emit(f, s * sol.xreplace(bond), el, el.span)

    def storage(self, el, e, f, s, sets_effort):
        if el.value is not None and isinstance(el.value.value, sp.MatrixBase):
            if el.kind == "I":
                self.coupled_field(el, e, sets_effort)
            else:
                self.coupled_capacitor(el, f, s, sets_effort)
            return
        st = el.spec.state  # "p" (I) or "q" (C)
        state = var(variable_name(el.name, st))
        partner = sp.Symbol("_V", real=True)  # f for I, e for C
        law = state / el.value.value if el.law is None else el.law[1].value  # f = p/m, e = q/c
        integral = sets_effort == (el.spec.preferred == "effort")
        if integral:
            if st == "p":
                self.emit(f, s * law, el, el.span)
                self.momenta.append((state, f, s))
                rate = e
            else:
                self.emit(e, law, el, el.span)
                rate = s * f
            self.states.append(StateVar(state, variable_name(el.name, st),
                                        self._init(el, law, state), el.kind, el.span))
            self.emit(der(state), rate, el, el.span)
            return
        bond_partner = e if st == "q" else s * f  # the law's input, from the bond
        dep = _invert(partner - law, state, el)
        if dep is None:
            self.emit(state, (partner - law).xreplace({partner: bond_partner}), el, el.span,
                      explicit=False)
        else:
            self.emit(state, dep.xreplace({partner: bond_partner}), el, el.span)
        # its output is the state's rate: I sets the effort dp/dt, C the flow dq/dt (own sign)
        if st == "p":
            self.emit(e, der(state), el, el.span)
        else:
            self.emit(f, s * der(state), el, el.span)
        given = self._init(el, law, state) if el.init is not None else None
        self.stores.append(Store(el.name, state, given, el.init[1].span if el.init else None))

    def coupled_field(self, el, e, sets_effort):
        """Part i of an I field with a full mass matrix M(q): the momentum p_i is a state, the
        flows solve M f = p together (an implicit equation per part: a linear block, solved in
        the generated code), and dp_i/dt = e_i + 1/2 f^T (dM/dq_i) f when M depends on the
        coordinate q_i that integrates the field's own flow f_i (Lagrange's equations: the
        energy 1/2 p^T M^-1 p is then conserved)."""
        M, origin = el.value.value, el.origin
        n = M.rows
        i = int(el.name[len(origin) + 1:-1])
        if sets_effort != (el.spec.preferred == "effort"):  # derivative causality
            fail(el.span, f"'{origin}' is a coupled I field (a non-diagonal mass matrix) and its "
                          f"component {i} gets derivative causality (its flow is imposed): not "
                          "supported; impose the flow on a scalar element instead")
        flows, own, sign = [], None, 1
        for j in range(n):
            part = part_name(origin, j)
            ((_, b),) = self.incident(part)
            flows.append((1 if b.dst == part else -1) * bond_flow(b.label))
            if j == i:
                own, sign = bond_flow(b.label), (1 if b.dst == part else -1)
        state = var(variable_name(el.name, "p"))
        self.momenta.append((state, own, sign))
        self.emit(own, sp.Add(*[M[i, j] * flows[j] for j in range(n)]) - state, el, el.span,
                  explicit=False)
        rate = e
        coordinate = self._coordinate_of(part_name(origin, i))
        entries = self._entries_with(origin, M).get(coordinate, ())
        if coordinate is not None and entries:
            # 1/2 f^T (dM/dq) f over the entries that hold q only (bgc's own derivative, entry
            # by entry: the work is the entries, not n^2 per coordinate)
            rate = e + sp.Rational(1, 2) * sp.Add(*[flows[j] * partial(M[j, k], coordinate) *
                                                     flows[k] for j, k in entries])
            self.hamiltonian.setdefault(origin, []).append(str(coordinate))
        self.fields.setdefault(origin, None)
        init = el.init[1].value if el.init is not None else sp.Integer(0)
        self.states.append(StateVar(state, variable_name(el.name, "p"), init, el.kind, el.span))
        self.emit(der(state), rate, el, el.span)

    def _entries_with(self, origin, M) -> dict:
        """For a field's matrix: symbol -> the (row, column) of the entries it occurs in, in
        order; worked out once per field."""
        if origin not in self._field_entries:
            where: dict = {}
            for j in range(M.rows):
                for k in range(M.cols):
                    for sym in sorted(M[j, k].free_symbols, key=lambda x: x.name):
                        where.setdefault(sym, []).append((j, k))
            self._field_entries[origin] = where
        return self._field_entries[origin]

    def coupled_capacitor(self, el, f, s, sets_effort):
        """Part i of a C field with a full matrix K: the charge q_i is a state and the efforts
        solve K e = q together (a linear block in the generated code); dq_i/dt = own flow."""
        K = el.value.value
        i, parts = self._parts(el)
        if sets_effort != (el.spec.preferred == "effort"):
            fail(el.span, f"'{el.origin}' is a coupled C field (a non-diagonal matrix) and its "
                          f"component {i} gets derivative causality (its effort is imposed): "
                          "not supported")
        state = var(variable_name(el.name, "q"))
        efforts = [bond_effort(b.label) for _, b in parts]
        self.emit(efforts[i], sp.Add(*[K[i, j] * efforts[j] for j in range(K.rows)]) - state,
                  el, el.span, explicit=False)
        self.fields.setdefault(el.origin, None)
        init = el.init[1].value if el.init is not None else sp.Integer(0)
        self.states.append(StateVar(state, variable_name(el.name, "q"), init, el.kind, el.span))
        self.emit(der(state), s * f, el, el.span)

    def _coordinate_of(self, part):
        """The integral signal that integrates this one-port's own flow (or its 1-junction's
        common flow), as a symbol; None if there is none."""
        if self._integrals is None:
            self._integrals = {s.expr.value: var(s.name) for s in self.g.signals
                               if s.is_integral and isinstance(s.expr.value, sp.Symbol)}
        ((_, b),) = self.incident(part)
        other = self.g.by_name[b.other(part)]
        candidates = [var(variable_name(part, "f"))]
        if other.kind == "1":
            candidates.append(var(variable_name(other.name, "f")))
        return next((self._integrals[c] for c in candidates if c in self._integrals), None)

    def _init(self, el, law, state):
        if el.init is None:
            return sp.Integer(0)
        which, expr = el.init
        if which == el.spec.state:
            return expr.value
        partner = sp.Symbol("_V", real=True)
        inverse = _invert(partner - law, state, el)
        if inverse is None:
            fail(expr.span, f"the law of '{el.name}' has no closed-form inverse, so its state "
                            f"cannot be computed from this value: write 'init {el.spec.state} "
                            "= ...' instead")
        return inverse.xreplace({partner: expr.value})

    # ------------------------------------------------------------ two-ports
    def two_port(self, el: Element):
        (ia, a), = [(i, b) for i, b in self.incident(el.name) if b.dst == el.name]
        (_, b), = [(i, b) for i, b in self.incident(el.name) if b.src == el.name]
        ea, fa, eb, fb = bond_effort(a.label), bond_flow(a.label), bond_effort(b.label), \
            bond_flow(b.label)
        n = el.value.value
        divides = self.effort_by[ia] != el.name
        if divides:
            self._check_divisor(el)
        if el.spec.role == "transformer":
            if not divides:  # e_in = n e_out, f_out = n f_in
                self.emit(ea, n * eb, el, el.span)
                self.emit(fb, n * fa, el, el.span)
            else:
                self.emit(eb, ea / n, el, el.span)
                self.emit(fa, fb / n, el, el.span)
        else:
            if not divides:  # e_in = r f_out, e_out = r f_in
                self.emit(ea, n * fb, el, el.span)
                self.emit(eb, n * fa, el, el.span)
            else:
                self.emit(fb, ea / n, el, el.span)
                self.emit(fa, eb / n, el, el.span)

    def _check_divisor(self, el: Element):
        """A two-port whose causality divides by its modulus: a modulus that is 0 at the
        given parameters is a model error (a modulated one that passes 0 stops the run)."""
        if self._defaults is None:
            self._defaults = parameter_values(self.g, self.sets)
        n = el.value.value.xreplace(self._defaults)
        if n.is_number and n.is_zero:
            fail(el.value.span, f"{el.kind}({el.value.value}) of '{el.origin or el.name}' is "
                                "singular: its causality divides by its value, 0 at the given "
                                "parameters")

    # ------------------------------------------------------------ junctions
    def junction(self, el: Element):
        bonds = self.incident(el.name)
        sigma = {i: (1 if b.dst == el.name else -1) for i, b in bonds}
        common, through = (bond_effort, bond_flow) if el.kind == "0" else (bond_flow, bond_effort)
        field = "e" if el.kind == "0" else "f"
        if el.constraint is not None:
            self.constraint(el, bonds, sigma, common, through, field)
            return
        if not bonds:
            return
        # the odd bond: at a 0-junction the one that sets the effort, at a 1-junction the one
        # whose effort the junction computes (equivalently, that sets the common flow).
        if el.kind == "0":
            (k, kb), = [(i, b) for i, b in bonds if self.effort_by[i] != el.name]
        else:
            (k, kb), = [(i, b) for i, b in bonds if self.effort_by[i] == el.name]
        for i, b in bonds:
            if i != k:
                self.emit(common(b.label), common(kb.label), el, el.span)
        others = sp.Add(*[_signed(sigma[i], through(b.label)) for i, b in bonds if i != k])
        self.emit(through(kb.label), -sigma[k] * others, el, el.span)
        self.emit(var(variable_name(el.name, field)), common(kb.label), el, el.span)

    def constraint(self, el, bonds, sigma, common, through, field):
        lam = var(variable_name(el.name, "lambda"))
        for _, b in bonds:
            self.emit(common(b.label), lam, el, el.span)
        self.emit(var(variable_name(el.name, field)), lam, el, el.span)
        balance = var(variable_name(el.name, "balance"))
        self.emit(balance, sp.Add(*[_signed(sigma[i], through(b.label)) for i, b in bonds]), el,
                  el.span)
        if el.constraint.kind in ("diode", "friction", "switch"):  # a switched one-port: its flow
            # (its effort, as the dual junction that imposes its flow: bgc.middle.causality)
            self.emit(var(variable_name(el.name, "f" if el.kind == "0" else "e")), balance, el,
                      el.span)
        c = el.constraint
        ann = None
        if c.annotation is not None:
            ann = (c.annotation[0], c.annotation[1].value, c.annotation[1].span)
        self.constraints.append(ConstraintDef(
            el.name, c.kind, c.corrector, tuple(g.value for g in c.gains), ann, lam, balance,
            var(variable_name(el.name, "residual")), el.span, el.name_span,
            c.restitution.value if c.restitution is not None else None, el.kind == "1"))

    def signal(self, s):
        if s.is_integral:
            sym = var(s.name)
            self.states.append(StateVar(sym, s.name, s.init.value, "integral signal", s.span))
            self.emit(der(sym), s.expr.value, s.name, s.span)
        else:
            self.emit(var(s.name), s.expr.value, s.name, s.span)


def _invert(equation, unknown, el: Element):
    """Solve equation == 0 for unknown: a clean closed form, or None (the equation then stays
    implicit, and is solved numerically unless the reduce stage finds better)."""
    if not equation.has(unknown):
        fail(el.span, f"the law of '{el.name}' does not involve the variable its causality asks for")
    return solve_for(equation, unknown)


# ---------------------------------------------------------------- outputs


def _outputs(b: _Builder, refs, left_out=()) -> tuple[OutputDef, ...]:
    states = {st.symbol: st for st in b.states}
    why = dict(left_out)
    if refs is None:
        return tuple(OutputDef(st.name, st.symbol, st.span) for st in b.states)
    targets = {eq.target for eq in b.equations}
    constraints = {c.junction: c for c in b.constraints}
    params = {p.name for p in b.g.parameters}
    discretes = {d.name: d.symbol for d in b.g.discretes}  # (their values between events)
    diags = Collector()
    out = []
    names = {s.name for s in b.g.signals} | params | {v.name for v in b.g.vectors
                                                      if v.what == "signal"} | set(why) | \
        set(discretes)
    for ref in refs:
        ref = _signal_path(ref, b.g, names)
        if ref.owner in why:
            diags.error(ref.span, f"output '{ref.text}' is left out by this scene's effects: "
                                  f"'{ref.owner}' {_reason(why[ref.owner])}")
            continue
        try:
            for name, part in _expand(ref, b.g):
                out.append(OutputDef(name, _output_expr(part, b.g, states, targets, constraints,
                                                        params, discretes), ref.span))
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    diags.raise_if_errors()
    return tuple(out)


def _signal_path(ref, g: Graph, names):
    """`p1.x` written as an output, x a signal (or parameter) of instance p1: the name
    `p1.x`, not variable x of an element p1."""
    if ref.field is None or ref.owner in g.by_name or ref.owner in g.vector_by_name:
        return ref
    name = f"{ref.owner}.{ref.field}"
    return replace(ref, owner=name, field=None) if name in names else ref


def _reason(why: str) -> str:
    return "is " + why if why.startswith("tagged") else (
        "is left out: " + why)


def _expand(ref, g: Graph) -> list:
    """(column name, scalar reference) of an output: a multiport's or vector signal's variable
    is a column per component (`q[0]`, `rod.lambda[1]`), or the one its index names."""
    v = g.vector_by_name.get(ref.owner)
    if v is None:
        return [(ref.text, ref)]
    if ref.index is not None and not 0 <= ref.index < v.dim:
        fail(ref.span, f"'{ref.owner}' has {v.dim} components: index [{ref.index}] is out of "
                       f"range (0 .. {v.dim - 1})")
    indices = range(v.dim) if ref.index is None else (ref.index,)
    out = []
    for i in indices:
        name = f"{ref.owner}.{ref.field}[{i}]" if ref.field else f"{ref.owner}[{i}]"
        out.append((name, replace(ref, owner=part_name(ref.owner, i), index=None)))
    return out


# The modes an output may name, per kind of constraint junction: the field -> the suffix of
# its discrete value (bgc.middle.contact: a diode's `blocking` and a switch's `open` are its
# `J.active`)
MODE_FIELDS = {"unilateral": {"active": "active", "vmax": "vmax"},
               "diode": {"blocking": "active"}, "switch": {"open": "active"},
               "friction": {"stick": "active", "dir": "dir"}}


def _output_expr(ref, g: Graph, states, targets, constraints, params, discretes):
    if ref.index is not None and ref.index != 0:
        fail(ref.span, f"'{ref.owner}' is a scalar: index [{ref.index}] is out of range")
    if ref.field is None:
        sym = var(ref.owner)
        if sym in states or sym in targets or ref.owner in params:
            return sym
        if ref.owner in discretes:
            return discretes[ref.owner]
        if ref.owner in g.by_name or ref.owner in g.vector_by_name:
            hint = f" ('{ref.owner}' is an element: name one of its variables, e.g. " \
                   f"{ref.owner}.{'p' if _kind_of(ref.owner, g) == 'I' else 'e'})"
        else:
            names = [s.name for s in g.signals] + list(params) + [v.name for v in g.vectors] \
                + list(discretes)
            hint = did_you_mean(ref.owner, names)
        fail(ref.span, f"unknown output '{ref.owner}'{hint}")
    if ref.owner not in g.by_name:
        names = [el.origin or el.name for el in g.elements]
        fail(ref.span, f"unknown element '{ref.owner}' in outputs{did_you_mean(ref.owner, names)}")
    c = constraints.get(ref.owner)
    if c is not None and ref.field in MODE_FIELDS.get(c.kind, {}):
        # a switched element's or a contact's mode (bgc.middle.contact's discrete values)
        return var(f"{c.junction}.{MODE_FIELDS[c.kind][ref.field]}")
    if ref.field in ("lambda", "residual"):
        if c is None:
            fail(ref.span, f"'{ref.owner}' is not a constraint junction")
        return c.multiplier if ref.field == "lambda" else c.residual
    sym = var(variable_name(ref.owner, ref.field))
    if ref.field in ("e", "f", "p", "q") and (sym in states or sym in targets):
        return sym
    defined = states.keys() | targets
    have = [f for f in ("e", "f", "p", "q") if var(variable_name(ref.owner, f)) in defined] + \
        (["lambda", "residual"] if ref.owner in constraints else []) + \
        (list(MODE_FIELDS.get(c.kind, ())) if c is not None else [])
    fail(ref.span, f"'{g.by_name[ref.owner].origin or ref.owner}' has no variable '{ref.field}'"
                   + (f" (it has: {', '.join(have)})" if have else ""))


def _kind_of(name, g: Graph) -> str | None:
    el = g.by_name.get(name)
    if el is None:
        v = g.vector_by_name.get(name)
        el = g.by_name.get(part_name(name, 0)) if v is not None else None
    return el.kind if el is not None else None


def build_equations(cg: CausalGraph) -> EquationSystem:
    b = _Builder(cg)
    g = cg.graph
    diags = Collector()
    for item in sorted(list(g.elements) + list(g.signals), key=lambda d: d.order):
        try:
            if not isinstance(item, Element):
                b.signal(item)
            elif item.is_junction:
                b.junction(item)
            elif item.spec.ports == 2:
                b.two_port(item)
            else:
                b.one_port(item)
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    diags.raise_if_errors()
    s = cg.settings
    sets = {name: expr for name, expr in s.sets}
    params = tuple(ParameterDef(p.name, sets.get(p.name, p.expr).value, p.span)
                   for p in g.parameters)
    run = s.run
    return EquationSystem(g.name, params, tuple(b.states), tuple(b.equations),
                          tuple(b.constraints), tuple(b.stores), _outputs(b, s.outputs, s.left_out), run,
                          tuple(g.warnings),
                          tuple((name, tuple(b.hamiltonian.get(name, ()))) for name in b.fields),
                          tuple(b.momenta), (g.relations, g.squares, g.discretes, g.whens),
                          tuple(g.tables), tuple(g.inputs))


def with_residual_outputs(es: EquationSystem) -> EquationSystem:
    """The system with each constraint's residual appended to the outputs (unless there)."""
    have = {o.expr for o in es.outputs}
    extra = tuple(OutputDef(variable_name(c.junction, "residual"), c.residual, c.span)
                  for c in es.constraints if c.residual not in have)
    return replace(es, outputs=es.outputs + extra) if extra else es


__all__ = ["TIME", "Equation", "EquationSystem", "StateVar", "ConstraintDef", "Store",
           "OutputDef", "ParameterDef", "build_equations", "with_residual_outputs", "der", "bond_effort",
           "bond_flow"]
