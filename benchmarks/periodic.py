"""bgc periodic beside brute-force simulation: the periodic steady state of a switched model.

    python benchmarks/periodic.py [--repeats 3] [--tol 1e-8]

For each model, in the same run: `bgc.periodic` (shooting: Newton on the period map with the
monodromy matrix from the sensitivities through every event of the period) against
`bgc.simulate` from rest over as many periods as it takes to settle to the same tolerance:
the first whole period k at which every state is within `--tol` of the orbit's size of the
orbit found by shooting, and stays so over the next 20 periods (read from one long run,
a row at every period's start).  Both use the model's C program, built before the timing
(the compile cache warm), the scene's solver and tolerances; times are the best wall time of
`--repeats`.  Columns: the periods brute force needs, its time, the shooting's Newton
iterations and time, the ratio, and how far brute force's state after k periods is from the
shooting's orbit (relative to the orbit's size).

The models: models/buck.bg (100 kHz, ideal switch and diode) in continuous conduction (R =
5) and discontinuous (R = 50), and tests/models/pwm_motor.bg (a PWM DC motor, its mechanical
time constant 250 PWM periods).  Issue 40's done-when: the buck at least 20 times faster.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import bgc  # noqa: E402

CASES = [  # (label, model, scene, params, periods of the long run)
    ("buck, continuous (R = 5)", ROOT / "models" / "buck.bg", "run", {"R": 5.0}, 600),
    ("buck, discontinuous (R = 50)", ROOT / "models" / "buck.bg", "run", {"R": 50.0}, 800),
    ("PWM motor", ROOT / "tests" / "models" / "pwm_motor.bg", "run", {}, 12000),
]


def _best(fn, repeats):
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _row(label, model, scene, params, periods, tol, repeats):
    from bgc.analysis import periodic
    from bgc.base import processes
    from bgc.execute import runner
    orbit = bgc.periodic(model, scene, params=params)  # (builds and caches the programs)
    T, x0 = orbit.period, np.array(orbit.x0)
    drifting = dict(orbit.drift)
    moving = [i for i, name in enumerate(orbit.states) if name not in drifting]
    size = np.max(np.abs(x0[moving]))
    t, Y, names = bgc.simulate(model, scene, params=params, t_end=periods * T, dt=T,
                               outputs=list(orbit.states))
    off = np.max(np.abs(Y[:, moving] - x0[moving]), axis=1) / size
    k = next(k for k in range(len(off) - 20) if np.all(off[k:k + 21] <= tol))
    brute, run = _best(lambda: bgc.simulate(model, scene, params=params, t_end=k * T, dt=T,
                                            outputs=list(orbit.states)), repeats)
    shoot, again = _best(lambda: bgc.periodic(model, scene, params=params), repeats)
    gap = np.max(np.abs(run[1][-1, moving] - x0[moving])) / size
    # the runs alone: each side's program prepared once, no pipeline
    compiled = bgc.build(str(model), scene, outputs=list(orbit.states))
    prepared = runner.prepare(compiled, "c")
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names, params, t_end=k * T, dt=T)
    brute_runs, _ = _best(lambda: runner.run(prepared, settings), repeats)
    shooting = periodic.build(str(model), scene)
    shoot_runs, prepared_orbit = _best(lambda: periodic.periodic(
        model, scene, params=params, shooting=shooting), repeats)
    # the integration alone, as the programs count their CPU time: brute force's one run
    # against the shooting's Newton runs (the period's output runs apart)
    brute_cpu = min(float(runner.run(prepared, settings, stats=True).stats["cpu"])
                    for _ in range(repeats))
    newton_cpu = min(periodic.periodic(model, scene, params=params,
                                       shooting=shooting).newton_cpu for _ in range(repeats))
    # the same in a warm process: each side's runs repeated in one process (runner.Session),
    # the best; a process's first run pays for its page faults and first calls, once
    with runner.Session(prepared, settings, ()) as warm:
        brute_warm = min(warm.run({})["cpu"] for _ in range(repeats + 1))
    T = prepared_orbit.period
    given = dict(params)
    warm = periodic.open_session(shooting, given, T)
    try:
        newton_warm = min(periodic.newton(shooting, given, T, warm).cpu
                          for _ in range(repeats + 1))
    finally:
        warm.close()
    start, _ = _best(lambda: processes.run_captured([str(prepared.path), "--t-end",
                                                     repr(float(compiled.program.scene.t0)),
                                                     "--dt", "1"]), repeats)
    return (label, k, brute, again.iterations, shoot, brute_runs, shoot_runs, brute_cpu,
            newton_cpu, brute_warm, newton_warm, start, gap)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-8)
    args = ap.parse_args(argv)
    print(f"# settled: every state within {args.tol:g} of the orbit's size; best of "
          f"{args.repeats}; times in ms")
    print(f"{'model':29} {'periods':>7} {'Newton':>6} | {'brute':>7} {'periodic':>8} "
          f"{'ratio':>6} | {'brute':>7} {'shoot':>7} {'ratio':>6} | {'brute':>7} {'Newton':>7} "
          f"{'ratio':>6} | {'brute':>7} {'Newton':>7} {'ratio':>6} | {'start':>6} {'gap':>8}")
    print(f"{'':29} {'':>7} {'':>6} | {'API calls':^23} | {'runs alone':^22} | "
          f"{'CPU, a new process':^22} | {'CPU, a warm process':^22} |")
    for case in CASES:
        (label, k, brute, its, shoot, b_runs, s_runs, b_cpu, n_cpu, b_warm, n_warm, start,
         gap) = _row(*case, args.tol, args.repeats)
        print(f"{label:29} {k:7d} {its:6d} | {1e3 * brute:7.2f} {1e3 * shoot:8.2f} "
              f"{brute / shoot:5.2f}x | {1e3 * b_runs:7.2f} {1e3 * s_runs:7.2f} "
              f"{b_runs / s_runs:5.2f}x | {1e3 * b_cpu:7.3f} {1e3 * n_cpu:7.3f} "
              f"{b_cpu / n_cpu:5.1f}x | {1e3 * b_warm:7.3f} {1e3 * n_warm:7.3f} "
              f"{b_warm / n_warm:5.1f}x | {1e3 * start:6.2f} {gap:8.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
