"""An H-bridge PWM motor drive: bgc's C program beside SUNDIALS CVODE with root finding driven
from C and SciPy solve_ivp with events restarted per mode, at equal achieved error against the
exact piecewise-linear solution, in one run.

    python benchmarks/hbridge.py [--quick] [--repeats N]

The problem: tests/models/hbridge.bg, scene `run`: four ideal switches, each with its
anti-parallel ideal diode (electrical.switch_diode), with dead time, driving a DC motor (L di/dt
= v - R i - k w, J dw/dt = k i - b w; R = 1 ohm, L = 1 mH, k = 0.05, J = 1e-4, b = 1e-5) from
24 V.  s1 and s4 follow square(1/f, duty), s2 and s3 square(1/f, 1 - duty - 2 dead, (duty +
dead)/f): f = 20 kHz, duty 0.7, dead 0.05, so each 50 us period is +V for 70 %, dead 5 %, -V
for 20 %, dead 5 %; in the dead time the diodes apply -V while i > 0, +V while i < 0, and hold
i at zero where it would reverse.  Run over 10 ms: 200 periods, 800 edges (--quick: 1 ms).
Between events the drive is linear, so the reference is exact: the matrix exponential of each
mode from event to event, the edges computed as bgc's square(period, duty, t0) computes them,
the current's zero in the dead time (where it reverses) found by bisection on the exact
current to the last bit.

Methods (every baseline on a right side written from the same equations, on the model's
states, the momenta L i and J w):
  bgc C            the program of `bgc.compile(target="c")` built with cc -O2,
                   `./prog --rtol R --atol A --stats --max-steps 0` (dopri5, the default).
  CVODE-C BDF|Adams root  benchmarks/cvode_hbridge.c built against the system's SUNDIALS
                   (Debian's libsundials-dev): root finding on the next edge and on the
                   current in the dead time, CVodeReInit at each root.
  SciPy RK45 events  solve_ivp(method="RK45") per mode, from event to event: the edges known,
                   the current's zero in the dead time a terminal event.

Tolerances: atol = rtol * 1e-3, rtol a decade at a time.  Columns: steps, rhs, events (the
tool's), error (max over the output rows of |y - y_ref| / max|y_ref| per column, the motor's
current and speed, the larger), cpu (ms: the C programs' own clock() around the integration,
median over the repeats of the run writing two rows; SciPy's process time).  Below the table:
each baseline's time at bgc's achieved errors (log-log interpolation along its runs) over
bgc's.  Times are printed, never asserted.
"""
from __future__ import annotations

import argparse
import shutil
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
from switched import SUNDIALS_LIBS, parse_stats, print_table, read_csv, timed  # noqa: E402

MODEL = ROOT / "tests" / "models" / "hbridge.bg"
HBRIDGE = {"V": 24.0, "f": 2e4, "duty": 0.7, "dead": 0.05, "R": 1.0, "L": 1e-3, "k": 0.05,
           "J": 1e-4, "b": 1e-5}
ATOL_RATIO = 1e-3


# ---------------------------------------------------------------- the switching instants

def waves(p):
    """The two square waves' (period, duty, t0), computed as the generated program computes
    them: s1 and s4's, s2 and s3's."""
    period = 1.0 / p["f"]
    return ((period, p["duty"], 0.0),
            (period, -p["duty"] - 2.0 * p["dead"] + 1.0, (p["duty"] + p["dead"]) / p["f"]))


def wave_edges(period, duty, t0, t_end):
    """One square wave's edges in (0, t_end) as (time, value after), each as bgc's
    square_next computes it: t0 (where t0 > 0), then t0 + (k + duty) period and
    t0 + (k + 1) period for k = 0, 1, ..."""
    out, k = [], 0.0
    if 0.0 < t0 < t_end:
        out.append((t0, 1))
    while True:
        for e, value in ((t0 + (k + duty) * period, 0), (t0 + (k + 1.0) * period, 1)):
            if e >= t_end:
                return out
            out.append((e, value))
        k += 1.0


def edges(p, t_end):
    """Both waves' edges in (0, t_end), in time order, as (time, wave, value after)."""
    both = [(e, j, value) for j, w in enumerate(waves(p))
            for e, value in wave_edges(*w, t_end)]
    return sorted(both)


# ---------------------------------------------------------------- the exact solution

def _system(p, v, held):
    """(A, g) on x = (i, w): the motor under the bridge's voltage v, or with i held at 0."""
    R, L, k, J, b = p["R"], p["L"], p["k"], p["J"], p["b"]
    if held:
        return np.array([[0.0, 0.0], [0.0, -b / J]]), np.zeros(2)
    return np.array([[-R / L, -k / L], [k / J, -b / J]]), np.array([v / L, 0.0])


def _flow(A, g, h):
    """x -> exp(A h) x + int_0^h exp(A s) ds g, as the blocks of a 3 x 3 exponential."""
    from scipy.linalg import expm
    E = np.zeros((3, 3))
    E[:2, :2], E[:2, 2] = A, g
    F = expm(E * h)
    return F[:2, :2], F[:2, 2]


def bridge_voltage(p, on, i):
    """The bridge's voltage on the motor and whether the current is held at zero: from the
    switches' values (s1 and s4, s2 and s3) and the current (its sign in the dead time)."""
    if on[0]:
        return p["V"], False
    if on[1]:
        return -p["V"], False
    if i == 0.0:
        return 0.0, True
    return (-p["V"] if i > 0.0 else p["V"]), False


def exact(p, t_end, times):
    """(i, w) at `times`, and the event times (edges and current zeros), marched exactly."""
    from scipy.optimize import brentq
    x, t = np.zeros(2), 0.0
    on = [0.0 >= t0 for _, _, t0 in waves(p)]
    out = np.empty((len(times), 2))
    k, events = 0, []

    def at(x0, v, held, h):
        P, q = _flow(*_system(p, v, held), h)
        return P @ x0 + q

    for b, j, value in edges(p, t_end) + [(t_end, None, None)]:
        while t < b:
            v, held = bridge_voltage(p, on, x[0])
            stop, zero = b, False
            if not on[0] and not on[1] and not held:  # the current reaches zero inside?
                i_end = at(x, v, held, b - t)[0]
                if i_end * x[0] <= 0.0:
                    x0, t_start = x.copy(), t
                    stop = brentq(lambda s: at(x0, v, held, s - t_start)[0], t, b,
                                  xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
                    zero = True
            while k < len(times) and times[k] <= stop:
                out[k] = at(x, v, held, times[k] - t)
                k += 1
            x = at(x, v, held, stop - t)
            t = stop
            if zero:
                x[0] = 0.0
                events.append(stop)
        if j is not None:
            on[j] = value == 1
            events.append(b)
    while k < len(times):
        out[k] = x
        k += 1
    return out, events


# ---------------------------------------------------------------- the methods

def run_bgc(exe, rtol, t_end, dt):
    args = [str(exe), "--rtol", repr(rtol), "--atol", repr(rtol * ATOL_RATIO), "--stats",
            "--max-steps", "0", "--t-end", repr(t_end)]
    full = subprocess.run(args + ["--dt", repr(dt)], capture_output=True, text=True, check=True)
    return read_csv(full.stdout), parse_stats(full.stderr), args + ["--dt", repr(t_end)]


def run_cvode(exe, method, rtol, t_end, dt, p):
    tail = [repr(p[k]) for k in ("V", "f", "duty", "dead", "R", "L", "k", "J", "b")]
    args = [str(exe), method, repr(rtol), repr(rtol * ATOL_RATIO), repr(t_end)]
    full = subprocess.run(args + [repr(dt)] + tail, capture_output=True, text=True, check=True)
    t, Y = read_csv(full.stdout)  # (motor.ind.p, motor.rotor.p): L i and J w
    return (t, Y / np.array([p["L"], p["J"]])), parse_stats(full.stderr), \
        args + [repr(t_end)] + tail


def run_scipy(rtol, t_end, dt, p):
    """solve_ivp per mode from event to event, on the momenta (L i, J w); returns the rows
    (i, w), the counters, and the time."""
    from scipy.integrate import solve_ivp
    M = np.diag([p["L"], p["J"]])
    Minv = np.diag([1.0 / p["L"], 1.0 / p["J"]])
    grid = np.arange(0, round(t_end / dt) + 1) * dt
    t0 = time.process_time()
    y, t, k = np.zeros(2), 0.0, 0
    on = [0.0 >= w0 for _, _, w0 in waves(p)]
    out = np.empty((len(grid), 2))
    nfev = steps = events = 0

    def current(t, y):
        return y[0]
    current.terminal = True
    for b, j, value in edges(p, t_end) + [(t_end, None, None)]:
        while t < b:
            v, held = bridge_voltage(p, on, y[0])
            A, g = _system(p, v, held)
            Ap, gp = M @ A @ Minv, M @ g
            dead = not on[0] and not on[1] and not held
            current.direction = -1.0 if y[0] > 0.0 else 1.0
            sol = solve_ivp(lambda s, z: Ap @ z + gp, (t, b), y, method="RK45", rtol=rtol,
                            atol=rtol * ATOL_RATIO, dense_output=True,
                            events=current if dead else None)
            nfev += sol.nfev
            steps += len(sol.t) - 1
            end = sol.t[-1]
            while k < len(grid) and grid[k] <= end:
                out[k] = Minv @ sol.sol(grid[k])
                k += 1
            y, t = sol.y[:, -1].copy(), end
            if sol.status == 1:  # the current reaches zero: held there
                y[0] = 0.0
                events += 1
        if j is not None:
            on[j] = value == 1
            events += 1
    cpu = (time.process_time() - t0) * 1e3
    out[k:] = Minv @ y
    return (grid, out), {"steps": steps, "rhs": nfev, "events": events}, cpu


def error_of(t, Y, reference, p, t_end, scale):
    """max |y - y_ref| / max |y_ref| per column (the motor's current and speed), the larger;
    the reference of the output grid `reference` = (times, rows), marched again where a
    method's times differ from them."""
    t_ref, ref = reference
    if len(t) != len(t_ref) or not np.array_equal(t, t_ref):
        ref, _ = exact(p, t_end, t)
    return float(np.max(np.abs(Y - ref).max(axis=0) / scale))


# ---------------------------------------------------------------- the table

def build(work):
    """The generated program and the CVODE baseline (None where SUNDIALS is missing)."""
    import bgc
    (_, text), = bgc.compile(MODEL, target="c", scene="run").items()
    src = work / "hbridge.c"
    src.write_text(text)
    exe = work / "hbridge"
    subprocess.run([*c_compiler(), *CFLAGS, str(src), "-o", str(exe), "-lm"], check=True)
    cv = work / "cvode_hbridge"
    built = subprocess.run([*c_compiler(), *CFLAGS, str(HERE / "cvode_hbridge.c"), "-o",
                            str(cv), *SUNDIALS_LIBS, "-lm"], capture_output=True, text=True)
    if built.returncode != 0:
        print(f"# CVODE-C not built (needs libsundials-dev): {built.stderr.strip()[:200]}")
        cv = None
    return exe, cv


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    p = dict(HBRIDGE)
    t_end = 1e-3 if args.quick else 1e-2
    dt = 1e-6
    work = Path(tempfile.mkdtemp(prefix="bgc-hbridge-"))
    try:
        print(f"# H-bridge drive, {p['f'] / 1e3:g} kHz, duty {p['duty']:g}, dead {p['dead']:g}, "
              f"0 .. {t_end:g} s ({len(edges(p, t_end))} edges); {machine.processor()}; "
              f"load {machine.load_average()}")
        exe, cv = build(work)
        t_ref = np.arange(0, round(t_end / dt) + 1) * dt
        ref, events = exact(p, t_end, t_ref)
        print(f"# the exact solution: {len(events)} events, i(end) = {ref[-1, 0]:.6g} A, "
              f"w(end) = {ref[-1, 1]:.6g} rad/s, min i = {ref[:, 0].min():.3g} A")
        scale = np.max(np.abs(ref), axis=0)
        rows, by_method = table(args, p, t_end, dt, exe, cv, (t_ref, ref), scale)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print_table(rows, by_method)
    return 0


def table(args, p, t_end, dt, exe, cv, reference, scale):
    """Every method at every tolerance: the rows (method, rtol, steps, rhs, events, error,
    cpu) and each method's (error, cpu) pairs."""
    rows, by_method = [], {}

    def add(label, rtol, st, err, cpu):
        rows.append((label, rtol, st.get("steps"), st.get("rhs"), st.get("events"), err, cpu))
        by_method.setdefault(label, []).append((err, cpu))

    for rtol in [10.0 ** -k for k in range(4, 12 if not args.quick else 10)]:
        (t, Y), st, quiet = run_bgc(exe, rtol, t_end, dt)
        add("bgc C dopri5", rtol, st, error_of(t, Y, reference, p, t_end, scale),
            timed(quiet, args.repeats, None))
        for method in ("bdf", "adams") if cv is not None else ():
            (t, Y), st, quiet = run_cvode(cv, method, rtol, t_end, dt, p)
            label = f"CVODE-C {'BDF' if method == 'bdf' else 'Adams'} root"
            add(label, rtol, st, error_of(t, Y, reference, p, t_end, scale),
                timed(quiet, args.repeats, None))
        if rtol >= 1e-8:  # (SciPy's restarts make its tight runs minutes long)
            (t, Y), st, cpu = run_scipy(rtol, t_end, dt, p)
            add("SciPy RK45 events", rtol, st, error_of(t, Y, reference, p, t_end, scale), cpu)
    return rows, by_method


if __name__ == "__main__":
    sys.exit(main())
