"""Where a fixed step makes an explicit solver unstable on a constraint corrector.

A Baumgarte corrector turns the drift of a constraint into a linear ODE with constant
coefficients (docs/semantics.md): Phi'' + 2 alpha Phi' + beta^2 Phi = 0 for `pid(alpha, beta)`,
B' + gamma B = 0 for `pd(gamma)`.  Its roots are eigenvalues of the whole system's Jacobian,
exactly, whatever the mechanism; an explicit Runge-Kutta method with fixed step h keeps that
mode bounded only if |R(h lambda)| <= 1 for its stability function R.  For the classical RK4
on the negative real axis the bound is h |lambda| <= 2.785; for explicit Euler 2.  Large gains
with a coarse step therefore make a run blow up however gentle the mechanism is; this module
says so before the run (`bgc simulate`) and tabulates it (`bgc accuracy --gains`).

Adaptive solvers are not checked: their error control shrinks the step (at a cost that the
accuracy report shows), and the stiff solvers are A-stable.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

from ..base import solvers
from ..middle.scene import parameter_values as scene_parameter_values


@dataclass(frozen=True)
class CorrectorModes:
    """A corrected constraint's error dynamics at given parameter values."""

    junction: str
    corrector: str  # pid | pd
    gains: tuple[float, ...]
    eigenvalues: tuple[complex, ...]


def parameter_values(compiled, overrides: dict | None = None) -> dict:
    """Every parameter's value: command-line overrides over the scene's over the defaults,
    derived parameters recomputed from the ones before them (bgc.middle.scene.parameter_values)."""
    return scene_parameter_values(compiled.graph, compiled.settings.sets, overrides or {})


def corrector_modes(compiled, overrides: dict | None = None) -> list[CorrectorModes]:
    """The error dynamics' eigenvalues of every constraint with a pid or pd corrector."""
    values = parameter_values(compiled, overrides)
    out = []
    for c in compiled.reduced.constraints:
        if c.corrector not in ("pid", "pd"):
            continue
        gains = tuple(float(g.xreplace(values)) for g in c.gains)  # SymPy values, built by resolve
        if c.corrector == "pid":
            alpha, beta = gains
            root = cmath.sqrt(alpha * alpha - beta * beta)
            eig = (-alpha + root, -alpha - root)
        else:
            eig = (complex(-gains[0]),)
        out.append(CorrectorModes(c.junction, c.corrector, gains, eig))
    return out


def stability_function(name: str):
    """R(z) of an explicit Runge-Kutta solver (y1 = R(h lambda) y0 on y' = lambda y), or None
    for the implicit families."""
    tab = solvers.get(name).tableau
    if not isinstance(tab, solvers.ERKTableau):
        return None
    import numpy as np  # (not at import: a run's warnings without a fixed step need none)
    s = len(tab.b)
    A = np.zeros((s, s))
    for i, row in enumerate(tab.a[:s]):
        A[i, :len(row)] = [float(v) for v in row]
    b = np.array([float(v) for v in tab.b])

    def R(z: complex) -> complex:
        # explicit: (I - z A) is unit lower triangular, so the stages follow by substitution
        k = np.zeros(s, dtype=complex)
        for i in range(s):
            k[i] = 1.0 + z * (A[i, :i] @ k[:i])
        return complex(1.0 + z * (b @ k))
    return R


def real_axis_bound(name: str) -> float:
    """The largest r with |R(-x)| <= 1 for all x in [0, r] (RK4: 2.785, Euler: 2)."""
    R = stability_function(name)
    if R is None:
        return math.inf
    return _ray_bound(R, -1.0)


def _ray_bound(R, direction: complex) -> float:
    """The largest r with |R(x direction)| <= 1 for x in [0, r] (|direction| = 1): a scan in
    steps of 1e-3 from the origin, then bisection."""
    x, dx = 0.0, 1e-3
    while abs(R((x + dx) * direction)) <= 1.0 + 1e-12:
        x += dx
        if x > 100.0:
            return math.inf
    lo, hi = x, x + dx
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if abs(R(mid * direction)) <= 1.0 + 1e-12:
            lo = mid
        else:
            hi = mid
    return lo


@dataclass(frozen=True)
class StepCheck:
    junction: str
    eigenvalue: complex
    h_lambda: float  # h |lambda|
    amplification: float  # |R(h lambda)|: above 1, the corrector's mode grows each step
    bound: float  # the real-axis bound of the solver, for the message
    largest_stable_step: float  # the largest h with |R(h lambda)| <= 1 (and all smaller ones)

    @property
    def unstable(self) -> bool:
        return self.amplification > 1.0 + 1e-12


def fixed_step_checks(compiled, solver: str, step: float,
                      overrides: dict | None = None) -> list[StepCheck]:
    """|R(h lambda)| for every corrector mode, for an explicit solver run with fixed step h."""
    R = stability_function(solver)
    if R is None:
        return []
    bound = real_axis_bound(solver)
    out = []
    for modes in corrector_modes(compiled, overrides):
        for lam in modes.eigenvalues:
            limit = _ray_bound(R, lam / abs(lam)) / abs(lam) if lam else math.inf
            out.append(StepCheck(modes.junction, lam, step * abs(lam), abs(R(step * lam)),
                                 bound, limit))
    return out


def fixed_step_of(solver: str, step: float | None, dt: float) -> float | None:
    """The fixed step a run takes (None: the solver adapts its steps)."""
    if solvers.get(solver).family == "fixed":
        return step if step else dt
    return step or None


NEAR_BOUND = 0.8  # warn from this fraction of the largest stable step on


def warnings_for_run(compiled, solver: str, step: float | None, dt: float,
                     overrides: dict | None = None) -> list[str]:
    """Messages for `bgc simulate` when a fixed step crosses a corrector's stability bound, or
    comes within 20% of it (a critically damped corrector is a double root: near the bound
    its mode decays too slowly to stop the drift the mechanism keeps feeding it)."""
    h = fixed_step_of(solver, step, dt)
    if h is None:
        return []
    worst: dict[str, StepCheck] = {}
    for chk in fixed_step_checks(compiled, solver, h, overrides):
        if h >= NEAR_BOUND * chk.largest_stable_step and (
                chk.junction not in worst or chk.amplification > worst[chk.junction].amplification):
            worst[chk.junction] = chk
    out = []
    for chk in worst.values():
        mode = (f"its error mode lambda = {_complex(chk.eigenvalue)} gives h*|lambda| = "
                f"{chk.h_lambda:.3g} and |R(h*lambda)| = {chk.amplification:.3g}")
        if chk.unstable:
            head = f"is unstable on the corrector of '{chk.junction}': {mode} > 1"
            tail = "the constraint drift will grow each step"
        else:
            head = (f"is within {100 * (1 - NEAR_BOUND):.0f}% of its stability bound on the "
                    f"corrector of '{chk.junction}': {mode}")
            tail = "the drift is barely damped and the run may diverge or lose its accuracy"
        out.append(f"warning: {solver} with fixed step {h:g} {head} (the real-axis bound of "
                   f"{solver} is {chk.bound:.3g}); {tail}. Use a step below "
                   f"{NEAR_BOUND * chk.largest_stable_step:.3g}, smaller gains, or an adaptive "
                   "solver; `bgc accuracy --gains` shows the trade-off.")
    return out


def _complex(z: complex) -> str:
    if abs(z.imag) < 1e-12 * max(1.0, abs(z.real)):
        return f"{z.real:.4g}"
    return f"{z.real:.4g}{z.imag:+.4g}i"
