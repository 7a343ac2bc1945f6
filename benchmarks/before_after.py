"""A change measured against the code before it, in the same run.

Builds each case's generated C program and generated Python module twice, from two source trees:
the "before" tree (a git ref checked out with `git worktree add --detach` into a temporary
directory, removed at the end) and the "after" tree (this working tree, or another ref).  Each
tree's own compiler generates its programs: the tree's bgc is imported in a child process with
PYTHONPATH pointing at the tree (checked through bgc.__file__), and each C program is built with
that tree's C_FLAGS (`cc -O2 -std=c99 ... -lm`).  The models (models/*.bg and the 16-link chain
of benchmarks/families.py) are this tree's, the same text for both builds.

Timing alternates the builds run by run (one warm-up of each, then ABAB...), so that a change of
the machine's load hits both alike, and reports the medians of wall time and of the child's cpu
time (user + system, from os.wait4), and the after/before ratios.  With --callgrind it also counts
the C programs' instructions with valgrind (deterministic, immune to load).  It checks whether the
two builds write byte-identical CSV.  Nothing here asserts a time.

    python benchmarks/before_after.py --before 29f94ed [--after REF|worktree] [--repeats N]
                                      [--quick] [--plot ratios.png] [--callgrind]
"""
from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))  # machine.py, families.py

import machine  # noqa: E402
from families import pendulum_chain  # noqa: E402

# The child that generates the programs with one tree's bgc: argv = [outdir, specs JSON].
GENERATE = r"""
import json, sys
from pathlib import Path
import bgc
try:
    from bgc.base.toolchain import C_FLAGS, C_LIBS
    from bgc.codegen.emit import emit_c, emit_python
except ImportError:  # (a tree from before bgc.base.toolchain: bgc.base.backends, bgc.backends)
    try:
        from bgc.base.backends import C_FLAGS, C_LIBS
        from bgc.codegen.emit import emit_c, emit_python
    except ImportError:
        from bgc.backends import C_FLAGS, C_LIBS
        from bgc.emit import emit_c, emit_python
out, specs = Path(sys.argv[1]), json.loads(sys.argv[2])
for name, model, scene in specs:
    program = bgc.build(Path(model), scene).program
    (c_text,) = emit_c(program).values()
    (py_text,) = emit_python(program).values()
    (out / (name + ".c")).write_text(c_text)
    (out / (name + ".py")).write_text(py_text)
print(json.dumps({"bgc": bgc.__file__, "flags": list(C_FLAGS), "libs": list(C_LIBS)}))
"""


@dataclass(frozen=True)
class Model:
    name: str
    path: str  # a .bg file, or how the model is generated
    scene: str


@dataclass(frozen=True)
class Case:
    model: Model
    solver: str
    backend: str  # "c" or "python"
    args: tuple[str, ...] = ()  # beyond --solver

    @property
    def label(self) -> str:
        extra = f" {' '.join(self.args)}" if self.args else ""
        return f"{self.model.name} {self.solver} {self.backend}{extra}"


PENDULUM = Model("pendulum", "models/pendulum.bg", "long")
VDP = Model("van_der_pol", "models/van_der_pol.bg", "period")
FOUR_BAR = Model("four_bar", "models/four_bar.bg", "swing")
CHAIN = Model("chain16", "benchmarks/families.py pendulum_chain(16)", "swing")

# (model, solver, arguments of the Python module: a shorter run where the whole scene would take
# well over a second or two in Python).  The C program always runs the whole scene.
PLAN = [
    (PENDULUM, "dopri5", ("--t-end", "10")),
    (PENDULUM, "rk4", ("--t-end", "10")),
    (VDP, "radau5", ()),
    (VDP, "rodas5p", ()),
    (VDP, "radau", ()),
    (FOUR_BAR, "dop853", ("--t-end", "1")),
    (FOUR_BAR, "rodas4", ("--t-end", "0.5")),
    (CHAIN, "dopri5", ("--t-end", "0.2")),
    (CHAIN, "radau5", ("--t-end", "0.05")),
]
QUICK = {("pendulum", "dopri5"), ("van_der_pol", "radau5"), ("chain16", "dopri5")}


def cases(quick: bool) -> list[Case]:
    chosen = [p for p in PLAN if not quick or (p[0].name, p[1]) in QUICK]
    out = []
    for model, solver, py_args in chosen:
        out.append(Case(model, solver, "c"))
        out.append(Case(model, solver, "python", py_args))
    return out


# -- the two trees ---------------------------------------------------------------------------

def git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout.strip()


def checkout(ref: str, parent: Path, side: str) -> Path:
    """ref checked out (detached) in a new worktree under parent."""
    tree = parent / f"{side}-{re.sub(r'[^A-Za-z0-9_.-]', '_', ref)}"
    git("worktree", "add", "--detach", "--quiet", str(tree), ref)
    return tree


def remove_worktree(tree: Path) -> None:
    try:
        git("worktree", "remove", "--force", str(tree))
    except subprocess.CalledProcessError as err:
        print(f"warning: could not remove worktree {tree}: {err.stderr.strip()}", file=sys.stderr)
        shutil.rmtree(tree, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, check=False)


def describe(tree: Path) -> str:
    head = git("log", "-1", "--format=%h %s", cwd=tree)
    dirty = " (+ uncommitted changes)" if git("status", "--porcelain", "--untracked-files=no",
                                              cwd=tree) else ""
    return f"{head[:70]}{'...' if len(head) > 70 else ''}{dirty}"


def model_files(models: set[Model], work: Path) -> dict[str, str]:
    """Model name -> the absolute path of its source (the chain written out once)."""
    paths = {}
    for m in models:
        if m.name == "chain16":
            path = work / "chain16.bg"
            path.write_text(pendulum_chain(16))
            paths[m.name] = str(path)
        else:
            paths[m.name] = str(ROOT / m.path)
    return paths


def generate(tree: Path, out: Path, specs: list[list[str]]) -> dict:
    """The programs of specs generated by tree's own bgc into out; what the child reports."""
    out.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, "-c", GENERATE, str(out), json.dumps(specs)],
                          cwd=out, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"generating with {tree} failed:\n{done.stderr[-3000:]}")
    info = json.loads(done.stdout.strip().splitlines()[-1])
    if not Path(info["bgc"]).resolve().is_relative_to(tree.resolve()):
        raise SystemExit(f"the child imported {info['bgc']}, not the bgc of {tree}")
    return info


def compile_all(out: Path, names: list[str], info: dict, cc: list[str]) -> None:
    for name in names:
        cmd = [*cc, *info["flags"], str(out / f"{name}.c"), "-o", str(out / name), *info["libs"]]
        subprocess.run(cmd, check=True)


def c_compiler() -> list[str]:
    return (os.environ.get("CC") or "cc").split()


# -- running and timing ----------------------------------------------------------------------

def argv_of(case: Case, build: Path) -> list[str]:
    name = case.model.name
    program = ([str(build / name)] if case.backend == "c"
               else [sys.executable, str(build / f"{name}.py")])
    return [*program, "--solver", case.solver, *case.args]


def run_once(argv: list[str], sink) -> tuple[float, float]:
    """Wall and cpu (user + sys of the child) seconds of one run, its stdout into sink."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=sink, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited with {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime


def csv_digest(argv: list[str]) -> tuple[str, int]:
    """The SHA-256 of one run's CSV and its number of lines."""
    done = subprocess.run(argv, capture_output=True, check=True)
    return hashlib.sha256(done.stdout).hexdigest(), done.stdout.count(b"\n")


@dataclass
class Timing:
    wall: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)


def time_case(argvs: dict[str, list[str]], repeats: int) -> dict[str, Timing]:
    """One warm-up of each build, then repeats rounds of before, after (ABAB...)."""
    timings = {side: Timing() for side in argvs}
    with open(os.devnull, "wb") as sink:
        for argv in argvs.values():
            run_once(argv, sink)
        for _ in range(repeats):
            for side, argv in argvs.items():
                wall, cpu = run_once(argv, sink)
                timings[side].wall.append(wall)
                timings[side].cpu.append(cpu)
    return timings


def callgrind(argv: list[str], work: Path) -> int | None:
    """Instructions executed (callgrind's Ir total), or None if it failed."""
    out = work / "callgrind.out"
    done = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", *argv],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    found = re.search(r"Collected\s*:\s*(\d+)", done.stderr)
    out.unlink(missing_ok=True)
    return int(found.group(1)) if done.returncode == 0 and found else None


# -- the report ------------------------------------------------------------------------------

def fmt_s(x: float) -> str:
    return f"{x * 1e3:.2f} ms" if x < 1 else f"{x:.3f} s"


def row(case: Case, timings: dict[str, Timing], digests: dict, ir: dict | None) -> list[str]:
    b, a = timings["before"], timings["after"]
    bw, aw = statistics.median(b.wall), statistics.median(a.wall)
    bc, ac = statistics.median(b.cpu), statistics.median(a.cpu)
    cells = [case.label, fmt_s(bw), fmt_s(aw), f"{aw / bw:.3f}", fmt_s(bc), fmt_s(ac),
             f"{ac / bc:.3f}"]
    if ir is not None:
        if ir.get("before") and ir.get("after"):
            cells.append(f"{ir['before'] / 1e6:.1f}M / {ir['after'] / 1e6:.1f}M = "
                         f"{ir['after'] / ir['before']:.3f}")
        else:
            cells.append("n/a" if case.backend == "python" else "failed")
    (b_sha, b_rows), (a_sha, a_rows) = digests["before"], digests["after"]
    cells.append(f"yes ({a_rows} lines)" if b_sha == a_sha
                 else f"**no** ({b_rows} / {a_rows} lines)")
    return cells


def table(rows: list[list[str]], with_ir: bool) -> str:
    head = ["case", "wall before", "wall after", "wall a/b", "cpu before", "cpu after", "cpu a/b"]
    head += ["instr before / after = a/b"] if with_ir else []
    head += ["same CSV"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def plot(path: str, labels: list[str], ratios: dict[str, list[float]]) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("--plot: matplotlib is not installed, no plot written")
        return
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(labels) + 1.5))
    height = 0.8 / len(ratios)
    for k, (name, values) in enumerate(ratios.items()):
        ax.barh([i + k * height for i in range(len(labels))], values, height, label=name)
    ax.set_yticks([i + 0.4 - height / 2 for i in range(len(labels))], labels)
    ax.invert_yaxis()
    ax.axvline(1.0, color="black", linewidth=0.8)
    ax.set_xlabel("after / before (below 1: faster)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"plot written to {path}")


def header(args, trees: dict[str, Path], cc: list[str]) -> None:
    print(f"date:     {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%dT%H:%M:%SZ}")
    print(f"machine:  {machine.processor()}, {os.cpu_count()} cores, "
          f"load average {machine.load_average()} (start)")
    print(f"cc:       {machine.cc_version(cc)}")
    print(f"python:   {sys.version.split()[0]}")
    for side, tree in trees.items():
        print(f"{side + ':':9} {describe(tree)}")
    print(f"repeats:  {args.repeats} per build, alternated, after one warm-up of each")


# -- main ------------------------------------------------------------------------------------

def parse(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="git ref of the baseline")
    ap.add_argument("--after", default="worktree",
                    help="git ref to compare, or 'worktree' (default): this working tree")
    ap.add_argument("--repeats", type=int, help="timed runs per build (default 7, --quick 2)")
    ap.add_argument("--quick", action="store_true", help="three cases, two repeats")
    ap.add_argument("--plot", metavar="FILE.png", help="a bar chart of the after/before ratios")
    ap.add_argument("--callgrind", action="store_true",
                    help="also count the C programs' instructions with valgrind")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    if args.repeats is None:
        args.repeats = 2 if args.quick else 7
    return args


def print_cases(chosen: list[Case]) -> None:
    for case in chosen:
        print(f"{case.label}: model {case.model.path}, scene {case.model.scene}"
              + (", the scene's whole run" if not case.args else ""))


def measure(args, chosen: list[Case], builds: dict[str, Path], work: Path) -> None:
    with_ir = args.callgrind and shutil.which("valgrind") is not None
    if args.callgrind and not with_ir:
        print("--callgrind: valgrind is not installed, no instruction counts")
    rows, labels, ratios = [], [], {"wall": [], "cpu": []}
    for case in chosen:
        argvs = {side: argv_of(case, build) for side, build in builds.items()}
        digests = {side: csv_digest(argv) for side, argv in argvs.items()}
        timings = time_case(argvs, args.repeats)
        ir = None
        if with_ir:
            ir = ({side: callgrind(argv, work) for side, argv in argvs.items()}
                  if case.backend == "c" else {})
        rows.append(row(case, timings, digests, ir))
        labels.append(case.label)
        ratios["wall"].append(float(rows[-1][3]))
        ratios["cpu"].append(float(rows[-1][6]))
        print(f"  measured {case.label}", file=sys.stderr)
    print()
    print(table(rows, with_ir))
    print()
    print(f"load average {machine.load_average()} (end)")
    if args.plot:
        plot(args.plot, labels, ratios)


def main(argv=None) -> None:
    args = parse(argv)
    chosen = cases(args.quick)
    if args.list:
        print_cases(chosen)
        return
    cc = c_compiler()
    with tempfile.TemporaryDirectory(prefix="bgc-before-after-") as tmp:
        work = Path(tmp)
        trees = {}
        try:
            trees["before"] = checkout(args.before, work, "before")
            trees["after"] = ROOT if args.after == "worktree" else checkout(args.after, work, "after")
            run(args, chosen, trees, work, cc)
        finally:
            for tree in trees.values():
                if tree != ROOT:
                    remove_worktree(tree)


def run(args, chosen: list[Case], trees: dict[str, Path], work: Path, cc: list[str]) -> None:
    header(args, trees, cc)
    print_cases(chosen)
    models = {c.model for c in chosen}
    paths = model_files(models, work)
    specs = [[m.name, paths[m.name], m.scene] for m in sorted(models, key=lambda m: m.name)]
    builds = {}
    for side, tree in trees.items():
        builds[side] = work / f"build-{side}"
        info = generate(tree, builds[side], specs)
        compile_all(builds[side], [s[0] for s in specs], info, cc)
        print(f"{side + ':':9} generated by {info['bgc']}, built with cc {' '.join(info['flags'])} "
              f"... {' '.join(info['libs'])}")
    measure(args, chosen, builds, work)


if __name__ == "__main__":
    main()
