"""The Modelica ScalableTestSuite's families as bond graphs, as they grow: compile, build, memory,
code size and run time, with their growth exponents, beside CasADi MX.

    python benchmarks/scalable.py [--quick] [--families a,b] [--sizes N,N,..] [--repeats R]

The families (benchmarks/families.py, written as a modeller writes them: a component and `for`
loops, the form that issue 41's array-preserving compilation is to take at a cost that does not
grow with N): heat_line (1-D heat conduction, N cells, stiff: rodas5p), thermal_grid_cells (the
2-D plate, N cells in a square), transmission_line (an RLC line of N sections, 2N states),
cascaded_first_order (N buffered lags) and harmonic_oscillators (N mass-springs, 2N states).
Their equations are checked against their matrices or closed forms in
tests/test_scalable_families.py.

For every family and size, each in a fresh process:
  compile  wall clock of `python -m bgc compile FILE --target c -o OUT.c` (Python's start and
           imports included), and its peak resident memory (the child's ru_maxrss)
  code     bytes of the generated C file
  cc       wall clock of `cc -O2 -std=c99 OUT.c -o prog -lm` (the standalone program, runtime
           included)
  run      wall clock of the program running the family's scene (`prog > /dev/null`)
The growth exponent of each column is the least-squares slope of log(time) against log(N) over
the sizes given.  Issue 41's targets: at most N^0.1 for a regular `for` loop, from 10^3 to 10^6
(today every loop is unrolled, so these grow at least linearly: this table is the baseline).

CasADi MX (if importable), in this process: the same right side as an MX function of the
state, x' = A x + b with the family's sparse A (scipy.sparse, from the matrices its tests
check bgc against), built, code-generated and compiled with `cc -O2 -c`: build + codegen + cc.
(An MX graph of one sparse product: CasADi stores A's entries as data, so its cost grows with
the entries, not with the statements a scalar compiler writes.)  Not for the 2-D grid, whose
matrix is not written out here, nor past 6000 states (the matrices are written dense).  Times are medians of --repeats, printed, never asserted.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import families  # noqa: E402

SCENES = {"heat_line": "cool", "thermal_grid_cells": "cool", "transmission_line": "step",
          "cascaded_first_order": "step", "harmonic_oscillators": "swing"}
SIZES = (100, 300, 1000, 3000)
MAX_CASADI_STATES = 6000  # (the families' matrices are written dense: 288 MB at 6000 states)
QUICK = (100, 300)


def matrices(family: str, n: int):
    """(A, b) of the family's x' = A x + b in bgc's state order, or None."""
    if family == "heat_line":
        A, b, _ = families.heat_line_matrices(n)
        return A, b  # (temperatures: c = 1, so the states' q are the e)
    if family == "transmission_line":
        A, b, _ = families.transmission_line_matrices(n)
        return A, b
    if family == "cascaded_first_order":
        rate = n / 1.0
        A = rate * (np.eye(n, k=-1) - np.eye(n))
        b = np.zeros(n)
        b[0] = rate
        return A, b
    if family == "harmonic_oscillators":
        A = np.zeros((2 * n, 2 * n))
        for i in range(n):  # (osc[i].mass.p, osc[i].spring.q): p' = -k_i q, q' = p / m
            A[2 * i, 2 * i + 1] = -100.0 * (1 + (i + 1) / n)
            A[2 * i + 1, 2 * i] = 1.0
        return A, np.zeros(2 * n)
    return None


# each measured command is started by this small launcher, which times it and reads its peak
# memory from RUSAGE_CHILDREN: a child forked from this (large) process would report this
# process's memory as its own high-water mark
_LAUNCH = """import resource, subprocess, sys, time
t = time.perf_counter()
code = subprocess.run(sys.argv[2:]).returncode
wall = time.perf_counter() - t
with open(sys.argv[1], "w") as f:
    f.write(f"{wall} {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}")
sys.exit(code)
"""


def _timed(cmd, **kw):
    """(wall seconds, peak resident bytes) of one command."""
    with tempfile.NamedTemporaryFile("r", suffix=".txt") as report:
        proc = subprocess.run([sys.executable, "-c", _LAUNCH, report.name, *map(str, cmd)],
                              **kw)
        if proc.returncode:
            raise SystemExit(f"failed ({proc.returncode}): {' '.join(map(str, cmd))}")
        wall, rss = report.read().split()
    return float(wall), int(rss) * 1024


def bgc_row(family: str, n: int, repeats: int, work: Path) -> dict:
    text = families.FAMILIES[family](n)
    model = work / f"{family}{n}.bg"
    model.write_text(text)
    out, prog = work / f"{family}{n}.c", work / f"{family}{n}"
    env = dict(os.environ, PYTHONPATH=str(ROOT), BGC_CACHE_DIR=str(work / "cache"))
    compile_cmd = [sys.executable, "-m", "bgc", "compile", str(model), "--target", "c",
                   "--scene", SCENES[family], "-o", str(out)]
    cc = os.environ.get("CC", "cc")
    rows = []
    for _ in range(repeats):
        wall, rss = _timed(compile_cmd, env=env)
        build, _ = _timed([cc, "-O2", "-std=c99", str(out), "-o", str(prog), "-lm"])
        with open(os.devnull, "wb") as sink:
            run, _ = _timed([str(prog)], stdout=sink)
        rows.append((wall, rss, build, run))
    med = [statistics.median(r[k] for r in rows) for k in range(4)]
    return {"compile": med[0], "memory": med[1], "code": out.stat().st_size, "cc": med[2],
            "run": med[3]}


def casadi_row(family: str, n: int, repeats: int, work: Path) -> dict | None:
    try:
        import casadi
        import scipy.sparse
    except ImportError:
        return None
    if _states(family, n) > MAX_CASADI_STATES:
        return None
    AB = matrices(family, n)
    if AB is None:
        return None
    A, b = AB
    cc = os.environ.get("CC", "cc")
    rows = []
    for k in range(repeats):
        t0 = time.perf_counter()
        S = scipy.sparse.csc_matrix(A)
        D = casadi.DM(casadi.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(),
                                      S.indices.tolist()), S.data.tolist())
        x = casadi.MX.sym("x", A.shape[0])
        f = casadi.Function("rhs", [x], [casadi.mtimes(D, x) + casadi.DM(b)])
        t1 = time.perf_counter()
        name = f"casadi_{family}{n}_{k}"
        gen = casadi.CodeGenerator(name + ".c")
        gen.add(f)
        cwd = os.getcwd()
        os.chdir(work)
        try:
            gen.generate()
        finally:
            os.chdir(cwd)
        t2 = time.perf_counter()
        _timed([cc, "-O2", "-c", str(work / (name + ".c")), "-o", str(work / (name + ".o"))])
        t3 = time.perf_counter()
        rows.append((t1 - t0, t2 - t1, t3 - t2))
        x0 = np.linspace(0.0, 1.0, A.shape[0])  # (the product against numpy's: the same A)
        got = np.asarray(f(x0)).ravel()
        assert np.allclose(got, A @ x0 + b, rtol=1e-12, atol=1e-12)
    med = [statistics.median(r[k] for r in rows) for k in range(3)]
    return {"build": med[0], "codegen": med[1], "cc": med[2], "total": sum(med)}


def growth(sizes, values) -> float:
    if len(sizes) < 2:
        return float("nan")
    return float(np.polyfit(np.log(sizes), np.log(values), 1)[0])


def _states(family: str, n: int) -> int:
    return 2 * n if family in ("transmission_line", "harmonic_oscillators") else n


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"sizes {QUICK}")
    parser.add_argument("--families", default=",".join(SCENES))
    parser.add_argument("--sizes", help="N,N,.. (thermal_grid_cells: perfect squares)")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args(argv)
    sizes = tuple(int(s) for s in args.sizes.split(",")) if args.sizes else \
        (QUICK if args.quick else SIZES)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for family in args.families.split(","):
            own = tuple(round(math.isqrt(n)) ** 2 for n in sizes) \
                if family == "thermal_grid_cells" else sizes
            print(f"\n{family} (scene {SCENES[family]})")
            print(f"{'N':>7} {'states':>7} | {'compile s':>9} {'memory MiB':>10} "
                  f"{'code KiB':>9} {'cc s':>7} {'run s':>7} | {'CasADi MX: build':>16} "
                  f"{'codegen':>8} {'cc':>7} {'total s':>8}")
            got, theirs = [], []
            for n in own:
                r = bgc_row(family, n, args.repeats, work)
                c = casadi_row(family, n, args.repeats, work)
                got.append(r)
                theirs.append(c)
                cas = (f"{c['build']:16.3f} {c['codegen']:8.3f} {c['cc']:7.3f} "
                       f"{c['total']:8.3f}") if c else f"{'-':>16} {'-':>8} {'-':>7} {'-':>8}"
                print(f"{n:7d} {_states(family, n):7d} | {r['compile']:9.2f} "
                      f"{r['memory'] / 2 ** 20:10.0f} {r['code'] / 1024:9.0f} {r['cc']:7.2f} "
                      f"{r['run']:7.3f} | {cas}", flush=True)
            line = "  ".join(f"{k} N^{growth(own, [r[k] for r in got]):.2f}"
                             for k in ("compile", "memory", "code", "cc", "run"))
            if all(theirs):
                line += f"  | CasADi total N^{growth(own, [c['total'] for c in theirs]):.2f}"
            print(f"{'growth':>15} | {line}")


if __name__ == "__main__":
    main()
