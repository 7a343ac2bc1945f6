"""What a `bgc simulate` of a model compiled before costs, against the ways it could start.

    python benchmarks/warm.py [--runs 20] [--cold-runs 5] [--model models/pendulum.bg]
                              [--scene S] [--before TREE] [--backend c|python]

Each row runs a command line `--runs` times in a fresh cache directory (BGC_CACHE_DIR) and
prints the best and the median wall time (time.perf_counter around subprocess.run, the
process's start and exit included) and the median CPU time of the child (user + system):

  program alone       the cached generated program itself, writing the same CSV: the floor
  bgc --help          the command line's start: Python, click, bgc's light modules
  warm simulate       `bgc simulate MODEL -o out.csv` after a first run: bgc.execute.warm's record
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

With --backend python the program is the generated Python module: "program alone" is
`python model.py` (Python compiles the whole file at every start), "program, bytecode" the
same program started from the bytecode bgc keeps beside it (what a warm run starts), and
there is no standalone row.

The targets: a warm simulate of the pendulum under 0.15 s wall, `bgc --help` under 0.2 s
(issue 12); a cold simulate of the pendulum under 1 s wall, warm under 0.1 s (issue 27).  `bgc` is the console script on PATH if there is one, else `python -m bgc`.
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
    return [sys.executable, "-c", "import sys, bgc.codegen.emit; "
            "bgc.codegen.emit.linkable = lambda p: False; "
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


def _before_rows(args, tmp: Path, command: list[str]) -> list:
    """The warm and cold rows of another source tree of bgc (`--before TREE`), imported with
    PYTHONPATH=TREE in a cache of its own."""
    cache = tmp / "cache-before"
    env = dict(os.environ, BGC_CACHE_DIR=str(cache), PYTHONPATH=str(Path(args.before).resolve()))
    where = subprocess.run([sys.executable, "-c", "import bgc; print(bgc.__file__)"], env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
    if not where.startswith(env["PYTHONPATH"]):
        raise SystemExit(f"--before {args.before}: bgc comes from {where}")
    simulate = [sys.executable, "-m", "bgc", *command]
    subprocess.run(simulate, env=env, check=True, capture_output=True)
    return [("warm simulate, before", _timed(simulate, env, runs=args.runs)),
            ("cold, before", _timed(simulate, env, lambda: shutil.rmtree(cache),
                                    runs=args.cold_runs))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--cold-runs", type=int, default=5)
    ap.add_argument("--model", default=str(ROOT / "models" / "pendulum.bg"))
    ap.add_argument("--scene", default=None)
    ap.add_argument("--before", metavar="TREE",
                    help="a source tree of bgc (the code before a change): its warm and cold "
                         "rows in the same run")
    ap.add_argument("--backend", choices=("c", "python"), default="c")
    args = ap.parse_args(argv)

    args.model = str(Path(args.model).resolve())
    with tempfile.TemporaryDirectory(prefix="bgc-warm-bench-") as tmp:
        os.chdir(tmp)  # (python -c and -m put the working directory first on the path)
        cache = Path(tmp) / "cache"
        env = dict(os.environ, BGC_CACHE_DIR=str(cache))
        out = str(Path(tmp) / "out.csv")
        simulate = [*_bgc(), "simulate", args.model, "--backend", args.backend, "-o", out] + \
            (["--scene", args.scene] if args.scene else [])
        subprocess.run(simulate, env=env, check=True, capture_output=True)
        if args.backend == "c":
            (program,) = [[str(p)] for p in cache.glob("bgc-*")
                          if p.suffix not in (".sha256", ".py", ".pyc", ".o")]
        else:
            (program,) = [[sys.executable, str(p)] for p in cache.glob("bgc-*.py")]
            bytecode = [[sys.executable, str(p)] for p in cache.glob("bgc-*.pyc")]
        scene_args = []  # the program runs its own scene: the one it was compiled for

        def forget_records():
            for record in cache.glob("warm-*.json"):
                record.unlink()

        def empty_cache():
            shutil.rmtree(cache, ignore_errors=True)

        def keep_runtime():  # (and the parser's tables, also kept once per machine)
            for path in cache.iterdir():
                if not path.name.startswith(("bgc-runtime-", "lark-")):
                    path.unlink()

        standalone = [*_standalone(), *simulate[len(_bgc()):]]

        rows = [("program alone", _timed([*program, *scene_args], env, runs=args.runs))]
        if args.backend == "python":
            rows += [("program, bytecode", _timed([*bytecode[0], *scene_args], env,
                                                  runs=args.runs))] if bytecode else []
        rows += [
            ("bgc --help", _timed([*_bgc(), "--help"], env, runs=args.runs)),
            ("warm simulate", _timed(simulate, env, runs=args.runs)),
            ("program cached", _timed(simulate, env, forget_records, runs=args.cold_runs)),
            ("cold, runtime kept", _timed(simulate, env, keep_runtime, runs=args.cold_runs)),
            ("cold", _timed(simulate, env, empty_cache, runs=args.cold_runs)),
        ]
        if args.backend == "c":
            rows.append(("cold, standalone", _timed(standalone, env, empty_cache,
                                                    runs=args.cold_runs)))
        if args.before:
            rows += _before_rows(args, Path(tmp), simulate[len(_bgc()):])
    print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, load average "
          f"{machine.load_average()}")
    print(f"bgc:      {' '.join(_bgc())}")
    print(f"model:    {args.model}" + (f" scene {args.scene}" if args.scene else "") +
          f", backend {args.backend}" +
          f"; {args.runs} runs each ({args.cold_runs} for the program cached and cold rows)")
    print(f"{'':20}{'best wall [s]':>15}{'median wall [s]':>17}{'median cpu [s]':>16}")
    for name, (best, median, cpu) in rows:
        print(f"{name:20}{best:15.3f}{median:17.3f}{cpu:16.3f}")
    if args.backend != "c":  # the issues' targets are the C backend's
        return
    warm = dict(rows)["warm simulate"]
    helps = dict(rows)["bgc --help"]
    print(f"warm simulate: best {warm[0]:.3f} s, median {warm[1]:.3f} s (target < 0.15 s): "
          f"{'met' if warm[1] < 0.15 else 'NOT MET'}; bgc --help: median {helps[1]:.3f} s "
          f"(target < 0.2 s): {'met' if helps[1] < 0.2 else 'NOT MET'}")
    for name in ("cold, runtime kept", "cold", "cold, standalone", "cold, before"):
        if name not in dict(rows):
            continue
        cold = dict(rows)[name]
        print(f"{name}: median {cold[1]:.3f} s (target < 1 s): "
              f"{'met' if cold[1] < 1.0 else 'NOT MET'}")


if __name__ == "__main__":
    main()
