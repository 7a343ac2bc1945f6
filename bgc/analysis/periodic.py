"""The periodic steady state of a periodically driven model, by shooting (`bgc periodic`).

The period map takes the state at the scene's start t0 to the state one period T later,
x(t0 + T) = Phi(x0).  A periodic orbit is a fixed point, Phi(x0) = x0, found by Newton's method
with the exact Jacobian of the map, the monodromy matrix M = dPhi/dx0: each iteration is one
run of one period of the program augmented with the states' sensitivities to their own initial
values (bgc.codegen.sensitivity, seeded by a parameter per state, `x0(NAME)`, that the initial
value is read from), and solves (M - I) dx = x0 - Phi(x0).  A linear model converges in one
iteration; Newton stops when the defect is below 1e-12 of the state's size (or, where the
run's own error keeps it above that, at the floating-point noise of the map itself, and says
so).

The sensitivities pass the time events unchanged (the square waves' edges, relations of t:
their times depend on neither the states nor x0), and jump at the events whose times or maps
read the states (a diode, a switch's mode from a state, an impact: bgc.codegen.sensitivity,
"Through events"), so M is exact through every event of the period; a model whose events
they cannot pass (a discrete value sampled from the states) is refused, located.

A state whose column of M is the unit column (nothing in the model reads it: a shaft's angle)
drifts: it advances by the same amount every period and takes no part in the fixed point; it is
reported with its advance.  The Floquet multipliers are the eigenvalues of M without such
states; the orbit is stable when all lie inside the unit circle, and an unstable orbit is not
one a run reaches: refused, with its multipliers.

The period: --period, or the model's time sources (square waves, sin and cos of a multiple of
t, relations of t with periodic crossings): the least common multiple of their periods.  A
time source that is not periodic from t0 (a step, a pulse, a table of t, an input's data, a
square wave that starts after t0) makes the model aperiodic: refused, with the source named.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import sympy as sp

from .. import api, ir
from ..codegen.lower import lower
from ..base.diagnostics import ModelError
from ..codegen.sensitivity import SensitivityError
from ..execute import runner
from ..front.graph import TIME, var
from .operating import AnalysisArgumentError, AnalysisError

NEWTON_TOL = 1e-12  # the defect |Phi(x0) - x0|, relative to the state's size
MAX_ITERATIONS = 30
MAX_LINE_SEARCH = 8
MAX_PERIODS = 1000  # the period's least common multiple, at most this many of the shortest
ROWS_PER_PERIOD = 200  # the orbit's output rows when the scene's dt does not resolve a period


class NoOrbit(AnalysisError):
    """No periodic orbit (the message says why, for people); `multipliers` where found."""

    def __init__(self, message: str, multipliers=None):
        super().__init__(message)
        self.multipliers = multipliers


def initial_parameter(state: str) -> str:
    """The parameter the shooting reads state's initial value from."""
    return f"x0({state})"


@dataclass(frozen=True)
class Orbit:
    """A periodic orbit: x0 at t0 returns after one period; the outputs over one period."""

    period: float
    t0: float
    states: tuple[str, ...]
    x0: np.ndarray  # the orbit's state at t0
    iterations: int  # Newton iterations (runs of one period, the first excluded)
    defect: float  # max |Phi(x0) - x0| at the end
    resolution: bool  # Newton stopped at the map's own noise, above NEWTON_TOL
    monodromy: np.ndarray  # dPhi/dx0, every state
    multipliers: np.ndarray  # complex: the Floquet multipliers (drifting states left out)
    drift: tuple[tuple[str, float], ...]  # states that advance each period: (name, advance)
    outputs: tuple[str, ...]
    t: np.ndarray  # one period's output times
    y: np.ndarray  # (len(t), len(outputs))
    figures: tuple[tuple[str, float, float, float, float], ...]  # (name, mean, min, max,
    #                                                              ripple) per output
    compiled: object = None  # the shooting program's api.Compiled (the plot's units)
    newton_cpu: float = 0.0  # the Newton runs' own CPU seconds, as the program counts them

    @property
    def stable(self) -> bool:
        return bool(np.all(np.abs(self.multipliers) < 1.0))

    def plot(self, target, fmt: str | None = None) -> None:
        """One period of the outputs drawn into target (a path: its suffix gives the format,
        .png, .svg or .pdf; or a binary file, with fmt); needs matplotlib."""
        if fmt is None:
            from ..reports import plot as plots
            fmt = plots.check_format(target)
        plot(self, target, fmt)

    def csv(self) -> str:
        """One period of the outputs as `bgc simulate` writes them."""
        lines = [",".join(("t",) + self.outputs)]
        lines += [",".join(_number(v) for v in (t, *row)) for t, row in zip(self.t, self.y)]
        return "\n".join(lines) + "\n"

    def lines(self) -> list[str]:
        out = [f"periodic orbit: period T = {self.period:.17g}, from t = {self.t0:.17g} "
               f"({self.iterations} Newton iteration{'s' if self.iterations != 1 else ''}, "
               f"|x(t0 + T) - x(t0)| = {self.defect:.3g})"]
        if self.resolution:
            out.append("note: Newton stopped at the run's own resolution (tighten rtol for a "
                       "smaller defect)")
        out += [f"{name}(t0) = {v:.17g}" for name, v in zip(self.states, self.x0)]
        for name, advance in self.drift:
            out.append(f"{name} drifts: it advances by {advance:.17g} each period")
        if self.figures:
            width = max(len(f[0]) for f in self.figures + (("output",),))
            out.append(f"{'output':<{width}}  {'mean':>24}  {'min':>24}  {'max':>24}  "
                       f"{'ripple':>24}")
            out += [f"{n:<{width}}  {a:>24.17g}  {b:>24.17g}  {c:>24.17g}  {d:>24.17g}"
                    for n, a, b, c, d in self.figures]
        out.append("Floquet multipliers: " + ", ".join(_complex(m) for m in self.multipliers)
                   if len(self.multipliers) else "Floquet multipliers: none")
        out.append("stable: every multiplier is inside the unit circle (largest |mu| = "
                   f"{np.max(np.abs(self.multipliers), initial=0.0):.6g})")
        return out

    def as_dict(self) -> dict:
        return {"period": self.period, "t0": self.t0, "iterations": self.iterations,
                "defect": self.defect,
                "x0": {n: float(v) for n, v in zip(self.states, self.x0)},
                "drift": {n: a for n, a in self.drift},
                "outputs": {n: {"mean": a, "min": b, "max": c, "ripple": d}
                            for n, a, b, c, d in self.figures},
                "multipliers": [[float(m.real), float(m.imag)] for m in self.multipliers],
                "monodromy": [[float(v) for v in row] for row in self.monodromy],
                "stable": self.stable}


def _number(v: float) -> str:
    return f"{float(v):.17g}"


def _complex(m) -> str:
    if m.imag == 0:
        return f"{m.real:.6g}"
    return f"{m.real:.6g}{'+' if m.imag > 0 else '-'}{abs(m.imag):.6g}i (|mu| = {abs(m):.6g})"


# ---------------------------------------------------------------- the shooting program


@dataclass(frozen=True)
class Shooting:
    """The program of the period map: the scene's with every state kept, each state's initial
    value read from its parameter x0(NAME), and the sensitivities to those."""

    compiled: api.Compiled
    states: tuple[str, ...]
    outputs: tuple[str, ...]  # the scene's (or --outputs') output columns
    reduced: object  # the reduced system (the time sources' periods)
    prepared: dict = field(default_factory=dict, compare=False)  # backend -> its program,
    #                                 prepared once (preparing emits the code to find it)

    def program_for(self, backend: str):
        if backend not in self.prepared:
            self.prepared[backend] = runner.prepare(self.compiled, backend,
                                                    in_process=backend == "python")
        return self.prepared[backend]


def build(model, scene=None, outputs=None, effects=None, algebra="auto") -> Shooting:
    """The shooting program of model's scene; raises api's errors, NoOrbit for a model whose
    events the sensitivities cannot pass."""
    first = api.build(model, scene, algebra=algebra, outputs=outputs, effects=effects,
                      program=False, option_names=("--outputs", "--effects", "--scene"))
    # the outputs and states the program would have (lower keeps reduce's, in its order)
    asked = tuple(o.name for o in first.reduced.outputs)
    states = tuple(st.name for st in first.reduced.states) + tuple(first.reduced.pruned)
    names = ", ".join(list(asked) + [s for s in states if s not in asked])
    compiled = api.build(first.source, scene, algebra=algebra, outputs=names or None,
                         effects=effects, program=False,
                         option_names=("--outputs", "--effects", "--scene"))
    reduced = _seeded(compiled.reduced)
    chosen = tuple(initial_parameter(st.name) for st in compiled.reduced.states)
    try:
        program = lower(reduced, chosen, chosen, True)
    except SensitivityError as error:
        raise NoOrbit(f"bgc periodic cannot shoot through this model's events: {error}") \
            from None
    except ModelError as error:  # (located: an event the sensitivities cannot pass)
        raise api.BgcModelError(error, compiled.source) from None
    from dataclasses import replace
    return Shooting(replace(compiled, reduced=reduced, program=program),
                    tuple(st.name for st in reduced.states), asked, reduced)


def _seeded(reduced):
    """reduced with each state's initial value read from a parameter x0(NAME), whose default
    is the model's initial value (its parameters: a -p of them still moves it)."""
    from dataclasses import replace
    from ..middle.system import ParameterDef
    t0 = sp.Float(reduced.run.t0)
    added = tuple(ParameterDef(initial_parameter(st.name), st.init.xreplace({TIME: t0}),
                               st.span) for st in reduced.states)
    states = tuple(replace(st, init=var(initial_parameter(st.name))) for st in reduced.states)
    return replace(reduced, parameters=reduced.parameters + added, states=states)


# ---------------------------------------------------------------- the period


def _values(reduced, given: dict) -> dict:
    """Each parameter's symbol -> its value (given overrides, else its default)."""
    env: dict = {}
    for p in reduced.parameters:
        if p.name in given:
            v = float(given[p.name])
        else:
            v = float(p.expr.xreplace(env)) if p.expr is not None else math.nan
        env[var(p.name)] = sp.Float(v)
    return env


def _number_of(e, env) -> float:
    try:
        return float(e.xreplace(env) if isinstance(e, sp.Basic) else e)
    except (TypeError, ValueError):
        return math.nan


def sources(reduced, given: dict) -> tuple[list, list]:
    """The periods of the model's time sources, (period, what) each, and the sources that are
    not periodic from the scene's start, (what, why) each."""
    env = _values(reduced, given)
    t0 = float(reduced.run.t0)
    periods, aperiodic = [], []
    sel = reduced.events
    if sel is not None:
        for r, at, _ in sel.time:
            tau = _number_of(at, env)
            if math.isfinite(tau) and tau > t0:
                aperiodic.append((r.text, f"changes once, at t = {tau:.6g}"))
        for s in sel.squares:
            if s.kind != "square":
                aperiodic.append((s.text, f"a {'table of t' if s.kind == 'table' else 'data input'}"
                                          " is not periodic"))
                continue
            start = _number_of(s.t0, env)
            if start > t0:
                aperiodic.append((s.text, f"starts at t = {start:.6g}, after the scene's start "
                                          f"t = {t0:.6g}"))
            periods.append((_number_of(s.period, env), s.text))
        known = dict(sel.crossings)
        for r in sel.state:
            if not r.relation.has(TIME):
                continue
            forms = known.get(r.symbol)
            if not forms:
                aperiodic.append((r.text, "reads t: bgc cannot tell whether it is periodic"))
                continue
            for C, P in forms:
                if P == 0:
                    tau = _number_of(C, env)
                    if math.isfinite(tau) and tau > t0:
                        aperiodic.append((r.text, f"changes once, at t = {tau:.6g}"))
                else:
                    periods.append((abs(_number_of(P, env)), r.text))
    for e in _laws(reduced):
        for f in e.atoms(sp.sin, sp.cos):
            a = f.args[0]
            if a.has(TIME):
                w = sp.diff(a, TIME)
                if w.has(TIME):
                    continue  # (a chirp: found as a law reading t below)
                periods.append((2 * math.pi / abs(_number_of(w, env)), str(f)))
    return periods, aperiodic


def _laws(reduced):
    """The expressions the steps and outputs compute."""
    out = []
    for s in reduced.steps:
        out += list(ir.inner_expressions(s) if isinstance(s, ir.Newton) else ir.expressions(s))
    return out + [o.expr for o in reduced.outputs]


def _reads_t_otherwise(reduced) -> list:
    """The laws that read t other than through sin or cos of a multiple of t."""
    found = []
    for e in _laws(reduced):
        if not e.has(TIME):
            continue
        rest = e.replace(lambda x: isinstance(x, (sp.sin, sp.cos)) and
                         not sp.diff(x.args[0], TIME).has(TIME), lambda x: sp.Integer(0))
        if rest.has(TIME):
            found.append(e)
    return found


def common_period(periods: list) -> float:
    """The least common multiple of the periods (period, what); NoOrbit if they are
    incommensurate or one is not a positive number."""
    for T, what in periods:
        if not (math.isfinite(T) and T > 0):
            raise NoOrbit(f"'{what}' has no positive period (T = {T:g})")
    base = min(T for T, _ in periods)
    ratios = []
    for T, what in periods:
        r = Fraction(T / base).limit_denominator(MAX_PERIODS)
        if abs(float(r) - T / base) > 1e-9 * T / base:
            raise NoOrbit(f"the time sources' periods are incommensurate ('{what}': {T:.6g} "
                          f"against {base:.6g}): the model is not periodic; give --period "
                          "if it is")
        ratios.append(r)
    q = math.lcm(*[r.denominator for r in ratios])
    k = math.lcm(*[r.numerator * (q // r.denominator) for r in ratios])
    if k > MAX_PERIODS * q:
        raise NoOrbit(f"the time sources' common period is {k / q:.6g} times the shortest "
                      f"({base:.6g}): more than {MAX_PERIODS}; give --period")
    return base * k / q


def period_of(shooting: Shooting, given: dict, period=None) -> float:
    """The period: `period` (a number), checked against the time sources, or theirs."""
    periods, aperiodic = sources(shooting.reduced, given)
    if aperiodic:
        what, why = aperiodic[0]
        more = f" (and {len(aperiodic) - 1} more)" if len(aperiodic) > 1 else ""
        raise NoOrbit(f"not periodic: '{what}' {why}{more}")
    if period is not None:
        T = float(period)
        if not (math.isfinite(T) and T > 0):
            raise AnalysisArgumentError(f"--period must be a positive number, not {period!r}")
        if periods:
            least = common_period(periods)
            n = T / least
            if abs(n - round(n)) > 1e-9 * max(1.0, n) or round(n) < 1:
                raise NoOrbit(f"--period {T:.6g} is not a multiple of the time sources' "
                              f"period {least:.6g}")
        return T
    if _reads_t_otherwise(shooting.reduced):
        raise NoOrbit("not periodic as far as bgc can tell: a law reads t other than through "
                      "a periodic source (square, sin, cos of a multiple of t); give --period "
                      "if it is periodic")
    if not periods:
        raise NoOrbit("no period: the model has no periodic time source (an autonomous "
                      "oscillation's period is not found by bgc periodic yet); give --period")
    return common_period(periods)


# ---------------------------------------------------------------- the shooting


def _initial_state(shooting: Shooting, given: dict):
    """The model's initial state with the parameters given (each state's x0(NAME) at its
    default), evaluated here: the shooting's starting point, passed to every run as numbers so
    that every backend starts from the same bits; None where a value is not a finite number."""
    try:
        env = _values(shooting.reduced, given)
        x = [float(env[var(initial_parameter(s))]) for s in shooting.states]
    except (TypeError, ValueError):
        return None
    return np.array(x) if all(math.isfinite(v) for v in x) else None


def _one_period(prepared, program, n, T, t0, given, x0, dt=None, event_rows=False):
    """A run of one period from x0 (None: the model's initial state): the times, the states,
    their sensitivities S[k, i, j] = d x_i / d x0_j and the outputs."""
    params = dict(given)
    if x0 is not None:
        params.update((initial_parameter(s), float(v))
                      for s, v in zip(program.states[:n], x0))
    settings = runner.settings_for(program.scene, [p.name for p in program.params], params,
                                   t_end=t0 + T, dt=T if dt is None else dt,
                                   event_rows=event_rows or None)
    t, Y = api.arrays(runner.run(prepared, settings))
    width = len(program.outputs) // (1 + n)
    Y = Y.reshape(len(t), 1 + n, width)
    M = width - n  # the outputs asked for, then the states
    return t, Y[:, 0, M:], np.moveaxis(Y[:, 1:, M:], 1, 2), Y[:, 0, :M]


def periodic(model, scene=None, period=None, params=None, outputs=None, effects=None,
             backend="c", algebra="auto", dt=None, shooting=None) -> Orbit:
    """The periodic orbit of model's scene (see the module's doc); params: overrides
    {name: value}; period: a number, or None for the time sources' period; dt: the orbit's
    output interval (default: the scene's, or a 200th of the period where that is longer);
    shooting: build's result for these model, scene, outputs, effects and algebra, to shoot
    again without the pipeline (other parameters, a benchmark's repeats).
    Raises api's errors, AnalysisArgumentError for arguments it refuses and NoOrbit."""
    if shooting is None:
        shooting = build(model, scene, outputs, effects, algebra)
    program = shooting.compiled.program
    given = dict(params or {})
    names = [p.name for p in program.params]
    for name in given:
        if name not in names or name.startswith("x0("):
            raise AnalysisArgumentError(f"unknown parameter {name!r}")
    T = period_of(shooting, given, period)
    n = len(shooting.states)
    t0 = float(program.scene.t0)
    backend, _ = runner.choose_backend(backend)
    prepared = shooting.program_for(backend)
    session = open_session(shooting, given, T, backend)
    try:
        found = newton(shooting, given, T, session, backend)
    finally:
        session.close()
    x, drifting = found.x, found.drifting
    if dt is None:
        dt = float(program.scene.dt)
        if not dt < T / 20:
            dt = T / ROWS_PER_PERIOD
    try:  # the orbit's rows, and its monodromy matrix under the error control of every state
        t, _, S, y = _one_period(prepared, program, n, T, t0, given, x, dt)
    except api.SimulationFailed as failed:
        raise NoOrbit(f"the run of one period failed: {failed}") from None
    M = S[-1]
    kept = [j for j in range(n) if j not in drifting]
    multipliers = np.linalg.eigvals(M[np.ix_(kept, kept)]) if kept else np.zeros(0, complex)
    multipliers = multipliers[np.lexsort((multipliers.imag, -np.abs(multipliers)))]
    if np.any(np.abs(multipliers) >= 1.0):
        raise NoOrbit("unstable: the orbit's Floquet multipliers " +
                      ", ".join(_complex(m) for m in multipliers if abs(m) >= 1.0) +
                      " lie on or outside the unit circle (a run does not settle on it)",
                      multipliers)
    figures = _figures(prepared, program, n, T, t0, given, x, dt, shooting.outputs)
    drift = tuple((shooting.states[j], float(found.end[j] - x[j])) for j in drifting)
    return Orbit(T, t0, shooting.states, x, found.iterations, found.defect, found.resolution,
                 M, multipliers, drift, shooting.outputs, t, y[:, :len(shooting.outputs)],
                 figures, shooting.compiled, found.cpu)


def _metrics(program, n) -> list[str]:
    """The batch's columns of a period's run: the states at its end, then their sensitivities
    to each x0(NAME) in turn."""
    outputs = program.outputs
    width = len(outputs) // (1 + n)
    first = width - n  # the outputs asked for, then the states
    return [f"final:{outputs[b * width + first + i]}" for b in range(1 + n) for i in range(n)]


def open_session(shooting: Shooting, given: dict, T: float, backend: str = "c"):
    """The runs of one period (from t0 to t0 + T) of the shooting program, in one process
    (runner.Session), with the error control over the states alone (error_states: the
    sensitivities follow the steps the states' control chooses); NoOrbit if it cannot start."""
    program = shooting.compiled.program
    n = len(shooting.states)
    t0 = float(program.scene.t0)
    settings = runner.settings_for(program.scene, [p.name for p in program.params], given,
                                   t_end=t0 + T, dt=T, error_states=n)
    try:
        return runner.Session(shooting.program_for(runner.choose_backend(backend)[0]),
                              settings, _metrics(program, n))
    except runner.SessionFailed as failed:
        raise NoOrbit(f"the run of one period failed: {failed}") from None


@dataclass(frozen=True)
class Newton:
    """Where Newton's method on the period map ended."""

    x: np.ndarray  # the periodic state at t0
    end: np.ndarray  # Phi(x)
    M: np.ndarray  # the last run's monodromy matrix (sensitivities outside the error control)
    iterations: int
    defect: float
    resolution: bool
    drifting: list
    cpu: float  # the runs' own CPU seconds, as the program counts them
    runs: int


def newton(shooting: Shooting, given: dict, T: float, session, backend: str = "c") -> Newton:
    """Newton's method on the period map of shooting's program, its runs in session (from
    open_session, which the caller closes)."""
    program = shooting.compiled.program
    n = len(shooting.states)
    metrics = _metrics(program, n)
    cpu, runs = [0.0], [0]

    def shoot(x):
        try:
            row = session.run({initial_parameter(s): v for s, v in zip(shooting.states, x)})
        except runner.SessionFailed as failed:
            raise NoOrbit(f"the run of one period failed: {failed}") from None
        if row["status"] != "ok":
            raise NoOrbit(f"the run of one period failed: {row['message']}")
        cpu[0] += row["cpu"]
        runs[0] += 1
        v = np.array([row[m] for m in metrics]).reshape(1 + n, n)
        return np.array(x, dtype=float), v[0], v[1:].T

    start = _initial_state(shooting, given)
    if start is None:  # (an initial value bgc cannot evaluate here: the program's own)
        prepared = shooting.program_for(runner.choose_backend(backend)[0])
        try:
            start = _one_period(prepared, program, n, T, float(program.scene.t0), given,
                                None)[1][0]
        except api.SimulationFailed as failed:
            raise NoOrbit(f"the run of one period failed: {failed}") from None
    x, end, M, iterations, size, resolution, drifting = _newton(shoot, start, n, program.scene)
    return Newton(x, end, M, iterations, size, resolution, drifting, cpu[0], runs[0])


def _newton(shoot, start, n, scene):
    """Newton's method on the period map from start: shoot(x) gives (x, Phi(x), M(x)).
    Returns (x, Phi(x), M, iterations, defect, resolution, drifting states)."""
    x, end, M = shoot(start)
    drifting = [j for j in range(n) if np.array_equal(M[:, j], np.eye(n)[:, j])]
    kept = [j for j in range(n) if j not in drifting]
    resolution = False
    iterations = 0
    rtol = float(scene.rtol)

    def defect(x, end):
        F = (end - x)[kept]
        return F, float(np.max(np.abs(F), initial=0.0))

    F, size = defect(x, end)
    while True:
        scale = max(float(np.max(np.abs(x[kept]), initial=0.0)), float(scene.atol))
        if size <= NEWTON_TOL * scale:
            break
        if iterations >= MAX_ITERATIONS:
            raise NoOrbit(f"not converged: after {iterations} Newton iterations the state "
                          f"returns {size:.3g} away from where it started")
        A = M[np.ix_(kept, kept)] - np.eye(len(kept))
        try:
            step = np.linalg.solve(A, -F)
        except np.linalg.LinAlgError:
            step = None
        if step is None or not np.all(np.isfinite(step)):
            raise NoOrbit("not periodic: the monodromy matrix has a multiplier 1 (M - I is "
                          "singular): the orbit is not isolated (multipliers: " +
                          ", ".join(_complex(m) for m in np.linalg.eigvals(M[np.ix_(kept, kept)]))
                          + ")")
        lam, tried = 1.0, 0
        while True:
            trial = x.copy()
            trial[kept] = x[kept] + lam * step
            t_x, t_end, t_M = shoot(trial)
            t_F, t_size = defect(trial, t_end)
            if t_size < size or tried >= MAX_LINE_SEARCH:
                break
            lam, tried = lam / 2, tried + 1
        iterations += 1
        if t_size >= size:  # no decrease along Newton's direction: the map's own noise
            if size <= 100 * rtol * scale:
                resolution = True
                break
            raise NoOrbit(f"not converged: Newton's iteration stalls {size:.3g} away from a "
                          "periodic state")
        x, end, M, F, size = t_x, t_end, t_M, t_F, t_size
    return x, end, M, iterations, size, resolution, drifting


def _figures(prepared, program, n, T, t0, given, x, dt, outputs):
    """Per output: the mean over the period (the trapezoidal rule over the rows, with both
    limits at each event: the rule is exact for a piecewise linear output), min, max and
    ripple (max - min)."""
    t, _, _, y = _one_period(prepared, program, n, T, t0, given, x, dt, event_rows=True)
    out = []
    for k, name in enumerate(outputs):
        v = y[:, k]
        mean = float(np.sum((v[1:] + v[:-1]) * np.diff(t)) / 2 / (t[-1] - t[0]))
        lo, hi = float(np.min(v)), float(np.max(v))
        mean = min(max(mean, lo), hi)  # (a constant output: the sum's rounding aside)
        out.append((name, mean, lo, hi, hi - lo))
    return tuple(out)


def plot(orbit: Orbit, target, fmt: str = "png") -> None:
    """The orbit's outputs over one period, one panel per unit (bgc.reports.plot), to target
    (a path or a binary file)."""
    from ..reports import plot as plots
    if not orbit.outputs:
        raise plots.PlotError("the orbit has no outputs: nothing to plot")
    table = plots.Table(orbit.outputs, [float(t) for t in orbit.t],
                        [[float(v) for v in orbit.y[:, k]] for k in range(len(orbit.outputs))],
                        len(orbit.t), 1)
    heading = plots.title_lines(orbit.compiled) + [
        f"periodic orbit, period {orbit.period:.6g} s"]
    plots.plot_run(table, plots.columns(orbit.compiled, orbit.outputs), target, fmt, heading)
