"""`bgc accuracy`: what each solver's accuracy costs in time, measured on the user's own model.

For every solver and every tolerance of a sweep (every step size, for the fixed-step solvers)
the compiled program runs twice over: once on the scene's output grid, whose CSV gives the
error and whose `--stats` line the counters, and `repeats` times with two output rows, whose
best processor time (measured inside the program, around the integration) is the cost.  The
program is compiled once and reused for every run.

Errors are measured against a reference: by default bgc itself at a far tighter tolerance with
another method (DOP853 at rtol 1e-13, or Radau IIA at 1e-12 when `auto`'s stiffness test
fires on the model; that method's own rows are measured against a second reference, Dopri5 at
1e-13 or Rodas4 at 1e-11, and the two references' disagreement is reported as the floor below
which errors mean nothing), or a
CSV given by the user on the same output grid.  Each output column's error is taken relative
to the column's scale (its largest magnitude in the reference); a row's error is the largest
over the columns, at the final time and over the whole grid.  Constraint residuals are not
compared with the reference: their largest magnitude is the row's drift.

Nothing here is timed by a test; tests check the ordering of errors, not the times.
"""
from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import sympy as sp

from ..execute import runner
from ..base import solvers
from ..api import Compiled
from ..base.run_settings import RunSettings
from .stability import fixed_step_checks, fixed_step_of

DEFAULT_RTOLS = tuple(10.0 ** -k for k in range(3, 11))
DEFAULT_STEP_DIVISIONS = tuple(2 ** k for k in range(6))  # step = dt / k
REFERENCES = {False: (("dop853", 1e-13), ("dopri5", 1e-13)),
              True: (("radau5", 1e-12), ("rodas4", 1e-11))}


class AccuracyError(RuntimeError):
    """A sweep that cannot be run as asked (a bad reference, no outputs to compare)."""


@dataclass
class Point:
    """One run of the sweep."""

    solver: str
    setting: str  # "rtol" or "step"
    value: float
    gain: float | None = None
    steps: int | None = None
    rejected: int | None = None
    rhs: int | None = None
    jac: int | None = None
    lu: int | None = None
    error_final: float | None = None
    error_max: float | None = None
    residual: float | None = None
    cpu: float | None = None
    amplification: float | None = None  # fixed steps: the corrector's worst |R(h lambda)|
    status: str = "ok"


@dataclass
class Result:
    model: str
    scene: str | None
    backend: str
    reference: str  # how the reference was made
    floor: float | None  # the references' disagreement (None: a given CSV)
    points: list[Point] = field(default_factory=list)


# ---------------------------------------------------------------- running the program


def _is_residual(name: str) -> bool:
    """A constraint residual's column: `rod.residual`, or `rod.residual[i]` of an array."""
    return re.fullmatch(r".*\.residual(\[[0-9]+\])?", name) is not None


def parse_csv(text: str) -> tuple[list[str], np.ndarray]:
    lines = text.splitlines()
    if not lines:
        return [], np.zeros((0, 0))
    names = lines[0].split(",")
    if len(lines) == 1:
        return names, np.zeros((0, len(names)))
    return names, np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2)


@dataclass
class Trajectory:
    names: list[str]
    data: np.ndarray  # t in column 0
    stats: dict
    status: int
    message: str


@dataclass(frozen=True)
class Runs:
    """The compiled scene as a runnable program (built once), and the time budget of a run."""

    program: runner.Program
    timeout: float


def run_once(runs: Runs, settings: RunSettings) -> Trajectory:
    """One run, with its counters (bgc.execute.runner.run)."""
    done = runner.run(runs.program, settings, stats=True, timeout=runs.timeout)
    names, data = parse_csv(done.csv)
    return Trajectory(names, data, done.stats, done.status,
                      "" if done.status == 0 else done.message)


# ---------------------------------------------------------------- errors


def compare(traj: Trajectory, ref: Trajectory) -> tuple[float, float, float | None]:
    """(error at the final time, max over the grid, largest |residual|) of a full run."""
    names = traj.names[1:]
    residual_cols = [j for j, n in enumerate(names) if _is_residual(n)]
    compared = [j for j in range(len(names)) if j not in residual_cols]
    Y, R = traj.data[:, 1:], ref.data[:, 1:]
    if Y.shape != R.shape or not np.allclose(traj.data[:, 0], ref.data[:, 0], rtol=1e-12,
                                             atol=1e-12):
        raise AccuracyError("the run and the reference are not on the same output grid")
    residual = float(np.max(np.abs(Y[:, residual_cols]))) if residual_cols else None
    if not compared:
        raise AccuracyError("no outputs to compare (the scene outputs residuals only)")
    scale = np.max(np.abs(R[:, compared]), axis=0)
    scale[scale == 0.0] = 1.0
    diff = np.abs(Y[:, compared] - R[:, compared]) / scale
    return float(np.max(diff[-1])), float(np.max(diff)), residual


def load_reference(path: str, names: list[str], times: np.ndarray) -> Trajectory:
    """A user's CSV (t and the outputs, by name) on the scene's output grid."""
    from ..base.resources import MAX_REFERENCE_BYTES, read_bounded
    try:
        data = read_bounded(path, MAX_REFERENCE_BYTES)
    except OSError as exc:
        raise AccuracyError(f"{path}: cannot read: {exc.strerror}") from None
    if len(data) > MAX_REFERENCE_BYTES:
        raise AccuracyError(f"{path}: too large for a reference (more than "
                            f"{MAX_REFERENCE_BYTES} bytes)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise AccuracyError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        ref_names, data = parse_csv(text)
    except ValueError as exc:  # (numpy's loadtxt: a cell that is not a number, a short row)
        raise AccuracyError(f"{path}: not a CSV of numbers with a header: "
                            f"{str(exc).splitlines()[0]}") from None
    if not ref_names or ref_names[0] != "t":
        raise AccuracyError(f"{path}: the first column must be 't'")
    cols = [0]
    for n in names[1:]:
        if _is_residual(n):
            cols.append(None)
        elif n in ref_names:
            cols.append(ref_names.index(n))
        else:
            raise AccuracyError(f"{path}: no column '{n}' (it has {', '.join(ref_names)})")
    if data.shape[0] != len(times) or not np.allclose(data[:, 0], times, rtol=1e-9,
                                                      atol=1e-12):
        raise AccuracyError(f"{path}: its times are not the scene's output grid "
                            f"({len(times)} rows from {times[0]:g} to {times[-1]:g})")
    out = np.column_stack([data[:, c] if c is not None else np.zeros(len(times))
                           for c in cols])
    return Trajectory(names, out, {}, 0, "")


# ---------------------------------------------------------------- the sweep


def _ratio(base: RunSettings) -> float:
    """atol / rtol: the scene's, kept as rtol is swept."""
    return base.atol / base.rtol


def _tolerance(base: RunSettings, solver: str, rtol: float) -> RunSettings:
    return replace(base, solver=solver, rtol=rtol, atol=rtol * _ratio(base))


def _is_stiff(program: Runs, base: RunSettings) -> bool:
    """Whether `auto` switches to its stiff method at rtol 1e-6 (Hairer's stiffness test)."""
    t = run_once(program, _tolerance(base, "auto", 1e-6))
    return "stiff_from" in t.stats


def make_references(program: Runs, base: RunSettings, progress) -> tuple[dict, str, float]:
    """{method: Trajectory} for the two reference methods, a description, and their
    disagreement (the error floor)."""
    stiff = _is_stiff(program, base)
    refs, parts = {}, []
    for name, rtol in REFERENCES[stiff]:
        progress(f"reference {name} rtol={rtol:g}")
        t = run_once(program, _tolerance(base, name, rtol))
        if t.status != 0:
            raise AccuracyError(f"the reference run ({name}, rtol {rtol:g}) failed: {t.message}")
        refs[name] = t
        parts.append(f"{name} rtol={rtol:g}")
    (a, ta), (b, tb) = refs.items()
    _, floor, _ = compare(ta, tb)
    what = (f"{parts[0]} ({parts[1]} for the {a} rows){'; the model is stiff' if stiff else ''}")
    return refs, what, floor


def measure(program: Runs, settings: RunSettings, point: Point, ref: Trajectory, repeats: int,
            span: float) -> Trajectory:
    """Fill `point` from one full run and `repeats` timing runs."""
    traj = run_once(program, settings)
    st = traj.stats
    for key in ("steps", "rejected", "rhs", "jac", "lu"):
        if key in st:
            setattr(point, key, int(st[key]))
    if traj.status != 0:
        point.status = traj.message
        return traj
    point.error_final, point.error_max, point.residual = compare(traj, ref)
    best = math.inf
    for _ in range(repeats):
        t = run_once(program, replace(settings, dt=span))
        if t.status == 0 and "cpu" in t.stats:
            best = min(best, float(t.stats["cpu"]))
    point.cpu = best if best < math.inf else None
    return traj


def plan(compiled: Compiled, names=None, rtols=None, steps=None, dt=None) -> list[Point]:
    """`bgc accuracy`'s points: each solver (names; default: all) at each tolerance (rtols;
    default DEFAULT_RTOLS) or, fixed-step, each step (steps; default dt / 1 .. dt / 32, dt:
    the output interval, default the scene's)."""
    out_dt = dt or compiled.settings.dt
    points = []
    for n in names or list(solvers.NAMES):
        if solvers.get(n).swept_by_step:
            hs = steps or [out_dt / k for k in DEFAULT_STEP_DIVISIONS]
            points += [Point(n, "step", h) for h in hs]
        else:
            points += [Point(n, "rtol", r) for r in (rtols or DEFAULT_RTOLS)]
    return points


def plan_gains(compiled: Compiled, names=None, rtols=None, steps=None,
               dt=None) -> list[tuple[str, str, float]]:
    """`bgc accuracy --gains`'s (solver, setting, value) at each gain: each solver (names;
    default the scene's and rk4) at each tolerance (default the scene's) or each step
    (default the scene's, else the output interval)."""
    s = compiled.settings
    chosen = names or [s.solver] + (["rk4"] if s.solver != "rk4" else [])
    settings = []
    for n in chosen:
        if solvers.get(n).swept_by_step:
            settings += [(n, "step", h) for h in (steps or [s.step or dt or s.dt])]
        else:
            settings += [(n, "rtol", r) for r in (rtols or [s.rtol])]
    return settings


def _base(compiled: Compiled, backend: str, timeout: float, params, t_end, dt):
    """The program (built once), the runs' common settings, the span of the timing runs."""
    runs = Runs(runner.prepare(compiled, backend), timeout)
    base = runs.program.defaults.with_options(t_end=t_end, dt=dt, params=dict(params or {}))
    return runs, base, base.t_end - base.t0


def _point_settings(base: RunSettings, solver: str, setting: str, value: float) -> RunSettings:
    if setting == "rtol":
        return _tolerance(base, solver, value)
    return replace(base, solver=solver, step=value)


def run_sweep(compiled: Compiled, points: list[Point], backend: str = "c", repeats: int = 3,
              reference_csv: str | None = None, params: dict | None = None,
              t_end: float | None = None, dt: float | None = None, timeout: float = 60.0,
              progress=None) -> Result:
    """Run every point (in order; a solver's failure skips its later, harder points)."""
    progress = progress or (lambda text, done=None, total=None: None)
    program, base, span = _base(compiled, backend, timeout, params, t_end, dt)
    if reference_csv:
        probe = run_once(program, _tolerance(base, "dop853", 1e-3))
        refs = {None: load_reference(reference_csv, probe.names, probe.data[:, 0])}
        what, floor = f"{reference_csv} (given)", None
    else:
        refs, what, floor = make_references(program, base, progress)
    result = Result(compiled.source.path, compiled.settings.scene, backend, what, floor)
    failed: set = set()
    for k, pt in enumerate(points):
        progress(f"{pt.solver} {pt.setting}={pt.value:.3g}", k, len(points))
        key = (pt.solver, pt.gain)
        if key in failed:
            pt.status = "skipped (an easier setting failed)"
            result.points.append(pt)
            continue
        run = _point_settings(base, pt.solver, pt.setting, pt.value)
        measure(program, run, pt, _reference_for(refs, pt.solver), repeats, span)
        if pt.status != "ok":
            failed.add(key)
        result.points.append(pt)
    progress(None)
    return result


def _reference_for(refs: dict, solver: str) -> Trajectory:
    if None in refs:
        return refs[None]
    names = list(refs)
    return refs[names[1]] if solver == names[0] else refs[names[0]]


# ---------------------------------------------------------------- gains


def gain_parameters(compiled: Compiled) -> list[str]:
    """The parameters that are a corrector's gains (each gain must be a bare parameter)."""
    names: list[str] = []
    params = {p.name for p in compiled.graph.parameters}
    for c in compiled.reduced.constraints:
        if c.corrector not in ("pid", "pd"):
            continue
        for g in c.gains:
            text = g.name if isinstance(g, sp.Symbol) else str(g)
            if not isinstance(g, sp.Symbol) or text not in params:
                raise AccuracyError(
                    f"the corrector of '{c.junction}' has the gain '{text}', not a parameter: "
                    "--gains sets gain parameters (sweep an expression's parameters with bgc "
                    "sweep or -p)")
            if text not in names:
                names.append(text)
    if not names:
        raise AccuracyError("--gains needs a constraint with a pid or pd corrector")
    return names


def run_gains(compiled: Compiled, gains: list[float], solver_settings: list[tuple[str, str, float]],
              backend: str = "c", repeats: int = 3, t_end: float | None = None,
              dt: float | None = None, params: dict | None = None, timeout: float = 60.0,
              progress=None) -> Result:
    """For each gain value (every gain parameter set to it) and each (solver, setting, value):
    drift, error against a reference at that gain, cost; fixed steps also |R(h lambda)|."""
    progress = progress or (lambda text, done=None, total=None: None)
    names = gain_parameters(compiled)
    program, base, span = _base(compiled, backend, timeout, params, t_end, dt)
    result = None
    total = len(gains) * len(solver_settings)
    k = 0
    for g in gains:
        over = dict(base.params, **{n: g for n in names})
        gbase = base.with_options(params=over)
        refs, what, floor = make_references(program, gbase, progress)
        if result is None:
            result = Result(compiled.source.path, compiled.settings.scene, backend, what, floor)
        else:
            result.floor = max(result.floor or 0.0, floor)
        for name, setting, value in solver_settings:
            progress(f"gain {g:g}: {name} {setting}={value:.3g}", k, total)
            k += 1
            pt = Point(name, setting, value, gain=g)
            run = _point_settings(gbase, name, setting, value)
            h = fixed_step_of(name, value if setting == "step" else None, base.dt)
            if h is not None:
                checks = fixed_step_checks(compiled, name, h, over)
                if checks:
                    pt.amplification = max(c.amplification for c in checks)
            measure(program, run, pt, _reference_for(refs, name), repeats, span)
            result.points.append(pt)
    progress(None)
    return result


# ---------------------------------------------------------------- reports


def _fmt(v, spec=".3g"):
    return "-" if v is None else format(v, spec)


def table(result: Result, gains: bool = False) -> str:
    head = ["solver", "setting"] + (["gain", "|R(hλ)|"] if gains else []) + \
        ["steps", "rejected", "rhs", "jac", "lu", "err final", "err max", "residual",
         "cpu [s]", "status"]
    rows = []
    for p in result.points:
        row = [p.solver, f"{p.setting}={p.value:.3g}"]
        if gains:
            row += [_fmt(p.gain), _fmt(p.amplification)]
        row += [_fmt(p.steps, "d"), _fmt(p.rejected, "d"), _fmt(p.rhs, "d"), _fmt(p.jac, "d"),
                _fmt(p.lu, "d"), _fmt(p.error_final, ".2e"), _fmt(p.error_max, ".2e"),
                _fmt(p.residual, ".2e"), _fmt(p.cpu, ".3e"), p.status]
        rows.append(row)
    widths = [max(len(str(r[j])) for r in rows + [head]) for j in range(len(head))]
    lines = [f"model: {result.model}, scene {result.scene or '(default)'}, backend {result.backend}",
             f"reference: {result.reference}"]
    if result.floor is not None:
        lines.append(f"reference floor: the two references differ by {result.floor:.2e} "
                     "(errors near it are the references', not the solver's)")
    lines.append("errors: max |y - y_ref| / max |y_ref| over the outputs (residuals apart), at "
                 "t_end and over the grid; residual: max |constraint residual|; cpu: best "
                 "processor time of the integration alone")
    lines.append("  ".join(h.ljust(w) for h, w in zip(head, widths)).rstrip())
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join(lines) + "\n"


CSV_FIELDS = ("solver", "setting", "value", "gain", "steps", "rejected", "rhs", "jac", "lu",
              "error_final", "error_max", "residual", "cpu_s", "amplification", "status")


def csv_text(result: Result) -> str:
    out = [",".join(CSV_FIELDS)]
    for p in result.points:
        vals = [p.solver, p.setting, repr(p.value), p.gain, p.steps, p.rejected, p.rhs, p.jac,
                p.lu, p.error_final, p.error_max, p.residual, p.cpu, p.amplification,
                '"' + p.status.replace('"', "'") + '"']
        out.append(",".join("" if v is None else (f"{v:.17g}" if isinstance(v, float) else str(v))
                            for v in vals))
    return "\n".join(out) + "\n"


def plot(result: Result, path, gains: bool = False) -> None:
    """Work-precision (error against time, log-log, one line per solver) and error against
    right-side calls; with gains, drift and error against the gain.  As PNG, to path (a file
    name or a binary file)."""
    from ..reports.plot import pyplot, save, style
    plt = pyplot()
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 3 if gains else 2, figsize=(15 if gains else 11, 4.5))
    groups: dict = {}
    for p in result.points:
        if p.status == "ok" and p.error_max is not None:
            key = (p.solver, p.setting, p.value) if gains else p.solver
            groups.setdefault(key, []).append(p)
    markers = "osD^vP"  # with the ten colours of the cycle: 60 lines tell apart
    for k, (key, pts) in enumerate(groups.items()):
        label = f"{key[0]} {key[1]}={key[2]:.3g}" if gains else key
        look = {"label": label, "color": f"C{k % 10}", "marker": markers[k // 10 % 6],
                "ls": "-"}
        if gains:
            xs = [p.gain for p in pts]
            axes[0].loglog(xs, [max(p.residual or 0.0, 1e-300) for p in pts], **look)
            axes[1].loglog(xs, [max(p.error_max, 1e-300) for p in pts], **look)
            axes[2].loglog(xs, [p.rhs for p in pts], **look)
        else:
            pts = [p for p in pts if p.cpu]
            axes[0].loglog([p.cpu for p in pts], [p.error_max for p in pts], **look)
            axes[1].loglog([p.rhs for p in pts], [p.error_max for p in pts], **look)
    if gains:
        axes[0].set(xlabel="corrector gain", ylabel="max |constraint residual|",
                    title="drift against gain")
        axes[1].set(xlabel="corrector gain", ylabel="max relative error",
                    title="error against gain")
        axes[2].set(xlabel="corrector gain", ylabel="right-side calls",
                    title="cost against gain (failed runs left out)")
    else:
        axes[0].set(xlabel="processor time of the integration [s]",
                    ylabel="max relative error over the grid", title="work-precision")
        axes[1].set(xlabel="right-side calls", ylabel="max relative error over the grid",
                    title="error against right-side calls")
    if result.floor:  # on the relative-error axes
        for ax in ([axes[1]] if gains else axes):
            ax.axhline(result.floor, color="0.6", ls=":", lw=1)
    for ax in axes:
        style(ax)
        ax.xaxis.set_minor_formatter(NullFormatter())
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{os.path.basename(result.model)}, scene {result.scene or '(default)'}, "
                 f"{result.backend} backend")
    fig.tight_layout()
    save(fig, path, "png")
