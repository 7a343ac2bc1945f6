"""Stage 6, reduce: EquationSystem -> Reduced, a sorted program of bgc.ir statements over the
model's symbols (Assign, and Solve or Newton for the blocks solved numerically).

1. Constraints (the paper's sections 2-4): each constraint junction's balance is written in the
   coordinates that integral signals integrate; the integrability test decides holonomic or
   not, and gives Phi (`init`/`phi` annotation).  The multiplier gets its equation, the
   acceleration-level constraint with the corrector: der(B) + 2 alpha B + beta^2 Phi = 0
   (pid), der(B) + gamma B = 0 (pd), der(B) = 0 (none).  It is implicit: the multiplier
   does not occur in it, it acts through the efforts it sets.
2. Time derivatives der(v) that equations use (constraints, storage in derivative causality)
   are derived on demand by differentiating v's own equation (forward, symbolically, one
   equation each: linear in the model's size), the derivative of a state being its rate.
3. Only what the outputs need is kept: the outputs' dependencies, the states they reach and
   those states' rates, to a fixed point.
4. The kept equations are sorted into strongly connected blocks in evaluation order (BLT).  A
   block of one explicit equation is an assignment; any other block is torn, and its tears
   z are the unknowns of residual equations r(z) = 0, the rest of the block being explicit
   given z.  Each block is then solved
   - symbolically when it is linear and small, or a single equation with a clean inverse;
   - else numerically in the generated code: A z = b by LU when linear (A and b emitted as
     expressions, derived forward through the block: the coefficients' assignments, then a
     Solve, then the block's body), Newton's method with the block's symbolic Jacobian when
     not (a Newton statement); each with its factorization plan (bgc.symbolic.sparse).
   `algebra="symbolic"|"numeric"` forces either path.
5. The initial conditions are checked against the constraints.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mpmath  # SymPy's own: a number beyond a double, shown
import sympy as sp

from ..symbolic import blt
from .. import ir
from ..symbolic.canonical import new, xreplace
from ..symbolic.walk import DESCEND, fold
from ..ir import Assign, BlockPlan, Newton, Solve, Store, defines
from ..symbolic.algebra import (antiderivative, cancel_bounded, expand_bounded, is_singular,
                                is_symmetric, is_zero, lu_solution_nodes, solve_for)
from ..base.diagnostics import Collector, ModelError, Note, Span, fail, warning
from ..symbolic.differentiate import directional, partial
from . import contact
from ..front import events
from .system import (TIME, ConstraintDef, Equation, EquationSystem, OutputDef, ParameterDef,
                     StateVar, der)
from ..front.graph import var, written
from ..base.run_settings import ALGEBRA, RunSettings
from ..base.resources import (MAX_EXPANDED_TERMS, MAX_EXPRESSION_DEPTH, MAX_EXPRESSION_NODES,
                              SYMBOLIC_MAX_BLOCK, fits)
from ..symbolic.sparse import plan as lu_plan

RELATIVE_TOLERANCE = 1e-9
SYMBOLIC_MAX_UNKNOWNS = 1  # auto: linear blocks up to this size are solved symbolically ...
SYMBOLIC_MAX_OPS = 400  # ... when their matrix and right side are no bigger than this
TEAR_READS_MAX = 8  # a block's residuals read at most this many tears through each input
SUBSTITUTE_MAX_BODY = 40  # a nonlinear block of one unknown: body small enough to substitute
SINGULAR_CHECK_MAX = 40  # linear blocks up to this size: determinant tested at compile time
SYMMETRY_CHECK_MAX = 200  # ... and up to this size: symmetry (LDL^T-like elimination) tested
MAX_DERIVATIVE_ORDER = 3
SOLVED_WITH_BLOCK = "(solved with its block)"
TOO_LARGE = "(too large to write out)"
NOT_FINITE = (sp.zoo, sp.nan, sp.oo, -sp.oo)


# ---------------------------------------------------------------- the result


@dataclass(frozen=True)
class BlockInfo:
    """What `bgc check` says of a block: its unknowns, where it comes from, how it is solved."""

    index: int
    unknowns: tuple[str, ...]
    origins: tuple[str, ...]
    linear: bool
    method: str  # symbolic | lu | newton
    span: Span
    residuals: tuple[sp.Expr, ...] = ()  # a numeric block's equations, as reports show them:
    body: tuple[Assign, ...] = ()  # 0 = residuals(z), where body (explicit given z)
    internal: frozenset = frozenset()  # the variables its statements define besides z
    note: str = ""  # why a block that auto would solve symbolically is solved numerically


@dataclass(frozen=True)
class ConstraintInfo:
    junction: str
    kind: str  # holonomic | nonholonomic
    detected: bool  # kind found by the integrability test (not declared)
    corrector: str
    gains: tuple
    phi: sp.Expr | None  # holonomic Phi(q, t)
    balance: sp.Expr  # the balance in the states: dPhi/dt (holonomic) or Phi (nonholonomic)
    multiplier: sp.Symbol
    span: Span
    name_span: Span


@dataclass(frozen=True)
class ConstraintRow:
    """One scalar constraint residual in the kept states, checked at the initial time."""

    junction: str
    level: str  # "position" (holonomic Phi) or "velocity" (dPhi/dt, or nonholonomic Phi)
    expr: sp.Expr
    scale: sp.Expr  # the row holds when |expr| <= 1e-9 * scale
    weights: tuple = ()  # velocity rows: (p, d row / d v) of each momentum p whose velocity v
    #                      the row reads; the projection moves p by M(q) in these directions


@dataclass(frozen=True)
class Reduced:
    name: str
    parameters: tuple[ParameterDef, ...]
    states: tuple[StateVar, ...]  # kept: integrated, in the system's order
    pruned: tuple[str, ...]  # states not integrated because no output needs them
    steps: tuple  # bgc.ir statements over model symbols (Assign, Solve, Newton), in order
    plans: tuple[BlockPlan, ...]  # of the numeric blocks: Solve.block, Newton.block index it
    rates: tuple[sp.Symbol, ...]  # der(x) of each kept state, computed by the steps
    outputs: tuple[OutputDef, ...]
    constraints: tuple[ConstraintInfo, ...]
    rows: tuple[ConstraintRow, ...]
    blocks: tuple[BlockInfo, ...]
    eliminated: tuple[tuple[str, sp.Expr | str], ...]  # derivative causality: state = expr,
    # or why it is not written out (SOLVED_WITH_BLOCK, TOO_LARGE)
    run: RunSettings
    algebra: str
    warnings: tuple = ()
    events: object = None  # bgc.front.events.Selected, or None: no events
    tables: tuple = ()  # bgc.front.tables.TableData of the model (Table(k, ...) in the steps)
    inputs: tuple = ()  # graph.InputInfo of the model


# ---------------------------------------------------------------- equations by target


class _System:
    """The equations indexed by target, growing as constraints and derivatives add to them."""

    def __init__(self, es: EquationSystem):
        self.es = es
        self.eqs: dict[sp.Symbol, Equation] = {}
        self.order: dict[sp.Symbol, int] = {}
        self.states = {st.symbol: st for st in es.states}
        self.parameters = {var(p.name) for p in es.parameters}
        self.constants = self.parameters | events.leaves(es.events)  # constant between events
        self.by_name: dict[str, sp.Symbol] = {}
        diags = Collector()
        for eq in es.equations:
            if eq.target in self.eqs:
                first = self.eqs[eq.target]
                diags.error(eq.span, f"'{eq.target}' is computed twice (by '{first.origin}' and "
                                     f"'{eq.origin}'): check the causality of the model")
                continue
            self.add(eq)
        diags.raise_if_errors()
        for st in es.states:
            self.by_name[st.symbol.name] = st.symbol

    def add(self, eq: Equation):
        self.eqs[eq.target] = eq
        self.order[eq.target] = len(self.order)
        self.by_name[eq.target.name] = eq.target

    def is_leaf(self, s) -> bool:
        return s is TIME or s in self.constants or s in self.states

    def symbols(self, expr) -> list[sp.Symbol]:
        """The free symbols of expr in a deterministic order."""
        return sorted(expr.free_symbols, key=lambda s: s.name)

    # -- time derivatives on demand

    def derivative_of(self, d: sp.Symbol) -> sp.Symbol | None:
        """v for a symbol named der(v) whose v is known, else None."""
        name = d.name
        if not (name.startswith("der(") and name.endswith(")")):
            return None
        return self.by_name.get(name[4:-1])

    def differentiate(self, v: sp.Symbol) -> Equation:
        """The equation of der(v), from v's own equation (which must exist)."""
        eq = self.eqs[v]
        if v.name.count("der(") >= MAX_DERIVATIVE_ORDER:
            fail(eq.span, f"'{eq.origin}' needs a time derivative of order "
                          f"{MAX_DERIVATIVE_ORDER + 1} ({der(v)}): the model's index is too high")
        direction = {u: der(u) for u in eq.expr.free_symbols if u not in self.constants}
        direction[TIME] = sp.Integer(1)
        new = Equation(der(v), directional(eq.expr, direction), eq.explicit, eq.origin, eq.span)
        self.add(new)
        return new


# ---------------------------------------------------------------- leaf forms


class _Cycle(Exception):
    pass


def _leaf_forms(targets, defs, expandable, memo):
    """memo[s] := the expression of s with every expandable symbol replaced by its own
    definition, recursively (explicit stack).  Raises _Cycle on an algebraic loop."""
    for root in targets:
        if root in memo or not expandable(root):
            continue
        stack = [(root, False)]
        on_path = set()
        while stack:
            s, ready = stack.pop()
            if s in memo:
                continue
            expr = defs[s]
            inner = [u for u in expr.free_symbols if expandable(u)]
            if not ready:
                if s in on_path:
                    raise _Cycle(s)
                on_path.add(s)
                stack.append((s, True))
                for u in inner:
                    if u not in memo:
                        if u in on_path:
                            raise _Cycle(u)
                        stack.append((u, False))
                continue
            on_path.discard(s)
            memo[s] = xreplace(expr, {u: memo[u] for u in inner}) if inner else expr


def _leaf(expr, defs, expandable, memo=None):
    memo = {} if memo is None else memo
    inner = [u for u in expr.free_symbols if expandable(u)]
    _leaf_forms(inner, defs, expandable, memo)
    return xreplace(expr, {u: memo[u] for u in inner}) if inner else expr


# ---------------------------------------------------------------- constraints


def _explicit_defs(system: _System) -> dict:
    return {s: eq.expr for s, eq in system.eqs.items() if eq.explicit}


class _Coordinates:
    """The coordinates that integral signals integrate, and the flows they integrate (at the
    end of their alias chains), each solved for its coordinate's rate: worked out once for all
    the constraint junctions of the model."""

    def __init__(self, system: _System, defs: dict):
        self.system, self.defs = system, defs
        self.integrals = [st for st in system.es.states if st.kind == "integral signal"]
        self.coords = [st.symbol for st in self.integrals]
        self.rate = {q: var(f"d{q.name}/dt") for q in self.coords}
        self.others = set(system.states) - set(self.coords)
        frozen = set()
        for st in self.integrals:
            frozen |= {_alias_end(u, defs, system.eqs)
                       for u in system.eqs[der(st.symbol)].expr.free_symbols}
        self.frozen = frozen
        self.memo: dict = {}
        self.solved: dict = {}
        self.loop = False
        try:
            rates = {q: self.leaf(system.eqs[der(q)].expr) for q in self.coords}
        except _Cycle:
            self.loop = True
            return
        pending = list(self.coords)
        while pending:
            progress, still = False, []
            for q in pending:
                expr = rates[q].xreplace(self.solved) if self.solved else rates[q]
                open_ = [u for u in expr.free_symbols if self.unknown(u) and u not in self.solved]
                if len(open_) == 1:
                    sol = solve_for(expr - self.rate[q], open_[0])
                    if sol is not None:
                        self.solved[open_[0]] = sol
                        progress = True
                        continue
                still.append(q)
            if not progress:
                break
            pending = still

    def unknown(self, u) -> bool:
        return u in self.frozen or u in self.others

    def expandable(self, s) -> bool:
        return s in self.defs and s not in self.frozen and not self.system.is_leaf(s)

    def leaf(self, expr):
        return _leaf(expr, self.defs, self.expandable, self.memo)

    def form(self, c: ConstraintDef):
        """The balance as sum_i a_i(q, t) dq_i/dt + a_0(q, t), or None with a reason."""
        if not self.integrals:
            return None, "no integral signal integrates its flows into coordinates"
        if self.loop:
            return None, "its flows depend on an algebraic loop"
        try:
            balance = self.leaf(self.defs[c.balance])
        except _Cycle:
            return None, "its flows depend on an algebraic loop"
        unknowns = [u for u in balance.free_symbols if self.unknown(u)]
        if any(u not in self.solved for u in unknowns):
            return None, "its flows are not all integrated into coordinates by integral signals"
        balance = balance.xreplace({u: self.solved[u] for u in unknowns})
        multipliers = set(_multipliers(self.system))
        if any(s in self.defs or s in self.others or s in multipliers
               for s in balance.free_symbols):
            return None, "its flows are not all integrated into coordinates by integral signals"
        rates = {r: q for q, r in self.rate.items()}
        coeffs = {rates[r]: partial(balance, r) for r in
                  sorted(balance.free_symbols & rates.keys(), key=lambda s: s.name)}
        coeffs = {q: coeffs[q] for q in self.coords if q in coeffs}
        if any(co.free_symbols & rates.keys() for co in coeffs.values()):
            return None, "it is not linear in the coordinate rates"
        a0 = expand_bounded(balance.xreplace({r: sp.Integer(0) for r in rates}))
        if a0 is None:
            fail(c.name_span, f"the flow balance of constraint junction '{c.junction}' is too "
                              f"large to expand (more than {MAX_EXPANDED_TERMS} terms)")
        return (coeffs, a0, self.coords), None


def _multipliers(system):
    return [c.multiplier for c in system.es.constraints]


def _alias_end(s, defs, eqs):
    """What s is a plain alias of at the end of its chain (vx.f -> f[vx->mx]): an explicitly
    defined symbol, or the unknown of an implicit equation (a flow of a coupled I field, which
    solves M f = p with the others)."""
    seen = {s}
    while isinstance(defs.get(s), sp.Symbol) and defs[s] not in seen and \
            (defs[s] in defs or (defs[s] in eqs and not eqs[defs[s]].explicit)):
        s = defs[s]
        seen.add(s)
    return s


def _integrable(coeffs, a0, coords) -> bool:
    """Closed 1-form test over (q, t): d a_i / d z_j == d a_j / d z_i for every pair of the
    variables that occur (a coordinate that occurs in no coefficient has a_j = 0)."""
    occurring = set(coeffs)
    for a in list(coeffs.values()) + [a0]:
        occurring |= a.free_symbols & set(coords)
    zs = [q for q in coords if q in occurring] + [TIME]
    comp = dict(coeffs)
    comp[TIME] = a0
    for i, zi in enumerate(zs):
        for zj in zs[i + 1:]:
            d = partial(comp.get(zi, sp.Integer(0)), zj) - partial(comp.get(zj, sp.Integer(0)), zi)
            if d != 0 and not is_zero(d):
                return False
    return True


def _potential(coeffs, a0, span, name):
    comps = list(coeffs.items()) + [(TIME, a0)]
    P = sp.Integer(0)
    for z, a in comps:
        rest = a - partial(P, z)
        if rest == 0 or is_zero(rest):
            continue
        term = antiderivative(rest, z)
        if term is None:
            fail(span, f"cannot integrate the balance of '{name}' symbolically: give "
                       "'phi = ...' on the junction")
        P += term
    zero = {z: sp.S.Zero for z, _ in comps}
    at_zero = P.xreplace(zero)
    if at_zero.has(*NOT_FINITE):  # log(q): no value at q = 0 to measure the constant from
        return sp.expand(P), False
    return sp.expand(P - at_zero), True


def _phi(c: ConstraintDef, form, system: _System):
    coeffs, a0, coords = form
    if c.annotation is not None and c.annotation[0] == "phi":
        phi, span = c.annotation[1], c.annotation[2]
        zs = list(dict.fromkeys(list(coeffs) + sorted(phi.free_symbols & set(coords),
                                                      key=lambda s: s.name))) + [TIME]
        comp = dict(coeffs)
        comp[TIME] = a0
        for z in zs:
            a = comp.get(z, sp.Integer(0))
            if not is_zero(partial(phi, z) - a):
                fail(span, f"phi of '{c.junction}' does not match its flow balance: "
                           f"d(phi)/d{z} = {partial(phi, z)}, the balance has {a}")
        return phi, None
    P, from_zero = _potential(coeffs, a0, c.span, c.junction)
    if c.annotation is not None:
        if not from_zero:
            fail(c.annotation[2], f"'init' of '{c.junction}' is Phi where the coordinates are "
                                  f"0, but Phi = {written(P)} + constant has no value there: give "
                                  "'phi = ...' on the junction, or leave the constant to the "
                                  "initial state")
        return P + c.annotation[1], None
    t0 = sp.Float(system.es.run.t0)
    init = {st.symbol: st.init for st in system.es.states}
    const = -P.xreplace(init).xreplace({TIME: t0})
    if const.has(*NOT_FINITE) or const.has(sp.I):
        fail(c.name_span, f"constraint '{c.junction}' has no 'init = ...' or 'phi = ...', and "
                          f"Phi = {written(P)} + constant has no finite real value at the "
                          "initial state to take the constant from: give 'phi = ...' or "
                          "fix the initial values")
    msg = (f"constraint '{c.junction}' has no 'init = ...' or 'phi = ...': the geometric "
           f"constant is taken from the initial state (Phi = {P + const})")
    return P + const, msg


def _constraints(system: _System, diags: Collector) -> list[ConstraintInfo]:
    if not system.es.constraints:
        return []
    defs = _explicit_defs(system)
    coordinates = _Coordinates(system, defs)
    multipliers = set(_multipliers(system))
    memo: dict = {}
    infos = []
    for c in system.es.constraints:
        try:
            infos.append(_constraint(c, system, defs, coordinates, multipliers, memo, diags))
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    return infos


def _constraint(c, system, defs, coordinates, multipliers, memo, diags) -> ConstraintInfo:
    def expandable(s):
        return s in defs and not system.is_leaf(s)

    try:
        in_states = _leaf(defs[c.balance], defs, expandable, memo)
    except _Cycle:
        fail(c.name_span, f"the balance of constraint junction '{c.junction}' depends on an "
                          "algebraic loop; not supported")
    if not fits(in_states):
        fail(c.name_span, f"the flow balance of constraint junction '{c.junction}', written in "
                          "the states, is too large for symbolic work (bgc's limits: "
                          f"{MAX_EXPRESSION_NODES} operations, {MAX_EXPRESSION_DEPTH} levels)")
    if in_states.has(*NOT_FINITE):
        fail(c.name_span, f"the flow balance of constraint junction '{c.junction}' is not "
                          "finite (a division by zero?)")
    resistive = bool(in_states.free_symbols & multipliers)
    if c.kind in contact.SWITCHED and not c.dual:
        _refuse_imposed_flow(c, in_states, system, multipliers)
    if resistive and c.kind not in contact.SWITCHED:
        fail(c.span, f"the flow balance of constraint junction '{c.junction}' depends on a "
                     "multiplier directly (a resistive path?): declare it as a plain junction")
    form, reason = coordinates.form(c)
    integrable = form is not None and _integrable(*form)
    unilateral = c.kind == "unilateral"
    switched = c.kind in contact.SWITCHED  # a one-port that is a constraint in one mode
    kind, detected = ("holonomic" if unilateral else "nonholonomic" if switched else c.kind), \
        c.kind is None
    if kind is None:
        kind = "holonomic" if integrable else "nonholonomic"
    if kind == "holonomic" and not integrable:
        why = reason or "its coefficients have no symmetric Jacobian (not the derivative of a " \
                        "function of the coordinates)"
        fail(c.name_span, f"constraint '{c.junction}' is declared holonomic but is not "
                          f"integrable: {why}")
    phi = None
    if kind == "holonomic":
        phi, msg = _phi(c, form, system)
        if msg and (c.corrector == "pid" or _residual_asked(system.es, c)):
            diags.warning(c.name_span, msg)
    residual = phi if kind == "holonomic" else c.balance
    system.add(Equation(c.residual, residual, True, c.junction, c.span))
    B, dB, gains = c.balance, der(c.balance), c.gains
    if c.corrector == "pid":
        law = dB + 2 * gains[0] * B + gains[1] ** 2 * c.residual
    elif c.corrector == "pd":
        law = dB + gains[0] * B
    else:
        law = dB
    if resistive:  # a switched one-port on a resistive path: its flow itself is held at zero
        law = B
    if unilateral or switched:  # active: the constraint's law; else no force (bgc.middle.contact)
        free = c.multiplier - (c.gains[0] * contact.direction(c) if c.kind == "friction" else 0)
        law = sp.Piecewise((law, contact.holds(c)), (free, True))
    system.add(Equation(c.multiplier, law, False, c.junction, c.span))
    return ConstraintInfo(c.junction, c.kind if unilateral or switched else kind, detected,
                          c.corrector, c.gains, phi, in_states, c.multiplier, c.span,
                          c.name_span)


SWITCHED_WORDS = {  # kind: what it is, the mode that holds its flow at zero (to, being), what
    #                 that mode meets, what gives the flow another path
    "diode": ("ideal diode", "block", "blocking", "a current source forcing flow through a "
              "blocking diode", "a resistance across it"),
    "switch": ("ideal switch", "open", "open", "a current source forcing flow through an open "
               "switch", "a resistance across it"),
    "friction": ("dry friction", "stick", "sticking", "a velocity source forcing motion "
                 "through sticking friction", "a spring or a damper beside it"),
    "junction": ("switched junction", "switch", "its switch open", "a flow source forcing "
                 "flow through an open switch", "a resistance that carries it")}


def _refuse_imposed_flow(c: ConstraintDef, in_states, system: _System, multipliers) -> None:
    """A switched one-port whose flow, written in the states, reads neither a state nor a
    multiplier has it imposed from outside (a current source in series): the mode that holds
    that flow at zero (blocking, open, sticking) contradicts it, and the multiplier's law
    would divide by zero.  Refused at the element, with a note where the flow is imposed; a
    diode's flow that is a positive number never needs to block, and a zero flow never
    contradicts."""
    if in_states.free_symbols & (set(system.states) | multipliers) or in_states == 0:
        return
    if any(s in system.eqs and not system.eqs[s].explicit for s in in_states.free_symbols):
        return  # (a coupled field's velocities: they solve M(q) v = p, so follow the states)
    if c.kind == "diode" and in_states.is_number and in_states > 0:
        return
    name = c.junction.removesuffix(".switch")  # (`J : 1 switch(C)`: its switch J.switch)
    word, mode, being, what, path = SWITCHED_WORDS["junction" if name != c.junction
                                                   else c.kind]
    source = _imposed_by(system, c.balance, c.junction)
    by = f" by '{source.origin}'" if source is not None else ""
    notes = [Note(source.span, f"'{source.origin}' imposes the flow here, whatever the "
                               f"effort of '{name}'")] if source is not None else []
    fail(c.name_span, f"{word} '{name}' cannot {mode}: its flow is imposed{by} whatever "
                      f"its effort, and {being} (f = 0) would contradict it: {what}; give the "
                      f"flow another path ({path}) or drive it with an effort source", *notes)


def _imposed_by(system: _System, start, junction: str) -> Equation | None:
    """The equation an imposed flow comes from: the first met, walking the definitions from
    `start` breadth first, whose right side reads parameters, t and event values only (a
    source's law); None if there is none."""
    seen, todo = set(), [start]
    while todo:
        s = todo.pop(0)
        eq = system.eqs.get(s)
        if eq is None or s in seen:
            continue
        seen.add(s)
        inner = [u for u in system.symbols(eq.expr) if not system.is_leaf(u)]
        if not inner and eq.origin != junction:
            return eq
        todo += inner
    return None


def _residual_asked(es, c) -> bool:
    return any(o.expr == c.residual for o in es.outputs)


# ---------------------------------------------------------------- what the outputs need


def _needed(system: _System, roots=()) -> tuple[list[sp.Symbol], list[StateVar]]:
    """The targets the outputs (and the events' roots: (expr, span)) need (deriving der()
    equations on demand), and the states."""
    needed: set = set()
    kept: set = set()
    todo: list = []  # (symbol, the span of what needs it)
    for expr, span in [(o.expr, o.span) for o in system.es.outputs] + list(roots):
        todo.extend((u, span) for u in reversed(system.symbols(expr)))
    while todo:
        s, span = todo.pop()
        if s in needed or s is TIME or s in system.constants:
            continue
        if s in system.states:
            if s not in kept:
                kept.add(s)
                todo.append((der(s), span))
            continue
        eq = system.eqs.get(s)
        if eq is None:
            v = system.derivative_of(s)
            if v is None or v not in system.eqs:
                fail(span, f"'{s.name}' is not determined in this scene: nothing sets it (a "
                           "junction without bonds?)")
            eq = system.differentiate(v)
        needed.add(s)
        todo.extend((u, eq.span) for u in reversed(system.symbols(eq.expr)))
    targets = sorted(needed, key=lambda s: system.order[s])
    states = [st for st in system.es.states if st.symbol in kept]
    return targets, states


# ---------------------------------------------------------------- blocks


class _Blocks:
    def __init__(self, system: _System, algebra: str):
        self.system = system
        self.algebra = algebra
        self.steps: list = []  # bgc.ir statements over model symbols
        self.plans: list[BlockPlan] = []
        self.infos: list[BlockInfo] = []
        self.plan_eq: list = []  # per plan, and per variable a block introduces (its
        self.owner: dict = {}  # coefficients, its Jacobian's tangents): the block's equation
        self.fresh = 0
        self.note = ""  # the block's BlockInfo.note, while it is being solved

    def symbol(self, hint: str) -> sp.Symbol:
        self.fresh += 1
        return sp.Symbol(f"{hint}#{self.fresh}", real=True)

    def run(self, targets):
        index = {s: i for i, s in enumerate(targets)}
        eqs = [self.system.eqs[s] for s in targets]
        succ = [sorted(index[u] for u in eq.expr.free_symbols if u in index) for eq in eqs]
        for comp in blt.components(len(targets), succ):
            if len(comp) == 1 and eqs[comp[0]].explicit and comp[0] not in succ[comp[0]]:
                eq = eqs[comp[0]]
                self.steps.append(Assign(eq.target, eq.expr))
            else:
                self.block([eqs[i] for i in comp], {i: succ[i] for i in comp}, comp)

    # -- one block

    def block(self, eqs, succ, comp):
        pos = {v: k for k, v in enumerate(comp)}
        fixed = [v for v in comp if not eqs[pos[v]].explicit]
        tears, body_order = blt.tear(comp, succ, fixed, _inputs_of_nonlinearities(eqs, comp))
        tears, body_order = blt.bound(tears, body_order, succ, TEAR_READS_MAX)
        tear_eqs = [eqs[pos[v]] for v in tears]
        z = tuple(eq.target for eq in tear_eqs)
        body = tuple(Assign(eqs[pos[v]].target, eqs[pos[v]].expr) for v in body_order)
        residuals = tuple(eq.expr if not eq.explicit else eq.target - eq.expr
                          for eq in tear_eqs)
        origins = tuple(dict.fromkeys(eq.origin for eq in eqs))
        span = tear_eqs[0].span
        index = len(self.infos) + 1
        self._check_structure(z, body, residuals, origins, span)
        partials = _partials(z, body, residuals)
        linear = partials is not None
        prelude = ()
        self.note = ""
        method = self._choose(z, linear)
        if linear:
            prelude, matrix, rhs = self._linear_system(z, body, residuals, partials)
            if method == "symbolic":
                method = self._symbolic_linear(z, body, prelude, matrix, rhs, origins, span)
            if method == "lu":
                self._lu(index, z, body, prelude, matrix, rhs, origins, span, tear_eqs[0])
        else:
            if method == "symbolic":
                method = self._symbolic_nonlinear(z, body, residuals, origins, span)
            if method == "newton":
                self._newton(index, z, body, residuals, tear_eqs[0])
        numeric = method in ("lu", "newton")
        internal = frozenset(a.target for a in body + prelude) if method == "lu" else frozenset()
        self.infos.append(BlockInfo(index, tuple(s.name for s in z), origins, linear, method,
                                    span, residuals if numeric else (), body if numeric else (),
                                    internal, self.note))

    def _lu(self, index, z, body, prelude, matrix, rhs, origins, span, eq):
        """A z = b as statements: the coefficients (prelude), the Solve, the body."""
        symmetric = False
        if len(z) <= SYMMETRY_CHECK_MAX:
            A, _, _ = self._matrix_in_outer(z, prelude, matrix, origins, span)
            entries = [(i, k, A[i, k]) for i, k, _ in matrix]
            symmetric = len({i for i, k, _ in matrix if i == k}) == len(z) and \
                is_symmetric(entries)
        lu = self._plan(index, z, "lu", matrix, symmetric, eq)
        self.steps.extend(prelude)
        self.steps.append(Solve(len(self.plans) - 1, tuple(z[c] for c in lu.col_of),
                                tuple(e for _, _, e in matrix), tuple(rhs[r] for r in lu.row_of)))
        self.steps.extend(body)
        self.owner.update((a.target, eq) for a in prelude)

    def _newton(self, index, z, body, residuals, eq):
        """The block as one Newton statement: its body, residuals and Jacobian."""
        tangents, jacobian = self._jacobian(z, body, residuals)
        lu = self._plan(index, z, "newton", jacobian, False, eq)
        self.steps.append(Newton(len(self.plans) - 1, tuple(z[c] for c in lu.col_of), body,
                                 tuple(residuals[r] for r in lu.row_of), tangents,
                                 tuple(e for _, _, e in jacobian)))
        self.owner.update((a.target, eq) for a in tangents)

    def _plan(self, index, z, method, entries, symmetric, eq):
        """The block's factorization plan (bgc.symbolic.sparse), on the structure of its entries."""
        pattern = tuple((i, k) for i, k, _ in entries)
        cols = [[] for _ in z]
        for i, k in pattern:
            cols[i].append(k)
        matching = blt.perfect_matching(len(z), cols)
        if matching is None:  # pragma: no cover - _check_structure found one
            raise AssertionError("bgc bug: a block without a matching")
        lu = lu_plan(len(z), list(pattern), matching, symmetric)
        self.plans.append(BlockPlan(index, tuple(s.name for s in z), method, lu, pattern))
        self.plan_eq.append(eq)
        return lu

    def _choose(self, z, linear) -> str:
        if self.algebra == "numeric":
            return "lu" if linear else "newton"
        if self.algebra == "symbolic":
            return "symbolic"
        if linear:
            return "symbolic" if len(z) <= SYMBOLIC_MAX_UNKNOWNS else "lu"
        return "symbolic" if len(z) == 1 else "newton"

    def _check_structure(self, z, body, residuals, origins, span):
        """Each residual must be matchable to its own unknown through the body."""
        bit = {s: 1 << k for k, s in enumerate(z)}
        deps = dict(bit)
        for a in body:
            m = 0
            for u in a.expr.free_symbols:
                m |= deps.get(u, 0)
            deps[a.target] = m
        cols = []
        for r in residuals:
            m = 0
            for u in r.free_symbols:
                m |= deps.get(u, 0)
            cols.append([k for k in range(len(z)) if m >> k & 1])
        if blt.perfect_matching(len(z), cols) is None:
            names = ", ".join(f"'{o}'" for o in origins)
            fail(span, f"the equations through {names} do not determine "
                       f"{', '.join(s.name for s in z)} (structurally singular)")

    # -- linear blocks

    def _linear_system(self, z, body, residuals, partials):
        """A z = b: A by forward differentiation through the body, b = -r(0)."""
        prelude: list[Assign] = []
        matrix = self._forward(z, body, partials, prelude)
        at_zero = {s: sp.Integer(0) for s in z}
        for a in body:
            value = xreplace(a.expr, at_zero)
            at_zero[a.target] = self._named(value, prelude, "z0")
        rhs = tuple(-r.xreplace(at_zero) for r in residuals)
        return tuple(prelude), tuple(matrix), rhs

    def _named(self, expr, prelude, hint):
        """expr itself when it is a number or one symbol, else a new symbol assigned to it."""
        if expr.is_Number or expr.is_Symbol or (expr.is_Mul and len(expr.args) == 2
                                                and expr.args[0] == -1 and expr.args[1].is_Symbol):
            return expr
        s = self.symbol(hint)
        prelude.append(Assign(s, expr))
        return s

    def _matrix_in_outer(self, z, prelude, matrix, origins, span):
        """A with the prelude substituted (in what precedes the block); a located error when
        it is singular whatever the state (the block then determines nothing)."""
        defs = {a.target: a.expr for a in prelude}
        memo: dict = {}
        m = len(z)
        A = sp.zeros(m, m)
        for i, k, e in matrix:
            A[i, k] = _leaf(e, defs, lambda s: s in defs, memo)
        # (with every mode open: rows that hold only in some modes, two gaps on one
        # coordinate, may be dependent when both hold; a run that reaches that says so)
        off = {contact.active(c): sp.Integer(1 if c.dual else 0)
               for c in self.system.es.constraints
               if c.kind == "unilateral" or c.kind in contact.SWITCHED}
        A_off = A.xreplace(off) if off else A
        if m <= SINGULAR_CHECK_MAX and is_singular(m, [(i, k, A_off[i, k])
                                                       for i, k, _ in matrix]):
            rows = _dependent_rows(self.system.es.constraints, z, _at_random_point(A_off))
            if rows:
                fail(rows[0].name_span, f"the constraint rows {_listed(rows)} are not "
                                        "independent, whatever the state: their multipliers "
                                        "cannot be determined.  Remove the rows that repeat "
                                        "or combine the others")
            names = ", ".join(f"'{o}'" for o in origins)
            fail(span, f"the equations through {names} are singular: "
                       f"{', '.join(s.name for s in z)} cannot be determined")
        return A, defs, memo

    def _symbolic_linear(self, z, body, prelude, matrix, rhs, origins, span) -> str:
        """Solve the block in closed form, or say "lu" (auto) when it is too large to; the
        size is checked before each step of symbolic work (bgc.base.resources)."""
        m = len(z)
        if m > SYMBOLIC_MAX_BLOCK:
            return self._too_large(z, origins, span, f"more than {SYMBOLIC_MAX_BLOCK} unknowns")
        A, defs, memo = self._matrix_in_outer(z, prelude, matrix, origins, span)
        b = sp.Matrix([_leaf(e, defs, lambda s: s in defs, memo) for e in rhs])
        entries = list(A) + list(b)
        if not all(map(fits, entries)) or (self.algebra == "auto" and sum(
                sp.count_ops(e) for e in entries) > SYMBOLIC_MAX_OPS):
            return self._too_large(z, origins, span, "its coefficients are too large")
        if lu_solution_nodes(A, b, MAX_EXPRESSION_NODES) > MAX_EXPRESSION_NODES:
            return self._too_large(z, origins, span, "its solution would have more than "
                                                     f"{MAX_EXPRESSION_NODES} nodes")
        sol = [b[0] / A[0, 0]] if m == 1 else list(A.LUsolve(b))
        if not all(map(fits, sol)):  # (a safety net: the estimate above bounds it)
            return self._too_large(z, origins, span, "its solution is too large")
        for s, value in zip(z, sol):
            self.steps.append(Assign(s, _tidy(value)))
        self.steps.extend(body)
        return "symbolic"

    def _too_large(self, z, origins, span, why) -> str:
        """"lu" in auto, the reason kept for `bgc check`; with --algebra symbolic, a located
        error."""
        if self.algebra == "symbolic":
            names = ", ".join(f"'{o}'" for o in origins)
            fail(span, f"the linear equations through {names} are too large to solve "
                       f"symbolically ({len(z)} unknowns; {why}); let bgc solve them "
                       "numerically (--algebra auto or numeric)")
        self.note = f"not symbolically: {why}"
        return "lu"

    # -- nonlinear blocks

    def _symbolic_nonlinear(self, z, body, residuals, origins, span) -> str:
        if len(z) == 1 and len(body) <= SUBSTITUTE_MAX_BODY:
            defs = {a.target: a.expr for a in body}
            r = _leaf(residuals[0], defs, lambda s: s in defs)
            sol = solve_for(r, z[0])  # None too when r is beyond bgc.base.resources' limits
            if sol is not None:
                self.steps.append(Assign(z[0], sol))
                self.steps.extend(body)
                return "symbolic"
        if self.algebra == "symbolic":
            names = ", ".join(f"'{o}'" for o in origins)
            fail(span, f"nonlinear algebraic equations through {names} have no clean "
                       "closed-form solution; let bgc solve them numerically (--algebra auto "
                       "or numeric)")
        return "newton"

    def _jacobian(self, z, body, residuals):
        """d residuals / d z by forward differentiation through the body: tangent assignments
        (over z, the body and what precedes the block) and the nonzero entries."""
        tangents: list[Assign] = []
        jacobian = self._forward(z, body, _all_partials(z, body, residuals), tangents)
        return tuple(tangents), jacobian

    def _forward(self, z, body, partials, out):
        """The entries (i, k, d r_i / d z_k) by forward differentiation through the body: the
        intermediate coefficients d v / d z_k are variables assigned in out, so that the work
        stays linear in the body.  partials: {u: d expr / d u} of each body assignment and
        each residual (_partials, _all_partials)."""
        tangent = {(s, k): sp.Integer(1) for k, s in enumerate(z)}
        zdep = {s: [k] for k, s in enumerate(z)}
        for a, parts in zip(body, partials[0]):
            zdep[a.target] = ks = sorted({k for u in parts for k in zdep[u]})
            for k in ks:
                tangent[(a.target, k)] = self._named(_chain(parts, tangent, k), out, "dz")
        entries = []
        for i, parts in enumerate(partials[1]):
            for k in sorted({k for u in parts for k in zdep[u]}):
                entry = _chain(parts, tangent, k)
                if entry != 0:
                    entries.append((i, k, entry))
        return tuple(entries)


def _at_random_point(A: sp.Matrix):
    """A's values at a random point of its symbols (a seeded generator: the same point every
    run), as floats; None where it is not real there."""
    import random

    rng = random.Random(1)
    symbols = sorted(A.free_symbols, key=lambda s: s.name)
    point = {s: sp.Float(rng.uniform(0.3, 1.7)) for s in symbols}
    try:
        return [[float(A[i, k].xreplace(point)) for k in range(A.cols)] for i in range(A.rows)]
    except (TypeError, ValueError):
        return None


def _dependent_rows(constraints, z, values) -> list:
    """The constraints (ConstraintDef or ConstraintInfo) whose multipliers are among the
    unknowns z of a singular block and take part in its dependence: nonzero in a null vector of
    its matrix (values: its entries as floats, None if unknown).  All the block's multipliers
    when the vector cannot say; none when it has no multiplier."""
    import numpy

    by_multiplier = {c.multiplier: c for c in constraints}
    involved = [k for k, u in enumerate(z) if u in by_multiplier]
    if not involved:
        return []
    A = None if values is None else numpy.array(values, dtype=float)
    if A is not None and numpy.all(numpy.isfinite(A)):
        null = numpy.linalg.svd(A)[2][-1]
        big = numpy.abs(null).max()
        rows = [by_multiplier[z[k]] for k in involved if abs(null[k]) > 1e-6 * big]
        if rows:
            return rows
    return [by_multiplier[z[k]] for k in involved]


def _listed(rows) -> str:
    return ", ".join(f"'{c.junction}'" for c in rows)


def _chain(parts, tangent, k):
    """d expr / d z_k from expr's partials and its inputs' tangents."""
    return new(sp.Add, [new(sp.Mul, (d, tangent[(u, k)])) for u, d in parts.items()
                        if (u, k) in tangent])


def _all_partials(z, body, residuals):
    """{u: d expr / d u} over the block's variables (z and the body before expr) of each body
    assignment and each residual."""
    inner = set(z)
    body_parts = []
    for a in body:
        body_parts.append({u: partial(a.expr, u) for u in a.expr.free_symbols if u in inner})
        inner.add(a.target)
    return body_parts, [{u: partial(r, u) for u in r.free_symbols if u in inner}
                        for r in residuals]


def _inputs_of_nonlinearities(eqs, comp) -> frozenset:
    """The block's variables that occur inside a function or a non-polynomial power of its
    equations.  Tearing there evaluates each nonlinearity forward from the unknown, which
    suits Newton's method (for a diode, its voltage rather than its current: from a poor
    start the exponential overshoots and the damping pulls back, instead of Newton creeping
    up its flat side one thermal voltage per step)."""
    targets = {eq.target: v for eq, v in zip(eqs, comp)}
    out = set()
    for eq in eqs:
        stack = [(eq.expr, False)]
        while stack:
            e, inside = stack.pop()
            if e.is_Symbol:
                if inside and e in targets:
                    out.add(targets[e])
                continue
            nonlinear = inside or isinstance(e, sp.Function) or (
                e.is_Pow and not (e.exp.is_Integer and e.exp > 0))
            stack.extend((a, nonlinear) for a in e.args)
    return frozenset(out)


def _partials(z, body, residuals):
    """For each body assignment and each residual, {u: d expr / d u} over its z-dependent
    inputs u; None when some partial itself depends on z (the block is nonlinear)."""
    zdep = set(z)
    body_parts = []
    for a in body:
        parts = _linear_parts(a.expr, zdep)
        if parts is None:
            return None
        body_parts.append(parts)
        if parts:
            zdep.add(a.target)
    res_parts = []
    for r in residuals:
        parts = _linear_parts(r, zdep)
        if parts is None:
            return None
        res_parts.append(parts)
    return body_parts, res_parts


def _linear_parts(expr, zdep):
    parts = {}
    for u in sorted((u for u in expr.free_symbols if u in zdep), key=lambda s: s.name):
        d = partial(expr, u)
        if d.free_symbols & zdep:
            return None
        if d != 0:
            parts[u] = d
    return parts


def _tidy(expr):
    """A symbolic solution's fraction cancelled and its common factors taken out, when that
    is small work (bgc.symbolic.algebra.cancel_bounded: estimated before it starts); else as it is.
    (The cancelled form of a sum of N reciprocals is also N times larger than the sum.)"""
    if not fits(expr, 600) or sp.count_ops(expr) >= 300:
        return expr
    cancelled = cancel_bounded(expr)
    return expr if cancelled is None else sp.factor_terms(cancelled)


# ---------------------------------------------------------------- main


def reduce(es: EquationSystem, project_initial: bool = False, algebra: str = "auto") -> Reduced:
    if algebra not in ALGEBRA:
        raise ValueError(f"algebra must be one of {', '.join(ALGEBRA)}, not {algebra!r}")
    system = _System(es)
    diags = Collector()
    infos = _constraints(system, diags)
    diags.raise_if_errors()
    if any(c.kind == "unilateral" or c.kind in contact.SWITCHED for c in infos):
        es = contact.with_contact_events(system, infos, _Weights(system), _explicit_defs(system), _leaf,
                                         _Cycle)
        system.es = es
        system.constants = system.parameters | events.leaves(es.events)
    try:
        targets, kept = _needed(system)
        selected = None
        if any(es.events):
            targets, kept, selected = _with_events(system, targets, kept)
            _warn_unsolved_times(selected, diags)
            selected = _with_start_forms(system, selected)
        blocks = _Blocks(system, algebra)
        blocks.run(targets)
    except ModelError as err:
        _switched_modes_unsupported(err, infos)
        raise
    _check_constants(blocks, system)
    rows = _rows(system, infos, kept)
    kept_symbols = {st.symbol for st in kept}
    pruned = tuple(st.name for st in es.states if st.symbol not in kept_symbols)
    eliminated = _eliminated(system)
    reduced = Reduced(es.name, es.parameters, tuple(kept), pruned, tuple(blocks.steps),
                      tuple(blocks.plans),
                      tuple(der(st.symbol) for st in kept), es.outputs, tuple(infos),
                      tuple(rows), tuple(blocks.infos), eliminated, es.run, algebra,
                      tuple(es.warnings) + tuple(diags.warnings), selected, es.tables,
                      es.inputs)
    if not project_initial:
        check_initial(reduced)
    else:
        initial_values(reduced)  # every initial state a double, projected or not
    return _with_init_warnings(reduced, system, eliminated)


def _warn_unsolved_times(selected, diags: Collector) -> None:
    """A relation of t and parameters alone whose crossings bgc cannot find in advance
    (bgc.front.events.time_roots) is checked at the ends of steps only: say so where it is."""
    if selected is None:
        return
    where = {r.symbol: r for r in selected.state}
    for symbol, forms in selected.crossings:
        if forms is None:
            r = where[symbol]
            diags.warning(r.span, f"the condition '{r.text}' depends on t alone, but bgc cannot "
                                  "find its times in advance (t must occur once, under sums, "
                                  "products and functions with known inverses): it is checked "
                                  "at the end of each step, and a window shorter than a step "
                                  "can be missed; bound the step with --max-step (or hmax)")


def _switched_modes_unsupported(err: ModelError, infos) -> None:
    """A model whose switched one-ports (D, Sw, Fr) force storages into derivative causality
    in one of their modes (a switch closing a loop of capacitors with nothing to limit the
    flow, a diode across a capacitor): the high index or the undetermined balance met is the
    mode's; say so at the switched elements, with what was met as a note."""
    switched = [c for c in infos if c.kind in contact.SWITCHED]
    d = err.diagnostics[0]
    if not switched or not ("index is too high" in d.message
                            or "is not determined in this scene" in d.message):
        return
    names = ", ".join(f"'{c.junction}'" for c in switched)
    fail(switched[0].name_span, f"a mode of {names} forces storages into derivative causality "
                                "(closed or conducting, it joins storages with nothing to limit "
                                "the flow between them, or blocking, it leaves one without a "
                                "path); bgc does not support such modes yet: put a resistance "
                                "or an inductance in the switched path",
         Note(d.span, d.message), *d.notes)


def _with_start_forms(system: _System, selected):
    """The state relations that read signals, written in what the signals are computed from,
    for the start's first pass (bgc.front.events._at_start): a relation of a signal of a time
    source must read the source's value at t0 there, not its value before the start.  Only
    the signals that read a time source are written out, and a form beyond MAX_START_FORM
    operations is left as it is."""
    if selected is None:
        return None
    defs, memo = _explicit_defs(system), {}
    sources = {q.symbol for q in selected.squares} | {r.symbol for r, _, _ in selected.time}

    def expandable(s):
        return s in defs and not system.is_leaf(s)

    starts = []
    for r in selected.state:
        timed = {}
        for s in sorted(r.relation.free_symbols, key=lambda s: s.name):
            if not expandable(s):
                continue
            try:
                form = _leaf(s, defs, expandable, memo)
            except _Cycle:
                continue
            if form.free_symbols & sources and fits(form, MAX_START_FORM):
                timed[s] = form  # (a signal of a time source: written out)
        if timed:
            starts.append((r.symbol, r.relation.xreplace(timed)))
    return replace(selected, starts=tuple(starts))


MAX_START_FORM = 2000


def _with_events(system: _System, targets, kept):
    """The targets and states once the events the scene needs are counted in (what they read
    is computed too, and a kept when-block's state is kept), and those events."""
    selected = None
    for _ in range(len(system.es.events[3]) + 2):
        used = set()
        for t in targets:
            used |= system.eqs[t].expr.free_symbols
        for o in system.es.outputs:
            used |= o.expr.free_symbols
        new = events.select(system.es.events, used, {st.symbol: st for st in kept},
                            system.parameters)
        if new == selected:
            break
        selected = new
        targets, kept = _needed(system, selected.roots())
    events.check(selected, system.es)
    return targets, kept, (None if selected.empty else selected)


def _check_constants(blocks: _Blocks, system: _System):
    """The variables that are numbers put into what reads them, forward, as the lowering stage
    does: an expression that then is not finite (1/s where s = 0 is an equation of the model)
    is a located error, not an infinity in the generated code."""
    known: dict = {}

    def put(expr, eq: Equation):
        used = expr.free_symbols & known.keys()
        if not used:
            return expr
        value = expr.xreplace({u: known[u] for u in used})
        names = ", ".join(f"{u.name} = {known[u]}" for u in sorted(used, key=lambda u: u.name))
        if value.has(*NOT_FINITE):
            fail(eq.span, f"'{eq.origin}' is not finite where {names} (a division by zero?)")
        if value.has(sp.I):  # a negative constant to a fractional power: no real value
            fail(eq.span, f"'{eq.origin}' is a complex number where {names} (a negative number "
                          "to a fractional power?)")
        return value

    for step in blocks.steps:
        if isinstance(step, Assign):
            assigns, uses = [step], []
            eq = system.eqs.get(step.target) or blocks.owner[step.target]
        else:
            eq = blocks.plan_eq[step.block]
            assigns = list(step.body) + list(step.tangents) if isinstance(step, Newton) else []
            uses = list(step.residuals) + list(step.jacobian) if isinstance(step, Newton) \
                else list(step.matrix) + list(step.rhs)
        for a in assigns:
            value = put(a.expr, system.eqs.get(a.target) or blocks.owner.get(a.target, eq))
            if value.is_Number:
                known[a.target] = value
        for e in uses:
            put(e, eq)


def _eliminated(system: _System):
    defs = _explicit_defs(system)

    def expandable(s):
        return s in defs and not system.is_leaf(s)

    out = []
    for st in system.es.stores:
        if st.state not in defs:
            out.append((st.state.name, SOLVED_WITH_BLOCK))
            continue
        try:
            expr = _leaf(st.state, defs, expandable)
        except _Cycle:
            out.append((st.state.name, SOLVED_WITH_BLOCK))
            continue
        out.append((st.state.name, expr if fits(expr) else TOO_LARGE))
    return tuple(out)


def _rows(system, infos, kept) -> list[ConstraintRow]:
    """The constraint rows in the kept states (constraints on states that this scene does not
    integrate are left out)."""
    kept_symbols = {st.symbol for st in kept}
    all_states = set(system.states)
    balances = {c.junction: c.balance for c in system.es.constraints}
    weigh = _Weights(system)
    rows = []
    for c in infos:
        if c.kind == "unilateral" or c.kind in contact.SWITCHED:
            continue  # a gap, or a mode: not an equality, checked by its events
            #           (bgc.middle.contact)
        levels = ([("position", c.phi)] if c.kind == "holonomic" else []) + \
            [("velocity", c.balance)]
        for level, expr in levels:
            if (expr.free_symbols & all_states) - kept_symbols:
                continue
            weights = weigh(balances[c.junction]) if level == "velocity" else ()
            rows.append(ConstraintRow(c.junction, level, expr, scale_of(expr), weights))
    # A velocity row's terms may all vanish where it holds (the tip's sideways velocity, one
    # term): its scale then also counts the speeds of the momenta the velocity rows read,
    # through its weights, so that it holds to 1e-9 of the system's motion, not of nothing.
    speeds = weigh.speeds({p for r in rows for p, _ in r.weights})
    return [replace(r, scale=r.scale + sp.Add(*[sp.Abs(d, evaluate=False) for _, d in r.weights])
                    * speeds) if r.weights and speeds != 0 else r for r in rows]


class _Weights:
    """The velocity rows' derivatives by the velocities of the momenta they read: a row is
    the balance of its junction's flows, written here in those velocities (the flows of the
    I elements held as they are), differentiated by each, then written in the states.  With
    them the projection onto the velocity rows moves the momenta by the kinetic metric: the
    smallest change of kinetic energy, as an impulse of the constraint would, which for a
    coupled field is dp = G^T mu whatever M(q) is."""

    def __init__(self, system: _System):
        self.system = system
        self.defs = _explicit_defs(system)
        self.momenta = [(p, f, sign) for p, f, sign in system.es.momenta if p in system.states]
        self.frozen = {f for _, f, _ in self.momenta}
        self.memo: dict = {}
        self.memo_all: dict = {}

    def __call__(self, balance) -> tuple:
        defs, system = self.defs, self.system

        def held(s):
            return s in defs and s not in self.frozen and not system.is_leaf(s)

        try:
            in_flows = _leaf(defs[balance], defs, held, self.memo)
            out, flows = [], in_flows.free_symbols
            for p, f, sign in self.momenta:
                if f in flows:
                    d = sign * partial(in_flows, f)
                    out.append((p, _leaf(d, defs, lambda s: s in defs and not system.is_leaf(s),
                                         self.memo_all)))
        except _Cycle:
            return ()
        return tuple(out)

    def speeds(self, moved) -> sp.Expr:
        """The sum of the magnitudes of the velocities of the momenta in moved, in the states
        (a coupled field's through its block)."""
        defs, system = self.defs, self.system
        try:
            return sp.Add(*[sp.Abs(_leaf(sign * f, defs, lambda s: s in defs and
                                         not system.is_leaf(s), self.memo_all), evaluate=False)
                            for p, f, sign in self.momenta if p in moved])
        except _Cycle:
            return sp.Integer(0)


def scale_of(expr):
    """The sum of the magnitudes of expr's terms (Abs left unevaluated: evaluating it asks
    SymPy's assumptions about every factor, which costs more than all else here)."""
    return sp.Add(*[sp.Abs(term, evaluate=False) for term in sp.Add.make_args(expr)])


# ---------------------------------------------------------------- initial conditions


def initial_values(reduced: Reduced) -> dict:
    """Numeric parameters, initial states and t0 at the scene's defaults."""
    params = parameter_values(reduced.parameters)
    t0 = sp.Float(reduced.run.t0)
    x0 = {st.symbol: sp.Float(_initial_value(st, params, t0)) for st in reduced.states}
    return {**params, **x0, TIME: t0}


def _initial_value(st, params: dict, t0) -> float:
    """A state's initial value as a double: C(1e308) init e = -10 gives q = -1e309, which
    no double holds, a located error here rather than an infinity in the generated code."""
    value = st.init.xreplace(params).xreplace({TIME: t0})
    try:
        x = float(value)
    except (TypeError, OverflowError):
        x = math.nan
    if not math.isfinite(x):
        if value.is_Float and value.is_finite:  # computed exactly, beyond a double's range
            shown = mpmath.nstr(mpmath.mpf(value), 3)
            fail(st.span, f"the initial state of '{st.name}' does not fit a double: it is "
                          f"{shown} at the given parameters (choose smaller values)")
        fail(st.span, f"the initial state of '{st.name}' is not finite: it is {value} at the "
                      "given parameters")
    return x


def parameter_values(parameters) -> dict:
    values = {}
    for p in parameters:
        values[var(p.name)] = sp.Float(float(p.expr.xreplace(values)))
    return values


class _NotNumeric(Exception):
    """An expression that the initial values do not make a number (a Newton block's unknown)."""


def _number(expr, values, done=None) -> float:
    """expr in doubles, given the doubles of its symbols (values: symbol -> float); a walk of
    the tree without SymPy's arithmetic (the check at the start evaluates a whole model once).
    Raises _NotNumeric for a symbol without a value; NaN where a function is undefined.
    done (shared by the expressions of one evaluation, whose symbols each take one value):
    the values of the subexpressions already walked."""
    def leaf(e):
        if e.is_Symbol:
            if e not in values:
                raise _NotNumeric(e)
            return values[e]
        if e.is_Number or e.is_NumberSymbol:
            return float(e)
        return DESCEND

    return fold(expr, {} if done is None else done, leaf, _apply)


_FLOAT_FUNCTIONS = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin,
                    "acos": math.acos, "atan": math.atan, "atan2": math.atan2,
                    "sinh": math.sinh, "cosh": math.cosh, "tanh": math.tanh,
                    "asinh": math.asinh, "atanh": math.atanh, "exp": math.exp, "log": math.log,
                    "Abs": abs}


def _apply(e, args) -> float:
    try:
        if e.is_Add:
            return math.fsum(args)
        if e.is_Mul:
            out = 1.0
            for a in args:
                out *= a
            return out
        if e.is_Pow:
            return math.pow(args[0], args[1])
        name = type(e).__name__
        if name in _FLOAT_FUNCTIONS:
            return _FLOAT_FUNCTIONS[name](*args)
        if name == "sign":
            return math.copysign(1.0, args[0]) if args[0] != 0 else 0.0
        if name == "Heaviside":
            return 1.0 if args[0] > 0 else 0.0 if args[0] < 0 else 0.5
        if name == "Min":
            return min(args)
        if name == "Max":
            return max(args)
    except (ValueError, OverflowError, ZeroDivisionError):
        return math.nan
    raise _NotNumeric(e)


def evaluate(reduced: Reduced, values: dict, exprs) -> list[float]:
    """exprs at the given values of the parameters, states and time, through the steps they
    need: the rows of a constraint on a coupled field read its flows, which solve M(q) f = p.
    Raises _NotNumeric where a step cannot be evaluated here, ModelError where a linear block
    is singular at these values (naming its equations)."""
    body = ir.prune(list(reduced.steps) + [Store(k, e) for k, e in enumerate(exprs)])
    v = {}
    for k, value in values.items():
        try:
            v[k] = float(value)
        except TypeError:
            raise _NotNumeric(k) from None
    out = [0.0] * len(exprs)
    done: dict = {}  # (each symbol is assigned once, before what reads it)
    for s in body:
        if isinstance(s, Assign):
            v[s.target] = _number(s.expr, v, done)
        elif isinstance(s, Store):
            out[s.index] = _number(s.expr, v, done)
        elif isinstance(s, Solve):
            import numpy  # (here: only models whose rows go through a block need it)
            plan = reduced.plans[s.block]
            m = len(s.unknowns)
            A = numpy.zeros((m, m))
            for (i, k), e in zip(plan.pattern, s.matrix):
                A[i, k] = _number(e, v, done)
            b = numpy.zeros(m)
            for r, e in zip(plan.lu.row_of, s.rhs):
                b[r] = _number(e, v, done)
            if not numpy.all(numpy.isfinite(A)):
                raise _NotNumeric(s)
            if numpy.linalg.matrix_rank(A) < m:
                _singular_at_start(reduced, plan, s, A)
            z = numpy.linalg.solve(A, b)
            for c, u in zip(plan.lu.col_of, s.unknowns):
                v[u] = float(z[c])
        else:
            raise _NotNumeric(s)
    return out


def _singular_at_start(reduced: Reduced, plan: BlockPlan, s: Solve, A):
    """A located error for a linear block that is singular at the initial state: the constraint
    rows that lose their independence there, or the block's equations."""
    info = reduced.blocks[plan.index - 1]
    z = [None] * len(s.unknowns)
    for c, u in zip(plan.lu.col_of, s.unknowns):
        z[c] = u
    rows = _dependent_rows(reduced.constraints, z, A)
    if rows:
        if len(rows) == 1:
            fail(rows[0].name_span, f"constraint {_listed(rows)} has a zero Jacobian at the "
                                    "initial state (a singular configuration): its multiplier "
                                    "cannot be determined.  Start from another configuration")
        fail(rows[0].name_span, f"the constraint rows {_listed(rows)} are not independent at "
                                "the initial state (their Jacobian loses rank there, a "
                                "singular configuration): their multipliers cannot be "
                                "determined.  Start from another configuration, or remove a "
                                "row that repeats or combines the others")
    fail(info.span, f"block {plan.index} ({', '.join(info.unknowns)}) is singular at the "
                    "initial state: its equations do not determine its unknowns there (through "
                    f"{', '.join(info.origins)})")


def check_initial(reduced: Reduced):
    values = initial_values(reduced)
    diags = Collector()
    kinds = {c.junction: c for c in reduced.constraints}
    rows = reduced.rows
    try:
        numbers = evaluate(reduced, values, [r.expr for r in rows] + [r.scale for r in rows])
    except _NotNumeric:
        return  # a row through a Newton block: the generated program checks it
    for k, row in enumerate(rows):
        c = kinds[row.junction]
        r, s = numbers[k], numbers[len(rows) + k]
        if not (math.isfinite(r) and math.isfinite(s)):  # log(q) at q = 0, sqrt of a negative
            diags.error(c.name_span, f"constraint '{row.junction}' has no finite real value "
                                     f"at the initial values: {written(row.expr)} (fix the "
                                     "initial values)")
            continue
        if abs(r) > RELATIVE_TOLERANCE * s:
            what = "Phi" if row.level == "position" else "dPhi/dt" if c.kind == "holonomic" \
                else "Phi (nonholonomic)"
            diags.error(c.name_span, f"initial conditions violate constraint '{row.junction}': "
                                     f"{what} = {r:.6g} (relative {abs(r) / s if s else r:.3g}, "
                                     f"tolerance {RELATIVE_TOLERANCE:g}); fix the initial values, "
                                     "or use --project-initial or --allow-inconsistent")
    diags.raise_if_errors()
    if reduced.constraints:  # the multipliers' block: solvable at the start?
        try:
            evaluate(reduced, values, reduced.rates)
        except _NotNumeric:
            pass  # through a Newton block, or not finite there: the generated program says


def _with_init_warnings(reduced: Reduced, system: _System, eliminated) -> Reduced:
    """Warn where an init clause on a derivative-causality element disagrees with the model."""
    stores = [s for s in system.es.stores if s.given_init is not None]
    if not stores:
        return reduced
    implied_of = dict(eliminated)
    params = parameter_values(reduced.parameters)
    t0 = sp.Float(reduced.run.t0)
    values = {**params, TIME: t0,
              **{st.symbol: sp.Float(float(st.init.xreplace(params).xreplace({TIME: t0})))
                 for st in system.es.states}}
    out = []
    for s in stores:
        expr = implied_of.get(s.state.name)
        if not isinstance(expr, sp.Basic):
            continue
        try:
            implied = float(expr.xreplace(values))
            given = float(s.given_init.xreplace(values))
        except TypeError:  # no real value at the start (a ratio 1/t at t = 0): nothing to
            continue       # compare (the run says where the state is not finite)
        if abs(implied - given) > RELATIVE_TOLERANCE * max(abs(implied), abs(given), 1e-300):
            out.append(warning(s.init_span, f"'{s.element}' is in derivative causality: its "
                                            f"state is {implied:.6g} at the start, not the "
                                            f"{given:.6g} given here, which is ignored"))
    return Reduced(**{**reduced.__dict__, "warnings": reduced.warnings + tuple(out)})


# ---------------------------------------------------------------- explicit forms (reports)


def shown_steps(reduced: Reduced):
    """The steps as reports show them: the assignments, and in place of each numeric block's
    statements its BlockInfo (its equations, 0 = residuals where body)."""
    hidden = set().union(*(b.internal for b in reduced.blocks))
    for s in reduced.steps:
        if not isinstance(s, Assign):
            yield reduced.blocks[reduced.plans[s.block].index - 1]
        elif s.target not in hidden:
            yield s


def explicit_forms(reduced: Reduced, symbols, max_ops: int = 3000) -> dict | None:
    """Each symbol in the states, parameters and t alone (every assignment substituted), or
    None when a block is solved numerically on the way or an expression grows beyond max_ops:
    the equations are then shown as the program that computes them."""
    defs = {}
    for step in reduced.steps:
        if isinstance(step, Assign):
            defs[step.target] = step.expr
        else:
            defs.update((s, None) for s in defines(step))
    memo: dict = {}
    out = {}
    for s in symbols:
        try:
            expr = _explicit(s, defs, memo, max_ops)
        except _Cycle:
            return None
        if expr is None:
            return None
        out[s] = expr
    return out


def _explicit(root, defs, memo, max_ops):
    stack = [(root, False)]
    while stack:
        s, ready = stack.pop()
        if s in memo:
            continue
        if s not in defs:
            memo[s] = s
            continue
        expr = defs[s]
        if expr is None:
            raise _Cycle(s)  # computed by a numeric block
        inner = [u for u in expr.free_symbols if u in defs and u not in memo]
        if not ready and inner:
            stack.append((s, True))
            stack.extend((u, False) for u in inner)
            continue
        value = expr.xreplace({u: memo[u] for u in expr.free_symbols if u in defs})
        if not fits(value) or sp.count_ops(value) > max_ops:
            raise _Cycle(s)
        memo[s] = value
    return memo[root]


__all__ = ["BlockInfo", "shown_steps", "ConstraintInfo", "ConstraintRow", "Reduced",
           "reduce", "check_initial", "explicit_forms", "initial_values", "parameter_values",
           "scale_of", "ALGEBRA"]
