"""What the first `bgc simulate` of a model costs, by backend, and where the time goes.

    python benchmarks/cold.py [--runs 3] [--models models/pendulum.bg,models/pendulum_chain.bg]

For each model (its default scene) and each backend (c: the model's part built in C and linked
with the runtime built once; vm: bgc's interpreter, built once per machine, running the
program's instruction list; python: the generated module; auto: what `bgc simulate` does by
default), `bgc simulate MODEL --backend B -o out.csv` runs in a fresh process with the cache
directory (BGC_CACHE_DIR) in three states:

  empty        nothing in the cache: the runtime object (c) or the interpreter (vm) is built
               first, once per machine, unless the bgc that runs was installed from a wheel
               (`pip install .`): its package carries them, built at install (bgc.execute.prebuild),
               and the first run copies them into the cache (the line "prebuilt" says which)
  once kept    what is built once per machine is there (runtime object, interpreter, the
               parser's tables); the model's own files are not: a model's first run
  warm         a second run: bgc.execute.warm's record names the cached program

Each cell is the best wall time of --runs runs (time.perf_counter around subprocess.run, the
process's start and exit included; the machine is shared, so the best is the least disturbed)
and the best cpu time (user + system of bgc and of the compiler and program it runs: on a
loaded machine the wall time measures the load, the cpu time what the command costs).
Python's bytecode cache is on, as an installed bgc has it (PYTHONDONTWRITEBYTECODE is unset
for the runs, and bgc's modules are imported once before them).

Then the stages of a first run (once kept), their cpu time inside one fresh process per
backend (the process's and its children's):
import (bgc's modules and SymPy), compile (parse to program IR, bgc.api.build), build (the
C part, the interpreter's program or the Python module, bgc.execute.runner.prepare), run (the
program started and its CSV read back, bgc.execute.runner.run).

And what a run costs once started: the model run over a longer span (--long times its
scene's) with each backend, the cpu time the program reports (--stats) divided by its
right-side calls: the C program's and the interpreter's (the same solvers, only the model's
functions interpreted) and the Python module's.

Targets (issue 27): cold `bgc simulate models/pendulum.bg` (once kept) under 1 s wall, warm
under 0.1 s.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine  # noqa: E402

BACKENDS = ("c", "vm", "python", "auto")
KEPT = ("bgc-runtime-", "bgc-vm-", "lark-")  # built once per machine

STAGES = r"""
import json, resource, sys, time
def now():  # cpu: this process's and its children's (the compiler, the program)
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime
c0 = now()
import bgc.api, bgc.execute.runner, bgc.cli, sympy
c1 = now()
compiled = bgc.api.build(sys.argv[1])
c2 = now()
program = bgc.execute.runner.prepare(compiled, sys.argv[2])
c3 = now()
result = bgc.execute.runner.run(program)
c4 = now()
assert result.status == 0, result.stderr
print(json.dumps([c1 - c0, c2 - c1, c3 - c2, c4 - c3]))
"""


def _bgc() -> list[str]:
    script = shutil.which("bgc")
    return [script] if script else [sys.executable, "-m", "bgc"]


def _best(argv, env, before, runs):
    """(best wall, best cpu) of runs runs; cpu: the processes' user + system time (bgc's and
    the compiler's and the program's, which it waits for)."""
    wall = cpu = float("inf")
    for _ in range(runs):
        before()
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True)
        wall = min(wall, time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = min(cpu, r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(argv)} failed:\n{done.stderr}")
    return wall, cpu


def _per_rhs(model: str, backend: str, env, factor: float) -> tuple[float, int]:
    """(seconds of the program's cpu per right-side call, calls) over factor x the span."""
    script = ("import sys, bgc.api, bgc.execute.runner\n"
              "c = bgc.api.build(sys.argv[1])\n"
              "s = c.program.scene\n"
              "st = s.with_options(t_end=s.t0 + float(sys.argv[3]) * (s.t_end - s.t0))\n"
              "from bgc.execute import runner\n"
              "r = runner.run(runner.prepare(c, sys.argv[2]), st, stats=True)\n"
              "assert r.status == 0, r.stderr\n"
              "print(r.stats['cpu'], r.stats['rhs'])\n")
    done = subprocess.run([sys.executable, "-c", script, model, backend, str(factor)], env=env,
                          capture_output=True, text=True, check=True)
    cpu, rhs = done.stdout.split()
    return float(cpu) / int(rhs), int(rhs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--models", default="models/pendulum.bg,models/pendulum_chain.bg")
    ap.add_argument("--long", type=float, default=20.0,
                    help="the span of the run-cost rows, in multiples of the scene's")
    args = ap.parse_args(argv)
    models = [str((ROOT / m).resolve()) for m in args.models.split(",")]

    with tempfile.TemporaryDirectory(prefix="bgc-cold-bench-") as tmp:
        os.chdir(tmp)
        cache = Path(tmp) / "cache"
        env = dict(os.environ, BGC_CACHE_DIR=str(cache))
        # (Python's bytecode cache as an installed bgc has it, written before the first row)
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        subprocess.run([sys.executable, "-c", "import bgc.api, bgc.cli, bgc.codegen.vm, "
                        "bgc.codegen.emit, bgc.reports.plot, bgc.reports.report"], env=env,
                       check=True)
        out = str(Path(tmp) / "out.csv")

        def empty():
            shutil.rmtree(cache, ignore_errors=True)

        def keep_once():
            cache.mkdir(exist_ok=True)
            for path in cache.iterdir():
                if not path.name.startswith(KEPT):
                    path.unlink()

        def nothing():
            pass

        table = {}
        for model in models:
            for backend in BACKENDS:
                simulate = [*_bgc(), "simulate", model, "--backend", backend, "-o", out]
                table[model, backend] = (
                    _best(simulate, env, empty, args.runs),
                    _best(simulate, env, keep_once, args.runs),
                    _best(simulate, env, nothing, args.runs))
        stages = {}
        for model in models:
            for backend in ("c", "vm", "python"):
                best = None
                for _ in range(args.runs):
                    keep_once()
                    done = subprocess.run([sys.executable, "-c", STAGES, model, backend],
                                          env=env, capture_output=True, text=True, check=True)
                    times = json.loads(done.stdout)
                    if best is None or sum(times) < sum(best):
                        best = times
                stages[model, backend] = best
        costs = {(model, b): _per_rhs(model, b, env, args.long)
                 for model in models for b in ("c", "vm", "python")}

    print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, load average "
          f"{machine.load_average()} (shared: the best of {args.runs} runs)")
    print(f"compiler: {machine.cc_version(['cc'])}; BGC_CFLAGS={os.environ.get('BGC_CFLAGS', '')}")
    print(f"prebuilt: {_prebuilt()}")
    print()
    print("bgc simulate MODEL --backend B: wall [s] / cpu [s]")
    print(f"{'model':22}{'backend':>8}{'empty':>16}{'once kept':>16}{'warm':>16}")
    for (model, backend), cells in table.items():
        print(f"{Path(model).stem:22}{backend:>8}"
              + "".join(f"{w:9.3f} /{c:6.3f}" for w, c in cells))
    print()
    print("a first run's stages (once kept), cpu [s]")
    print(f"{'model':22}{'backend':>8}{'import':>9}{'compile':>9}{'build':>9}{'run':>9}"
          f"{'total':>9}")
    for (model, backend), times in stages.items():
        print(f"{Path(model).stem:22}{backend:>8}" + "".join(f"{t:9.3f}" for t in times)
              + f"{sum(times):9.3f}")
    print()
    print(f"a run's cost per right-side call ({args.long:g} x the scene's span; the program's "
          "cpu / rhs calls)")
    print(f"{'model':22}{'rhs calls':>10}{'c [us]':>9}{'vm [us]':>9}{'python [us]':>13}"
          f"{'vm / c':>8}{'py / vm':>9}")
    for model in models:
        c, n = costs[model, "c"]
        v, _ = costs[model, "vm"]
        p, _ = costs[model, "python"]
        print(f"{Path(model).stem:22}{n:10d}{c * 1e6:9.3f}{v * 1e6:9.3f}{p * 1e6:13.3f}"
              f"{v / c:8.2f}{p / v:9.1f}")
    print()
    pend = [m for m in models if Path(m).stem == "pendulum"]
    if pend:
        (empty, empty_cpu), (cold, cold_cpu), (warm, warm_cpu) = table[pend[0], "auto"]
        print(f"bgc simulate models/pendulum.bg (auto): empty cache {empty:.3f} s wall, "
              f"{empty_cpu:.3f} s cpu, a model's first run {cold:.3f} s wall, {cold_cpu:.3f} s "
              f"cpu (target < 1 s): {'met' if max(empty, cold) < 1.0 else 'NOT MET'}; warm "
              f"{warm:.3f} s wall, {warm_cpu:.3f} s cpu (target < 0.1 s): "
              f"{'met' if warm < 0.1 else 'NOT MET'}")


def _prebuilt() -> str:
    """Which of bgc.execute.prebuild's files the bgc that runs carries (none in an editable
    install)."""
    done = subprocess.run([sys.executable, "-c", "import bgc.base.cache as b; "
                           "print(' '.join(p.name for p in b.PREBUILT.glob('*')))"],
                          capture_output=True, text=True, check=True)
    kinds = {"bgc-vm-": "the interpreter", "bgc-runtime-": "the runtime object",
             "lark-": "the parser's tables"}
    found = [what for prefix, what in kinds.items()
             if any(n.startswith(prefix) for n in done.stdout.split())]
    return (f"yes ({', '.join(found)}: built when the package was installed)" if found else
            "no (an editable install: what is built once per machine is built by the first run)")


if __name__ == "__main__":
    main()
