"""Switched circuits: bgc's C program beside SUNDIALS CVODE with root finding driven from C and
SciPy solve_ivp with events restarted per mode, at equal achieved error against the exact
piecewise-linear solution, in one run.

    python benchmarks/switched.py [--quick] [--repeats N] [--model models/buck.bg]

The problem: the buck converter of models/buck.bg, scene `run` (an ideal switch driven at
100 kHz, duty 0.5, a freewheeling ideal diode, L = 100 uH, C = 10 uF parallel to R = 5 ohm, from
12 V, run over 10 ms: 1 000 periods, 2 000 edges; --quick: 1 ms), written exactly as drawn: no
resistor in series with the switch or across the diode.  Between events the circuit is
linear, so the reference is exact: the matrix exponential of each mode from event to event
(on: L di/dt = V - v; off: L di/dt = -v while the diode conducts; both open, i = 0), the
diode's turn-off instants found by bisection on the exact current to the last bit.

Methods (every baseline on a right side written from the same equations):
  bgc C            the program of `bgc.compile(target="c")` built with cc -O2,
                   `./prog --rtol R --atol A --stats --max-steps 0` (dopri5, the default).
  CVODE-C BDF|Adams root  benchmarks/cvode_buck.c built against the system's SUNDIALS
                   (Debian's libsundials-dev): root finding on the next edge and on the
                   diode's current, CVodeReInit at each root.
  SciPy RK45 events  solve_ivp(method="RK45") per mode, from event to event: the edges known,
                   the diode's turn-off a terminal event (direction -1).

Tolerances: atol = rtol * 1e-3, rtol a decade at a time.  Columns: steps, rhs, events (the
tool's), error (max over the output rows of |y - y_ref| / max|y_ref| per column, the largest
over the columns, from a run writing every row), cpu (ms: the C programs' own clock() around
the integration, median over the repeats of the run writing two rows; SciPy's process time).  Below the table: each baseline's time
at bgc's achieved errors (log-log interpolation along its runs) over bgc's.  Times are
printed, never asserted.
"""
from __future__ import annotations

import argparse
import math
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]
import machine  # noqa: E402
from pendulum import CFLAGS, c_compiler  # noqa: E402

BUCK = {"V": 12.0, "L": 1e-4, "C": 1e-5, "R": 5.0, "T": 1e-5, "duty": 0.5}
ATOL_RATIO = 1e-3
SUNDIALS_LIBS = ("-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense",
                 "-lsundials_sunmatrixdense", "-lsundials_sunnonlinsolfixedpoint")


# ---------------------------------------------------------------- the exact solution

def _flow(A, g, h):
    """x -> exp(A h) x + int_0^h exp(A s) ds g, as the blocks of a 3 x 3 exponential."""
    from scipy.linalg import expm
    E = np.zeros((3, 3))
    E[:2, :2], E[:2, 2] = A, g
    F = expm(E * h)
    return F[:2, :2], F[:2, 2]


def _modes(p):
    """Each mode's (A, g) on x = (i, v)."""
    L, C, R, V = p["L"], p["C"], p["R"], p["V"]
    conducting = np.array([[0.0, -1.0 / L], [1.0 / C, -1.0 / (R * C)]])
    return {"on": (conducting, np.array([V / L, 0.0])),
            "off": (conducting, np.zeros(2)),
            "dcm": (np.array([[0.0, 0.0], [0.0, -1.0 / (R * C)]]), np.zeros(2))}


def edges(p, t_end):
    """The square wave's edges in (0, t_end) as bgc's square(T, duty) computes them."""
    out, k = [], 0.0
    while True:
        for e in ((k + p["duty"]) * p["T"], (k + 1.0) * p["T"]):
            if e >= t_end:
                return out
            out.append(e)
        k += 1.0


def exact(p, t_end, times):
    """(i, v) at `times`, and the event times (edges and turn-offs), marched exactly."""
    from scipy.optimize import brentq
    modes = _modes(p)
    x, t, mode = np.zeros(2), 0.0, "on"
    bounds = edges(p, t_end) + [t_end]
    out = np.empty((len(times), 2))
    k = 0
    events = []

    def at(x0, mode, h):
        P, q = _flow(*modes[mode], h)
        return P @ x0 + q

    for n, b in enumerate(bounds):
        while t < b:
            stop = b
            if mode == "off":  # the diode's current reaches zero inside?
                i_end = at(x, mode, b - t)[0]
                if i_end < 0:
                    stop = brentq(lambda s: at(x, mode, s - t)[0], t, b, xtol=1e-300,
                                  rtol=4 * np.finfo(float).eps, maxiter=500)
            while k < len(times) and times[k] <= stop:
                out[k] = at(x, mode, times[k] - t)
                k += 1
            x = at(x, mode, stop - t)
            t = stop
            if stop < b:
                x[0] = 0.0
                mode = "dcm"
                events.append(stop)
        if b < t_end:
            events.append(b)
            mode = "on" if n % 2 == 1 else ("off" if x[0] > 0 else "dcm")
    while k < len(times):
        out[k] = x
        k += 1
    return out, events


# ---------------------------------------------------------------- the methods

def parse_stats(stderr: str) -> dict:
    for line in stderr.splitlines():
        if line.startswith("stats:"):
            return {k: v for k, _, v in (w.partition("=") for w in line.split()[1:])}
    return {}


def read_csv(text: str):
    rows = [list(map(float, ln.split(","))) for ln in text.strip().splitlines()[1:]]
    a = np.array(rows)
    return a[:, 0], a[:, 1:]


def _start_time(repeats) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(["/bin/true"])
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def timed(cmd, repeats, spawn) -> float:
    """The median over the repeats of the program's own processor time of its integration
    (the cpu= of its stats line: the clock() around the run, which other jobs on the machine
    do not inflate as they do the wall time), in ms."""
    ts = []
    for _ in range(repeats):
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        ts.append(float(parse_stats(done.stderr)["cpu"]))
    return statistics.median(ts) * 1e3


def error_of(t, Y, p, t_end, scale):
    """max |y - y_ref| / max |y_ref| per column (the coil's current, the output voltage), the
    largest."""
    ref, _ = exact(p, t_end, t)
    return float(np.max(np.abs(Y - ref).max(axis=0) / scale))


def run_bgc(exe, rtol, t_end, dt):
    args = [str(exe), "--rtol", repr(rtol), "--atol", repr(rtol * ATOL_RATIO), "--stats",
            "--max-steps", "0", "--t-end", repr(t_end)]
    full = subprocess.run(args + ["--dt", repr(dt)], capture_output=True, text=True, check=True)
    return read_csv(full.stdout), parse_stats(full.stderr), args + ["--dt", repr(t_end)]


def run_cvode(exe, method, rtol, t_end, dt, p):
    tail = [repr(p[k]) for k in ("V", "L", "C", "R", "T", "duty")]
    args = [str(exe), method, repr(rtol), repr(rtol * ATOL_RATIO), repr(t_end)]
    full = subprocess.run(args + [repr(dt)] + tail, capture_output=True, text=True, check=True)
    t, Y = read_csv(full.stdout)  # (l.p, c.q): the current and the voltage
    return (t, Y / np.array([p["L"], p["C"]])), parse_stats(full.stderr), \
        args + [repr(t_end)] + tail


def run_scipy(rtol, t_end, dt, p):
    """solve_ivp per mode from event to event; returns the rows, counters, and the time."""
    from scipy.integrate import solve_ivp
    modes = _modes(p)
    grid = np.arange(0, round(t_end / dt) + 1) * dt
    t0 = time.process_time()
    x, t, mode, k = np.zeros(2), 0.0, "on", 0
    out = np.empty((len(grid), 2))
    nfev = steps = events = 0
    bounds = edges(p, t_end) + [t_end]

    def diode(t, y):
        return y[0]
    diode.terminal, diode.direction = True, -1
    for n, b in enumerate(bounds):
        while t < b:
            A, g = modes[mode]
            sol = solve_ivp(lambda s, y: A @ y + g, (t, b), x, method="RK45", rtol=rtol,
                            atol=rtol * ATOL_RATIO, dense_output=True,
                            events=diode if mode == "off" else None)
            nfev += sol.nfev
            steps += len(sol.t) - 1
            end = sol.t[-1]
            while k < len(grid) and grid[k] <= end:
                out[k] = sol.sol(grid[k])
                k += 1
            x, t = sol.y[:, -1].copy(), end
            if sol.status == 1:  # the diode stops
                x[0] = 0.0
                mode = "dcm"
                events += 1
        if b < t_end:
            events += 1
            mode = "on" if n % 2 == 1 else ("off" if x[0] > 0 else "dcm")
    cpu = (time.process_time() - t0) * 1e3
    out[k:] = x
    return (grid, out), {"steps": steps, "rhs": nfev, "events": events}, cpu


# ---------------------------------------------------------------- the table

def at_error(runs, err):
    """A method's time at an achieved error, log-log along its runs sorted by error."""
    pts = sorted((e, c) for e, c in runs if e > 0 and c > 0)
    if len(pts) < 2 or not pts[0][0] <= err <= pts[-1][0]:
        return None
    for (e0, c0), (e1, c1) in zip(pts, pts[1:]):
        if e0 <= err <= e1:
            if e1 == e0:
                return c0
            w = (math.log(err) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(c0) + w * (math.log(c1) - math.log(c0)))
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--model", default=str(ROOT / "models" / "buck.bg"))
    ap.add_argument("--scene", default="run")
    args = ap.parse_args(argv)
    import bgc
    p = dict(BUCK)
    t_end = 1e-3 if args.quick else 1e-2
    dt = 1e-6
    work = Path(tempfile.mkdtemp(prefix="bgc-switched-"))
    print(f"# buck converter, 100 kHz, 0 .. {t_end:g} s ({len(edges(p, t_end))} edges); "
          f"{machine.processor()}; load {machine.load_average()}")
    (name, text), = bgc.compile(args.model, target="c", scene=args.scene).items()
    src = work / "buck.c"
    src.write_text(text)
    exe = work / "buck"
    subprocess.run([*c_compiler(), *CFLAGS, str(src), "-o", str(exe), "-lm"], check=True)
    cv = None
    if shutil.which("pkg-config") or Path("/usr/include/cvode/cvode.h").exists():
        cv = work / "cvode_buck"
        built = subprocess.run([*c_compiler(), *CFLAGS, str(HERE / "cvode_buck.c"), "-o",
                                str(cv), *SUNDIALS_LIBS, "-lm"], capture_output=True, text=True)
        if built.returncode != 0:
            print(f"# CVODE-C not built (needs libsundials-dev): {built.stderr.strip()[:200]}")
            cv = None
    spawn = _start_time(args.repeats)
    t_ref = np.arange(0, round(t_end / dt) + 1) * dt
    ref, _ = exact(p, t_end, t_ref)
    scale = np.max(np.abs(ref), axis=0)
    rows, by_method = [], {}
    rtols = [10.0 ** -k for k in range(4, 12 if not args.quick else 10)]
    for rtol in rtols:
        (t, Y), st, quiet = run_bgc(exe, rtol, t_end, dt)
        err = error_of(t, Y, p, t_end, scale)
        cpu = timed(quiet, args.repeats, spawn)
        rows.append(("bgc C dopri5", rtol, st.get("steps"), st.get("rhs"), st.get("events"),
                     err, cpu))
        by_method.setdefault("bgc C dopri5", []).append((err, cpu))
        if cv is not None:
            for method in ("bdf", "adams"):
                (t, Y), st, quiet = run_cvode(cv, method, rtol, t_end, dt, p)
                err = error_of(t, Y, p, t_end, scale)
                cpu = timed(quiet, args.repeats, spawn)
                label = f"CVODE-C {method.upper() if method == 'bdf' else 'Adams'} root"
                rows.append((label, rtol, st.get("steps"), st.get("rhs"), st.get("events"),
                             err, cpu))
                by_method.setdefault(label, []).append((err, cpu))
        if rtol >= 1e-8:  # (SciPy's restarts make its tight runs minutes long)
            (t, Y), st, cpu = run_scipy(rtol, t_end, dt, p)
            err = error_of(t, Y, p, t_end, scale)
            rows.append(("SciPy RK45 events", rtol, st["steps"], st["rhs"], st["events"], err,
                         cpu))
            by_method.setdefault("SciPy RK45 events", []).append((err, cpu))
    print_table(rows, by_method)
    shutil.rmtree(work, ignore_errors=True)
    return 0


def print_table(rows, by_method) -> None:
    """The rows (method, rtol, steps, rhs, events, error, cpu), then each baseline's time at
    bgc's achieved errors over bgc's (or, where they never meet, its least error and bgc's
    largest)."""
    print(f"{'method':<20} {'rtol':>7} {'steps':>8} {'rhs':>9} {'events':>7} {'error':>9} "
          f"{'cpu ms':>9}")
    for m, rtol, steps, rhs, ev, err, cpu in rows:
        print(f"{m:<20} {rtol:>7.0e} {steps or '-':>8} {rhs or '-':>9} {ev or '-':>7} "
              f"{err:>9.1e} {cpu:>9.3g}")
    print("\n# each baseline's time at bgc's achieved error, over bgc's")
    ours = by_method["bgc C dopri5"]
    for m, runs in by_method.items():
        if m.startswith("bgc"):
            continue
        ratios = [(e, at_error(runs, e) / c) for e, c in ours
                  if at_error(runs, e) is not None and c > 0]
        e_best, c_best = min(runs)
        text = ", ".join(f"{r:.1f}x at {e:.0e}" for e, r in ratios) or \
            f"no common error (its least {e_best:.1e} in {c_best:.3g} ms; bgc's largest " \
            f"{max(ours)[0]:.1e})"
        print(f"{m:<20} {text}")


if __name__ == "__main__":
    sys.exit(main())
