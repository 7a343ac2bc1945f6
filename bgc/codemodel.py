"""The language-neutral code model: what the emitters print, nothing they must derive.

Every expression here is a SymPy expression over exactly these symbols:
  t            Symbol("t")            time
  x[i]         IndexedBase("x")[i]    state i, ordered as `states`
  p[j]         IndexedBase("p")[j]    parameter j, ordered as `params`
  c[k]         IndexedBase("c")[k]    constant k: result k of the `consts` block, a function of
                                      the parameters only, computed once whenever they are set
  w0, w1, ...  Symbol("w<k>")         common subexpressions, defined in a Block's `temps`
and the functions sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt Abs sign
Min Max Heaviside, Pow, Rational, Float, Integer, pi, E.  Model names never occur in
expressions, so nothing a model author writes can reach generated code except through the
`states`/`outputs`/`params` name strings, which the emitters escape as string literals
(names are identifiers with '.', '[', ']' only, but emitters escape them regardless).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

T = sp.Symbol("t")
X = sp.IndexedBase("x")
P = sp.IndexedBase("p")
C = sp.IndexedBase("c")


def as_expr(value) -> sp.Basic:
    """A SymPy object from a SymPy object or a Python number; never parses text."""
    if isinstance(value, sp.Basic):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"expected a SymPy expression or a number, got {type(value).__name__}")
    return sp.Integer(value) if isinstance(value, int) else sp.Float(value)


@dataclass(frozen=True)
class Block:
    """Straight-line code: temps in order (each may use earlier temps), then results[i] = out[i]."""

    temps: tuple[tuple[sp.Symbol, sp.Expr], ...]
    results: tuple[sp.Expr, ...]


@dataclass(frozen=True)
class Param:
    name: str
    default: sp.Expr  # uses only p[k] for k < own index; recomputed when not overridden


@dataclass(frozen=True)
class ConstraintRow:
    """One scalar constraint residual, checked (and optionally projected) at the initial time."""

    junction: str  # display name of the constraint junction, e.g. "rod" or "rod[1]"
    level: str  # "position" (holonomic Phi) or "velocity" (dPhi/dt, or nonholonomic Phi)


@dataclass(frozen=True)
class SceneSettings:
    t0: float
    t_end: float
    dt: float
    solver: str  # euler | rk4 | dopri5
    rtol: float
    atol: float
    step: float | None  # fixed step for euler/rk4; None: dt


@dataclass(frozen=True)
class CodeModel:
    name: str  # model name, an identifier
    states: tuple[str, ...]  # display names: "mx.p", "x", "q[1]"
    params: tuple[Param, ...]
    outputs: tuple[str, ...]  # display names, CSV columns after t
    init: Block  # results: x0[i], len(states); uses p only
    rhs: Block  # results: dx[i]/dt, len(states); uses t, x, p
    out: Block  # results: y[j], len(outputs); uses t, x, p
    constraints: tuple[ConstraintRow, ...]
    residual: Block  # results: r[k], len(constraints); uses t, x, p
    scale: Block  # results: s[k] >= 0; a row holds when |r[k]| <= 1e-9 * s[k]
    position_jac: Block  # results: row-major d r[k] / d x[i] for position rows, k in position order
    velocity_jac: Block  # results: row-major d r[k] / d x[i] for velocity rows
    velocity_movable: tuple[bool, ...]  # per state: may the velocity projection move it?
    scene: SceneSettings
    consts: Block = Block((), ())  # results: c[k]; uses p only (not t, x or c)

    @property
    def position_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "position")

    @property
    def velocity_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "velocity")


def make_block(exprs, prefix: str = "w") -> Block:
    """CSE a list of expressions into a Block with deterministic temporaries."""
    exprs = [as_expr(e) for e in exprs]
    if not exprs:
        return Block((), ())
    temps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols(prefix), order="none")
    return Block(tuple(temps), tuple(reduced))


def _parameter_only(expr: sp.Basic) -> bool:
    """Uses p and numbers only: no t, x or c."""
    return not (expr.has(T) or expr.has(X) or expr.has(C))


def hoist_constants(groups: Sequence[Sequence[sp.Expr]]
                    ) -> tuple[tuple[sp.Expr, ...], tuple[tuple[sp.Expr, ...], ...]]:
    """The parameter-only subexpressions of groups (sequences of expressions over t, x, p),
    replaced by constants c[k]: returns (constant expressions, rewritten groups).

    What becomes a constant: every largest subexpression that uses parameters and no t or
    x and is more than a single parameter; and within a sum or product that also uses t or
    x, its parameter-only terms or factors taken together (so that `2*m*g*y` becomes c[k]*y
    with c[k] = 2*m*g).  A constant that occurs more than once is one c[k]; the constants
    are numbered in order of first occurrence, walking the groups and the expression trees
    in their (canonical) argument order, so that no set or hash order reaches the result.
    Nothing changes but where the arithmetic is done: sums and products may group their
    terms differently, so values can differ in the last bits."""
    pool: dict[sp.Expr, sp.Indexed] = {}
    memo: dict[sp.Expr, sp.Expr] = {}

    def constant(expr):
        if expr.is_Atom or isinstance(expr, sp.Indexed) or not expr.has(P):
            return expr  # a number or one parameter: nothing to compute
        if expr not in pool:
            pool[expr] = C[len(pool)]
        return pool[expr]

    def visit(expr):
        if expr.is_Atom or isinstance(expr, sp.Indexed):
            return expr
        if expr not in memo:
            memo[expr] = rewrite(expr)
        return memo[expr]

    def rewrite(expr):
        if _parameter_only(expr):
            return constant(expr)
        if isinstance(expr, (sp.Add, sp.Mul)):
            fixed = [a for a in expr.args if _parameter_only(a)]
            if len(fixed) > 1:
                varying = [visit(a) for a in expr.args if not _parameter_only(a)]
                return expr.func(constant(expr.func(*fixed)), *varying)
        return expr.func(*[visit(a) for a in expr.args])

    rewritten = tuple(tuple(visit(as_expr(e)) for e in group) for group in groups)
    return tuple(pool), rewritten


# ---------------------------------------------------------------- lowering (Reduced -> CodeModel)

def _index_map(reduced):
    from .resolve import TIME, var

    es = reduced.system
    sub = {TIME: T}
    for i, st in enumerate(reduced.states):
        sub[st.symbol] = X[i]
    for j, prm in enumerate(es.graph.parameters):
        sub[var(prm.name)] = P[j]
    return sub


def _lowered(expr, sub, what: str):
    from .diagnostics import fail

    out = expr.xreplace(sub)
    stray = [s for s in out.free_symbols
             if isinstance(s, sp.Symbol) and s not in (T, X.label, P.label)]
    stray += [s for s in out.atoms(sp.Indexed) if s.base not in (X, P)]
    if stray:  # a state that pruning removed, or an unknown that survived: a bgc bug
        fail(None, f"internal error: {what} still refers to {sorted(map(str, stray))}")
    return out


def _init_exprs(reduced, sub):
    from .resolve import TIME

    es = reduced.system
    t0 = sp.Float(es.settings.t0)
    out = []
    for st in reduced.states:
        e = st.init.xreplace({TIME: t0})
        out.append(_lowered(e, sub, f"the initial value of {st.name}"))
    return out


def _params(reduced, sub):
    es = reduced.system
    sets = dict(es.settings.sets)
    return tuple(Param(p.name, _lowered(sets.get(p.name, p.expr).value, sub, f"parameter {p.name}"))
                 for p in es.graph.parameters)


def _constraint_rows(reduced, sub):
    from .reduce import constraint_rows, scale_of

    kept = {st.symbol for st in reduced.states}
    all_states = {st.symbol for st in reduced.system.states}
    rows = []
    for junction, level, expr in constraint_rows(reduced):
        if (expr.free_symbols & all_states) - kept:
            continue  # a constraint on states that this scene does not integrate
        rows.append((ConstraintRow(junction, level), _lowered(expr, sub, f"constraint {junction}"),
                     _lowered(scale_of(expr), sub, f"constraint {junction}")))
    return rows


def _jacobian(rows, n):
    return [sp.diff(r, X[i]) for r in rows for i in range(n)]


def lower(reduced, name_override: str | None = None) -> CodeModel:
    """The code model of a reduced system: index maps, CSE'd blocks, constraint rows."""
    es = reduced.system
    sub = _index_map(reduced)
    n = len(reduced.states)
    rows = _constraint_rows(reduced, sub)
    pos = [r for c, r, _ in rows if c.level == "position"]
    vel = [r for c, r, _ in rows if c.level == "velocity"]
    in_position = set().union(*[r.atoms(sp.Indexed) for r in pos]) if pos else set()
    s = es.settings
    consts, (rhs, out, residual, scale, position_jac, velocity_jac) = hoist_constants((
        [_lowered(st.rhs, sub, f"d({st.name})/dt") for st in reduced.states],
        [_lowered(o.expr, sub, f"output {o.name}") for o in reduced.outputs],
        [r for _, r, _ in rows],
        [sc for _, _, sc in rows],
        _jacobian(pos, n),
        _jacobian(vel, n)))
    return CodeModel(
        name=name_override or es.graph.name,
        states=tuple(st.name for st in reduced.states),
        params=_params(reduced, sub),
        outputs=tuple(o.name for o in reduced.outputs),
        init=make_block(_init_exprs(reduced, sub)),
        rhs=make_block(rhs),
        out=make_block(out),
        constraints=tuple(c for c, _, _ in rows),
        residual=make_block(residual),
        scale=make_block(scale),
        position_jac=make_block(position_jac),
        velocity_jac=make_block(velocity_jac),
        velocity_movable=tuple(X[i] not in in_position for i in range(n)),
        scene=SceneSettings(s.t0, s.t_end, s.dt, s.solver, s.rtol, s.atol, s.step),
        consts=make_block(consts),
    )
