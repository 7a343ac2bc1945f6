"""The language-neutral code model: what the emitters print, nothing they must derive.

Every expression here is a SymPy expression over exactly these symbols:
  t            Symbol("t")            time
  x[i]         IndexedBase("x")[i]    state i, ordered as `states`
  p[j]         IndexedBase("p")[j]    parameter j, ordered as `params`
  w0, w1, ...  Symbol("w<k>")         common subexpressions, defined in a Block's `temps`
and the functions sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt Abs sign
Min Max Heaviside, Pow, Rational, Float, Integer, pi, E.  Model names never occur in
expressions, so nothing a model author writes can reach generated code except through the
`states`/`outputs`/`params` name strings, which the emitters escape as string literals
(names are identifiers with '.', '[', ']' only, but emitters escape them regardless).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

T = sp.Symbol("t")
X = sp.IndexedBase("x")
P = sp.IndexedBase("p")


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

    @property
    def position_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "position")

    @property
    def velocity_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "velocity")


def make_block(exprs, prefix: str = "w") -> Block:
    """CSE a list of expressions into a Block with deterministic temporaries."""
    exprs = [sp.Integer(e) if isinstance(e, int) else e for e in exprs]
    if not exprs:
        return Block((), ())
    temps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols(prefix), order="none")
    return Block(tuple(temps), tuple(reduced))
