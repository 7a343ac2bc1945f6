"""What bgc lsp's diagnostics of a 100-line model cost as one types, against a `bgc check`.

    python benchmarks/lsp.py [--runs 20] [--model tests/models/dc_drive.bg]

Rows, each the least and the median of --runs runs:

  warm check, thread   bgc.editor.language's check and its reduce stage in this process, the
                       libraries parsed before (what the server's worker spends on a change),
                       as the processor time of this thread: the target is under 0.1 s
  warm check, wall     the same, wall time (the machine's other load included)
  bgc check            the baseline: `bgc check MODEL` as a process (Python's start, every
                       library parsed, every stage), wall time

The figures depend on the machine; the table is what to compare, in one run."""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bgc.editor import language  # noqa: E402


def warm(text: str, path: str, runs: int) -> tuple[list[float], list[float]]:
    language.check_reduced(language.check(text, path))  # the libraries parsed: warm
    thread, wall = [], []
    for _ in range(runs):
        t0, w0 = time.thread_time(), time.perf_counter()
        checked = language.check(text, path)
        if language.reducible(checked):
            language.check_reduced(checked)
        thread.append(time.thread_time() - t0)
        wall.append(time.perf_counter() - w0)
    return thread, wall


def process(path: str, runs: int) -> list[float]:
    wall = []
    for _ in range(runs):
        w0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "bgc", "check", path], cwd=ROOT, check=True,
                       capture_output=True)
        wall.append(time.perf_counter() - w0)
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--model", default=str(ROOT / "tests" / "models" / "dc_drive.bg"))
    args = ap.parse_args()
    text = Path(args.model).read_text("utf-8")
    thread, wall = warm(text, args.model, args.runs)
    baseline = process(args.model, max(3, args.runs // 4))
    print(f"{Path(args.model).name}: {len(text.splitlines())} lines")
    print(f"{'':22}{'least (ms)':>12}{'median (ms)':>13}")
    for name, xs in (("warm check, thread", thread), ("warm check, wall", wall),
                     ("bgc check (process)", baseline)):
        print(f"{name:22}{min(xs) * 1e3:12.1f}{statistics.median(xs) * 1e3:13.1f}")
    print(f"target: warm check under 100 ms of thread time: "
          f"{'met' if min(thread) < 0.1 else 'NOT met'}")


if __name__ == "__main__":
    main()
