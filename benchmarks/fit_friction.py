"""A fit of a Coulomb friction level through stick-slip: `bgc fit` beside SciPy.

    python benchmarks/fit_friction.py [--noise 0.01] [--seed 3] [--repeats 3]

The data: tests/models/stick_slip.bg (a mass on a spring dragged by a belt through dry
friction, Fr(Fc, Fs)) simulated by bgc at Fc = 1.6 (the model's 2.0, where every fit starts;
Fs = 3.0 fixed) at dopri5, rtol 1e-10, atol 1e-12, its spring displacement and momentum
sampled every 0.01 s over 10 s (1001 samples, four sticks and breakaways), with seeded
Gaussian noise of s.d. `--noise`.  Fc moves every breakaway and stop: the residuals are
smooth in Fc only through the events' times.

  bgc fit (C)                 bgc.fit: Levenberg-Marquardt on the forward sensitivities, their
                              jumps at every event included (docs/analysis.md), the augmented
                              C program compiled once per fit (warm cache)
  bgc fit (Python)            the same with the generated Python module in this process
  SciPy least_squares, bgc    scipy.optimize.least_squares (trf, 2-point finite differences)
                              on residuals from runs of the plain model's C program (compiled
                              once, run with -p at each point, as `bgc simulate` runs it)

Columns: the best wall time of `--repeats`, iterations (least_squares: residual
evaluations), runs of the model, the final cost, Fc's relative error, and the half-width of
the 95 % interval where the method gives one.  No hand-written SciPy model: solve_ivp has no
sticking mode (a Filippov system needs an event-driven automaton, which tests/test_switching.py
writes for its own references, not a fit's inner loop).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine  # noqa: E402

MODEL = ROOT / "tests" / "models" / "stick_slip.bg"
TRUE, START = 1.6, 2.0
OUTPUTS = "k.q, m.p"
SOLVER = dict(solver="dopri5", rtol=1e-10, atol=1e-12)


def make_data(path: Path, noise: float, seed: int):
    from bgc import api
    t, Y, _ = api.simulate(MODEL, "run", outputs=OUTPUTS, params={"Fc": TRUE}, **SOLVER)
    Y = Y + noise * np.random.default_rng(seed).standard_normal(Y.shape)
    with open(path, "w") as fh:
        fh.write("t,k.q,m.p\n")
        for ti, (a, b) in zip(t, Y):
            fh.write(f"{float(ti)!r},{float(a)!r},{float(b)!r}\n")
    return t, Y


def bgc_fit(data: Path, backend: str):
    from bgc.analysis import estimate
    start = time.perf_counter()
    fit = estimate.fit(MODEL, data, ["Fc=0.5..2.9"], scene="run", backend=backend, **SOLVER)
    half = (fit.upper[0] - fit.lower[0]) / 2
    return (time.perf_counter() - start, fit.iterations, fit.runs, fit.cost,
            abs(fit.estimates[0] - TRUE) / TRUE, half)


def scipy_bgc(t, data_y):
    """least_squares on residuals from runs of the plain model's C program (compiled once)."""
    from scipy.optimize import least_squares

    from bgc import api
    from bgc.execute import runner
    start = time.perf_counter()
    compiled = api.build(MODEL, "run", outputs=OUTPUTS)
    program = runner.prepare(compiled, "c")
    names = [p.name for p in compiled.program.params]
    runs = [0]

    def residuals(x):
        runs[0] += 1
        settings = runner.settings_for(compiled.program.scene, names,
                                       params={"Fc": float(x[0])}, **SOLVER)
        return (api.arrays(runner.run(program, settings))[1] - data_y).ravel()

    sol = least_squares(residuals, [START], method="trf", bounds=([0.5], [2.9]))
    return (time.perf_counter() - start, sol.nfev, runs[0], sol.cost,
            abs(sol.x[0] - TRUE) / TRUE, float("nan"))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.01)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    print(f"# machine: {machine.processor()}; {machine.cc_version(['cc'])}; load "
          f"{machine.load_average()}")
    with tempfile.TemporaryDirectory(prefix="bgc-fit-friction-") as tmp:
        os.environ["BGC_CACHE_DIR"] = str(Path(tmp) / "cache")
        data = Path(tmp) / "stick.csv"
        t, Y = make_data(data, args.noise, args.seed)
        print(f"# data: {len(t)} samples of k.q and m.p, noise s.d. {args.noise}; Fc = {TRUE} "
              f"(the fits start at {START})")
        bgc_fit(data, "c")  # (the augmented program into the cache)
        rows = []
        for label, call in [("bgc fit (C)", lambda: bgc_fit(data, "c")),
                            ("bgc fit (Python)", lambda: bgc_fit(data, "python")),
                            ("SciPy least_squares, bgc", lambda: scipy_bgc(t, Y))]:
            best = None
            for _ in range(args.repeats):
                got = call()
                best = got if best is None or got[0] < best[0] else best
            rows.append((label, *best))
        print(f"{'method':<26} {'time s':>8} {'iter':>5} {'runs':>5} {'final cost':>14} "
              f"{'Fc err':>10} {'95% half':>10}")
        for label, seconds, iterations, runs, cost, err, half in rows:
            print(f"{label:<26} {seconds:>8.3f} {iterations:>5} {runs:>5} {cost:>14.8g} "
                  f"{err:>10.2e} {half:>10.2e}")
        ratio = rows[2][1] / rows[0][1]
        print(f"\nSciPy's finite differences / bgc's sensitivities, time: {ratio:.1f}x")


if __name__ == "__main__":
    main()
