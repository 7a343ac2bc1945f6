"""The solvers' work-precision benchmark: bgc's solvers in the generated C program beside SciPy
and SUNDIALS CVODE, on a non-stiff, a linear stiff and a nonlinear stiff problem, in one run.

    python benchmarks/solvers.py [--quick] [--repeats N] [--plot-dir DIR] [--only KEYS]
                                 [--per-decade N]

Problems (each model's header gives its equations and closed form or reference): pendulum
(models/pendulum.bg, scene long over 0..10 s; columns x, y; reference SciPy's DOP853 at
rtol = atol = 1e-13), rc_pair (models/rc_pair.bg, scene step; c1.e, c2.e; the closed form
rc_exact), vdp_1e3 and vdp_1e5 (models/van_der_pol.bg, scene period, mu = 1e3 and -p mu=1e5;
cap.q = y1, ind.p = y2; SciPy's Radau at rtol = atol = 1e-12 with the analytic Jacobian).
Adaptive methods run a sweep of rtol with atol = rtol/1000 (tests/test_stiff.py's ratio; one
rtol a decade, or N with --per-decade N: 1e-6, 5.6e-7, 3.2e-7, 1.8e-7, 1e-7 for 4), euler
and rk4 a sweep of steps: bgc's in the C program of `bgc.compile(target="c")` built with cc -O2
(`./model --solver NAME --rtol R --atol A --t-end T [-p mu=1e5] --stats --max-steps 0`);
SciPy's solve_ivp (RK45, DOP853, Radau, BDF, LSODA; the implicit ones with the analytic
Jacobian) and CVODE's BDF through scikit-sundae (analytic Jacobian, dense solver) on numpy
right sides written from the same equations (the pendulum's and its Jacobian by SymPy from
eq. 12); a missing scipy or sksundae is reported "not installed".  Explicit methods are not
run where stability alone costs millions of steps; the table gives the estimate: the integral
of rho(J(y_ref(t))) dt over r, rho the Jacobian's spectral radius, r the method's real
stability boundary (from its tableau).  On the stiff problems also CVODE's BDF driven from C
(benchmarks/cvode_stiff.c, built against the system's SUNDIALS: the right sides and Jacobians
written by hand in C, the dense solver, no Python in the loop).

Columns:
  method   bgc NAME: the C program with --solver NAME;  SciPy NAME: solve_ivp(method=NAME);
           CVODE BDF: sksundae.cvode.CVODE(method="BDF");  CVODE-C BDF: cvode_stiff.c.
  rtol     the relative tolerance (two digits), or h=H: the step of a fixed-step method.
  steps    accepted steps;  rej: rejected steps ("-": the solver does not report them).
  rhs      right-side calls of the timed run (bgc: the 2-row run, without dense-output calls;
           SciPy, CVODE: nfev of a run that keeps only its own steps).
  jac, lu  Jacobian evaluations, LU factorisations (SciPy: njev, nlu; CVODE: njev, no LU count).
  error    max over the output grid of |y - y_ref| / max(1, max|y_ref|), each column over its
           own scale (its largest |value| on the grid), the largest over the columns; from a run
           writing every row (bgc's CSV, SciPy's t_eval, CVODE's tspan), which takes the same
           steps as the timed run (outputs are interpolated).
  wall, cpu  median ms of the integration over the rounds after a warm-up.  C program: its run
           writing 2 rows (--dt t_end) less the median of /bin/true (a process start), both timed
           from Python in the same rounds (cpu: the child's user + system time), so a run much
           shorter than the spread of a process start can come out negative.  SciPy, CVODE: the
           call in this process.  Each round runs every measurement in turn (short C runs and
           /bin/true ten times), so a change of load hits all alike.
  prog     the C program's own clock() around its integration (cpu= in its stats line), median:
           no process start at all ("-" if the program does not print it); CVODE-C's the
           same (its driver's clock() from CVodeInit to its last row).
Below each table, "at equal error": each method's time and steps at one error level, linear in
log time (log steps) against log error along its runs sorted by error; the level is the one
inside most methods' ranges of error (the tightest of equals), a method whose range misses it
shows its nearest run.  Time there, in the goals and in the plots is prog where the program
prints it, else cpu.  Last, each goal of the issue: "goal: ... measured: ... (met / NOT MET)";
the goals at equal error give, per bgc solver, the worst and best ratio over its runs inside the
baseline's range of error (the verdict is on the worst) and their geometric mean.
Times are printed, never asserted.
"""
from __future__ import annotations

import argparse
import datetime
import importlib.util
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]  # machine.py and pendulum.py beside this file, bgc above
import machine  # noqa: E402
from pendulum import CFLAGS, PARAMS, c_compiler, compile_c, cpu_seconds  # noqa: E402

from bgc.base import solvers  # noqa: E402

ATOL_RATIO = 1e-3
EXPLICIT = [s.name for s in solvers.SOLVER_LIST if s.family in ("fixed", "erk")]
STIFF = [s.name for s in solvers.SOLVER_LIST if s.uses_jacobian]  # rodas4 .. radau, auto
SCIPY_EXPLICIT = {"RK45": "dopri5", "DOP853": "dop853"}  # the same pairs as bgc's
IMPLICIT = ("Radau", "BDF", "LSODA")
CVODE_C_LIBS = ("-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense",
                "-lsundials_sunmatrixdense")
RC = {"V0": 1.0, "R1": 1e-6, "C1": 1.0, "R2": 1.0, "C2": 1.0}  # as in models/rc_pair.bg


def tol_text(tol: float) -> str:
    """1e-06, 5.6e-07: one digit where it is exact, else two."""
    return f"{tol:.0e}" if float(f"{tol:.0e}") == tol else f"{tol:.1e}"


def decades(first: int, last: int, per: int = 1) -> list[float]:
    """10^-first .. 10^-last, `per` values a decade (to three digits; each power of ten exact)."""
    return [float(f"{10.0 ** (-k / per):.3g}") for k in range(first * per, last * per + 1)]


@dataclass
class Row:
    method: str
    setting: str
    rtol: float | None = None
    steps: int | None = None
    rejected: int | None = None
    rhs: int | None = None
    jac: int | None = None
    lu: int | None = None
    error: float | None = None
    wall: float | None = None  # seconds of integration, medians
    cpu: float | None = None
    prog: float | None = None  # the C program's own clock
    note: str = ""

    @property
    def time(self) -> float | None:
        """The C program's own clock if it prints one, else the cpu time if positive."""
        return self.prog if self.prog is not None else (self.cpu if self.cpu and self.cpu > 0
                                                         else None)


@dataclass
class Job:
    """A timed action; `c`: a C program run (stats on stderr, a process start subtracted)."""
    row: Row
    action: Callable
    c: bool = False
    per_round: int = 1
    walls: list = field(default_factory=list)
    cpus: list = field(default_factory=list)
    progs: list = field(default_factory=list)


@dataclass
class Problem:
    key: str
    title: str
    model: str
    scene: str
    t_end: float
    dt: float
    outputs: tuple  # the CSV columns compared ...
    compared: tuple  # ... and the states of the baselines they are
    system: tuple  # (f(t, y), jac(t, y), y0) in numpy, for the baselines
    bgc: dict  # solver -> rtols, or ("h", steps) for a fixed-step solver
    baselines: dict  # "SciPy RK45" ... "CVODE BDF" -> rtols
    reference: Callable  # grid -> the states there; it may set ref_note
    ref_note: str = ""
    params: dict = field(default_factory=dict)  # -p overrides
    stiff: bool = False


# ---------------------------------------------------------------- right sides and references

def pendulum_system():
    """Eq. (12) with pendulum.py's parameters, s = (px, py, x, y): f(t, s) and its Jacobian, by
    sympy.lambdify from the same expressions, and s(0)."""
    import sympy as sp

    px, py, x, y, t = sp.symbols("px py x y t")
    m, l, g, alpha, beta = (sp.Float(PARAMS[k]) for k in ("m", "l", "g", "alpha", "beta"))
    xd, yd = px / m, py / m
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    rhs = sp.Matrix([-m * x / (x**2 + y**2) * bracket,
                     m * (g - y / (x**2 + y**2) * bracket), xd, yd])
    s = (px, py, x, y)
    f = sp.lambdify((t, s), list(rhs), modules="math", cse=True)
    jac = sp.lambdify((t, s), rhs.jacobian(s).tolist(), modules="math", cse=True)
    theta0, length = PARAMS["theta0"], PARAMS["l"]
    return f, jac, (0.0, 0.0, length * math.sin(theta0), length * math.cos(theta0))


def rc_matrix() -> tuple[np.ndarray, np.ndarray]:
    """v' = A v + b of models/rc_pair.bg, v the two capacitor voltages (= charges: C = 1 F)."""
    a, b, d = 1 / (RC["R1"] * RC["C1"]), 1 / (RC["R2"] * RC["C1"]), 1 / (RC["R2"] * RC["C2"])
    return np.array([[-(a + b), b], [d, -d]]), np.array([RC["V0"] * a, 0.0])


def rc_exact(t: np.ndarray) -> np.ndarray:
    """The closed form v = v_inf + sum_k c_k u_k exp(lambda_k t), c from v(0) = 0, with no
    cancellation: the eigenvalues as roots of the characteristic polynomial, the small one as
    det / the large one; the fast eigenvector (lambda_0 - A11, A10), the slow (A01,
    lambda_1 - A00)."""
    A, b = rc_matrix()
    tr, det = A[0, 0] + A[1, 1], A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    big = (tr - math.sqrt(tr * tr - 4 * det)) / 2  # tr < 0: a sum of two negatives
    lam = np.array([big, det / big])
    U = np.array([[lam[0] - A[1, 1], A[0, 1]], [A[1, 0], lam[1] - A[0, 0]]])
    v_inf = np.linalg.solve(A, -b)
    return v_inf + (np.exp(np.outer(t, lam)) * np.linalg.solve(U, -v_inf)) @ U.T


def rc_system():
    A, b = rc_matrix()
    (a00, a01), (a10, a11) = A

    def f(t, v):
        return np.array([a00 * v[0] + a01 * v[1] + b[0], a10 * v[0] + a11 * v[1]])

    return f, lambda t, v: A, (0.0, 0.0)


def vdp_system(mu: float):
    """Hairer's scaled Van der Pol, eps = 1/mu^2: y1' = y2, eps y2' = (1 - y1^2) y2 - y1."""
    eps = 1 / mu**2

    def f(t, y):
        return np.array([y[1], ((1 - y[0] ** 2) * y[1] - y[0]) / eps])

    def jac(t, y):
        return np.array([[0.0, 1.0], [(-2 * y[0] * y[1] - 1) / eps, (1 - y[0] ** 2) / eps]])

    return f, jac, (2.0, -2 / 3 + 10 / 81 * eps)


def scipy_reference(method: str, tol: float, check: bool) -> Callable:
    """(problem, grid) -> solve_ivp at rtol = atol = tol on the grid; with `check`, the note
    says how far the same at 10 tol is from it."""
    def reference(problem: Problem, grid: np.ndarray) -> np.ndarray:
        from scipy.integrate import solve_ivp

        f, jac, y0 = problem.system
        kw = {"jac": jac} if method in IMPLICIT else {}
        sols = [solve_ivp(f, (0.0, problem.t_end), y0, method=method, t_eval=grid, rtol=r,
                          atol=r, **kw) for r in ((tol, 10 * tol) if check else (tol,))]
        if not all(s.success for s in sols):
            raise RuntimeError(f"reference failed: {sols[0].message}")
        problem.ref_note = f"{method} rtol=atol={tol:g} ({sols[0].nfev} rhs calls)"
        if check:
            problem.ref_note += (f"; {method} at {10 * tol:g} differs from it by "
                                 f"{scaled_error(sols[1].y.T, sols[0].y.T):.1e}")
        return sols[0].y.T

    return reference


def scaled_error(Y: np.ndarray, ref: np.ndarray) -> float:
    scale = np.maximum(1.0, np.max(np.abs(ref), axis=0))
    return float(np.max(np.max(np.abs(Y - ref), axis=0) / scale))


def stability_boundary(name: str) -> float:
    """r with |R(-r)| = 1 first, R(z) = sum_k z^k b.A^(k-1).1 the explicit method's stability
    polynomial (A strictly lower triangular)."""
    tab = solvers.get(name).tableau
    n = len(tab.b)
    A = np.zeros((n, n))
    for i, row in enumerate(tab.a[:n]):
        A[i, :len(row)] = [float(v) for v in row]
    b, power, coeffs = np.array([float(v) for v in tab.b]), np.ones(n), [1.0]
    for _ in range(n):
        coeffs.append(float(b @ power))
        power = A @ power
    z = np.arange(1e-3, 40.0, 1e-3)
    return float(z[np.argmax(np.abs(np.polyval(coeffs[::-1], -z)) > 1.0)])


def explicit_estimate(problem: Problem, grid: np.ndarray, ref: np.ndarray, r: float) -> float:
    jac = problem.system[1]
    rho = [np.max(np.abs(np.linalg.eigvals(jac(t, y)))) for t, y in zip(grid, ref)]
    return float(np.trapezoid(rho, grid)) / r


def problems(quick: bool, per: int = 1) -> list[Problem]:
    adaptive = [1e-4, 1e-7, 1e-10] if quick else decades(3, 10, per)
    steps = {"euler": [1e-3, 1e-4, 1e-5]}  # rk4: steps dividing dt
    every = ("SciPy RK45", "SciPy DOP853", "SciPy Radau", "SciPy BDF", "SciPy LSODA",
             "CVODE BDF")
    pendulum = Problem(
        "pendulum", "Baumgarte pendulum, eq. (12), 0..10 s", "pendulum.bg", "long", 10.0, 0.01,
        ("x", "y"), (2, 3), pendulum_system(),
        {s.name: ("h", steps.get(s.name, [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4]))
         if s.family == "fixed" else adaptive for s in solvers.SOLVER_LIST},
        {name: adaptive for name in every}, scipy_reference("DOP853", 1e-13, not quick))
    sweep = [1e-3, 1e-6] if quick else decades(2, 8, per)
    rc = Problem(
        "rc_pair", "stiff RC pair, tau 1e-6 s and 1 s, 0..5 s", "rc_pair.bg", "step", 5.0, 0.05,
        ("c1.e", "c2.e"), (0, 1), rc_system(), {**{s: sweep for s in STIFF}, "dopri5": [1e-6]},
        {name: sweep for name in (*every[2:], "CVODE-C BDF")},
        lambda problem, grid: rc_exact(grid),
        "the closed form (eigenpairs of the 2x2 matrix)", stiff=True)
    out = [pendulum, rc]
    for mu, explicit in ((1e3, {"dopri5": [1e-6], "dop853": [1e-6]}), (1e5, {})):
        sweep = [1e-3, 1e-6, 1e-9] if quick else decades(3, 9, per)
        out.append(Problem(
            f"vdp_1e{round(math.log10(mu))}", f"Van der Pol, mu = 1e{round(math.log10(mu))}, "
            "0..2 (scaled time)", "van_der_pol.bg", "period", 2.0, 0.02, ("cap.q", "ind.p"),
            (0, 1), vdp_system(mu), {**{s: sweep for s in STIFF}, **explicit},
            {name: sweep for name in (*every[2:], "CVODE-C BDF")},
            scipy_reference("Radau", 1e-11 if quick else 1e-12, not quick),
            params={"mu": mu}, stiff=True))
    return out


# ---------------------------------------------------------------- runs

def grid_of(problem: Problem) -> np.ndarray:
    """t0 + k dt while below t_end (within 1e-6 dt), then t_end: the programs' output grid."""
    n = int(math.ceil(problem.t_end / problem.dt - 1e-6))
    return np.append(np.arange(n) * problem.dt, problem.t_end)


def parse_stats(stderr: str) -> dict:
    line = next((ln for ln in stderr.splitlines() if ln.startswith("stats:")), "stats:")
    return {k: float(v) for k, v in (part.split("=", 1) for part in line.split()[1:])}


def failed(row: Row, message: str) -> tuple[Row, None]:
    lines = str(message).strip().splitlines()
    row.note += f"FAILED: {lines[-1] if lines else '?'}; "
    return row, None


def bgc_program(problem: Problem, workdir: Path) -> Path:
    import bgc

    exe = workdir / Path(problem.model).stem
    if not exe.exists():
        (name, text), = bgc.compile(str(ROOT / "models" / problem.model), target="c",
                                    scene=problem.scene).items()
        (workdir / name).write_text(text, encoding="utf-8")
        compile_c(workdir / name, exe)
    return exe


def first_run(job: Job) -> tuple[object, Job]:
    """The warm-up: its result, and short C runs set to ten runs a round."""
    start = time.perf_counter()
    result = job.action()
    job.per_round = 10 if job.c and time.perf_counter() - start < 0.02 else 1
    return result, job


def bgc_run(problem: Problem, exe: Path, ref, solver: str, setting) -> tuple[Row, Job | None]:
    fixed = isinstance(setting, tuple)
    row = Row(f"bgc {solver}", f"h={setting[1]:g}" if fixed else tol_text(setting),
              None if fixed else setting)
    args = [str(exe), "--solver", solver, "--t-end", repr(problem.t_end), "--stats",
            "--max-steps", "0"]  # no step budget: explicit runs on stiff problems take millions
    args += ["--step", repr(setting[1])] if fixed else [
        "--rtol", repr(setting), "--atol", repr(setting * ATOL_RATIO)]
    for name, value in problem.params.items():
        args += ["-p", f"{name}={value!r}"]
    full = subprocess.run([*args, "--dt", repr(problem.dt)], capture_output=True, text=True)
    if full.returncode != 0:
        return failed(row, full.stderr)
    header, *lines = full.stdout.splitlines()
    columns = [header.split(",").index(name) for name in problem.outputs]
    if ref is not None:
        data = np.loadtxt(lines, delimiter=",", ndmin=2)
        row.error = scaled_error(data[:, columns], ref[:, problem.compared])
    quiet = [*args, "--dt", repr(problem.t_end)]
    done, job = first_run(Job(row, lambda: subprocess.run(
        quiet, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True), c=True))
    if done.returncode != 0:
        return failed(row, done.stderr)
    stats = parse_stats(done.stderr)
    for key in ("steps", "rejected", "rhs", "jac", "lu"):
        setattr(row, key, int(stats[key]) if key in stats else None)
    if stats.get("steps") != parse_stats(full.stderr).get("steps"):
        row.note += "the full-grid run takes other steps; "
    if "stiff_from" in stats:
        row.note += f"stiff from t = {stats['stiff_from']:.2g}; "
    return row, job


def cvode_c(workdir: Path) -> tuple[Path | None, str]:
    """benchmarks/cvode_stiff.c built in workdir (once), or None and why not."""
    exe = workdir / "cvode_stiff"
    if exe.exists():
        return exe, ""
    cmd = [*c_compiler(), *CFLAGS, str(HERE / "cvode_stiff.c"), "-o", str(exe),
           *CVODE_C_LIBS, "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        return None, ("cannot build cvode_stiff.c against SUNDIALS ("
                      f"{(done.stderr.strip().splitlines() or ['?'])[0]})")
    return exe, ""


def cvode_c_run(problem: Problem, ref, exe: Path, rtol: float) -> tuple[Row, Job | None]:
    """CVODE driven from C: the full-grid run for the error, the 2-row run timed."""
    row = Row("CVODE-C BDF", tol_text(rtol), rtol)
    args = [str(exe), "vdp" if problem.key.startswith("vdp") else "rc",
            repr(problem.params.get("mu", 1e3)), repr(rtol), repr(rtol * ATOL_RATIO),
            repr(problem.t_end)]
    full = subprocess.run([*args, repr(problem.dt)], capture_output=True, text=True)
    if full.returncode != 0:
        return failed(row, full.stderr)
    if ref is not None:
        data = np.loadtxt(full.stdout.splitlines()[1:], delimiter=",", ndmin=2)
        row.error = scaled_error(data[:, 1:3][:, problem.compared], ref[:, problem.compared])
    done, job = first_run(Job(row, lambda: subprocess.run(
        [*args, repr(problem.t_end)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True), c=True))
    if done.returncode != 0:
        return failed(row, done.stderr)
    stats = parse_stats(done.stderr)
    for key in ("steps", "rejected", "rhs", "jac", "lu"):
        setattr(row, key, int(stats[key]) if key in stats else None)
    return row, job


def baseline_run(problem: Problem, ref, grid, name: str, rtol: float,
                 workdir: Path) -> tuple[Row, Job | None]:
    if name == "CVODE-C BDF":
        return cvode_c_run(problem, ref, cvode_c(workdir)[0], rtol)
    row = Row(name, tol_text(rtol), rtol)
    f, jac, y0 = problem.system
    tol = {"rtol": rtol, "atol": rtol * ATOL_RATIO}
    if name.startswith("CVODE"):
        from sksundae.cvode import CVODE

        def rhs(t, y, yp):
            yp[:] = f(t, y)

        def jacfn(t, y, yp, JJ):
            JJ[:, :] = jac(t, y)

        def solve(tspan):  # tspan (t0, t_end): the solver's own steps, else these times
            return CVODE(rhs, method="BDF", jacfn=jacfn, max_num_steps=10**8, **tol).solve(
                np.array(tspan), np.array(y0))

        action, states = (lambda: solve([0.0, problem.t_end])), (lambda: solve(grid).y)
    else:
        from scipy.integrate import solve_ivp

        def solve(t_eval=None):
            kw = {"jac": jac} if name.split()[1] in IMPLICIT else {}
            return solve_ivp(f, (0.0, problem.t_end), y0, method=name.split()[1],
                             t_eval=t_eval, **tol, **kw)

        action, states = solve, (lambda: solve(grid).y.T)
    with warnings.catch_warnings():  # LSODA's failures warn too: the table says FAILED
        warnings.simplefilter("ignore", UserWarning)
        sol, job = first_run(Job(row, action))
    if not sol.success:
        return failed(row, sol.message)
    row.steps, row.rhs = len(sol.t) - 1, sol.nfev
    if name.split()[-1] in IMPLICIT:
        row.jac, row.lu = sol.njev, getattr(sol, "nlu", None)
    if ref is not None:
        row.error = scaled_error(states()[:, problem.compared], ref[:, problem.compared])
    return row, job


def measure(jobs: list[Job], spawn: Job, repeats: int) -> None:
    """Medians over `repeats` rounds, each running every job (per_round times) in turn; a C
    run's time less the median process start."""
    for _ in range(repeats):
        for job in [spawn, *jobs]:
            for _ in range(job.per_round):
                cpu0, start = cpu_seconds(), time.perf_counter()
                done = job.action()
                job.walls.append(time.perf_counter() - start)
                job.cpus.append(cpu_seconds() - cpu0)
                if job.c and "cpu" in (stats := parse_stats(done.stderr)):
                    job.progs.append(stats["cpu"])
    spawn.row.wall, spawn.row.cpu = statistics.median(spawn.walls), statistics.median(spawn.cpus)
    for job in jobs:
        job.row.wall = statistics.median(job.walls) - (spawn.row.wall if job.c else 0.0)
        job.row.cpu = statistics.median(job.cpus) - (spawn.row.cpu if job.c else 0.0)
        job.row.prog = statistics.median(job.progs) if job.progs else None
    spawn.walls.clear(), spawn.cpus.clear()


def missing(name: str, workdir: Path) -> str | None:
    """None if the baseline's package is installed (CVODE-C: its driver builds), else why
    not."""
    if name == "CVODE-C BDF":
        return cvode_c(workdir)[1] or None
    module = "sksundae" if name.startswith("CVODE") else "scipy"
    return None if importlib.util.find_spec(module) else f"{module} not installed"


def run_problem(problem: Problem, workdir: Path, spawn: Job, repeats: int):
    """(rows, [(method, why not run)]) of one problem, every run timed."""
    grid, skipped, ref = grid_of(problem), [], None
    try:
        ref = problem.reference(problem, grid)
    except ImportError as exc:
        problem.ref_note = f"none ({exc.name} not installed): no errors"
    runs, exe = [], bgc_program(problem, workdir)
    for solver, settings in problem.bgc.items():
        fixed = isinstance(settings, tuple)
        for setting in settings[1] if fixed else settings:
            runs.append(bgc_run(problem, exe, ref, solver, ("h", setting) if fixed else setting))
    for name, rtols in problem.baselines.items():
        if why := missing(name, workdir):
            skipped.append((name, why))
        else:
            runs += [baseline_run(problem, ref, grid, name, rtol, workdir) for rtol in rtols]
    rows, jobs = [r for r, _ in runs], [j for _, j in runs if j]
    if problem.stiff and ref is not None:
        explicit = [f"bgc {m}" for m in EXPLICIT] + [f"SciPy {m}" for m in SCIPY_EXPLICIT]
        for name in (n for n in explicit if n not in {r.method for r in rows}):
            r = stability_boundary(SCIPY_EXPLICIT.get(name[6:], name[4:]))
            skipped.append((name, f"explicit: stability alone needs about "
                                  f"{explicit_estimate(problem, grid, ref, r):.1e} steps "
                                  f"(integral of rho(J) dt / {r:.3g})"))
    measure(jobs, spawn, repeats)
    return rows, skipped


# ---------------------------------------------------------------- equal error, goals

def curve(rows: list[Row], method: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    """(log error, log key) of a method's runs, sorted by error."""
    pts = sorted((r.error, getattr(r, key)) for r in rows
                 if r.method == method and r.error and getattr(r, key))
    return np.log([p[0] for p in pts]), np.log([p[1] for p in pts])


def at_error(rows, method: str, key: str, error: float, extrapolate=False) -> float | None:
    """The method's `key` at `error`, interpolated in log-log; None outside its runs' range,
    unless `extrapolate`: then along the line through its two most accurate runs."""
    x, y = curve(rows, method, key)
    e = math.log(error)
    if len(x) and x[0] - 1e-9 <= e <= x[-1] + 1e-9:
        return float(math.exp(np.interp(e, x, y)))
    if extrapolate and len(x) >= 2 and e < x[0]:
        return float(math.exp(y[0] + (y[1] - y[0]) / (x[1] - x[0]) * (e - x[0])))
    return None


def equal_error(rows: list[Row]) -> list[str]:
    methods = list(dict.fromkeys(r.method for r in rows))
    curves = {m: curve(rows, m, "time")[0] for m in methods}
    ends = sorted({e for c in curves.values() if len(c) >= 2 for e in (c[0], c[-1])})
    if not ends:
        return []
    inside = lambda c, e: len(c) >= 2 and c[0] - 1e-9 <= e <= c[-1] + 1e-9  # noqa: E731
    level = max(ends, key=lambda e: (sum(inside(c, e) for c in curves.values()), -e))
    cells = []
    for m in methods:
        if inside(curves[m], level):
            t = at_error(rows, m, "time", math.exp(level))
            cells.append((t, f"{m} {ms(t)} {at_error(rows, m, 'steps', math.exp(level)):.0f} "
                             "steps"))
        elif mine := [r for r in rows if r.method == m and r.error and r.time]:
            r = min(mine, key=lambda r: abs(math.log(r.error) - level))
            cells.append((r.time, f"{m} {ms(r.time)} {r.steps} steps (nearest: its run at "
                                   f"{r.error:.1e})"))
    return [f"at equal error {math.exp(level):.1e} (fastest first):"] + [
        "  " + text for _, text in sorted(cells)]


def ms(seconds: float | None) -> str:
    return "n/a" if seconds is None else f"{seconds * 1e3:.3g} ms"


def find(rows: list[Row], method: str, rtol: float) -> Row | None:
    return next((r for r in rows if r.method == method and r.rtol == rtol), None)


def goal(text: str, measured: str, ok: bool | None) -> str:
    verdict = "n/a" if ok is None else "met" if ok else "NOT MET"
    return f"goal: {text}; measured: {measured} ({verdict})"


def goals(results: dict) -> list[str]:
    rc, vdp, pend = (results.get(k, []) for k in ("rc_pair", "vdp_1e5", "pendulum"))
    stiff = [f"bgc {m}" for m in STIFF]
    picked = {m: find(rc, m, 1e-6) for m in stiff}
    have = all(r and r.error is not None and r.time for r in picked.values())
    cv, cvc = find(rc, "CVODE BDF", 1e-6), find(rc, "CVODE-C BDF", 1e-6)
    out = [goal("RC pair at rtol 1e-6, each stiff solver within 1e-5 of the closed form in under "
                "150 steps", ", ".join(f"{m[4:]} {r.error:.1e} in {r.steps} steps" if r and
                                       r.error is not None else f"{m[4:]} n/a"
                                       for m, r in picked.items()),
                None if not have else all(r.error <= 1e-5 and r.steps < 150
                                          for r in picked.values())),
           goal("RC pair at rtol 1e-6, the generated C faster than CVODE",
                ", ".join(f"{m[4:]} {ms(r and r.time)}" for m, r in picked.items()) +
                f" vs CVODE {ms(cv and cv.time)}",
                None if not (have and cv and cv.time) else
                all(r.time < cv.time for r in picked.values())),
           goal("RC pair at rtol 1e-6, the generated C faster than CVODE driven from C",
                ", ".join(f"{m[4:]} {ms(r and r.time)}" for m, r in picked.items()) +
                f" vs CVODE-C {ms(cvc and cvc.time)}",
                None if not (have and cvc and cvc.time) else
                all(r.time < cvc.time for r in picked.values()))]
    checks = {"steps no more than SciPy Radau's": (1.0, []), "at least 20x faster than the "
              "fastest SciPy method": (20.0, []), "at least as fast as CVODE": (1.0, []),
              "at least as fast as CVODE driven from C": (1.0, [])}
    for r in (r for r in vdp if r.method in stiff and r.error and r.time):
        radau = at_error(vdp, "SciPy Radau", "steps", r.error)
        scipy = [t for n in ("SciPy Radau", "SciPy BDF", "SciPy LSODA")
                 if (t := at_error(vdp, n, "time", r.error))]
        cvode = at_error(vdp, "CVODE BDF", "time", r.error)
        cvode_c = at_error(vdp, "CVODE-C BDF", "time", r.error)
        for (_, pairs), value in zip(checks.values(), (radau and radau / r.steps,
                                                       scipy and min(scipy) / r.time,
                                                       cvode and cvode / r.time,
                                                       cvode_c and cvode_c / r.time)):
            pairs += [(r.method, value)] if value else []
    for what, (bar, pairs) in checks.items():
        ratios = {m: [v for n, v in pairs if n == m] for m in stiff}
        measured = ", ".join(f"{m[4:]} " + (f"{min(v):.3g}x..{max(v):.3g}x "
                                            f"({math.exp(np.mean(np.log(v))):.3g}x)"
                                            if v else "n/a") for m, v in ratios.items())
        text = (f"Van der Pol mu = 1e5 at equal error, bgc's stiff solvers {what} (the "
                "baseline's over bgc's, worst..best over the runs of each in the baseline's "
                "range of error; geometric mean)")
        met = [m[4:] for m, v in ratios.items() if v and min(v) >= bar]
        if all(ratios.values()) and met and len(met) < len(ratios):  # say which
            out.append(f"goal: {text}; measured: {measured} (met by {', '.join(met)}; NOT MET "
                       f"by {', '.join(m[4:] for m in ratios if m[4:] not in met)})")
            continue
        out.append(goal(text, measured, None if not all(ratios.values()) else
                        min(min(v) for v in ratios.values()) >= bar))
    slowest = {m: max((r.time for r in vdp if r.method == m and r.time), default=None)
               for m in stiff}
    out.append(goal("Van der Pol mu = 1e5, each stiff solver under 1 s (its slowest run)",
                    ", ".join(f"{m[4:]} {ms(v)}" for m, v in slowest.items()),
                    None if None in slowest.values() else max(slowest.values()) < 1.0))
    d8, d5, how = find(pend, "bgc dop853", 1e-10), None, ""
    if d8 and d8.error:
        d5 = at_error(pend, "bgc dopri5", "rhs", d8.error)
        if d5 is None and (d5 := at_error(pend, "bgc dopri5", "rhs", d8.error, True)):
            how = " (extrapolated along dopri5's two most accurate runs)"
    out.append(goal("pendulum at rtol 1e-10, dop853 at most half of dopri5's rhs calls at the "
                    "same error", "n/a" if not d5 else
                    f"{d8.rhs} vs {d5:.0f} at {d8.error:.1e}{how}: {d8.rhs / d5:.2f}x",
                    None if not d5 else d8.rhs / d5 <= 0.5))
    return out


# ---------------------------------------------------------------- reporting

def fmt(value, spec: str, width: int) -> str:
    return format("-" if value is None else format(value, spec), f">{width}")


def table(rows: list[Row], skipped: list) -> str:
    head = (f"{'method':<14}{'rtol':>8}{'steps':>9}{'rej':>6}{'rhs':>10}{'jac':>8}{'lu':>8}"
            f"{'error':>9}{'wall ms':>11}{'cpu ms':>11}{'prog ms':>9}")
    lines = [head, "-" * len(head)]
    for r in rows:
        wall, cpu, prog = (None if v is None else v * 1e3 for v in (r.wall, r.cpu, r.prog))
        lines.append(f"{r.method:<14}{r.setting:>8}{fmt(r.steps, 'd', 9)}"
                     f"{fmt(r.rejected, 'd', 6)}{fmt(r.rhs, 'd', 10)}{fmt(r.jac, 'd', 8)}"
                     f"{fmt(r.lu, 'd', 8)}{fmt(r.error, '.1e', 9)}{fmt(wall, '.4g', 11)}"
                     f"{fmt(cpu, '.4g', 11)}{fmt(prog, '.3g', 9)}"
                     + (f"  {r.note.rstrip('; ')}" if r.note else ""))
    return "\n".join(lines + [f"not run: {name}: {why}" for name, why in skipped])


def plot(problem: Problem, rows: list[Row], directory: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    methods = list(dict.fromkeys(r.method for r in rows))
    for method, color in zip(methods, plt.cm.tab20(np.linspace(0, 1, len(methods)))):
        pts = sorted((r.error, r.time) for r in rows if r.method == method and r.error and r.time)
        if pts:
            ax.plot([p[1] * 1e3 for p in pts], [p[0] for p in pts],
                    "o-" if method.startswith("bgc") else "s--", color=color, label=method,
                    markersize=4)
    ax.set(xscale="log", yscale="log", title=f"{problem.title}: work-precision",
           xlabel="time of the integration [ms] (C: the program's own clock; else cpu)",
           ylabel="error, relative to each column's scale")
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path = directory / f"solvers_{problem.key}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def header(repeats: int, per: int = 1) -> list[str]:
    versions = [f"numpy {np.__version__}"]
    for name in ("scipy", "sksundae", "sympy"):
        try:
            versions.append(f"{name} {__import__(name).__version__}")
        except ImportError:
            versions.append(f"{name} not installed")
    return [f"date:     {datetime.datetime.now().isoformat(timespec='seconds')}",
            f"cc:       {machine.cc_version(c_compiler())}  (flags: {' '.join(CFLAGS)} ... -lm)",
            f"python:   {sys.version.split()[0]}  {'  '.join(versions)}",
            f"machine:  {machine.processor()}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, load average {machine.load_average()}",
            f"timing:   medians of {repeats} rounds after a warm-up; the C program's wall and "
            "cpu: its run writing 2 rows less a /bin/true process start; prog: its own clock()",
            f"tolerance: atol = rtol * {ATOL_RATIO:g}; {per} rtol a decade"]


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer tolerances, 1 repeat")
    parser.add_argument("--repeats", type=int, help="timed rounds (default 5, --quick 1)")
    parser.add_argument("--plot-dir", type=Path, help="write solvers_<problem>.png there")
    parser.add_argument("--only", help="comma-separated problems: pendulum,rc_pair,vdp_1e3,"
                                       "vdp_1e5")
    parser.add_argument("--per-decade", type=int, default=1,
                        help="tolerances a decade in the sweeps (default 1)")
    args = parser.parse_args(argv)
    args.repeats = args.repeats or (1 if args.quick else 5)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    if args.per_decade < 1:
        parser.error("--per-decade must be >= 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    began = time.perf_counter()
    print("\n".join(header(args.repeats, args.per_decade)))
    true = shutil.which("true") or "/bin/true"
    spawn = Job(Row("process start", ""), lambda: subprocess.run(
        [true], stderr=subprocess.PIPE, text=True), c=True, per_round=10)
    results = {}
    with tempfile.TemporaryDirectory(prefix="bgc-solvers-") as tmp:
        for problem in problems(args.quick, args.per_decade):
            if args.only and problem.key not in args.only.split(","):
                continue
            print(f"\n== {problem.key}: {problem.title}; models/{problem.model} scene "
                  f"{problem.scene}" + "".join(f" -p {k}={v:g}" for k, v in
                                               problem.params.items()))
            rows, skipped = run_problem(problem, Path(tmp), spawn, args.repeats)
            results[problem.key] = rows
            print(f"reference: {problem.ref_note}\nprocess start (subtracted): "
                  f"{ms(spawn.row.wall)} wall, {ms(spawn.row.cpu)} cpu\n")
            print(table(rows, skipped))
            print("\n".join(equal_error(rows)))
            if args.plot_dir:
                args.plot_dir.mkdir(parents=True, exist_ok=True)
                print(f"plot: {plot(problem, rows, args.plot_dir)}")
    print("\n" + "\n".join(goals(results)))
    print(f"\ntotal: {time.perf_counter() - began:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
