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

A model with events is refused: the sensitivities jump at an event, and the jump conditions
are not implemented.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp

from .. import ir
from ..symbolic.differentiate import directional
from ..ir import P, V, X, Function, JacobianPattern, Resolve, Store
from ..ir.tangent import _Forward


class SensitivityError(ValueError):
    """Parameters or a model that sensitivities cannot be computed for (for people)."""


def column(of: str, param: str) -> str:
    """The name of the sensitivity of `of` (a state or an output) to parameter `param`."""
    return f"d({of})/d({param})"


def check(params, names, has_events: bool) -> tuple[str, ...]:
    """The parameters asked for, checked against the program's parameters (`names`)."""
    params = tuple(params)
    if not params:
        raise SensitivityError("no parameter given for the sensitivities")
    for p in params:
        if p not in names:
            raise SensitivityError(f"unknown parameter {p!r} (parameters: "
                                   f"{', '.join(names) or 'none'})")
    if len(set(params)) != len(params):
        raise SensitivityError("a parameter is named twice for the sensitivities")
    if has_events:
        raise SensitivityError(
            "the model has events (a when-block, a switch, a relation of the states or time): "
            "its sensitivities jump at an event, and bgc does not compute those jumps")
    return params


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
    names = list(states) + [column(s, p) for p in chosen for s in states]
    shown = list(outputs) + (list(states) if state_outputs else [])
    columns = shown + [column(y, p) for p in chosen for y in shown]
    return Augmented(tuple(names), tuple(columns), out,
                     tuple(movable) + (False,) * (n * m), count, exact, base)

