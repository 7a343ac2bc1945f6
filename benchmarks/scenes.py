"""What each scene saves: states, operations, code size, compile time and run time of every
scene of a model beside the full model, in one run.

    python benchmarks/scenes.py [--model FILE.bg] [--repeats N] [--t-end T] [--solver NAME]
                                [--step H] [--no-own] [--callgrind] [--quick] [--plot FILE.png]

Rows: the full model first (its default scene, `bgc.build(model, None)`: every effect, every
state an output), then each scene the model declares, in its order.  Columns of the table:

  physics  "all effects" for the full model; "= S" when the scene takes the same effects as
           the row S above it (so it can only prune: the same equations, fewer of them
           computed); else "-N effects": N effects of the full model left out (other
           physics).  The effects left out are listed under the table.
  states   states integrated (len(program.states)); pruned: states of the scene's physics
           that no output needs; out: states of the full model left out with the effects.
  alg      algebraic unknowns solved in the right side (sum of len(block.unknowns) over the
           reduced blocks);  mult: constraint multipliers computed (a step or block defines
           them).
  rhs ops, out ops  operations of the generated right side and outputs, counted on the IR by
           bgc.ir.count_ops(program, ("rhs",)) and (("outputs",)), totalled over
           bgc.reports.report.OP_KINDS (add, neg, mul, div, call, solve: one solve of a linear block
           counts 1, as in `bgc check`).  The full model's outputs are its states: 0 ops.
  C bytes  the generated C file less its model-independent parts
  (bgc.codegen.emit.c_runtime_parts(),
           the same bytes in every program; the idea of tests/test_golden.py's model_part).
  bgc s    bgc's front end, model file to C text: bgc.build + bgc.codegen.emit.emit_c, in this
           process, SymPy's cache cleared before each (wall, median over the repeats).
  cc s     bgc.base.cache.compile_c of that text (cc -O2 -std=c99 ... -lm, the whole program),
           into a private cache emptied before each (wall, median).
  rhs      right-side evaluations of the timed run: the generated C program with the SAME
           solver and settings for every row (default --solver rk4 --step 1e-3 --t-end 60,
           writing 2 rows: --dt t_end), so rows compare.
  cpu ms   the `cpu=` of the program's `--stats` line: its own clock() around bgc_simulate,
           no process start-up (median of 5 runs a round, over the rounds).  ns/rhs: cpu
           over rhs evaluations (the solver's own work per stage included).
  x full   a ratio to the full model's row: right-side ops, cpu (every row makes the same
           number of rhs evaluations, so it is also the ratio of ns/rhs).

A second table (unless --no-own) runs each row with its own solver and tolerances (the
scene's `solver` line; the full model's defaults) over the same 0..t_end, writing 2 rows:
accepted and rejected steps, rhs evaluations, cpu.  Different tolerances there make rows
differ by more than what they compute: read steps against rtol.

--callgrind (needs valgrind) counts instructions, which the machine's load does not disturb:
those of one more rhs evaluation in the common fixed-step run (runs of 2000 and 4000 steps
under callgrind, differenced, so that process start and set-up cancel), column ins/rhs, and a
table of where they go, by callgrind_annotate's self cost per function: model = bgc_model_*
(the generated right side, unless the compiler inlined it into the solver), blocks =
bgc_block_* (the runtime's sparse LU of the algebraic blocks), rest = the solver's stage sums
and step loop and the copies.

Under the tables, one line per scene: does the cost per rhs evaluation (cpu, and with
--callgrind instructions) fall in proportion to the right-side ops (within 15%)?  And a
least-squares line cpu/rhs = a + b * ops over the rows: a is what an evaluation costs
regardless of the model's arithmetic.  Each round compiles every row in turn, then runs every
row's program in turn, five times over, so that a change of load hits all rows alike.  Times
are printed, never asserted.  --plot writes a bar chart of ops, states, run time and
instructions relative to the full model, in the common run (needs matplotlib).
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]  # machine.py beside this file, bgc above
import machine  # noqa: E402

import bgc  # noqa: E402
from bgc.base import cache, toolchain
from bgc import ir  # noqa: E402
from bgc.codegen.emit import c_runtime_parts, emit_c  # noqa: E402
from bgc.front.graph import model_effects  # noqa: E402
from bgc.ir import defines  # noqa: E402
from bgc.reports.report import OP_KINDS  # noqa: E402

MODEL = ROOT / "models" / "gantry_crane.bg"
FULL = "(full model)"
RUNS_PER_ROUND = 5  # runs of each program per round (they are short; cc is not)
CALLGRIND_STEPS = 2000  # --callgrind: runs of 2000 and 4000 fixed steps
STATS_FIELD = re.compile(r"(\w+)=(\S+)")


@dataclass
class Row:
    """One scene (scene None: the full model).  The static part is filled by describe()."""
    name: str
    scene: str | None
    effects: frozenset  # the effects the row takes
    effects_out: tuple  # the full model's effects it leaves out
    states: int
    pruned: int
    out: int
    unknowns: int
    multipliers: int
    rhs_ops: int
    out_ops: int
    c_bytes: int
    own: tuple  # (solver, rtol, atol) of the scene
    physics: str = ""
    c_text: str = field(default="", repr=False)
    exe: Path | None = None
    front: list = field(default_factory=list)  # seconds, one per round
    cc: list = field(default_factory=list)
    cpu: list = field(default_factory=list)
    rhs: int | None = None
    own_cpu: list = field(default_factory=list)
    own_stats: dict = field(default_factory=dict)
    instr: dict = field(default_factory=dict)  # --callgrind: instructions per rhs, by part

    @property
    def instr_per_rhs(self) -> float | None:
        return self.instr.get("total")

    @property
    def cpu_per_rhs(self) -> float | None:
        return median(self.cpu) / self.rhs if self.cpu and self.rhs else None

    def per_rhs(self, metric: str) -> float | None:
        return self.cpu_per_rhs if metric == "cpu" else self.instr_per_rhs  # "instr"


def total(ops) -> int:
    return sum(ops[k] for k in OP_KINDS)


def model_part(text: str) -> str:
    for part in c_runtime_parts().values():
        text = text.replace(part, "")
    return text


def multipliers_computed(reduced) -> int:
    """Constraint multipliers that some step or block of the right side defines."""
    defined = set()
    for step in reduced.steps:
        defined.update(defines(step))
    return sum(1 for k in reduced.constraints if k.multiplier in defined)


def front_end(model: Path, scene: str | None):
    """bgc's model -> C text: (compiled, the C text)."""
    compiled = bgc.build(model, scene)
    (text,) = emit_c(compiled.program).values()
    return compiled, text


def describe(model: Path, scene: str | None, full=None) -> Row:
    """The row's counts, no timing.  full: the full model's Compiled (for the states left out
    with the effects), built here when not given."""
    compiled, text = front_end(model, scene)
    if full is None:
        full = compiled if scene is None else bgc.build(model, None)
    s = compiled.settings
    known = model_effects(full.graph.elements)  # in the model's order
    effects = frozenset(known if s.effects is None else set(s.effects) & set(known))
    in_physics = {st.name for st in compiled.system.states}
    program = compiled.program
    return Row(
        name=FULL if scene is None else scene, scene=scene, effects=effects,
        effects_out=tuple(e for e in known if e not in effects), states=len(program.states),
        pruned=len(compiled.reduced.pruned),
        out=sum(1 for st in full.reduced.states if st.name not in in_physics),
        unknowns=sum(len(b.unknowns) for b in compiled.reduced.blocks),
        multipliers=multipliers_computed(compiled.reduced),
        rhs_ops=total(ir.count_ops(program, ("rhs",))),
        out_ops=total(ir.count_ops(program, ("outputs",))),
        c_bytes=len(model_part(text).encode()), own=(s.solver, s.rtol, s.atol), c_text=text)


def describe_all(model: Path, scenes: list[str] | None = None) -> list[Row]:
    """The full model's row, then each scene's (all the model's scenes when None)."""
    full = bgc.build(model, None)
    if scenes is None:
        scenes = [sc.name for sc in full.graph.scenes]
    rows = [describe(model, None, full)] + [describe(model, sc, full) for sc in scenes]
    for k, row in enumerate(rows):
        same = next((r.name for r in rows[:k] if r.effects == row.effects), None)
        n = len(row.effects_out)
        row.physics = f"= {same}" if same else (f"-{n} effect{'s' * (n > 1)}" if n
                                                 else "all effects")
    return rows


# ---------------------------------------------------------------- timing

def median(values):
    return statistics.median(values) if values else None


def parse_stats(stderr: str) -> dict:
    line = next((ln for ln in stderr.splitlines() if ln.startswith("stats:")), "")
    return {k: float(v) for k, v in STATS_FIELD.findall(line)}


def run_program(exe: Path, args: list[str]) -> dict:
    done = subprocess.run([str(exe), *args, "--stats"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True)
    stats = parse_stats(done.stderr)
    if done.returncode != 0 or "cpu" not in stats:
        raise RuntimeError(f"{exe.name} {' '.join(args)} exited {done.returncode}: "
                           f"{done.stderr.strip()}")
    return stats


def fixed_args(args) -> list[str]:
    return ["--solver", args.solver, "--step", repr(args.step), "--t-end", repr(args.t_end),
            "--dt", repr(args.t_end)]


def own_args(row: Row, args) -> list[str]:
    solver, rtol, atol = row.own
    return ["--solver", solver, "--rtol", repr(rtol), "--atol", repr(atol),
            "--t-end", repr(args.t_end), "--dt", repr(args.t_end)]


def time_compile(model: Path, row: Row) -> None:
    from sympy.core.cache import clear_cache

    clear_cache()
    start = time.perf_counter()
    _, text = front_end(model, row.scene)
    row.front.append(time.perf_counter() - start)
    if row.exe is not None:
        row.exe.unlink(missing_ok=True)  # the private cache: cc runs again
    start = time.perf_counter()
    row.exe = cache.compile_c(text)
    row.cc.append(time.perf_counter() - start)


ANNOTATE_LINE = re.compile(r"^\s*([\d,]+) \(\s*[\d.]+%\)\s+(?:\S*?:)?([A-Za-z_]\w*)")
PARTS = ("model", "blocks", "rest")  # --callgrind's split of an evaluation's instructions


def count_instructions(exe: Path, args: list[str], workdir: Path) -> tuple[dict, int] | None:
    """({"total", "model", "blocks", "rest": instructions}, rhs evaluations) of a run under
    valgrind's callgrind, or None.  model: the functions bgc_model_* (the generated right
    side, when the compiler did not inline it), blocks: bgc_block_* (the runtime's sparse LU
    of the algebraic blocks), rest: the solver and everything else; by callgrind_annotate's
    self cost per function (without it, the total only)."""
    out = workdir / "callgrind.out"
    proc = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                           str(exe), *args, "--stats"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True)
    found, stats = re.search(r"Collected : (\d+)", proc.stderr), parse_stats(proc.stderr)
    if proc.returncode != 0 or not found or "rhs" not in stats:
        return None
    counts = dict.fromkeys(PARTS, 0)
    counts["total"] = int(found.group(1))
    try:
        annotated = subprocess.run(["callgrind_annotate", "--threshold=100", str(out)],
                                   capture_output=True, text=True).stdout
    except OSError:
        annotated = ""
    for line in annotated.splitlines():
        hit = ANNOTATE_LINE.match(line)
        if hit and hit.group(2).startswith(("bgc_model_", "bgc_block_")):
            part = "model" if hit.group(2).startswith("bgc_model_") else "blocks"
            counts[part] += int(hit.group(1).replace(",", ""))
    if not annotated:
        counts["model"] = counts["blocks"] = None
    else:
        counts["rest"] = counts["total"] - counts["model"] - counts["blocks"]
    return counts, int(stats["rhs"])


def instructions_per_rhs(row: Row, args, workdir: Path) -> dict | None:
    """The instructions one more rhs evaluation costs in the common fixed-step run (solver
    work included), by part: two runs, of CALLGRIND_STEPS and twice as many steps,
    differenced, so that the process start and the set-up cancel."""
    counts = []
    for n in (CALLGRIND_STEPS, 2 * CALLGRIND_STEPS):
        t_end = n * args.step
        counted = count_instructions(row.exe, ["--solver", args.solver, "--step",
                                               repr(args.step), "--t-end", repr(t_end),
                                               "--dt", repr(t_end)], workdir)
        if counted is None:
            return None
        counts.append(counted)
    (c1, r1), (c2, r2) = counts
    if r2 <= r1:
        return None
    return {k: None if c1[k] is None else (c2[k] - c1[k]) / (r2 - r1) for k in c1}


def measure(model: Path, rows: list[Row], args) -> None:
    """A warm-up round (untimed: imports, the first build, a failing program fails here), then
    --repeats rounds: each compiles every row once in turn, then runs every row's program
    once in turn, RUNS_PER_ROUND times."""
    for row in rows:
        row.exe = cache.compile_c(row.c_text)
        row.rhs = int(run_program(row.exe, fixed_args(args))["rhs"])
        if args.own:
            run_program(row.exe, own_args(row, args))
    front_end(model, None)
    for _ in range(args.repeats):
        for row in rows:
            time_compile(model, row)
        for _ in range(RUNS_PER_ROUND):
            for row in rows:
                stats = run_program(row.exe, fixed_args(args))
                row.cpu.append(stats["cpu"])
                if int(stats["rhs"]) != row.rhs:
                    raise RuntimeError(f"{row.name}: the fixed-step run changed its rhs count")
                if args.own:
                    stats = run_program(row.exe, own_args(row, args))
                    row.own_cpu.append(stats["cpu"])
                    row.own_stats = stats
    if args.callgrind:
        with tempfile.TemporaryDirectory(prefix="bgc-scenes-cg-") as workdir:
            for row in rows:
                row.instr = instructions_per_rhs(row, args, Path(workdir)) or {}


# ---------------------------------------------------------------- reporting

def fmt(value, spec: str, width: int, unit: str = "") -> str:
    return format("n/a" if value is None else format(value, spec) + unit, f">{width}")


def ratio(a, b):
    return a / b if a is not None and b else None


def machine_facts(args) -> list[str]:
    import numpy
    import sympy

    return [f"date:     {datetime.datetime.now().isoformat(timespec='seconds')}",
            f"cc:       {machine.cc_version(toolchain.c_compiler())}  (flags: "
            f"{' '.join(toolchain.C_FLAGS)} ... {' '.join(toolchain.C_LIBS)})",
            f"python:   {sys.version.split()[0]}  bgc {bgc.__version__}  numpy "
            f"{numpy.__version__}  sympy {sympy.__version__}",
            f"machine:  {machine.processor()}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, load average {machine.load_average()}",
            f"model:    {display(args.model)}; run: --solver {args.solver} --step {args.step:g} "
            f"--t-end {args.t_end:g} --dt {args.t_end:g} for every row",
            f"timing:   medians of {args.repeats} rounds after a warm-up (runs: "
            f"{RUNS_PER_ROUND} a round); cpu: the program's own clock() (stats cpu=); "
            f"bgc, cc: wall"]


def display(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def main_table(rows: list[Row]) -> list[str]:
    full = rows[0]
    head = (f"{'scene':<14}{'physics':<15}{'states':>6}{'pruned':>7}{'out':>4}{'alg':>4}"
            f"{'mult':>5}{'rhs ops':>8}{'x full':>7}{'out ops':>8}{'C bytes':>8}{'bgc s':>7}"
            f"{'cc s':>6}{'rhs':>9}{'cpu ms':>8}{'x full':>7}{'ns/rhs':>7}")
    if any(r.instr_per_rhs for r in rows):
        head += f"{'ins/rhs':>8}{'x full':>7}"
    lines = [head, "-" * len(head)]
    for r in rows:
        cpu = median(r.cpu)
        lines.append(
            f"{r.name:<14}{r.physics:<15}{r.states:>6}{r.pruned:>7}{r.out:>4}{r.unknowns:>4}"
            f"{r.multipliers:>5}{r.rhs_ops:>8}{fmt(ratio(r.rhs_ops, full.rhs_ops), '.2f', 7)}"
            f"{r.out_ops:>8}{r.c_bytes:>8}{fmt(median(r.front), '.3f', 7)}"
            f"{fmt(median(r.cc), '.2f', 6)}{fmt(r.rhs, 'd', 9)}"
            f"{fmt(None if cpu is None else cpu * 1e3, '.2f', 8)}"
            f"{fmt(ratio(cpu, median(full.cpu)), '.2f', 7)}"
            f"{fmt(None if r.cpu_per_rhs is None else r.cpu_per_rhs * 1e9, '.1f', 7)}"
            + (f"{fmt(r.instr_per_rhs, '.0f', 8)}"
               f"{fmt(ratio(r.instr_per_rhs, full.instr_per_rhs), '.2f', 7)}"
               if any(x.instr_per_rhs for x in rows) else ""))
    return lines


def legend(rows: list[Row]) -> list[str]:
    runtime = sum(len(p.encode()) for p in c_runtime_parts().values())
    lines = [f"every program also carries {runtime} bytes of runtime (not in C bytes)",
             "effects left out (against the full model):"]
    for r in rows:
        lines.append(f"  {r.name:<13} {', '.join(r.effects_out) or 'none'}")
    return lines


def own_table(rows: list[Row]) -> list[str]:
    full = rows[0]
    head = (f"{'scene':<14}{'solver':<8}{'rtol':>7}{'atol':>7}{'steps':>8}{'rejected':>9}"
            f"{'rhs':>8}{'cpu ms':>8}{'x full':>7}")
    lines = [head, "-" * len(head)]
    for r in rows:
        st, cpu = r.own_stats, median(r.own_cpu)
        solver, rtol, atol = r.own
        lines.append(f"{r.name:<14}{solver:<8}{rtol:>7.0e}{atol:>7.0e}"
                     f"{fmt(int(st['steps']) if st else None, 'd', 8)}"
                     f"{fmt(int(st['rejected']) if st else None, 'd', 9)}"
                     f"{fmt(int(st['rhs']) if st else None, 'd', 8)}"
                     f"{fmt(None if cpu is None else cpu * 1e3, '.3f', 8)}"
                     f"{fmt(ratio(cpu, median(full.own_cpu)), '.2f', 7)}")
    return lines


def instr_table(rows: list[Row]) -> list[str]:
    """--callgrind: where an evaluation's instructions go."""
    head = (f"{'scene':<14}{'states':>6}{'rhs ops':>8}{'total':>8}{'model':>8}{'per op':>7}"
            f"{'blocks':>8}{'rest':>8}{'per state':>10}")
    lines = [head, "-" * len(head)]
    for r in rows:
        i = r.instr
        model, blocks, rest = i.get("model"), i.get("blocks"), i.get("rest")
        inlined = model == 0 and r.rhs_ops > 0
        lines.append(f"{r.name:<14}{r.states:>6}{r.rhs_ops:>8}{fmt(i.get('total'), '.0f', 8)}"
                     f"{'inlined' if inlined else fmt(model, '.0f', 0):>8}"
                     f"{fmt(None if inlined else ratio(model, r.rhs_ops), '.1f', 7)}"
                     f"{fmt(blocks, '.0f', 8)}{fmt(rest, '.0f', 8)}"
                     f"{fmt(ratio(rest, r.states), '.1f', 10)}")
    return lines


def fit(rows: list[Row], metric: str):
    """Least squares per_rhs(metric) = a + b * ops over the rows: (a, b), or None."""
    pts = [(r.rhs_ops, r.per_rhs(metric)) for r in rows if r.per_rhs(metric)]
    if len(pts) < 3 or len({x for x, _ in pts}) < 2:
        return None
    n = len(pts)
    mx, my = sum(x for x, _ in pts) / n, sum(y for _, y in pts) / n
    b = sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)
    return my - b * mx, b


def verdict(measured: float, ops: float) -> str:
    off = measured / ops
    if abs(math.log(off)) <= math.log(1.15):
        return "in proportion (within 15%)"
    return f"falls {'less' if off > 1 else 'more'} than the ops ({off:.2f}x their ratio)"


def proportion_lines(rows: list[Row]) -> list[str]:
    """Per scene: the run time per rhs evaluation (and with --callgrind the instructions)
    against the right-side ops, each relative to the full model."""
    full = rows[0]
    lines = ["does the cost of a rhs evaluation fall in proportion to the right side's ops?"]
    line = fit(rows, "cpu")
    if line:
        a, b = line[0] * 1e9, line[1] * 1e9
        lines.append(f"  least squares over the rows: cpu/rhs = {a:.1f} ns + {b:.3f} ns x ops "
                     f"(the full model: {a:.1f} + {b * full.rhs_ops:.1f} ns)")
    for r in rows[1:]:
        ops_r = ratio(r.rhs_ops, full.rhs_ops)
        cpu_r = ratio(r.cpu_per_rhs, full.cpu_per_rhs)
        if not ops_r or cpu_r is None:
            lines.append(f"  {r.name:<13} n/a")
            continue
        text = (f"  {r.name:<13} ops {ops_r:.2f}x ({r.states}/{full.states} states): cpu/rhs "
                f"{cpu_r:.2f}x, {verdict(cpu_r, ops_r)}")
        instr_r = ratio(r.instr_per_rhs, full.instr_per_rhs)
        if instr_r is not None:
            model = ratio(r.instr.get("model"), full.instr.get("model"))
            own = f" (the model's own {model:.2f}x)" if model else ""  # 0: inlined
            text += f"; instructions/rhs {instr_r:.2f}x{own}, {verdict(instr_r, ops_r)}"
        lines.append(text)
    return lines


def plot(rows: list[Row], path: str, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    full = rows[0]
    series = [("right-side ops", [ratio(r.rhs_ops, full.rhs_ops) for r in rows]),
              ("states", [ratio(r.states, full.states) for r in rows]),
              (f"cpu, {args.solver} h={args.step:g} (= cpu per rhs)",
               [ratio(median(r.cpu), median(full.cpu)) for r in rows])]
    if full.instr_per_rhs:
        series.append(("instructions per rhs", [ratio(r.instr_per_rhs, full.instr_per_rhs)
                                                for r in rows]))
    fig, ax = plt.subplots(figsize=(11, 4.5))
    where = np.arange(len(rows))
    width = 0.8 / len(series)
    for k, (label, values) in enumerate(series):
        bars = ax.bar(where + (k - (len(series) - 1) / 2) * width,
                      [np.nan if v is None else v for v in values], width, label=label)
        ax.bar_label(bars, fmt="%.2f", fontsize=6)
    ax.axhline(1.0, color="gray", lw=0.8)
    ax.set_xticks(where, [f"{r.name}\n{r.physics}" for r in rows], fontsize=8)
    ax.set_ylabel("relative to the full model")
    ax.set_ylim(0, 1.3 * max(v for _, values in series for v in values if v is not None))
    ax.set_title(f"{display(args.model)}: what each scene saves (medians of {args.repeats})")
    ax.legend(fontsize=8, loc="upper center", ncol=len(series))
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------- main

def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=MODEL, help="a .bg file with scenes")
    parser.add_argument("--repeats", type=int, help="rounds (median); default 5, 1 with --quick")
    parser.add_argument("--t-end", type=float, help="end time of every run [s]; default 60, "
                        "6 with --quick")
    parser.add_argument("--solver", default="rk4", help="the common solver (default rk4)")
    parser.add_argument("--step", type=float, default=1e-3, help="its step (default 1e-3)")
    parser.add_argument("--no-own", dest="own", action="store_false",
                        help="skip the runs with each scene's own solver")
    parser.add_argument("--callgrind", action="store_true",
                        help="also count the instructions of a rhs evaluation (needs valgrind)")
    parser.add_argument("--quick", action="store_true", help="a smoke run: 1 round, 0..6 s")
    parser.add_argument("--plot", metavar="FILE.png", help="bar chart against the full model")
    args = parser.parse_args(argv)
    args.repeats = args.repeats or (1 if args.quick else 5)
    args.t_end = args.t_end or (6.0 if args.quick else 60.0)
    if args.repeats < 1 or not args.t_end > 0 or not args.step > 0:
        parser.error("--repeats must be >= 1, --t-end and --step > 0")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if not toolchain.have_c_compiler():
        print("no C compiler (cc or $CC): nothing to time", file=sys.stderr)
        return 1
    print("\n".join(machine_facts(args)), flush=True)
    rows = describe_all(args.model)
    with tempfile.TemporaryDirectory(prefix="bgc-scenes-") as cache:
        previous = os.environ.get("BGC_CACHE_DIR")
        os.environ["BGC_CACHE_DIR"] = cache  # cc really runs; the user's cache untouched
        try:
            measure(args.model, rows, args)
        finally:
            if previous is None:
                del os.environ["BGC_CACHE_DIR"]
            else:
                os.environ["BGC_CACHE_DIR"] = previous
    print()
    print("\n".join(main_table(rows)))
    print("\n".join(legend(rows)))
    if args.own:
        print(f"\neach row's own solver and tolerances, 0..{args.t_end:g} s, 2 rows out:")
        print("\n".join(own_table(rows)))
    if any(r.instr for r in rows):
        print(f"\ninstructions per rhs evaluation (callgrind, runs of {CALLGRIND_STEPS} and "
              f"{2 * CALLGRIND_STEPS} {args.solver} steps differenced), by function:\n"
              "model = bgc_model_* (the generated right side; 'inlined': the compiler put it "
              "into the solver, counted in rest),\nblocks = bgc_block_* (the runtime's LU of "
              "the algebraic blocks), rest = the solver's stage sums, step loop and copies")
        print("\n".join(instr_table(rows)))
    print()
    print("\n".join(proportion_lines(rows)))
    print(f"\nload average at the end: {machine.load_average()}")
    if args.plot:
        try:
            plot(rows, args.plot, args)
            print(f"plot written to {args.plot}")
        except ImportError:
            print("no matplotlib: no plot")
    return 0


if __name__ == "__main__":
    sys.exit(main())
