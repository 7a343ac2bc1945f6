"""The CSV bytes of every shipped model, before and after a change.

Runs each model of models/ in every scene, in both backends, with the scene's own settings and
with every solver (adaptive, and with a fixed step), and records the SHA-256 of each run's CSV,
its exit status and the first line of its error output.  Two records compare with --compare:
a refactoring that is meant to keep the numbers must show no difference.

    python tools/csv_digests.py -o before.json            # on the old commit
    python tools/csv_digests.py -o after.json --compare before.json

The C programs are built as `bgc simulate` builds them (--c-build linked: the model's part
linked with the runtime built once), or as the standalone program `bgc compile` writes
(--c-build standalone); --backends c compares the C programs alone.

Not a test: it takes minutes (the Python backend's stiff runs), and a test could only compare
bgc with itself.  tests/test_parity.py holds the C-against-Python half of it.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import bgc  # noqa: E402
from bgc.base import cache, solvers
from bgc.execute import runner  # noqa: E402
from bgc.codegen.emit import emit_c, emit_python  # noqa: E402

SHORT = ("--t-end", "0.5")  # every solver, adaptive: half a second of each model
FIXED = ("--t-end", "0.05", "--step", "0.001")  # every solver with a fixed step


def programs(path: Path, scene: str | None, work: Path, c_build: str, chosen):
    compiled = bgc.build(path, scene)
    progs = {}
    if "c" in chosen and c_build == "linked":
        progs["c"] = [str(runner.c_executable(compiled.program))]
    elif "c" in chosen:
        (c_text,) = emit_c(compiled.program).values()
        progs["c"] = [str(cache.compile_c(c_text))]
    if "python" in chosen:
        (py_text,) = emit_python(compiled.program).values()
        py = work / f"{path.stem}_{scene or 'default'}.py"
        py.write_text(py_text)
        progs["python"] = [sys.executable, str(py)]
    return progs


def runs(path: Path, scene: str | None):
    yield "scene", ()
    if scene is not None:
        return
    for solver in solvers.NAMES:
        yield f"{solver}", ("--solver", solver, *SHORT)
        yield f"{solver}-fixed", ("--solver", solver, *FIXED)


def digest(argv, timeout):
    try:
        done = subprocess.run(argv, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": "timeout"}
    first = done.stderr.decode(errors="replace").strip().splitlines()[:1]
    return {"status": done.returncode, "csv": hashlib.sha256(done.stdout).hexdigest(),
            "rows": done.stdout.count(b"\n"), "stderr": first[0] if first else ""}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--compare", help="a record to compare with")
    ap.add_argument("--models", nargs="*", help="model stems (default: all of models/)")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("-j", "--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--c-build", choices=("linked", "standalone"), default="linked",
                    help="how the C programs are built (default: as bgc simulate does)")
    ap.add_argument("--backends", default="c,python", help="comma-separated: c, python")
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "models").glob("*.bg"))
    if args.models:
        paths = [p for p in paths if p.stem in args.models]
    jobs = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            graph = bgc.build(path).graph
            for scene in [None] + [s.name for s in graph.scenes]:
                progs = programs(path, scene, Path(tmp), args.c_build,
                                 args.backends.split(","))
                for label, extra in runs(path, scene):
                    for backend, prog in progs.items():
                        key = f"{path.stem}/{scene or 'default'}/{label}/{backend}"
                        jobs.append((key, [*prog, *extra]))
        with ThreadPoolExecutor(args.jobs) as pool:
            results = dict(zip([k for k, _ in jobs],
                               pool.map(lambda job: digest(job[1], args.timeout), jobs)))
    Path(args.output).write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
    pairs = [k for k in results if k.endswith("/c") and k[:-2] + "/python" in results]
    same = sum(1 for k in pairs if results[k] == results[k[:-2] + "/python"])
    print(f"{len(results)} runs; C and Python identical in {same} of {len(pairs)}")
    if args.compare:
        before = json.loads(Path(args.compare).read_text())
        changed = sorted(k for k in results if k in before and before[k] != results[k])
        for key in changed:
            print(f"changed: {key}: {before[key]} -> {results[key]}")
        print(f"{len(changed)} of {len(results)} runs changed against {args.compare}")
        return 1 if changed else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
