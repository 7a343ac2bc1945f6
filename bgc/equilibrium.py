"""`bgc steady`: an equilibrium of a model, dx/dt = 0, by Newton's method on the generated
right side with the Jacobian the compiler derives (bgc.operating).

The unknowns are the states at the scene's start time; the equations are the right side and
the constraint rows (a holonomic constraint's position and velocity rows, a nonholonomic
one's velocity row), stacked.  With a Baumgarte corrector dx/dt = 0 already implies them; a
constraint without a corrector leaves its position undetermined, and the stacked rows fix it.
Algebraic blocks are solved inside the right side as in a run.

Each step is the least-squares (minimum-norm) solution of J dx = -F, damped by halving until
|F| decreases; the linear algebra is bgc.orthogonal's, whose sums run in sequence, so an
equilibrium has the same bytes on every machine.  Where the Jacobian is singular, the equilibria form a family (a free mass
rests anywhere): the minimum-norm steps give the one nearest the initial state, and the
result says how many directions are free.  Where no step reduces |F| while |F| is not small
(a mass under a constant force), there is no equilibrium near the start: NoEquilibrium,
naming the state whose rate stays largest.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import operating, orthogonal
from .operating import AnalysisError

TOLERANCE = 1e-10  # |F| relative to max(1, |F| at the start)
MAX_ITERATIONS = 100


class NoEquilibrium(AnalysisError):
    """Newton's method found no equilibrium (the message says why)."""


@dataclass(frozen=True)
class Equilibrium:
    t: float
    states: tuple[tuple[str, float], ...]
    multipliers: tuple[tuple[str, float], ...]
    constraint_residuals: tuple[tuple[str, float], ...]
    residual: float  # max |dx/dt| at the equilibrium
    iterations: int
    free: int  # directions along which the equilibria form a family (the Jacobian's nullity)

    def lines(self) -> str:
        """`NAME = VALUE`, one a line: the states, the multipliers, the constraints'
        residuals, then the residual max |dx/dt|."""
        rows = self.states + self.multipliers + self.constraint_residuals + \
            (("residual", self.residual),)
        return "".join(f"{name} = {value:.17g}\n" for name, value in rows)

    def as_dict(self) -> dict:
        return {"t": self.t, "states": dict(self.states), "multipliers": dict(self.multipliers),
                "constraint_residuals": dict(self.constraint_residuals),
                "residual": self.residual, "iterations": self.iterations, "free": self.free}


def _system(ev: operating.Evaluator, t: float, x):
    """F(x) (the right side, then the constraint rows) and its Jacobian."""
    f = ev.rhs(t, x)
    if not ev.constraints:
        return f, None
    G, r = ev.constraint_rows(t, x)
    return np.concatenate([f, r]), G


def _residual(ev, t, x):
    try:
        F, _ = _system(ev, t, x)
    except AnalysisError:
        return None
    return F if np.all(np.isfinite(F)) else None


def solve(ev: operating.Evaluator, x0=None) -> Equilibrium:
    """The equilibrium nearest x0 (default: the scene's initial state); NoEquilibrium."""
    t = ev.t0
    x = ev.initial() if x0 is None else np.asarray(x0, dtype=float).copy()
    F = _residual(ev, t, x)
    if F is None:
        raise NoEquilibrium(f"the right side is not finite at the initial state (t = {t:g})")
    goal = TOLERANCE * max(1.0, np.abs(F).max(initial=0.0))
    for it in range(MAX_ITERATIONS + 1):
        J = _jacobian(ev, t, x)
        if np.abs(F).max(initial=0.0) <= goal:
            return _result(ev, t, *_polish(ev, t, x, F, J), it)
        if it == MAX_ITERATIONS:
            break
        dx = orthogonal.lstsq(J, -F)[0]
        step, norm = 1.0, orthogonal.norm(F)
        while step >= 1e-8:
            trial = x + step * dx
            Ft = _residual(ev, t, trial)
            if Ft is not None and orthogonal.norm(Ft) < (1 - 1e-4 * step) * norm:
                x, F = trial, Ft
                break
            step /= 2
        else:
            raise NoEquilibrium(_why(ev, x, F, J, it))
    raise NoEquilibrium(f"Newton's method did not converge in {MAX_ITERATIONS} iterations "
                        f"(max |dx/dt| = {np.abs(F[:ev.n]).max():.3g})")


def _polish(ev, t, x, F, J):
    """Up to three more full steps, each kept while it reduces |F| (Newton's method doubles
    the digits of a converged solution at each step): (x, J)."""
    for _ in range(3):
        trial = x + orthogonal.lstsq(J, -F)[0]
        Ft = _residual(ev, t, trial)
        if Ft is None or not orthogonal.norm(Ft) < orthogonal.norm(F):
            break
        x, F, J = trial, Ft, _jacobian(ev, t, trial)
    return x, J


def _jacobian(ev, t, x) -> np.ndarray:
    J = ev.jacobian(t, x)
    if ev.constraints:
        J = np.vstack([J, ev.constraint_rows(t, x)[0]])
    if not np.all(np.isfinite(J)):
        raise NoEquilibrium(f"the Jacobian is not finite at {_where(ev, x)}")
    return J


def _why(ev, x, F, J, it) -> str:
    k = int(np.argmax(np.abs(F)))
    what = f"d({ev.states[k]})/dt = {F[k]:.6g}" if k < ev.n else \
        f"the residual of constraint row {ev.constraint_names()[k - ev.n]} = {F[k]:.6g}"
    rank = orthogonal.rank(J)
    return (f"no equilibrium: after {it} Newton iterations no step reduces the right side, "
            f"which stays at {what} (the Jacobian has rank {rank} of {ev.n}: a state that "
            "integrates a nonzero constant, such as a free mass under a constant force, has "
            "no equilibrium)")


def _where(ev, x) -> str:
    return ", ".join(f"{s} = {v:.6g}" for s, v in zip(ev.states, x))


def _result(ev, t, x, J, it) -> Equilibrium:
    y = ev.outputs(t, x)
    outs = ev.all_outputs
    mult = tuple((name, float(y[outs.index(name)])) for name in ev.analysed.multipliers)
    res = tuple((name, float(y[outs.index(name)])) for name in ev.analysed.residuals)
    f = ev.rhs(t, x)
    return Equilibrium(float(t), tuple(zip(ev.states, (float(v) for v in x))), mult, res,
                       float(np.abs(f).max(initial=0.0)), it,
                       ev.n - orthogonal.rank(J))


def steady(model, scene=None, params=None, effects=None, algebra="auto") -> Equilibrium:
    """An equilibrium of model's scene (bgc.steady; see the module's doc); effects replace
    the scene's, algebra as bgc.build's."""
    analysed = operating.build(model, scene, None, effects, None, algebra)
    return solve(operating.Evaluator(analysed, params))
