"""Stiff models at scale: an n x n thermal RC grid (n^2 states) integrated by bgc's stiff solvers
in the generated C program, beside SUNDIALS CVODE driven from C with its banded, sparse (KLU)
and dense linear solvers, at equal achieved error, in one run.

    python benchmarks/stiff_scale.py [--sizes 10,20,50] [--quick] [--repeats N]
                                     [--plot FILE.png]

The model is benchmarks/families.py's thermal_grid(n) (scene cool: 0..50 s, the state written
at t_end only), a plate of n x n cells with a heat capacity each, thermal resistances between
neighbours, heat lost to an ambient along one edge and a heater in a corner; its eigenvalues
run from about -8 to -9.3e-4 at n = 50 (a stiffness ratio of 8600), the cells start at
1 + sin(k) so that every mode is excited.  bgc compiles it (its stiff solvers factor the
iteration matrices by the sparse LU the compiler plans for a large sparse Jacobian,
docs/solvers.md); the C program runs `--solver S --rtol R --atol R/1000 --dt 50 --stats`.
CVODE is benchmarks/cvode_grid.c, built against the system's SUNDIALS: BDF, Newton, the grid's
right side and its (constant) Jacobian written by hand from the same formula, with the band
solver (half-bandwidths n), KLU (CSC) or the dense one (n <= 20 only: its LU is O(n^6)).
"bgc ... dense" (n <= 20) is bgc's own program compiled with the sparse path switched off,
the same solver factoring dense: what the sparse LU buys.

Reference: the closed form.  With c = 1 the grid's matrix is the Kronecker sum A = Ay (+) Ax of
two n x n tridiagonal matrices (the rows' coupling, and the columns' with the edge's loss), so
T(t) = T_ss + V exp(Lambda t) V^T (T(0) - T_ss) with V = Vy (x) Vx from two symmetric n x n
eigenproblems, T_ss the steady state (the same modes).  tests/test_benchmarks_smoke.py checks
it against SciPy at n = 4.

Columns: steps (accepted), rej (rejected: error test and, for CVODE, Newton failures), rhs
(right-side calls; CVODE's with its linear solver's), jac (Jacobian evaluations), lu
(factorisations; CVODE: linear solver setups), error (max over the n^2 temperatures at
t_end of |T - T_exact| / max(1, max |T_exact|)), prog ms (the program's own clock() around
the integration, the `cpu=` of its stats line: no process start; a median over the rounds).
Below each size's table, every method's time at common errors (linear in log time against
log error along its runs); last, the goal of the issue for the 50 x 50 grid.  Times are
printed, never asserted.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
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
from families import thermal_grid  # noqa: E402
from pendulum import CFLAGS, c_compiler, compile_c  # noqa: E402
from solvers import Row, at_error, curve, decades, goal, ms, parse_stats, tol_text  # noqa: E402

T_END = 50.0
C, R, RB, Q_IN = 1.0, 1.0, 2.0, 1.0  # thermal_grid's defaults
ATOL_RATIO = 1e-3
BGC_SOLVERS = ("rodas5p", "radau5", "radau")
SUNDIALS_LIBS = ("-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense",
                 "-lsundials_sunmatrixdense", "-lsundials_sunlinsolband",
                 "-lsundials_sunmatrixband", "-lsundials_sunlinsolklu",
                 "-lsundials_sunmatrixsparse", "-lklu")
DENSE_MAX = 20  # CVODE's dense solver and bgc's dense path up to this n


# ---------------------------------------------------------------- the closed form

def path_matrix(n: int, loss: float = 0.0) -> np.ndarray:
    """The conductance coupling along one direction of the grid (c dT/dt = M T), n cells in a
    row, the last one losing `loss` to the ambient."""
    M = np.zeros((n, n))
    for i in range(n - 1):
        M[i, i] -= 1.0 / R
        M[i + 1, i + 1] -= 1.0 / R
        M[i, i + 1] += 1.0 / R
        M[i + 1, i] += 1.0 / R
    M[n - 1, n - 1] -= loss
    return M / C


def exact(n: int, t: float) -> np.ndarray:
    """The grid's temperatures at t (cell k = i n + j, 0-based), from its modes."""
    ly, Vy = np.linalg.eigh(path_matrix(n))  # along the columns (index i)
    lx, Vx = np.linalg.eigh(path_matrix(n, 1.0 / RB))  # along the rows (index j), the loss
    lam = ly[:, None] + lx[None, :]
    B = np.zeros((n, n))
    B[0, 0] = Q_IN / C
    G0 = (1.0 + np.sin(np.arange(1, n * n + 1))).reshape(n, n)
    modes = lambda G: Vy.T @ G @ Vx  # noqa: E731
    back = lambda H: Vy @ H @ Vx.T  # noqa: E731
    steady = back(-modes(B) / lam)
    return (steady + back(np.exp(lam * t) * modes(G0 - steady))).reshape(-1)


def scaled_error(T: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(T - ref)) / max(1.0, float(np.max(np.abs(ref)))))


# ---------------------------------------------------------------- the programs

def build_bgc(n: int, workdir: Path, dense: bool = False) -> tuple[Path, float, float]:
    """The grid's C program (dense: the sparse path switched off), the seconds of bgc's compile
    and of cc's."""
    import bgc
    from bgc.symbolic import sparse

    source = workdir / f"grid{n}.bg"
    source.write_text(thermal_grid(n, T_END), encoding="utf-8")
    saved = sparse.SPARSE_MIN_STATES
    if dense:
        sparse.SPARSE_MIN_STATES = 10 ** 9
    try:
        start = time.perf_counter()
        (name, text), = bgc.compile(str(source), target="c", scene="cool").items()
        compiled = time.perf_counter() - start
    finally:
        sparse.SPARSE_MIN_STATES = saved
    if ("#define BGC_JAC_SPARSE 1" in text) == dense:
        raise RuntimeError(f"grid{n}: the program is not on the {'dense' if dense else 'sparse'}"
                           " path")
    stem = f"grid{n}{'_dense' if dense else ''}"
    (workdir / f"{stem}.c").write_text(text, encoding="utf-8")
    start = time.perf_counter()
    exe = compile_c(workdir / f"{stem}.c", workdir / stem)
    return exe, compiled, time.perf_counter() - start


def build_cvode(workdir: Path) -> tuple[Path | None, str]:
    exe = workdir / "cvode_grid"
    cmd = [*c_compiler(), *CFLAGS, "-I/usr/include/suitesparse", str(HERE / "cvode_grid.c"),
           "-o", str(exe), *SUNDIALS_LIBS, "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        first = (done.stderr.strip().splitlines() or ["?"])[0]
        return None, f"cannot build cvode_grid.c against SUNDIALS and KLU ({first})"
    return exe, ""


def run_program(cmd: list) -> tuple[np.ndarray, dict]:
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError((done.stderr.strip().splitlines() or ["?"])[-1])
    last = done.stdout.strip().splitlines()[-1]
    values = np.array([float(v) for v in last.split(",")])
    return values[1:], parse_stats(done.stderr)


def bgc_cmd(exe: Path, solver: str, rtol: float) -> list:
    return [str(exe), "--solver", solver, "--rtol", repr(rtol), "--atol", repr(rtol * ATOL_RATIO),
            "--t-end", repr(T_END), "--dt", repr(T_END), "--stats", "--max-steps", "0"]


def cvode_cmd(exe: Path, n: int, kind: str, rtol: float) -> list:
    return [str(exe), str(n), kind, repr(rtol), repr(rtol * ATOL_RATIO), repr(T_END)]


def first_run(method: str, cmd: list, rtol: float, ref: np.ndarray) -> Row:
    """The row of one run: its counters, its error and its first time."""
    row = Row(method, tol_text(rtol), rtol)
    try:
        T, st = run_program(cmd)
    except RuntimeError as exc:
        row.note = f"FAILED: {exc}"
        return row
    row.steps, row.rejected = int(st.get("steps", 0)), int(st.get("rejected", 0))
    row.rhs, row.jac, row.lu = int(st.get("rhs", 0)), int(st.get("jac", 0)), int(st.get("lu", 0))
    row.error = scaled_error(T, ref)
    row.prog = st["cpu"]
    return row


def measure(runs: list, repeats: int) -> list[Row]:
    """Every (method, command, rtol) run once for its row, then repeats - 1 more rounds each
    running every one in turn (so that a change of load hits all alike); prog: the median."""
    rows = [first_run(*run) for run in runs]
    times = [[r.prog] for r in rows]
    for _ in range(repeats - 1):
        for (_, cmd, _, _), row, seen in zip(runs, rows, times):
            if row.error is not None:
                seen.append(run_program(cmd)[1]["cpu"])
    for row, seen in zip(rows, times):
        if row.error is not None:
            row.prog = statistics.median(seen)
    return rows


# ---------------------------------------------------------------- output

def table(rows: list[Row]) -> str:
    head = (f"{'method':<18}{'rtol':>8}{'steps':>8}{'rej':>6}{'rhs':>8}{'jac':>6}{'lu':>6}"
            f"{'error':>10}{'prog ms':>11}")
    out = [head, "-" * len(head)]
    for r in rows:
        if r.error is None:
            out.append(f"{r.method:<18}{r.setting:>8}  {r.note}")
            continue
        out.append(f"{r.method:<18}{r.setting:>8}{r.steps:>8}{r.rejected:>6}{r.rhs:>8}"
                   f"{r.jac:>6}{r.lu:>6}{r.error:>10.1e}{r.prog * 1e3:>11.4g}")
    return "\n".join(out)


def equal_error(rows: list[Row]) -> list[str]:
    """Each decade of error inside the ranges of at least two methods: their times there
    (linear in log time against log error along each one's runs), fastest first."""
    methods = list(dict.fromkeys(r.method for r in rows if r.error))
    ranges = {m: c for m in methods if len(c := curve(rows, m, "time")[0]) >= 2}
    if not ranges:
        return []
    lo = min(c[0] for c in ranges.values()) / math.log(10)
    hi = max(c[-1] for c in ranges.values()) / math.log(10)
    out = []
    for k in range(math.floor(hi), math.ceil(lo) - 1, -1):
        level = 10.0 ** k
        cells = sorted((t, m) for m in ranges
                       if (t := at_error(rows, m, "time", level)) is not None)
        if len(cells) >= 2:
            out.append(f"at equal error {level:.0e}: "
                       + ", ".join(f"{m} {ms(t)}" for t, m in cells))
    return out


def speedups(rows: list[Row], mine: str, theirs: str) -> list[float]:
    """theirs' time over mine at each of mine's runs inside theirs' range of error."""
    out = []
    for r in rows:
        if r.method == mine and r.error and r.time:
            t = at_error(rows, theirs, "time", r.error)
            if t is not None:
                out.append(t / r.time)
    return out


def goals(results: dict) -> list[str]:
    rows = results.get(50)
    if not rows:
        return [goal("the 50 x 50 grid with radau or rodas5p faster than CVODE (band or KLU) "
                     "at equal error", "not run (--sizes without 50)", None)]
    lines, best = [], {}
    for cv in ("CVODE-C BDF band", "CVODE-C BDF KLU"):
        parts = []
        for mine in ("bgc " + s for s in BGC_SOLVERS):
            s = speedups(rows, mine, cv)
            if s:
                best[(mine, cv)] = min(s)
                parts.append(f"{mine} {min(s):.3g}x..{max(s):.3g}x "
                             f"({math.exp(sum(map(math.log, s)) / len(s)):.3g}x)")
        lines.append(f"{cv}: " + ("; ".join(parts) or "no common error"))
    ok = any(v > 1.0 for (m, _), v in best.items()
             if m in ("bgc rodas5p", "bgc radau5", "bgc radau"))
    ok_both = all(any(best.get((m, cv), 0.0) > 1.0 for m in ("bgc rodas5p", "bgc radau5",
                                                             "bgc radau"))
                  for cv in ("CVODE-C BDF band", "CVODE-C BDF KLU"))
    return [goal("the 50 x 50 grid (2500 states) with radau or rodas5p faster than CVODE-C "
                 "with its band or KLU solver at equal error (CVODE's time over bgc's, worst.."
                 "best over bgc's runs inside CVODE's range of error; geometric mean)",
                 " | ".join(lines), ok and ok_both)]


def plot(results: dict, path: Path) -> Path | None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    sizes = sorted(results)
    methods = list(dict.fromkeys(r.method for n in sizes for r in results[n]))
    colors = {m: f"C{k}" for k, m in enumerate(methods)}
    fig, axes = plt.subplots(1, len(sizes), figsize=(5.2 * len(sizes), 4.4), squeeze=False)
    for ax, n in zip(axes[0], sizes):
        rows = results[n]
        for m in dict.fromkeys(r.method for r in rows if r.error):
            pts = sorted((r.prog * 1e3, r.error) for r in rows if r.method == m and r.error)
            style = "-o" if m.startswith("bgc") else "--s"
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], style, ms=3, label=m,
                      color=colors[m])
        ax.set_title(f"{n} x {n} thermal grid ({n * n} states)")
        ax.set_xlabel("integration time, ms (the program's own clock)")
        ax.set_ylabel("error at t_end (max over the cells)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def header(repeats: int) -> list[str]:
    import bgc
    return [f"date:     {datetime.datetime.now().isoformat(timespec='seconds')}",
            f"cc:       {machine.cc_version(c_compiler())}  (flags: {' '.join(CFLAGS)})",
            f"python:   {sys.version.split()[0]}  numpy {np.__version__}  bgc {bgc.__version__}",
            f"machine:  {machine.processor()}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, load average {machine.load_average()}",
            f"timing:   the programs' own clock() around the integration, median of {repeats} "
            "rounds (each round runs every program in turn)",
            f"tolerance: atol = rtol * {ATOL_RATIO:g}; error at t = {T_END:g} against the closed "
            "form"]


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,20,50", help="grid sizes n (default 10,20,50)")
    parser.add_argument("--quick", action="store_true", help="fewer tolerances, 1 round")
    parser.add_argument("--repeats", type=int, help="timed rounds (default 3, --quick 1)")
    parser.add_argument("--plot", type=Path, help="write the error-time plot there (PNG)")
    args = parser.parse_args(argv)
    args.sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    args.repeats = args.repeats or (1 if args.quick else 3)
    if args.repeats < 1 or not args.sizes or min(args.sizes) < 2:
        parser.error("--repeats must be >= 1, sizes >= 2")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    # bgc's errors at t_end lie far below its rtol on this problem, CVODE's near it: the
    # sweeps are shifted so that their errors overlap
    tols = {"bgc": decades(2, 9), "CVODE-C": decades(4, 11)}
    if args.quick:
        tols = {k: v[::3] for k, v in tols.items()}
    print("\n".join(header(args.repeats)))
    results = {}
    with tempfile.TemporaryDirectory(prefix="bgc-stiff-scale-") as tmp:
        workdir = Path(tmp)
        cvode, why = build_cvode(workdir)
        if cvode is None:
            print(f"CVODE-C: {why}")
        for n in args.sizes:
            ref = exact(n, T_END)
            exe, t_bgc, t_cc = build_bgc(n, workdir)
            print(f"\n== {n} x {n} thermal grid: {n * n} states; models: "
                  f"benchmarks/families.py thermal_grid({n})")
            print(f"build: bgc compile {t_bgc:.1f} s, cc {' '.join(CFLAGS)} {t_cc:.1f} s "
                  "(wall)")
            programs = [(f"bgc {s}", lambda r, s=s: bgc_cmd(exe, s, r)) for s in BGC_SOLVERS]
            if n <= DENSE_MAX:
                dense, _, _ = build_bgc(n, workdir, dense=True)
                programs.append(("bgc rodas5p dense", lambda r: bgc_cmd(dense, "rodas5p", r)))
            if cvode is not None:
                kinds = ["band", "KLU"] + (["dense"] if n <= DENSE_MAX else [])
                programs += [(f"CVODE-C BDF {k}", lambda r, k=k: cvode_cmd(cvode, n, k.lower(), r))
                             for k in kinds]
            rows = measure([(name, cmd(rtol), rtol, ref) for name, cmd in programs
                            for rtol in tols[name.split()[0]]], args.repeats)
            results[n] = rows
            print(table(rows))
            print("\n".join(equal_error(rows)))
    print()
    print("\n".join(goals(results)))
    if args.plot:
        path = plot(results, args.plot)
        print(f"plot: {path}" if path else "plot: matplotlib not installed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
