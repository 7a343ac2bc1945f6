"""What linking with the runtime built once costs a run: the same model's program built both
ways, its solver time side by side.

    python benchmarks/linked.py [--rounds 7]

`bgc simulate` builds a model's part and links it with the runtime compiled once per machine
(bgc.codegen.emit.c_runtime_unit); `bgc compile` and `bgc sweep` build the standalone program, where
the runtime sees the model's sizes as constants and may inline the model functions.  Each row
builds both (-O2 -std=c99, the C backend's flags), checks that they write the same bytes, and
runs them alternately `--rounds` times; cpu is the program's own clock() (--stats cpu=), the
median.  The output interval is long, so that the CSV is a small part of the time.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import machine  # noqa: E402

CASES = [  # model, arguments
    ("van_der_pol", ("--solver", "radau", "--t-end", "3000", "--dt", "10")),
    ("van_der_pol", ("--solver", "rodas5p", "--t-end", "3000", "--dt", "10")),
    ("van_der_pol", ("--solver", "dopri5", "-p", "mu=1", "--t-end", "3000", "--dt", "10")),
    ("pendulum", ("--solver", "dopri5", "--t-end", "2000", "--dt", "10", "--rtol", "1e-10")),
    ("pendulum_chain", ("--solver", "radau5", "--t-end", "50", "--dt", "1")),
    ("pendulum_chain", ("--solver", "dopri5", "--t-end", "200", "--dt", "1")),
    ("double_pendulum", ("--solver", "vern7", "--t-end", "1000", "--dt", "10")),
]


def _cpu(exe: Path, args) -> tuple[float, str]:
    done = subprocess.run([str(exe), *args, "--stats"], capture_output=True, text=True,
                          check=True)
    cpu = next(w for w in done.stderr.split() if w.startswith("cpu="))
    return float(cpu[4:]), done.stdout


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bgc-linked-bench-") as tmp:
        os.environ["BGC_CACHE_DIR"] = tmp
        os.environ.pop("BGC_CFLAGS", None)
        import bgc
        from bgc.base import cache, toolchain
        from bgc.execute import runner
        from bgc.codegen.emit import emit_c
        print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, load average "
              f"{machine.load_average()}")
        print(f"cc:       {machine.cc_version(toolchain.c_compiler())}  (flags: "
              f"{' '.join(toolchain.c_flags())})")
        print(f"rounds:   {args.rounds}, alternating; cpu: the program's own clock(), median")
        print(f"{'model':16}{'states':>7}  {'arguments':44}{'standalone [ms]':>16}"
              f"{'linked [ms]':>12}{'ratio':>7}")
        for model, run in CASES:
            program = bgc.build(ROOT / "models" / f"{model}.bg").program
            linked = runner.c_executable(program)
            alone = cache.compile_c(next(iter(emit_c(program).values())))
            times = {linked: [], alone: []}
            outputs = {}
            for _ in range(args.rounds):
                for exe in (alone, linked):
                    cpu, outputs[exe] = _cpu(exe, run)
                    times[exe].append(cpu)
            if outputs[linked] != outputs[alone]:
                raise SystemExit(f"{model} {' '.join(run)}: the two builds differ")
            a, b = statistics.median(times[alone]), statistics.median(times[linked])
            print(f"{model:16}{len(program.states):7}  {' '.join(run):44}{a * 1e3:16.1f}"
                  f"{b * 1e3:12.1f}{b / a:7.2f}")


if __name__ == "__main__":
    main()
