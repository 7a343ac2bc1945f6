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

Through events: at a time event whose time depends on none of the chosen parameters (a square
wave's edge, a relation of t, a table's or an input's breakpoint), where nothing that changes
reads the states or the chosen parameters, x is continuous for every value of the parameters,
and so is S: S(t+) = S(t-), and the augmented program runs through it unchanged (its update
passes S through).  Every other event is refused, named: a state event's time depends on the
states (S jumps by (f- - f+) dtau/dp), and a reinit or a mode read from the states sets x from
them; those jump conditions are not implemented yet.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp

from .. import ir
from ..symbolic.differentiate import directional
from ..front.graph import var
from ..ir import P, V, X, Function, JacobianPattern, Resolve, Store
from ..ir.tangent import _Forward


class SensitivityError(ValueError):
    """Parameters or a model that sensitivities cannot be computed for (for people)."""


def column(of: str, param: str) -> str:
    """The name of the sensitivity of `of` (a state or an output) to parameter `param`."""
    return f"d({of})/d({param})"


def check(params, names, events=None, states=(), defaults=None, steps=()) -> tuple[str, ...]:
    """The parameters asked for, checked against the program's parameters (`names`); events:
    the model's (bgc.front.events.Selected, or None), refused unless S is continuous through
    all of them (see the module's doc); states: the states' symbols; defaults: each
    parameter's name -> its default expression (a parameter defined from a chosen one
    follows it); steps: the statements that compute what the events read (bgc.ir's, over
    model symbols).  A true `events` that is not a Selected (an older caller) is refused."""
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
        why = jumps(events, params, states, defaults or {}, steps)
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


def jumps(sel, params, states, defaults: dict, steps=()) -> str | None:
    """Why the sensitivities to params would jump at one of sel's events (a sentence naming
    the event, for people), or None: every event is a time event that S passes unchanged."""
    if not hasattr(sel, "slots"):
        return ("the model has events (a when-block, a switch, a relation of the states or "
                "time): its sensitivities jump at an event, and bgc does not compute those "
                "jumps")
    reads = set(states) | _moved(params, defaults)  # what follows the states or the params
    grown = True
    while grown:  # (through the steps, and the discrete values' laws: to the fixed point)
        size = len(reads)
        for st in steps:
            if ir.uses(st) & reads:
                reads |= set(ir.defines(st))
        for d in sel.discretes:
            laws = [d.init] + ([d.next] if d.next is not None else [])
            laws += [a.expr for w in sel.whens for a in w.actions if a.symbol == d.symbol]
            if d.symbol not in reads and any(e.free_symbols & reads for e in laws):
                reads.add(d.symbol)
        grown = len(reads) > size
    changing = {d.symbol for d in sel.discretes} & reads

    def refuse(text, what):
        return (f"{what} '{text}': the sensitivities jump there, and bgc computes them "
                "through time events only (an event whose time and effect depend on neither "
                "the states nor the parameters asked for); not supported yet")
    for r in sel.state + sel.discrete:
        if r.indicator.free_symbols & reads:
            return refuse(r.text, "the model has the event" if r.indicator.free_symbols
                          & changing else "the model has the state event")
    for r, at, _ in sel.time:
        if _free(at) & reads:
            return refuse(r.text, "the time of the event")
    for s in sel.squares:
        if any(_free(getattr(s, f, 0)) & reads
               for f in ("period", "duty", "t0")):
            return refuse(s.text, "the time of the event")
    for w in sel.whens:
        for a in w.actions:
            if a.kind == "reinit":
                return refuse(w.text, "the when-block (a reinit)")
    for d in sel.discretes:
        if d.symbol in changing:
            return refuse(d.name, "the discrete value")
    return None


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


class _Second(_Forward):
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
        forward = _Second(tan, plans, fresh, solves) if second else _Forward(tan, plans, fresh)
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
            pattern_of=None) -> Augmented:
    """The functions of the augmented program (see the module's doc), from the model's own in
    the IR's symbols, before constants are hoisted.  chosen: the parameters (names); given:
    those the run overrides (a parameter computed from a chosen one by its default follows
    it unless given).  state_outputs: the states and S are outputs too, after the others."""
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
    if "update" in functions:  # (time events only, check's: S passes through unchanged)
        out["update"] = _passing(functions["update"], n, wide)
    names = list(states) + [column(s, p) for p in chosen for s in states]
    shown = list(outputs) + (list(states) if state_outputs else [])
    columns = shown + [column(y, p) for p in chosen for y in shown]
    return Augmented(tuple(names), tuple(columns), out,
                     tuple(movable) + (False,) * (n * m), count, exact, base)

