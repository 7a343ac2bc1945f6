"""Time a 10 000-run ensemble of the source paper's pendulum several ways and print one table.

    python benchmarks/sweep.py [--runs N] [--scipy-runs N] [--simulate-runs N] [--quick]
                               [--plot drift.png]

Scene `swing` of models/pendulum.bg: 0..10 s, output every 0.01 s (1001 rows), dopri5 with
rtol 1e-10, atol 1e-12.  The ensemble: --runs (10 000) parameter sets drawn with seed 1,
m ~ uniform(0.5, 2), l ~ normal(1, 0.05); metrics final:x, final:y, maxabs:rod.residual.
The rows:
  bgc sweep serial     bgc.sweep(..., workers=None): batches of 1000 runs, one program
                       process each, one after the other in this process
  bgc sweep, K workers the same sweep on a dask LocalCluster of K worker processes (started
                       before the clock starts; its start-up time is its own column)
  bgc simulate loop    `bgc simulate` as a new process per run (Python start-up, model
                       build, the C program from the cache, its CSV to a file); --simulate-runs
                       (100) are timed and the rate extrapolated
  SciPy loop           solve_ivp(RK45, the same rtol and atol, t_eval = the output grid) on
                       a right side lambdified (sympy, modules="math", cse=True) from the
                       paper's eq. (12) with m, l as arguments (not from bgc's equations);
                       --scipy-runs (20) timed, the rate extrapolated; metrics: final x, y and
                       max |x^2 + y^2 - l^2| on the grid
Columns:
  runs       runs timed (the rate of the extrapolated rows comes from these)
  wall [s]   wall-clock time of those runs (sweep rows: bgc.sweep's call, the model built
             and the C program compiled before it)
  runs/s     runs / wall
  vs SciPy   runs/s over the SciPy loop's
  start [s]  the LocalCluster's start-up (not in wall)
  same       the table equals the serial table (every column but cpu, bit for bit); for the
             simulate loop: its runs' metrics (from their CSV) equal the sweep's, bit for bit
Below it: the corrector-gain study, alpha and beta each on 20 log-spaced points from 0.5 to
50 (400 runs), maxabs:rod.residual (the drift), timed on the 2-worker cluster (serially if
Dask is missing), and with --plot its drift map (matplotlib).  Timings are printed, never
asserted; the target (2 000 runs/s on 2 cores, 200x the SciPy loop) is stated beside them.
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))  # machine.py
import machine  # noqa: E402

import bgc  # noqa: E402
from bgc import api
from bgc.base import toolchain
from bgc.execute import sweeps  # noqa: E402

MODEL = ROOT / "models" / "pendulum.bg"
SCENE = "swing"
RTOL, ATOL, T_END, DT = 1e-10, 1e-12, 10.0, 0.01
VARY = {"m": "uniform(0.5,2)", "l": "normal(1,0.05)"}
METRICS = ["final:x", "final:y", "maxabs:rod.residual"]
TARGET_RATE, TARGET_SCIPY = 2000.0, 200.0


def scipy_rhs():
    """f(t, s, m, l) of eq. (12) (g = 9.81, alpha = beta = 5), s = (px, py, x, y)."""
    import sympy as sp

    px, py, x, y, t, m, l = sp.symbols("px py x y t m l")
    g, alpha, beta = sp.Float(9.81), sp.Float(5.0), sp.Float(5.0)
    xd, yd = px / m, py / m
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    xdd = -x / (x**2 + y**2) * bracket
    ydd = g - y / (x**2 + y**2) * bracket
    return sp.lambdify((t, (px, py, x, y), m, l), [m * xdd, m * ydd, xd, yd], modules="math",
                       cse=True)


def scipy_loop(params, t_end):
    from scipy.integrate import solve_ivp
    f = scipy_rhs()
    grid = np.append(np.arange(0.0, t_end, DT), t_end)
    start = time.perf_counter()
    for m, l in params:
        s0 = [0.0, 0.0, l * math.sin(0.5), l * math.cos(0.5)]
        sol = solve_ivp(f, (0.0, t_end), s0, method="RK45", rtol=RTOL, atol=ATOL, t_eval=grid,
                        args=(m, l))
        _ = (sol.y[2, -1], sol.y[3, -1], np.max(np.abs(sol.y[2]**2 + sol.y[3]**2 - l * l)))
    return time.perf_counter() - start


def simulate_loop(table, count, t_end, workdir):
    """`bgc simulate` per run, as a process; whether the metrics equal the sweep's."""
    same = True
    start = time.perf_counter()
    for i in range(count):
        out = Path(workdir) / "run.csv"
        done = subprocess.run([sys.executable, "-m", "bgc", "simulate", str(MODEL), "--scene",
                               SCENE, "--t-end", repr(t_end), "-p", f"m={float(table['m'][i])!r}",
                               "-p", f"l={float(table['l'][i])!r}", "-o", str(out)],
                              capture_output=True, text=True,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        if done.returncode != 0:
            raise RuntimeError(done.stderr)
        data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
        same &= bool(data[-1, 1] == table["final:x"][i] and data[-1, 2] == table["final:y"][i]
                     and np.max(np.abs(data[:, 4])) == table["maxabs:rod.residual"][i])
    return time.perf_counter() - start, same


def same_table(a, b) -> bool:
    return all((np.array_equal(a[c], b[c], equal_nan=True) if c not in ("status", "message")
                else a[c] == b[c]) for c in a.names if c != "cpu")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--scipy-runs", type=int, default=20)
    ap.add_argument("--simulate-runs", type=int, default=100)
    ap.add_argument("--workers", default="1,2,4", help="Local cluster sizes (comma-separated).")
    ap.add_argument("--quick", action="store_true",
                    help="A smoke run: 200 runs of 1 s, 2 SciPy runs, 2 simulate runs, a 1- "
                         "worker cluster, a 5x5 gain grid.")
    ap.add_argument("--plot", default=None, help="PNG of the gain study's drift map.")
    args = ap.parse_args(argv)
    t_end, gains_n = T_END, 20
    worker_counts = [int(w) for w in args.workers.split(",") if w]
    if args.quick:
        args.runs, args.scipy_runs, args.simulate_runs = 200, 2, 2
        t_end, gains_n, worker_counts = 1.0, 5, [1]
    if not toolchain.have_c_compiler():
        sys.exit("benchmarks/sweep.py needs a C compiler (cc or $CC)")
    print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, load average "
          f"{machine.load_average()}")
    print(f"cc:       {machine.cc_version(toolchain.c_compiler())} (bgc: "
          f"{' '.join(toolchain.C_FLAGS)})")
    print(f"sweep:    {args.runs} runs of {MODEL.name} scene {SCENE}, 0..{t_end:g} s every "
          f"{DT} s, dopri5 rtol {RTOL:g} atol {ATOL:g}; m ~ {VARY['m']}, l ~ {VARY['l']}, "
          f"seed 1; metrics {', '.join(METRICS)}")
    compiled = api.build(MODEL, SCENE)
    options = dict(sample=args.runs, vary=VARY, seed=1, metrics=METRICS, t_end=t_end)
    bgc.sweep(compiled, **dict(options, sample=2))  # compile the C program (the cache)
    rows = []  # (name, runs, wall, start, same)
    start = time.perf_counter()
    serial = bgc.sweep(compiled, batch_size=1000, **options)
    rows.append(("bgc sweep serial", args.runs, time.perf_counter() - start, None, True))
    clusters_ok = sweeps.have_dask()
    for k in worker_counts if clusters_ok else []:
        t0 = time.perf_counter()
        client = sweeps.local_client(k)
        started = time.perf_counter() - t0
        try:
            t0 = time.perf_counter()
            table = bgc.sweep(compiled, client=client, **options)
            wall = time.perf_counter() - t0
        finally:
            cluster = client.cluster
            client.close()
            cluster.close()
        rows.append((f"bgc sweep, {k} worker{'s' if k > 1 else ''}", args.runs, wall, started,
                     same_table(serial, table)))
    with tempfile.TemporaryDirectory() as tmp:
        wall, same = simulate_loop(serial, args.simulate_runs, t_end, tmp)
    rows.append(("bgc simulate loop (extrapolated)", args.simulate_runs, wall, None, same))
    params = list(zip(serial["m"][:args.scipy_runs], serial["l"][:args.scipy_runs]))
    rows.append(("SciPy loop (extrapolated)", args.scipy_runs, scipy_loop(params, t_end), None,
                 None))
    scipy_rate = rows[-1][1] / rows[-1][2]
    print()
    print(f"{'':34} {'runs':>6} {'wall [s]':>9} {'runs/s':>9} {'vs SciPy':>9} "
          f"{'start [s]':>9} {'same':>5}")
    for name, n, wall, started, same in rows:
        rate = n / wall
        print(f"{name:34} {n:6d} {wall:9.3f} {rate:9.0f} {rate / scipy_rate:8.0f}x "
              f"{'' if started is None else f'{started:.2f}':>9} "
              f"{'' if same is None else ('yes' if same else 'NO'):>5}")
    best = max(n / w for name, n, w, _, _ in rows if name.startswith("bgc sweep"))
    print(f"\nfastest sweep: {best:.0f} runs/s (target >= {TARGET_RATE:.0f} on 2 cores), "
          f"{best / scipy_rate:.0f}x the SciPy loop (target >= {TARGET_SCIPY:.0f}x); "
          f"failed runs: {serial.failures()}")
    if not clusters_ok:
        print("(dask.distributed is not installed: no cluster rows; pip install '.[sweep]')")
    gains(compiled, gains_n, t_end, args.plot, clusters_ok)


def gains(compiled, n, t_end, plot, use_dask):
    grid = {"alpha": f"0.5:50:log{n}", "beta": f"0.5:50:log{n}"}
    client = sweeps.local_client(2) if use_dask else None
    try:
        t0 = time.perf_counter()
        table = bgc.sweep(compiled, grid=grid, metrics=["maxabs:rod.residual"], t_end=t_end,
                          client=client)
        wall = time.perf_counter() - t0
    finally:
        if client is not None:
            cluster = client.cluster
            client.close()
            cluster.close()
    drift = np.asarray(table["maxabs:rod.residual"]).reshape(n, n)
    where = "2 workers" if use_dask else "serially"
    print(f"gain study: alpha x beta = {n}x{n} log-spaced in 0.5..50, {len(table)} runs "
          f"{where} in {wall:.2f} s; drift max|rod.residual| from {np.nanmin(drift):.2e} to "
          f"{np.nanmax(drift):.2e}; failed runs: {table.failures()}")
    if plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.colors import LogNorm
        a, b = np.unique(table["alpha"]), np.unique(table["beta"])
        fig, ax = plt.subplots(figsize=(5, 4))
        mesh = ax.pcolormesh(b, a, drift, norm=LogNorm(), shading="nearest")
        ax.set(xscale="log", yscale="log", xlabel="beta", ylabel="alpha",
               title="pendulum, 10 s: max |rod.residual|")
        fig.colorbar(mesh)
        fig.tight_layout()
        fig.savefig(plot, dpi=100)
        print(f"wrote {plot}")


if __name__ == "__main__":
    main()
