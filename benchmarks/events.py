"""Events: bgc's C program and Python module beside SciPy solve_ivp with events and SUNDIALS
CVODE with root finding (from C and through scikit-sundae), at equal achieved error, in one run.

    python benchmarks/events.py [--quick] [--repeats N] [--plot FILE.png] [--only pwm,ball]

Problems (benchmarks/models/, each header gives the equations and the closed form):
  pwm   pwm_rl.bg, scene run: an RL load (tau = L/R = 5 ms) driven by a 12 V PWM voltage,
        period 1 ms, duty 0.3, over 10 000 periods (0..10 s; --quick 100 periods): 20 000
        edges, each a time event in bgc.  Output l.p every 0.25 ms against the exact chain of
        exponentials (pwm_exact).
  ball  bouncing_ball.bg, scene drop: a ball dropped from 1 m, e = 0.8, 0..4 s: 19 impacts,
        each a state event, against the closed form (ball_exact).  Output x, b.p every 1 ms.

Methods (every baseline on a right side written from the same equations):
  bgc C           the program of `bgc.compile(target="c")` built with cc -O2,
                  `./prog --rtol R --atol A --stats --max-steps 0` (dopri5, the default solver).
  bgc Python      the module of `bgc.compile(target="python")`, `simulate()` in this process;
                  it takes the C program's steps (the backends are byte-identical), so its
                  counters are the C program's.
  SciPy RK45 events  solve_ivp(method="RK45") with a terminal event: pwm g = t - (next edge),
                  ball g = x (direction -1); at each event solve_ivp is called again from the
                  event with the new input (pwm) or the reversed momentum (ball).
  SciPy RK45 pieces  pwm only: solve_ivp over each interval between two edges, the input
                  constant in each: no event location at all, the edges being known.
  CVODE-C BDF|Adams root  benchmarks/cvode_events.c built against the system's SUNDIALS: CVODE
                  driven from C, root finding (CVodeRootInit) on g = t - (next edge), the input
                  frozen between edges, or g = x; CVodeReInit at each root.  BDF: Newton with
                  the dense solver and the analytic Jacobian; Adams: the fixed-point iteration.
  CVODE-C BDF|Adams stop  pwm only: the same driver stopping on each edge (CVodeSetStopTime)
                  and restarting there: the piecewise way, no root finding.
  sksundae BDF|Adams  CVODE through scikit-sundae: eventsfn (g as for CVODE-C, terminal),
                  init_step(t, y) at each event to restart; right side and event function in
                  Python.

Tolerances: atol = rtol * 1e-3, rtol swept a decade at a time (fewer for the slow baselines).
Columns:
  steps, rej, rhs  the solver's counters over the run (SciPy: len(t) - 1 and nfev summed over
           the calls; sksundae reports nfev only).  rhs includes the calls for the Jacobian.
  ev       events the tool handled (bgc counts each change of a condition: an impact of the
           ball is two, x < 0 becoming true, then false as the ball rises again).
  steps/ev, rhs/ev  steps and rhs calls over the number of edges or impacts of the closed form:
           the cost of an event, since without them each run is a handful of steps.
  t err    the largest |t_event - t_exact| over the events (edges, impacts); 0 where the
           solver steps onto a known time.
  error    max over the output rows of |y - y_ref| / max|y_ref|, each column over its own
           scale, the largest over the columns; from a run writing every row, the timed run
           writing two (bgc: --dt t_end; CVODE-C the same; SciPy and sksundae without t_eval).
  wall, cpu  medians in ms of the timed run over the rounds after a warm-up; C programs less the
           median of a /bin/true process start (timed alongside).  A run whose warm-up takes
           over a second is timed once, by its warm-up.
  prog     the C program's own clock() around its integration (cpu= in its stats line).
Below each table: each method's time interpolated at common errors (log-log along its runs
sorted by error), and for pwm the issue's goal: bgc's C program at least 50x faster than SciPy
with events and faster than CVODE with root finding from C, at equal achieved error: for each
run of bgc C inside the baseline's range of error, the baseline's time there over bgc's (the
verdict on the worst).  Times are printed, never asserted.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import importlib.util
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]  # machine.py, pendulum.py, solvers.py beside this file
import machine  # noqa: E402
from pendulum import CFLAGS, c_compiler, compile_c, cpu_seconds  # noqa: E402
from solvers import (Job, Row, at_error, decades, fmt, measure, ms, parse_stats,  # noqa: E402
                     tol_text)
from solvers import header as solvers_header  # noqa: E402

MODELS = HERE / "models"
ATOL_RATIO = 1e-3
PWM = {"V": 12.0, "R": 2.0, "L": 0.01, "period": 0.001, "duty": 0.3}  # as in pwm_rl.bg
BALL = {"m": 1.0, "g": 9.81, "e": 0.8, "h0": 1.0}  # as in bouncing_ball.bg
SUNDIALS_LIBS = ("-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense",
                 "-lsundials_sunmatrixdense", "-lsundials_sunnonlinsolfixedpoint")
SLOW = 1.0  # seconds: a run slower than this is timed once


@dataclass
class EventRow(Row):
    events: int | None = None
    per_event: tuple | None = None  # (steps, rhs) per edge or impact
    t_error: float | None = None


@dataclass
class Problem:
    key: str
    title: str
    model: str
    scene: str
    t_end: float
    dt: float
    outputs: tuple
    exact: object  # times -> (states at them, event times up to t_end)
    rtols: dict  # method -> rtols


# ---------------------------------------------------------------- closed forms

def pwm_edges(t_end: float) -> np.ndarray:
    """The square wave's edges in (0, t_end), as bgc computes them: (k + duty) period (down)
    and (k + 1) period (up)."""
    T, D = PWM["period"], PWM["duty"]
    out, k = [], 0.0
    while True:
        for edge in ((k + D) * T, (k + 1.0) * T):
            if edge >= t_end:
                return np.array(out)
            out.append(edge)
        k += 1.0


def pwm_input(edge_index: int) -> float:
    """The input after edge number `edge_index` (0: the first, down)."""
    return 0.0 if edge_index % 2 == 0 else 1.0


def pwm_exact(times: np.ndarray, t_end: float):
    """l.p = L i at `times`: i marched exactly from edge to edge, then from the last edge."""
    V, R, L = PWM["V"], PWM["R"], PWM["L"]
    edges = pwm_edges(t_end)
    starts = np.concatenate([[0.0], edges])
    inputs = np.array([1.0] + [pwm_input(k) for k in range(len(edges))])
    rate = R / L
    i_start = np.empty(len(starts))
    i_start[0] = 0.0
    for k in range(1, len(starts)):
        target = V * inputs[k - 1] / R
        i_start[k] = target + (i_start[k - 1] - target) * math.exp(-(starts[k] - starts[k - 1])
                                                                    * rate)
    piece = np.searchsorted(starts, times, side="right") - 1
    target = V * inputs[piece] / R
    i = target + (i_start[piece] - target) * np.exp(-(times - starts[piece]) * rate)
    return (L * i)[:, None], edges


def ball_impacts(t_end: float) -> np.ndarray:
    m, g, e, h0 = (BALL[k] for k in ("m", "g", "e", "h0"))
    t1 = math.sqrt(2 * h0 / g)
    out, v = [t1], g * t1
    while True:
        v *= e
        nxt = out[-1] + 2 * v / g
        if nxt >= t_end:
            return np.array(out)
        out.append(nxt)


def ball_exact(times: np.ndarray, t_end: float):
    """(x, b.p) at `times`: a parabola from each impact, the fall before the first."""
    m, g, e, h0 = (BALL[k] for k in ("m", "g", "e", "h0"))
    impacts = ball_impacts(t_end)
    v1 = g * impacts[0]
    piece = np.searchsorted(impacts, times, side="right")  # 0: before the first impact
    s = times - np.where(piece > 0, impacts[np.maximum(piece - 1, 0)], 0.0)
    up = np.where(piece > 0, v1 * e ** piece.astype(float), 0.0)
    x = np.where(piece > 0, up * s - g * s * s / 2, h0 - g * s * s / 2)
    return np.column_stack([x, m * (up - g * s)]), impacts


def scaled_error(Y: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.max(np.abs(Y - ref), axis=0) / np.max(np.abs(ref), axis=0)))


def event_error(found, exact) -> tuple[float | None, str]:
    found = np.asarray(found, dtype=float)
    if len(found) != len(exact):
        return None, f"{len(found)} events, the closed form has {len(exact)}; "
    return (float(np.max(np.abs(found - exact))) if len(exact) else 0.0), ""


def problems(quick: bool) -> list[Problem]:
    wide = decades(3, 11)
    few = [1e-6, 1e-8, 1e-10]
    if quick:
        wide, few = [1e-5, 1e-8], [1e-6]
    pwm = {"bgc C": wide, "bgc Python": few, "SciPy RK45 events": few,
           "SciPy RK45 pieces": few, "CVODE-C BDF root": wide, "CVODE-C Adams root": wide,
           "CVODE-C BDF stop": wide, "CVODE-C Adams stop": wide, "sksundae BDF": few,
           "sksundae Adams": few}
    ball = {k: v for k, v in pwm.items() if "pieces" not in k and "stop" not in k}
    return [Problem("pwm", "PWM-driven RL circuit", "pwm_rl.bg", "run", 0.1 if quick else 10.0,
                    0.00025, ("l.p",), pwm_exact, pwm),
            Problem("ball", "bouncing ball", "bouncing_ball.bg", "drop", 4.0, 0.001,
                    ("x", "b.p"), ball_exact, ball)]


# ---------------------------------------------------------------- the runs

def tolerances(rtol: float) -> dict:
    return {"rtol": rtol, "atol": rtol * ATOL_RATIO}


def first_run(row: EventRow, action, c: bool = False):
    """The warm-up: (its result, the Job to time, or None when the warm-up is the timing)."""
    cpu0, start = cpu_seconds(), time.perf_counter()
    result = action()
    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu0
    if wall > SLOW:
        row.wall, row.cpu = wall, cpu
        if c and "cpu" in (stats := parse_stats(result.stderr)):
            row.prog = stats["cpu"]
        return result, None
    return result, Job(row, action, c=c, per_round=10 if c and wall < 0.02 else 1)


def read_csv(text: str) -> tuple[list[str], np.ndarray]:
    header, *lines = text.splitlines()
    return header.split(","), np.loadtxt(lines, delimiter=",", ndmin=2)


def program_run(problem: Problem, row: EventRow, args: list, workdir: Path, is_bgc: bool):
    """A C program (bgc's or the CVODE driver): the full-grid run for the errors and the
    events, then the two-row run to time."""
    log = workdir / "events.csv"
    full_args = (args + ["--dt", repr(problem.dt), "--events", str(log)] if is_bgc
                 else args + [repr(problem.dt), str(log)])
    full = subprocess.run(full_args, capture_output=True, text=True)
    if full.returncode != 0:
        row.note += f"FAILED: {full.stderr.strip().splitlines()[-1:]}; "
        return None
    names, data = read_csv(full.stdout)
    ref, exact = problem.exact(data[:, 0], problem.t_end)
    row.error = scaled_error(data[:, [names.index(n) for n in problem.outputs]], ref)
    if is_bgc:
        with open(log, encoding="utf-8") as fh:
            logged = list(csv.reader(fh))[1:]
        wanted = "b.p" if problem.key == "ball" else "square(period, duty)"
        times = [float(t) for t, what, _ in logged if what == wanted]
    else:
        times = np.loadtxt(log, ndmin=1) if log.stat().st_size else []
    row.t_error, note = event_error([t for t in times if t < problem.t_end], exact)
    row.note += note
    quiet = args + (["--dt", repr(problem.t_end)] if is_bgc else [repr(problem.t_end)])
    done, job = first_run(row, lambda: subprocess.run(quiet, stdout=subprocess.DEVNULL,
                                                      stderr=subprocess.PIPE, text=True), True)
    stats = parse_stats(done.stderr)
    for key in ("steps", "rejected", "rhs", "events"):
        setattr(row, key, int(stats[key]) if key in stats else None)
    if is_bgc and stats.get("steps") != parse_stats(full.stderr).get("steps"):
        row.note += "the full-grid run takes other steps; "
    return job


def bgc_c(problem, exe, rtol, workdir):
    row = EventRow("bgc C", tol_text(rtol), rtol)
    tol = tolerances(rtol)
    args = [str(exe), "--t-end", repr(problem.t_end), "--rtol", repr(tol["rtol"]), "--atol",
            repr(tol["atol"]), "--stats", "--max-steps", "0"]
    return row, program_run(problem, row, args, workdir, True)


def cvode_c(problem, exe, method, rtol, workdir):
    row = EventRow(method, tol_text(rtol), rtol)
    tol = tolerances(rtol)
    solver, mode = method.split()[1:]
    args = [str(exe), problem.key, solver.lower(), mode, repr(tol["rtol"]), repr(tol["atol"]),
            repr(problem.t_end)]
    return row, program_run(problem, row, args, workdir, False)


def bgc_python(problem, module, rtol, c_rows):
    row = EventRow("bgc Python", tol_text(rtol), rtol)
    tol = tolerances(rtol)
    log = []
    t, Y = module.simulate(t_end=problem.t_end, dt=problem.dt, events=log, max_steps=0, **tol)
    ref, exact = problem.exact(t, problem.t_end)
    row.error = scaled_error(Y, ref)
    wanted = "b.p" if problem.key == "ball" else "square(period, duty)"
    row.t_error, row.note = event_error([e[0] for e in log if e[1] == wanted and
                                         e[0] < problem.t_end], exact)
    twin = next((r for r in c_rows if r.rtol == rtol), None)
    if twin:
        row.steps, row.rejected, row.rhs, row.events = (twin.steps, twin.rejected, twin.rhs,
                                                        twin.events)
        if twin.error != row.error:
            row.note += "not the C program's numbers; "
    _, job = first_run(row, lambda: module.simulate(t_end=problem.t_end, dt=problem.t_end,
                                                     max_steps=0, **tol))
    return row, job


# The baselines' right sides and switching, in Python

def pwm_rhs(u):
    V, R, L = PWM["V"], PWM["R"], PWM["L"]
    return lambda t, y: [V * u - R / L * y[0]]


def ball_rhs(t, y):
    return [y[1] / BALL["m"], -BALL["m"] * BALL["g"]]


def scipy_solve(problem: Problem, rtol: float, pieces: bool, grid=None):
    """solve_ivp from event to event; returns (times, states, event times, steps, nfev)."""
    from scipy.integrate import solve_ivp

    tol = tolerances(rtol)
    t, y, k = 0.0, [0.0] if problem.key == "pwm" else [BALL["h0"], 0.0], 0
    edges = pwm_edges(problem.t_end) if problem.key == "pwm" else None
    ts, ys, found, steps, nfev = [], [], [], 0, 0
    while t < problem.t_end:
        if problem.key == "pwm":
            u = 1.0 if k == 0 else pwm_input(k - 1)
            f, stop = pwm_rhs(u), edges[k] if k < len(edges) else problem.t_end
            if pieces:
                span, events = (t, stop), None
            else:
                def events(s, z, stop=stop):
                    return s - stop
                events.terminal, span = True, (t, problem.t_end)
        else:
            def events(s, z):
                return z[0]
            events.terminal, events.direction = True, -1
            f, span = ball_rhs, (t, problem.t_end)
        t_eval = None  # the piece's grid rows, and its end for the state there
        if grid is not None:
            t_eval = np.append(grid[(grid >= t) & (grid < span[1])], span[1])
        sol = solve_ivp(f, span, y, method="RK45", events=events, t_eval=t_eval, **tol)
        if not sol.success:
            raise RuntimeError(sol.message)
        steps, nfev = steps + len(sol.t) - 1 if grid is None else steps, nfev + sol.nfev
        if grid is not None:
            rows = sol.t < span[1]
            ts.append(sol.t[rows]), ys.append(sol.y.T[rows])
        if events is not None and len(sol.t_events[0]):
            t, y = float(sol.t_events[0][0]), list(sol.y_events[0][0])
        else:
            t, y = span[1], list(sol.y[:, -1])
            if grid is not None and span[1] == problem.t_end:
                ts.append([t]), ys.append([y])
        if grid is not None:  # the grid's rows before the event are written; the rest follow
            grid = grid[grid >= t]
        if t >= problem.t_end:
            break
        found.append(t)
        if problem.key == "ball":
            y[1] = -BALL["e"] * y[1]
        k += 1
    return ts, ys, found, steps, nfev


def sksundae_solve(problem: Problem, method: str, rtol: float, grid=None):
    """CVODE through scikit-sundae, restarted with init_step at each event."""
    from sksundae.cvode import CVODE

    state = {"u": 1.0, "next": 0.0}
    if problem.key == "pwm":
        edges = pwm_edges(problem.t_end)
        state["next"] = edges[0]
        V, R, L = PWM["V"], PWM["R"], PWM["L"]

        def rhs(t, y, yp):
            yp[0] = V * state["u"] - R / L * y[0]

        def jac(t, y, yp, JJ):
            JJ[0, 0] = -R / L

        def g(t, y, ev):
            ev[0] = t - state["next"]
        g.terminal, g.direction, y0 = [True], [0], [0.0]
    else:
        m, gr = BALL["m"], BALL["g"]

        def rhs(t, y, yp):
            yp[0], yp[1] = y[1] / m, -m * gr

        def jac(t, y, yp, JJ):
            JJ[0, 1] = 1.0 / m

        def g(t, y, ev):
            ev[0] = y[0]
        g.terminal, g.direction, y0 = [True], [-1], [BALL["h0"], 0.0]
    kw = {"jacfn": jac} if method == "BDF" else {}
    solver = CVODE(rhs, method=method, eventsfn=g, num_events=1, max_num_steps=10**8,
                   **tolerances(rtol), **kw)
    outs = list(grid[1:]) if grid is not None else [problem.t_end]
    res = solver.init_step(0.0, np.array(y0))
    ts, ys, found, nfev, k = [[0.0]], [[list(y0)]], [], 0, 0
    for tout in outs:
        while res.t < tout:
            res = solver.step(tout)
            if not res.success:
                raise RuntimeError(res.message)
            if res.status == 2:  # an event
                for kept in (g._i, g._t, g._y):  # sksundae's log of the events: each step
                    kept.clear()  # would copy it whole, 20 000 events in all
                nfev += res.nfev
                y = np.array(res.y, dtype=float)
                found.append(res.t)
                if problem.key == "pwm":
                    k += 1
                    state["u"] = pwm_input(k - 1)
                    state["next"] = edges[k] if k < len(edges) else 2 * problem.t_end
                else:
                    y[1] = -BALL["e"] * y[1]
                res = solver.init_step(res.t, y)
        ts.append([res.t]), ys.append([list(res.y)])
    return ts, ys, found, None, nfev + res.nfev


def python_baseline(problem: Problem, method: str, rtol: float):
    row = EventRow(method, tol_text(rtol), rtol)
    grid = np.append(np.arange(int(math.ceil(problem.t_end / problem.dt - 1e-6))) * problem.dt,
                     problem.t_end)
    if method.startswith("SciPy"):
        pieces = method.endswith("pieces")
        solve = lambda g=None: scipy_solve(problem, rtol, pieces, g)  # noqa: E731
    else:
        solve = lambda g=None: sksundae_solve(problem, method.split()[1], rtol, g)  # noqa: E731
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ts, ys, *_ = solve(grid)
            (_, _, found, steps, nfev), job = first_run(row, solve)
    except RuntimeError as exc:
        row.note += f"FAILED: {exc}; "
        return row, None
    t = np.concatenate(ts)
    Y = np.concatenate([np.asarray(v, dtype=float) for v in ys])
    ref, exact = problem.exact(t, problem.t_end)
    row.error = scaled_error(Y, ref)
    row.steps, row.rhs, row.events = steps, nfev, len(found)
    row.t_error, note = event_error(found, [] if method.endswith("pieces") else exact)
    row.note += "" if method.endswith("pieces") else note
    if method.endswith("pieces"):
        row.t_error = 0.0
    return row, job


# ---------------------------------------------------------------- building

def build_bgc(problem: Problem, workdir: Path):
    import bgc
    from bgc.base.processes import load_python_module

    path = str(MODELS / problem.model)
    (name, text), = bgc.compile(path, target="c", scene=problem.scene).items()
    (workdir / name).write_text(text, encoding="utf-8")
    exe = compile_c(workdir / name, workdir / problem.key)
    (pytext,) = bgc.compile(path, target="python", scene=problem.scene).values()
    return exe, load_python_module(pytext)


def build_cvode(workdir: Path) -> tuple[Path | None, str]:
    """The CVODE driver, or None and why not."""
    exe = workdir / "cvode_events"
    cmd = [*c_compiler(), *CFLAGS, str(HERE / "cvode_events.c"), "-o", str(exe),
           *SUNDIALS_LIBS, "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        first = (done.stderr.strip().splitlines() or ["?"])[0]
        return None, f"cannot build cvode_events.c against SUNDIALS ({first})"
    return exe, ""


def missing(method: str, cvode_why: str) -> str | None:
    if method.startswith("CVODE-C"):
        return cvode_why or None
    module = {"SciPy": "scipy", "sksundae": "sksundae"}.get(method.split()[0])
    if module and not importlib.util.find_spec(module):
        return f"{module} not installed"
    return None


def run_problem(problem, workdir, spawn, repeats, cvode, cvode_why):
    exe, module = build_bgc(problem, workdir)
    rows, jobs, skipped = [], [], []
    for method, rtols in problem.rtols.items():
        if why := missing(method, cvode_why):
            skipped.append((method, why))
            continue
        for rtol in rtols:
            if method == "bgc C":
                row, job = bgc_c(problem, exe, rtol, workdir)
            elif method == "bgc Python":
                row, job = bgc_python(problem, module, rtol, [r for r in rows
                                                              if r.method == "bgc C"])
            elif method.startswith("CVODE-C"):
                row, job = cvode_c(problem, cvode, method, rtol, workdir)
            else:
                row, job = python_baseline(problem, method, rtol)
            rows.append(row)
            jobs += [job] if job else []
    n_exact = len(problem.exact(np.array([0.0]), problem.t_end)[1])
    for row in rows:
        if row.steps is not None or row.rhs is not None:
            row.per_event = (row.steps and row.steps / n_exact, row.rhs and row.rhs / n_exact)
    measure(jobs, spawn, repeats)
    return rows, skipped, n_exact


# ---------------------------------------------------------------- reporting

def table(rows: list[EventRow], skipped: list) -> str:
    head = (f"{'method':<20}{'rtol':>7}{'steps':>8}{'rej':>7}{'rhs':>9}{'ev':>7}"
            f"{'steps/ev':>9}{'rhs/ev':>8}{'t err':>9}{'error':>9}{'wall ms':>10}"
            f"{'cpu ms':>10}{'prog ms':>9}")
    lines = [head, "-" * len(head)]
    for r in rows:
        wall, cpu, prog = (None if v is None else v * 1e3 for v in (r.wall, r.cpu, r.prog))
        per_steps, per_rhs = r.per_event or (None, None)
        lines.append(f"{r.method:<20}{r.setting:>7}{fmt(r.steps, 'd', 8)}"
                     f"{fmt(r.rejected, 'd', 7)}{fmt(r.rhs, 'd', 9)}{fmt(r.events, 'd', 7)}"
                     f"{fmt(per_steps, '.2f', 9)}{fmt(per_rhs, '.1f', 8)}"
                     f"{fmt(r.t_error, '.1e', 9)}{fmt(r.error, '.1e', 9)}"
                     f"{fmt(wall, '.4g', 10)}{fmt(cpu, '.4g', 10)}{fmt(prog, '.3g', 9)}"
                     + (f"  {r.note.rstrip('; ')}" if r.note else ""))
    return "\n".join(lines + [f"not run: {name}: {why}" for name, why in skipped])


def levels(rows: list[EventRow]) -> list[float]:
    """Powers of ten inside bgc C's range of error, else the middle of that range (to two
    digits)."""
    errors = [r.error for r in rows if r.method == "bgc C" and r.error]
    if not errors:
        return []
    lo, hi = math.ceil(math.log10(min(errors))), math.floor(math.log10(max(errors)))
    middle = float(f"{math.sqrt(min(errors) * max(errors)):.1e}")
    return [10.0 ** k for k in range(hi, lo - 1, -1)] or [middle]


def equal_error(rows: list[EventRow]) -> list[str]:
    methods = list(dict.fromkeys(r.method for r in rows))
    out = []
    for level in levels(rows):
        cells = sorted((t, m) for m in methods if (t := at_error(rows, m, "time", level)))
        out.append(f"at error {level:.2g}: " + ", ".join(f"{m} {ms(t)}" for t, m in cells))
    return out


def ratios(rows: list[EventRow], baseline: str) -> list[float]:
    """The baseline's time over bgc C's at each bgc C run inside the baseline's error range."""
    return [b / r.time for r in rows if r.method == "bgc C" and r.error and r.time
            and (b := at_error(rows, baseline, "time", r.error))]


def goals(rows: list[EventRow]) -> list[str]:
    out = []
    for baseline, bar in (("SciPy RK45 events", 50.0), ("SciPy RK45 pieces", 50.0),
                          ("CVODE-C BDF root", 1.0), ("CVODE-C Adams root", 1.0),
                          ("CVODE-C BDF stop", 1.0), ("CVODE-C Adams stop", 1.0)):
        v = ratios(rows, baseline)
        measured = (f"{min(v):.3g}x..{max(v):.3g}x over {len(v)} runs of bgc C "
                    f"(geometric mean {math.exp(np.mean(np.log(v))):.3g}x)" if v else "n/a")
        verdict = "n/a" if not v else "met" if min(v) >= bar else "NOT MET"
        out.append(f"goal: pwm at equal error, bgc C at least {bar:g}x faster than {baseline}"
                   f"; measured: {measured} ({verdict})")
    return out


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6.5 * len(results), 5), squeeze=False)
    for ax, (title, rows) in zip(axes[0], results.items()):
        methods = list(dict.fromkeys(r.method for r in rows))
        for method in methods:  # each method its colour in both panels
            color = plt.cm.tab10(list(problems(False)[0].rtols).index(method) % 10)
            pts = sorted((r.error, r.time) for r in rows
                         if r.method == method and r.error and r.time)
            if pts:
                ax.plot([p[1] * 1e3 for p in pts], [p[0] for p in pts],
                        "o-" if method.startswith("bgc") else "s--", color=color, label=method,
                        markersize=4)
        ax.set(xscale="log", yscale="log", title=f"{title}: work-precision",
               xlabel="time of the integration [ms] (C: the program's own clock; else cpu)",
               ylabel="error, relative to each column's largest value")
        ax.grid(which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def header(repeats: int) -> list[str]:
    """benchmarks/solvers.py's lines on the date, the compiler, the versions and the machine,
    then how this one times and its tolerances."""
    return solvers_header(repeats)[:4] + [
        f"timing:   medians of {repeats} rounds after a warm-up (a warm-up over {SLOW:g} s is "
        "the timing); C programs: their 2-row run less a /bin/true; prog: their clock()",
        f"tolerance: atol = rtol * {ATOL_RATIO:g}"]


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="100 PWM periods, two tolerances for the C programs, one round")
    parser.add_argument("--repeats", type=int, help="timed rounds (default 5, --quick 1)")
    parser.add_argument("--plot", type=Path, help="write the work-precision plot there")
    parser.add_argument("--only", help="comma-separated problems: pwm,ball")
    args = parser.parse_args(argv)
    args.repeats = args.repeats or (1 if args.quick else 5)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    began = time.perf_counter()
    print("\n".join(header(args.repeats)))
    true = shutil.which("true") or "/bin/true"
    spawn = Job(Row("process start", ""), lambda: subprocess.run(
        [true], stderr=subprocess.PIPE, text=True), c=True, per_round=10)
    results, lines = {}, []
    with tempfile.TemporaryDirectory(prefix="bgc-events-") as tmp:
        cvode, why = build_cvode(Path(tmp))
        for problem in problems(args.quick):
            if args.only and problem.key not in args.only.split(","):
                continue
            rows, skipped, n_exact = run_problem(problem, Path(tmp), spawn, args.repeats,
                                                 cvode, why)
            results[problem.title] = rows
            kind = "edges (time events)" if problem.key == "pwm" else "impacts (state events)"
            print(f"\n== {problem.key}: {problem.title}, benchmarks/models/{problem.model} "
                  f"scene {problem.scene}, 0..{problem.t_end:g} s: {n_exact} {kind}\n"
                  f"process start (subtracted): {ms(spawn.row.wall)} wall, "
                  f"{ms(spawn.row.cpu)} cpu\n")
            print(table(rows, skipped))
            print("\n".join(equal_error(rows)))
            if problem.key == "pwm":
                lines = goals(rows)
    if args.plot:
        plot(results, args.plot)
        print(f"\nplot written to {args.plot}")
    if lines:
        print("\n" + "\n".join(lines))
    print(f"\ntotal: {time.perf_counter() - began:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
