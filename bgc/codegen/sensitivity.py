"""Forward sensitivities: the program of a model augmented with S = dx/dp for chosen parameters.

For parameters p_1..p_m the augmented state is (x, S_1, ..., S_m), S_k = dx/dp_k, and

    x' = f(t, x, p)                         x(0) = x0(p)
    S_k' = (df/dx) S_k + df/dp_k            S_k(0) = dx0/dp_k

which is the tangent of the right side along the seeds x -> S_k, p_k -> 1 (and every parameter
computed from p_k, unless the run overrides it).  The lowering stage builds it on the IR
functions before their constants are hoisted (bgc.codegen.lower.lower(reduced, sensitivities=...)),
with bgc.ir.tangent's forward differentiation, which goes through the linear and Newton blocks:
so the augmented program is an ordinary program, and both runtimes and every solver integrate
it unchanged.  Its outputs are the outputs y, then dy/dp_k = (dy/dx) S_k + dy/dp_k for each
parameter (columns `d(y)/d(p)`), and, asked for, the states and S.

The stiff solvers need the augmented system's Jacobian, whose S rows hold second derivatives:
d(J S_k + df/dp_k)/dx.  Where every block the right side solves is linear, it is exact: jvp is
the forward derivative of the augmented right side itself, and a tangent's Resolve through a
linear block is differentiated once more (d(dz) = A^-1 (dr - dA dz), `_Second`).  A Newton
block's tangent is not differentiated again, so a model with one gets the block-diagonal
diag(J, J, ..., J), J = df/dx, which leaves those second derivatives out: a simplified Newton
iteration as CVODES's simultaneous corrector uses.  Radau's Newton iteration converges with
it to the same collocation solution; a Rosenbrock method, which needs the exact Jacobian for
its order, loses accuracy in the sensitivities (docs/analysis.md gives the numbers).

Through events (needs_jumps): where every event is a time event whose time depends on none of
the chosen parameters (a square wave's edge, a relation of t, a table's or an input's
breakpoint) and nothing that changes reads the states or the chosen parameters, x is
continuous for every value of the parameters, and so is S: the augmented program's update
passes S through (_passing).  Otherwise, at an event at tau with map h (a reinit; the
identity where a mode change only switches the right side from f- to f+), S jumps:

    dtau/dp = -(g_x S- + g_p) / (g_x f- + g_t)        a state event, g(x, p, t) crossing zero
    dtau/dp = d(time)/dp                              a time event (step, pulse, square's edge)
    S+ = h_x S- + h_p + (h_x f- + h_t - f+) dtau/dp

The augmented update (_jumping) computes, in the event iteration's first pass, dtau/dp of the
first event that changed (the order in which the runtimes locate them) and the total
derivative T = S- + f- dtau/dp, and in every pass T+ = h_x T + h_p + h_t dtau/dp (the
tangent of the update's states), dtau/dp among its results; the runtimes hand it back in the
later passes and after the iteration subtract f+ dtau/dp (bgc_jumps_after in drive.c): the
passes compose, whatever the modes an event changes in turn.  What stays refused (refusal):
a discrete value the run reads that follows the states or the parameters continuously.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp

from .. import ir
from ..symbolic.differentiate import directional
from ..base.diagnostics import fail
from ..front.graph import var
from ..ir import D, P, R, V, X, Function, JacobianPattern, Resolve, Store
from ..ir.tangent import Forward


class SensitivityError(ValueError):
    """Parameters or a model that sensitivities cannot be computed for (for people)."""


def column(of: str, param: str) -> str:
    """The name of the sensitivity of `of` (a state or an output) to parameter `param`."""
    return f"d({of})/d({param})"


def check(params, names, events=None, states=(), defaults=None, steps=(),
          results=None) -> tuple[str, ...]:
    """The parameters asked for, checked against the program's parameters (`names`); events:
    the model's (bgc.front.events.Selected, or None), refused where the sensitivities'
    jumps at its events cannot be computed (refusal's); states: the states' symbols;
    defaults: each parameter's name -> its default expression (a parameter defined from a
    chosen one follows it); steps: the statements that compute what the events read
    (bgc.ir's, over model symbols); results: what the run reads of them (refusal's).  A
    true `events` that is not a Selected (an older caller) is refused."""
    params = tuple(params)
    if not params:
        raise SensitivityError("no parameter given for the sensitivities")
    for p in params:
        if p not in names:
            raise SensitivityError(f"unknown parameter {p!r} (parameters: "
                                   f"{', '.join(names) or 'none'})")
    if len(set(params)) != len(params):
        raise SensitivityError("a parameter is named twice for the sensitivities")
    if events is not None and events is not False:
        why = refusal(events, params, states, defaults or {}, steps, results)
        if isinstance(why, tuple):  # (where, what): a model error, located
            fail(*why)
        if why is not None:
            raise SensitivityError(why)
    return params


def _free(e) -> set:
    """e's free symbols (a plain number has none)."""
    return e.free_symbols if isinstance(e, sp.Basic) else set()


def _moved(params, defaults: dict) -> set:
    """The symbols of the chosen parameters and of every parameter defined from them."""
    moved = {var(p) for p in params}
    for name, expr in defaults.items():  # (in order: a default reads earlier ones only)
        if expr is not None and expr.free_symbols & moved:
            moved.add(var(name))
    return moved


def _laws(sel, d) -> list:
    """What sets discrete value d: its initial value, its next value (a mode's), the when-
    blocks' assignments to it."""
    laws = [d.init] + ([d.next] if d.next is not None else [])
    return laws + [a.expr for w in sel.whens for a in w.actions if a.symbol == d.symbol]


def _following(sel, params, states, defaults: dict, steps) -> tuple[set, dict]:
    """(what follows the states or the chosen parameters: the steps' symbols computed from
    them, to the fixed point through the discrete values; the discrete values among them
    that follow them continuously, each -> the symbols its law reads that move it).  A
    discrete value whose laws are piecewise constant in what they read (a mode, a counter,
    a relation's value: derivative zero wherever it is defined) does not follow them."""
    reads = set(states) | _moved(params, defaults)
    continuous: dict = {}
    grown = True
    while grown:  # (through the steps, and the discrete values' laws: to the fixed point)
        size = len(reads)
        for st in steps:
            if ir.uses(st) & reads:
                reads |= set(ir.defines(st))
        for d in sel.discretes:
            if d.symbol in continuous:
                continue
            for law in _laws(sel, d):
                moving = _free(law) & reads
                if moving and directional(law, {s: sp.Integer(1) for s in moving}) != 0:
                    continuous[d.symbol] = moving
                    reads.add(d.symbol)
                    break
        grown = len(reads) > size
    return reads, continuous


def _weighs(d, sel, steps, results) -> bool:
    """Whether discrete value d's own value moves anything the sensitivities carry: what the
    steps compute from it with a nonzero derivative (followed in order), read so by the
    results (the rates, the outputs), the state relations' indicators, the time events'
    times or the reinits.  A value read only in conditions (a contact's largest impact
    speed, which decides whether it rests) does not: their derivative is zero."""
    carried = {d}

    def moves(e) -> bool:
        free = _free(e) & carried
        return bool(free) and directional(e, {c: sp.Integer(1) for c in free}) != 0
    for st in steps:
        if any(moves(e) for e in ir.expressions(st)):
            carried |= set(ir.defines(st))
    exprs = list(results) + [r.indicator for r in sel.state] + [at for _, at, _ in sel.time]
    exprs += [getattr(q, f) for q in sel.squares if q.kind == "square"
              for f in ("period", "duty", "t0")]
    exprs += [a.expr for w in sel.whens for a in w.actions if a.kind == "reinit"]
    return any(moves(e) for e in exprs)


def refusal(sel, params, states, defaults: dict, steps=(), results=None):
    """Why the sensitivities to params cannot be carried through sel's events: (its span, a
    sentence for people), a sentence where there is no place to point at, or None.  What is
    refused: a discrete value set from the states or the chosen parameters by a law that is
    not piecewise constant (a sampled value, `when ... { d = x }`): its sensitivity would be
    a state's that the augmented program does not have.  A value read only in conditions
    passes (_weighs).  results: what the run computes from the steps (the rates, the
    outputs); None: everything the steps define."""
    if results is None:
        results = [t for st in steps for t in ir.defines(st)]
    if not hasattr(sel, "slots"):
        return ("the model has events (a when-block, a switch, a relation of the states or "
                "time): its sensitivities jump at an event, and bgc does not compute those "
                "jumps")
    _, continuous = _following(sel, params, states, defaults, steps)
    for d in sel.discretes:
        if d.symbol in continuous and _weighs(d.symbol, sel, steps, results):
            what = ", ".join(sorted(str(s) for s in continuous[d.symbol]))
            return d.span, (
                f"the sensitivities cannot pass the events of '{d.name}': it is set from "
                f"what the states or the parameters asked for move ({what}), by a law that "
                "is not piecewise constant, so its own sensitivity would have to be carried "
                "as a state's; bgc carries the states' only (not supported yet)")
    return None


def needs_jumps(sel, params, states, defaults: dict, steps=()) -> bool:
    """Whether the sensitivities to params jump at one of sel's events: a state event whose
    indicator reads what the states or the parameters move, a time event whose time reads
    the parameters, a reinit.  Else every event is a time event that S passes unchanged,
    and the augmented program's update passes S through (_passing)."""
    if sel is None or not hasattr(sel, "slots"):
        return False
    reads, _ = _following(sel, params, states, defaults, steps)
    if any(r.indicator.free_symbols & reads for r in sel.state + sel.discrete):
        return True
    if any(_free(at) & reads for _, at, _ in sel.time):
        return True
    if any(_free(getattr(s, f, 0)) & reads for s in sel.squares
           for f in ("period", "duty", "t0")):
        return True
    return any(a.kind == "reinit" for w in sel.whens for a in w.actions)


def seeds(params: tuple[ir.Param, ...], j: int, given) -> dict:
    """The tangents of the parameters along p_j: 1 for p[j], and the derivative of each
    parameter computed from it by its default (unless the run overrides it: `given`)."""
    dp = {P[j]: sp.Integer(1)}
    for i, par in enumerate(params):
        if i > j and par.name not in given:
            d = directional(par.default, dp)
            if d != 0:
                dp[P[i]] = d
    return dp


class _Second(Forward):
    """Forward differentiation that also goes through a Resolve of a linear block (the
    tangent of a tangent): for dz = A^-1 r, d(dz) = A^-1 (dr - dA dz), A's entries those of
    the block's Solve met before it in the function."""

    def __init__(self, seeds, plans, fresh, solves):
        super().__init__(seeds, plans, fresh)
        self.solves = solves  # block -> its Solve (shared: the primal part records them)

    def statement(self, s):
        if isinstance(s, ir.Solve):
            self.solves[s.block] = s
        if isinstance(s, Resolve):
            self.out.append(s)
            solve = self.solves[s.block]
            lu = self.plans[s.block].lu
            row_at, col_at = ir.positions(lu.row_of), ir.positions(lu.col_of)
            terms = [[] for _ in s.rhs]
            for (i, k), e in zip(self.plans[s.block].pattern, solve.matrix):
                d = self.of(e)
                if d != 0:
                    terms[row_at[i]].append(d * s.targets[col_at[k]])
            self.resolve(_Unknowns(s.block, s.targets),
                         [self.of(r) - sp.Add(*t) for r, t in zip(s.rhs, terms)])
            return
        super().statement(s)


@dataclass(frozen=True)
class _Unknowns:
    block: int
    unknowns: tuple


def _exact(f: Function, plans) -> bool:
    """Whether f's Jacobian can be derived exactly: every block it solves is linear (a
    Newton block's tangent is not differentiated again)."""
    return all(plans[s.block].method == "lu" for s in f.body
               if isinstance(s, (ir.Solve, ir.Newton, Resolve)))


def _forward(f: Function, name: str, size: int, seed_sets, offsets, plans, fresh,
             primal_stores: bool, second: bool = False) -> tuple[Function, int]:
    """f's statements once (its stores too when primal_stores), then for each seed set its
    tangents, result k of the set's tangent stored at offsets[set] + k (a zero too: every
    function this builds stores each of its results)."""
    out = [replace(s, final_factor=True) if isinstance(s, ir.Newton) else s
           for s in f.body if primal_stores or not isinstance(s, Store)]
    solves = {s.block: s for s in f.body if isinstance(s, ir.Solve)}
    for tan, offset in zip(seed_sets, offsets):
        forward = _Second(tan, plans, fresh, solves) if second else Forward(tan, plans, fresh)
        for s in f.body:
            if isinstance(s, Store):
                d = forward.of(s.expr)
                forward.out.append(Store(offset + s.index, ir.integral_floats(d)))
                continue
            mark = len(forward.out)
            forward.statement(s)
            del forward.out[mark]  # s itself, which the primal part has
        out += forward.out
        fresh = forward.fresh
    args = f.args + ("v",) if name == "jvp" else f.args
    return Function(name, args, size, tuple(out)), fresh


def _restride(f: Function, n: int, wide: int) -> Function:
    """A row-major Jacobian of n columns (store k*n + j) as one of `wide` columns."""
    rows = f.size // n if n else 0
    body = tuple(Store((s.index // n) * wide + s.index % n, s.expr) if isinstance(s, Store)
                 else s for s in f.body)
    return Function(f.name, f.args, rows * wide, body)


def _passing(f: Function, n: int, wide: int) -> Function:
    """The event iteration's update of the augmented program: the model's new states, then S
    as it is (its stores n..wide), then the discrete values (the model's stores from n on)."""
    body = tuple(Store(s.index + wide - n, s.expr) if isinstance(s, Store) and s.index >= n
                 else s for s in f.body)
    return Function(f.name, f.args, f.size + wide - n,
                    body + tuple(Store(i, X[i]) for i in range(n, wide)))


def _changed(sel, n: int, stores: dict):
    """Per event that can set the time of an event iteration, in the order the runtimes
    locate them (the state relations, the time relations, the square waves): (its kind,
    its number among its kind, the condition that it changed in this pass, in IR symbols)."""
    G = len(sel.state)
    out = [("state", k, sp.Ne(R[k], D[k])) for k in range(G)]
    out += [("time", k, sp.Ne(stores[n + G + k], D[G + k])) for k in range(len(sel.time))]
    first = G + len(sel.time) + len(sel.discrete)
    at = [first + q for q, s in enumerate(sel.squares) if s.kind == "square"]
    out += [("square", k, sp.Ne(stores[n + i], D[i])) for k, i in enumerate(at)]
    return out


def _jumping(f: Function, n: int, m: int, sel, dps, plans, fresh) -> tuple[Function, int]:
    """The event iteration's update of the augmented program through the jumps of S (the
    module's doc, "Through events").  f is the model's update with, after its results (the
    n states, then the discrete values), the right side f- (n), the state relations'
    indicators and the time relations' times; the result: the new states, the new T_k
    (n each), the discrete values, then dtau/dp_k (one per parameter), which the runtimes
    hand back as r[G + 2 + k] in the iteration's later passes (r[G + 1] = 1 in its first)."""
    ND = len(sel.slots())
    G, wide = len(sel.state), n * (1 + m)
    stores = {s.index: s.expr for s in f.body if isinstance(s, Store)}
    body = [replace(s, final_factor=True) if isinstance(s, ir.Newton) else s
            for s in f.body if not isinstance(s, Store)]
    rates = [stores[n + ND + i] for i in range(n)]
    indicators = [stores[n + ND + n + k] for k in range(G)]
    times = [stores[n + ND + n + G + k] for k in range(len(sel.time))]
    first = sp.Ne(R[G + 1], 0)

    def run(seeds, exprs):
        """The tangents of exprs along seeds, their statements appended to the body."""
        nonlocal fresh
        forward = Forward(seeds, plans, fresh)
        for s in [s for s in f.body if not isinstance(s, Store)]:
            mark = len(forward.out)
            forward.statement(s)
            del forward.out[mark]
        out = [ir.integral_floats(forward.of(e)) for e in exprs]
        body.extend(forward.out)
        fresh = forward.fresh
        return out

    def assign(expr):
        nonlocal fresh
        w = ir.W(fresh)
        fresh += 1
        body.append(ir.Assign(w, expr))
        return w

    rate = [assign(e) for e in rates]
    along = run({**{X[i]: rate[i] for i in range(n)}, ir.T: sp.Integer(1)}, indicators)
    along = [a if a.is_number else assign(a) for a in along]  # (a piecewise rate's zero
    #        branches stay in it: a quotient by the Piecewise itself would divide them by 0)
    changed = _changed(sel, n, stores)
    base = n + ND - len(sel.squares) - len(sel.discretes)  # the square waves' stores
    waves = [stores[base + q] for q, s in enumerate(sel.squares) if s.kind == "square"]
    edges = [a for w in waves for a in w.args[1:]]  # period, duty, t0 of each
    jumps, taus = [], []
    for j, dp in enumerate(dps):
        S = [X[(j + 1) * n + i] for i in range(n)]
        moved = run({**dp, **{X[i]: S[i] for i in range(n)}}, indicators + times + edges)
        pieces = []
        for kind, k, cond in changed:
            if kind == "state":  # (a rate that is 0 throughout: it never crosses in time)
                d = -moved[k] / along[k] if moved[k] != 0 and along[k] != 0 else 0
            elif kind == "time":
                d = moved[G + k]
            else:  # an edge at t0 + k*period (rising) or t0 + (k + duty)*period (falling)
                dP, dduty, dt0 = moved[G + len(times) + 3 * k:][:3]
                period, _, t0 = waves[k].args[1:]
                fall = sp.Piecewise((period * dduty, sp.Eq(waves[k], 0)), (0, True))
                d = dt0 + (ir.T - t0) / period * dP + fall
            if d != 0:
                pieces.append((d, cond))
        located = sp.Piecewise(*pieces, (0, True)) if pieces else sp.Integer(0)
        tau = assign(sp.Piecewise((located, first), (R[G + 2 + j], True)))
        total = [assign(sp.Piecewise((S[i] + rate[i] * tau, first), (S[i], True)))
                 for i in range(n)]
        h = run({**dp, **{X[i]: total[i] for i in range(n)}, ir.T: tau},
                [stores[i] for i in range(n)])
        jumps += [Store(n + j * n + i, h[i]) for i in range(n)]
        taus.append(Store(wide + ND + j, tau))
    out = [Store(i, stores[i]) for i in range(n)] + jumps + \
        [Store(wide + k, stores[n + k]) for k in range(ND)] + taus
    return Function(f.name, f.args, wide + ND + m, tuple(body + out)), fresh


@dataclass(frozen=True)
class Augmented:
    states: tuple[str, ...]
    outputs: tuple[str, ...]
    functions: dict
    movable: tuple[bool, ...]
    count: int
    exact: bool  # the augmented Jacobian is exact (else block-diagonal)
    base_pattern: JacobianPattern | None  # the model's own, for the block-diagonal one

    def pattern(self, program) -> ir.Program:
        """program with the block-diagonal Jacobian's pattern, when the Jacobian is one."""
        if self.exact:
            return program
        base = self.base_pattern
        n = len(base.columns)
        blocks = len(program.states) // n if n else 1
        columns = tuple(tuple(b * n + i for i in base.columns[j])
                        for b in range(blocks) for j in range(n))
        colors = tuple(tuple(b * n + j for b in range(blocks) for j in c) for c in base.colors)
        return replace(program, jacobian=JacobianPattern(columns, colors))


def augment(functions: dict, params: tuple[ir.Param, ...], states: tuple[str, ...],
            outputs: tuple[str, ...], movable: tuple[bool, ...], chosen: tuple[str, ...],
            given, plans, count: int, state_outputs: bool = False,
            pattern_of=None, events=None) -> Augmented:
    """The functions of the augmented program (see the module's doc), from the model's own in
    the IR's symbols, before constants are hoisted.  chosen: the parameters (names); given:
    those the run overrides (a parameter computed from a chosen one by its default follows
    it unless given).  state_outputs: the states and S are outputs too, after the others.
    events: the model's (a Selected) when S jumps at them (needs_jumps): the functions' update
    has the results _jumping reads after its own."""
    n, m, M = len(states), len(chosen), len(outputs)
    index = {p.name: k for k, p in enumerate(params)}
    given = set(given) | set(chosen)
    dps = [seeds(params, index[name], given) for name in chosen]
    wide = n * (1 + m)
    out = dict(functions)
    rhs = functions["rhs"]
    ts = [{**dp, **{X[i]: X[(k + 1) * n + i] for i in range(n)}} for k, dp in enumerate(dps)]
    out["rhs"], count = _forward(rhs, "rhs", wide, ts, [(k + 1) * n for k in range(m)],
                                 plans, count, True)
    out["init"], count = _forward(functions["init"], "init", wide, dps,
                                  [(k + 1) * n for k in range(m)], plans, count, True)
    extra = M * (1 + m)
    outs = functions["outputs"]
    if state_outputs:  # (their tangents are the S columns themselves)
        outs = Function(outs.name, outs.args, M + n, outs.body + tuple(
            Store(M + i, X[i]) for i in range(n)))
        M += n
        extra = M * (1 + m)
    out["outputs"], count = _forward(outs, "outputs", extra, ts, [(k + 1) * M for k in range(m)],
                                     plans, count, True)
    exact = _exact(out["rhs"], plans)
    base = None
    if exact:
        out["jvp"], count = _forward(out["rhs"], "jvp", wide, [{X[i]: V[i] for i in range(wide)}],
                                     [0], plans, count, False, second=True)
    else:
        base = pattern_of(rhs, n, plans)
        out["jvp"], count = _forward(rhs, "jvp", wide,
                                     [{X[i]: V[b * n + i] for i in range(n)}
                                      for b in range(1 + m)],
                                     [b * n for b in range(1 + m)], plans, count, False)
    for name in ("position_jac", "velocity_jac", "velocity_metric"):
        out[name] = _restride(functions[name], n, wide)
    if "update" in functions and events is not None:  # S jumps at the events
        try:
            out["update"], count = _jumping(functions["update"], n, m, events, dps, plans,
                                            count)
        except TypeError as error:  # (directional's: a function it has no derivative of)
            raise SensitivityError(
                f"the sensitivities cannot jump through the model's events: a map of an "
                f"event (a reinit, a mode change) or a relation is not differentiable "
                f"({error})") from None
    elif "update" in functions:  # (time events only, needs_jumps's: S passes unchanged)
        out["update"] = _passing(functions["update"], n, wide)
    names = list(states) + [column(s, p) for p in chosen for s in states]
    shown = list(outputs) + (list(states) if state_outputs else [])
    columns = shown + [column(y, p) for p in chosen for y in shown]
    return Augmented(tuple(names), tuple(columns), out,
                     tuple(movable) + (False,) * (n * m), count, exact, base)

