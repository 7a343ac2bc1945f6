"""What a `bgc simulate` of a model compiled before costs, against the ways it could start.

    python benchmarks/warm.py [--runs 20] [--model models/pendulum.bg] [--scene S]

Each row runs a command line `--runs` times in a fresh cache directory (BGC_CACHE_DIR) and
prints the best and the median wall time (time.perf_counter around subprocess.run, the
process's start and exit included) and the median CPU time of the child (user + system):

  program alone       the cached generated program itself, writing the same CSV: the floor
  bgc --help          the command line's start: Python, click, bgc's light modules
  warm simulate       `bgc simulate MODEL -o out.csv` after a first run: bgc.warm's record
                      names the cached program, no SymPy, no pipeline
  program cached      the same, with the warm records deleted before each run: the pipeline
                      runs (SymPy imported, the equations derived), the C program comes from
                      the cache (what every run cost before warm runs)
  cold, runtime kept  the cache emptied before each run but for the runtime object (bgc
                      builds the model-independent runtime once per machine and links each
                      model's part with it): the pipeline and the model part's compile
  cold                an empty cache before each run: the pipeline and the C compiler, the
                      runtime built too
  cold, standalone    the same, the program built as one file, runtime included (as every
                      cold run was before the runtime was built once): the baseline

The target (issue 12): a warm simulate of the pendulum under 0.15 s wall, `bgc --help` under
0.2 s.  `bgc` is the console script on PATH if there is one, else `python -m bgc`.
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine  # noqa: E402


def _bgc() -> list[str]:
    script = shutil.which("bgc")
    return [script] if script else [sys.executable, "-m", "bgc"]


def _standalone() -> list[str]:
    """bgc with the runtime never linked: every program built as the standalone file."""
    return [sys.executable, "-c", "import sys, bgc.emit; bgc.emit.linkable = lambda p: False; "
            "from bgc.cli import main; sys.argv[0] = 'bgc'; main()"]


def _timed(argv, env, before=None, runs=20):
    walls, cpus = [], []
    for _ in range(runs):
        if before:
            before()
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)
        walls.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(argv)} failed:\n{done.stderr}")
    return min(walls), statistics.median(walls), statistics.median(cpus)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--cold-runs", type=int, default=5)
    ap.add_argument("--model", default=str(ROOT / "models" / "pendulum.bg"))
    ap.add_argument("--scene", default=None)
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="bgc-warm-bench-") as tmp:
        cache = Path(tmp) / "cache"
        env = dict(os.environ, BGC_CACHE_DIR=str(cache))
        out = str(Path(tmp) / "out.csv")
        simulate = [*_bgc(), "simulate", args.model, "-o", out] + \
            (["--scene", args.scene] if args.scene else [])
        subprocess.run(simulate, env=env, check=True, capture_output=True)
        (program,) = [p for p in cache.glob("bgc-*")
                      if p.suffix not in (".sha256", ".py", ".o")]
        scene_args = []  # the program runs its own scene: the one it was compiled for

        def forget_records():
            for record in cache.glob("warm-*.json"):
                record.unlink()

        def empty_cache():
            shutil.rmtree(cache, ignore_errors=True)

        def keep_runtime():
            for path in cache.iterdir():
                if not path.name.startswith("bgc-runtime-"):
                    path.unlink()

        standalone = [*_standalone(), *simulate[len(_bgc()):]]

        rows = [
            ("program alone", _timed([str(program), *scene_args], env, runs=args.runs)),
            ("bgc --help", _timed([*_bgc(), "--help"], env, runs=args.runs)),
            ("warm simulate", _timed(simulate, env, runs=args.runs)),
            ("program cached", _timed(simulate, env, forget_records, runs=args.cold_runs)),
            ("cold, runtime kept", _timed(simulate, env, keep_runtime, runs=args.cold_runs)),
            ("cold", _timed(simulate, env, empty_cache, runs=args.cold_runs)),
            ("cold, standalone", _timed(standalone, env, empty_cache, runs=args.cold_runs)),
        ]
    print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, load average "
          f"{machine.load_average()}")
    print(f"bgc:      {' '.join(_bgc())}")
    print(f"model:    {args.model}" + (f" scene {args.scene}" if args.scene else "") +
          f"; {args.runs} runs each ({args.cold_runs} for the last four rows)")
    print(f"{'':20}{'best wall [s]':>15}{'median wall [s]':>17}{'median cpu [s]':>16}")
    for name, (best, median, cpu) in rows:
        print(f"{name:20}{best:15.3f}{median:17.3f}{cpu:16.3f}")
    warm = dict(rows)["warm simulate"]
    helps = dict(rows)["bgc --help"]
    print(f"warm simulate: best {warm[0]:.3f} s, median {warm[1]:.3f} s (target < 0.15 s): "
          f"{'met' if warm[1] < 0.15 else 'NOT MET'}; bgc --help: median {helps[1]:.3f} s "
          f"(target < 0.2 s): {'met' if helps[1] < 0.2 else 'NOT MET'}")


if __name__ == "__main__":
    main()
