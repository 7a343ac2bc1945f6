"""Time the source paper's Baumgarte-stabilised pendulum four ways and print one table.

    python benchmarks/pendulum.py [--repeats N] [--t-end T] [--plot out.png] [--callgrind]

Scene `long` of models/pendulum.bg: 0..100 s, output every 0.01 s, dopri5 rtol 1e-8, atol 1e-10.
The four rows:
  bgc C program      the generated C program, run as a process writing its CSV to a file
  bgc Python module  the generated Python module's simulate(), in this process
  SciPy RK45         solve_ivp(method="RK45") on a sympy.lambdify right side typed from eq. (12)
  hand-written C     benchmarks/handwritten_dopri5.c, the baseline for the generated C
Times are medians over the repeats (after one warm-up): wall clock, and CPU (user + system, of
this process and its children) which a busy machine disturbs less.  Errors are the max over the
output grid of |x - x_ref| and |y - y_ref|, the reference being DOP853 at rtol = atol = 1e-13
with dense output.  Timings are printed, never asserted.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MODEL = ROOT / "models" / "pendulum.bg"
HANDWRITTEN = HERE / "handwritten_dopri5.c"
sys.path.insert(0, str(HERE))  # machine.py, beside this file
import machine  # noqa: E402
SCENE = "long"
DT, RTOL, ATOL = 0.01, 1e-8, 1e-10
REF_TOL, REF_CHECK_TOL = 1e-13, 1e-12
PARAMS = {"m": 1.0, "l": 1.0, "g": 9.81, "theta0": 0.5, "alpha": 5.0, "beta": 5.0}
CFLAGS = ("-O2", "-std=c99")
STATS = re.compile(r"stats: steps=(\d+)(?: rejected=(\d+))?(?: rhs=(\d+))?")
TARGET_C_RATIO, TARGET_SCIPY_RATIO = 1.5, 100.0


@dataclass(frozen=True)
class Timing:
    wall: float  # median wall-clock seconds
    cpu: float   # median CPU seconds (user + system, this process and its children)


@dataclass
class Run:
    """One way of solving the scene: its timings, counters and output."""
    name: str
    full: Timing | None = None
    quiet: Timing | None = None  # C programs: the same run writing 2 rows (--dt t_end)
    plain: Timing | None = None  # bgc C built with -DBGC_PLAIN_PRINTF (snprintf for numbers)
    rhs: int | None = None
    steps: int | None = None
    rejected: int | None = None
    t: np.ndarray | None = None
    xy: np.ndarray | None = None  # columns x, y
    error: float | None = None
    instructions: int | None = None  # --callgrind: instructions of the 2-row run
    note: str = ""


# ---------------------------------------------------------------- the equations, eq. (12)

def pendulum_rhs():
    """A sympy.lambdify right side f(t, s) of eq. (12), s = (px, py, x, y); and s(0)."""
    import sympy as sp

    px, py, x, y, t = sp.symbols("px py x y t")
    m, l, g, alpha, beta = (sp.Float(PARAMS[k]) for k in ("m", "l", "g", "alpha", "beta"))
    xd, yd = px / m, py / m
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    xdd = -x / (x**2 + y**2) * bracket
    ydd = g - y / (x**2 + y**2) * bracket
    f = sp.lambdify((t, (px, py, x, y)), [m * xdd, m * ydd, xd, yd], modules="math", cse=True)
    theta0, length = PARAMS["theta0"], PARAMS["l"]
    return f, np.array([0.0, 0.0, length * np.sin(theta0), length * np.cos(theta0)])


def output_grid(t_end: float) -> np.ndarray:
    """t0 + k dt while below t_end, then t_end (the CSV convention of docs/cli.md)."""
    n = int(np.ceil(t_end / DT - 1e-6))
    return np.append(np.arange(n) * DT, t_end)


class Reference:
    """DOP853 at rtol = atol = tol with dense output: x(t), y(t) anywhere in [0, t_end]."""

    def __init__(self, t_end: float, tol: float = REF_TOL):
        from scipy.integrate import solve_ivp

        f, s0 = pendulum_rhs()
        self.solution = solve_ivp(f, (0.0, t_end), s0, method="DOP853", rtol=tol, atol=tol,
                                  dense_output=True)
        if not self.solution.success:
            raise RuntimeError(f"reference failed: {self.solution.message}")

    def xy(self, t: np.ndarray) -> np.ndarray:
        return self.solution.sol(t)[2:4].T

    def error(self, t: np.ndarray, xy: np.ndarray) -> float:
        return float(np.max(np.abs(xy - self.xy(t))))


# ---------------------------------------------------------------- timing helpers

def cpu_seconds() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def measure(actions: dict, repeats: int) -> dict:
    """{key: Timing}: medians over `repeats` rounds, each round running every action once in
    turn, so that a change of load on the machine hits all of them alike."""
    walls = {key: [] for key in actions}
    cpus = {key: [] for key in actions}
    for _ in range(repeats):
        for key, action in actions.items():
            cpu0, start = cpu_seconds(), time.perf_counter()
            action()
            walls[key].append(time.perf_counter() - start)
            cpus[key].append(cpu_seconds() - cpu0)
    return {key: Timing(statistics.median(walls[key]), statistics.median(cpus[key]))
            for key in actions}


def run_program(exe: Path, args: list[str], csv_path: Path) -> str:
    """Run a C program with its CSV going to a new file `csv_path`; returns its stderr."""
    csv_path.unlink(missing_ok=True)  # not truncated: ext4 flushes a file rewritten that way
    with open(csv_path, "wb") as out:
        proc = subprocess.run([str(exe), *args], stdout=out, stderr=subprocess.PIPE)
    if proc.returncode != 0:
        raise RuntimeError(f"{exe.name} {' '.join(args)} exited {proc.returncode}: "
                           f"{proc.stderr.decode(errors='replace').strip()}")
    return proc.stderr.decode(errors="replace")


def read_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t, [x, y]) from a CSV with a header naming the columns."""
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return data[:, 0], data[:, [header.index("x"), header.index("y")]]


def read_stats(run: Run, stderr: str) -> int | None:
    """Fill the counters from a `stats: steps=N rejected=N rhs=N` line; returns steps."""
    stats = STATS.search(stderr)
    if not stats:
        run.note += "no stats line on stderr; "
        return None
    run.steps = int(stats.group(1))
    run.rejected = int(stats.group(2)) if stats.group(2) else None
    run.rhs = int(stats.group(3)) if stats.group(3) else None
    return run.steps


def c_compiler() -> list[str]:
    """$CC split like a shell word list, else cc (as bgc does)."""
    return shlex.split(os.environ.get("CC") or "cc")


def compile_c(source: Path, exe: Path, defines: tuple[str, ...] = ()) -> Path:
    cmd = [*c_compiler(), *CFLAGS, *defines, str(source), "-o", str(exe), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    return exe


@dataclass
class Method:
    """A row being measured: its Run, the actions to time ({"full"|"quiet"|"plain": callable}),
    and `finish()`, which fills the counters and the output after the timing."""
    run: Run
    actions: dict
    finish: object
    quiet_cmd: list[str] | None = None  # C programs: the 2-row run, for --callgrind


def c_program(name: str, exe: Path, extra: list[str], t_end: float, workdir: Path) -> Method:
    """A C program timed writing every row and writing 2 rows (--dt t_end)."""
    run = Run(name)
    csv_path, quiet_path = workdir / f"{exe.name}.csv", workdir / f"{exe.name}.quiet.csv"
    full = ["--t-end", repr(t_end), *extra]
    quiet = ["--t-end", repr(t_end), "--dt", repr(t_end), *extra]

    def finish():
        steps_quiet = read_stats(Run(""), run_program(exe, quiet, quiet_path))
        steps = read_stats(run, run_program(exe, full, csv_path))
        if steps != steps_quiet:
            run.note += f"{steps_quiet} steps with --dt {t_end:g} (output changes the steps); "
        run.t, run.xy = read_csv(csv_path)

    return Method(run, {"full": lambda: run_program(exe, full, csv_path),
                        "quiet": lambda: run_program(exe, quiet, quiet_path)}, finish,
                  [str(exe), *quiet])


def count_instructions(cmd: list[str]) -> int | None:
    """Instructions executed by `cmd` under valgrind's callgrind: exact, unlike a stopwatch.
    Counted on runs that write next to nothing, so that the comparison is of the integration,
    not of two different number formatters."""
    proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                           *cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    found = re.search(r"Collected : (\d+)", proc.stderr)
    return int(found.group(1)) if proc.returncode == 0 and found else None


# ---------------------------------------------------------------- the four runs

def bgc_c(t_end: float, workdir: Path) -> Method:
    import bgc

    (name, text), = bgc.compile(str(MODEL), target="c", scene=SCENE).items()
    source = workdir / name
    source.write_text(text, encoding="utf-8")
    exe = compile_c(source, workdir / "bgc_pendulum")
    method = c_program("bgc C program", exe, ["--stats"], t_end, workdir)
    if "BGC_PLAIN_PRINTF" in text:  # the same program writing every number with snprintf
        plain = compile_c(source, workdir / "bgc_pendulum_plain", ("-DBGC_PLAIN_PRINTF",))
        plain_path = workdir / "plain.csv"
        method.actions["plain"] = lambda: run_program(plain, ["--t-end", repr(t_end)],
                                                      plain_path)
        finish = method.finish

        def finish_and_compare():
            finish()
            if plain_path.read_bytes() != (workdir / f"{exe.name}.csv").read_bytes():
                method.run.note += "-DBGC_PLAIN_PRINTF writes a different CSV; "

        method.finish = finish_and_compare
    return method


def bgc_python(t_end: float, workdir: Path) -> Method:
    import bgc
    import bgc.base.processes

    (name, text), = bgc.compile(str(MODEL), target="python", scene=SCENE).items()
    module = bgc.base.processes.load_python_module(text)
    run = Run("bgc Python module")

    def finish():
        t, Y = module.simulate(t_end=t_end)
        outputs = list(module.OUTPUTS)
        run.t = np.asarray(t)
        run.xy = np.asarray(Y)[:, [outputs.index("x"), outputs.index("y")]]
        path = workdir / name  # the counters from the module's own command line
        path.write_text(text, encoding="utf-8")
        proc = subprocess.run([sys.executable, str(path), "--stats", "--t-end", repr(t_end)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        read_stats(run, proc.stderr)

    return Method(run, {"full": lambda: module.simulate(t_end=t_end)}, finish)


def scipy_rk45(t_end: float, workdir: Path) -> Method:
    from scipy.integrate import solve_ivp

    f, s0 = pendulum_rhs()
    grid = output_grid(t_end)
    run = Run("SciPy RK45 (lambdify)")

    def solve(t_eval):
        return solve_ivp(f, (0.0, t_end), s0, method="RK45", rtol=RTOL, atol=ATOL,
                         t_eval=t_eval, dense_output=False)

    def finish():
        sol = solve(grid)
        run.rhs, run.t, run.xy = sol.nfev, sol.t, sol.y[2:4].T
        run.steps = len(solve(None).t) - 1  # the same steps: t_eval only interpolates

    return Method(run, {"full": lambda: solve(grid)}, finish)


def handwritten_c(t_end: float, workdir: Path) -> Method:
    exe = compile_c(HANDWRITTEN, workdir / "handwritten_dopri5")
    return c_program("hand-written C", exe, [], t_end, workdir)


def attempt(name: str, action):
    """Run `action()`; a failure becomes a Run that says why instead of stopping the benchmark."""
    try:
        return action()
    except Exception as exc:  # noqa: BLE001 - reported in the table
        lines = str(exc).strip().splitlines()
        return Run(name, note=f"FAILED: {type(exc).__name__}: {lines[0] if lines else ''}")


# ---------------------------------------------------------------- reporting

def machine_facts() -> list[str]:
    import scipy
    import sympy

    cc_line, processor, load = (machine.cc_version(c_compiler()), machine.processor(),
                                machine.load_average())
    try:
        from bgc.base.toolchain import C_FLAGS as bgc_flags
    except ImportError:
        bgc_flags = CFLAGS
    flags_note = "" if tuple(bgc_flags) == CFLAGS else f"; bgc simulate uses {' '.join(bgc_flags)}!"
    return [f"date:     {datetime.datetime.now().isoformat(timespec='seconds')}",
            f"cc:       {cc_line}  (flags: {' '.join(CFLAGS)} ... -lm{flags_note})",
            f"python:   {sys.version.split()[0]}  numpy {np.__version__}  "
            f"scipy {scipy.__version__}  sympy {sympy.__version__}",
            f"machine:  {processor}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, load average {load}"]


def fmt(value, spec: str, width: int = 0, unit: str = "") -> str:
    return format("n/a" if value is None else format(value, spec) + unit, f">{width}")


def ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


def wall(t: Timing | None) -> float | None:
    return None if t is None else t.wall


def cpu(t: Timing | None) -> float | None:
    return None if t is None else t.cpu


def table(runs: list[Run], baseline: Run) -> str:
    head = (f"{'method':<23}{'wall [s]':>10}{'cpu [s]':>10}{'vs hand C':>11}{'rhs evals':>11}"
            f"{'steps':>7}{'rejected':>10}{'max |err|':>11}")
    lines = [head, "-" * len(head)]
    for run in runs:
        vs = ratio(wall(run.full), wall(baseline.full))
        lines.append(f"{run.name:<23}{fmt(wall(run.full), '.4g', 10)}"
                     f"{fmt(cpu(run.full), '.4g', 10)}{fmt(vs, '.3g', 11, 'x')}"
                     f"{fmt(run.rhs, 'd', 11)}{fmt(run.steps, 'd', 7)}"
                     f"{fmt(run.rejected, 'd', 10)}{fmt(run.error, '.2e', 11)}")
    notes = [f"  {run.name}: {run.note.rstrip('; ')}" for run in runs if run.note]
    return "\n".join(lines + (["notes:"] + notes if notes else []))


def csv_share(t_full: float | None, t_quiet: float | None) -> float | None:
    if t_full is None or t_quiet is None:
        return None
    return max(0.0, (t_full - t_quiet) / t_full)


def verdict(value, ok) -> str:
    return "n/a" if value is None else ("met" if ok(value) else "NOT MET")


def ratio_line(label: str, num: Timing | None, den: Timing | None, comment: str) -> str:
    return (f"{label + ':':<44}{fmt(ratio(wall(num), wall(den)), '.3g', 7, 'x')} wall "
            f"{fmt(ratio(cpu(num), cpu(den)), '.3g', 7, 'x')} cpu  {comment}")


def headlines(gen_c: Run, hand_c: Run, scipy_run: Run, spawn: Timing) -> list[str]:
    c_ratio = ratio(wall(gen_c.full), wall(hand_c.full))
    scipy_ratio = ratio(wall(scipy_run.full), wall(gen_c.full))
    lines = [
        ratio_line("generated C / hand-written C", gen_c.full, hand_c.full,
                   f"(target <= {TARGET_C_RATIO:g}: "
                   f"{verdict(c_ratio, lambda v: v <= TARGET_C_RATIO)})"),
        ratio_line("SciPy / generated C", scipy_run.full, gen_c.full,
                   f"(target >= {TARGET_SCIPY_RATIO:g}: "
                   f"{verdict(scipy_ratio, lambda v: v >= TARGET_SCIPY_RATIO)})"),
        ratio_line("generated C / hand-written C, 2 rows out", gen_c.quiet, hand_c.quiet,
                   "(integration + process start)"),
        ratio_line("SciPy / generated C writing 2 rows", scipy_run.full, gen_c.quiet,
                   "(the generated C without its CSV)"),
        ratio_line("generated C, -DBGC_PLAIN_PRINTF / hand C", gen_c.plain, hand_c.full,
                   "(both formatting numbers with printf)"),
        ""]
    for run in (gen_c, hand_c):
        lines.append(f"{run.name + ':':<16}{ms(run.full)} every {DT:g} s, {ms(run.quiet)} with 2 "
                     f"rows -> the CSV takes {shares(run)}")
    lines.append(f"{'process start:':<16}{ms(spawn)} (/bin/true; included in every C time)")
    if gen_c.instructions or hand_c.instructions:
        lines.append(f"{'callgrind:':<16}2-row runs execute {fmt(gen_c.instructions, ',d')} "
                     f"(generated C) and {fmt(hand_c.instructions, ',d')} (hand-written C) "
                     f"instructions: {fmt(ratio(gen_c.instructions, hand_c.instructions), '.3f')}x")
    cpu_share = csv_share(cpu(gen_c.full), cpu(gen_c.quiet))  # wall is the noisier one
    if cpu_share is not None and cpu_share > 0.5:
        lines += ["", "!!! WRITING THE CSV DOMINATES THE GENERATED C PROGRAM'S TIME "
                  f"({shares(gen_c)}): the integration is the smaller part !!!"]
    return lines


def ms(t: Timing | None) -> str:
    return "n/a" if t is None else f"{t.wall * 1e3:6.2f} ms wall /{t.cpu * 1e3:6.2f} ms cpu"


def shares(run: Run) -> str:
    return (f"{fmt(pct(csv_share(wall(run.full), wall(run.quiet))), '.0f', 0, '%')} of the wall "
            f"time, {fmt(pct(csv_share(cpu(run.full), cpu(run.quiet))), '.0f', 0, '%')} of the cpu")


def pct(share: float | None) -> float | None:
    return None if share is None else 100 * share


def plot(runs: list[Run], path: str, t_end: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [r for r in runs if r.full is not None]
    names = [r.name.replace(" ", "\n", 1) for r in shown]
    fig, (ax_t, ax_e) = plt.subplots(1, 2, figsize=(11, 4.2))
    where = np.arange(len(shown))
    for offset, kind, color in ((-0.2, "wall", "tab:blue"), (0.2, "cpu", "tab:cyan")):
        bars = ax_t.bar(where + offset, [getattr(r.full, kind) for r in shown], 0.4,
                        color=color, label=kind)
        ax_t.bar_label(bars, fmt="%.3g", fontsize=7)
    times = [t for r in shown for t in (r.full.wall, r.full.cpu)]
    ax_t.set_xticks(where, names)
    ax_t.set_yscale("log")
    ax_t.set_ylim(min(times) / 3, max(times) * 3)
    ax_t.set_ylabel("time [s], median")
    ax_t.legend(fontsize=8)
    errors = [r.error if r.error else np.nan for r in shown]
    ax_t.set_title(f"pendulum, scene {SCENE}, 0..{t_end:g} s")
    ax_e.bar_label(ax_e.bar(names, errors, color="tab:red"), fmt="%.2e", fontsize=8)
    ax_e.set_yscale("log")
    if not np.all(np.isnan(errors)):
        ax_e.set_ylim(np.nanmin(errors) / 100, np.nanmax(errors) * 10)
    ax_e.set_ylabel("max |x - x_ref|, |y - y_ref|")
    ax_e.set_title(f"state error vs DOP853 at {REF_TOL:g}")
    for ax in (ax_t, ax_e):
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------- main

def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per method (median)")
    parser.add_argument("--t-end", type=float, default=100.0, help="end time [s]")
    parser.add_argument("--plot", metavar="FILE.png", help="write a bar chart of time and error")
    parser.add_argument("--callgrind", action="store_true",
                        help="also count the instructions of both C programs' 2-row runs "
                             "(needs valgrind)")
    args = parser.parse_args(argv)
    if args.repeats < 1 or not args.t_end > 0:
        parser.error("--repeats must be >= 1 and --t-end > 0")
    return args


def warmed_up(method: Method) -> Method:
    """Run each action once, untimed: fills caches, and a failing method fails here."""
    for action in method.actions.values():
        action()
    return method


def run_all(args) -> tuple[list[Run], Timing]:
    true = shutil.which("true") or "/bin/true"
    makers = [("bgc C program", bgc_c), ("bgc Python module", bgc_python),
              ("SciPy RK45 (lambdify)", scipy_rk45), ("hand-written C", handwritten_c)]
    with tempfile.TemporaryDirectory(prefix="bgc-bench-") as tmp:
        workdir = Path(tmp)
        methods = [attempt(name, lambda make=make: warmed_up(make(args.t_end, workdir)))
                   for name, make in makers]
        live = [m for m in methods if isinstance(m, Method)]
        actions = {(id(m), kind): action for m in live for kind, action in m.actions.items()}
        actions["spawn"] = lambda: subprocess.run([true])
        timings = measure(actions, args.repeats)
        for m in live:
            for kind in m.actions:
                setattr(m.run, kind, timings[(id(m), kind)])
            failed = attempt(m.run.name, m.finish)
            if isinstance(failed, Run):
                m.run.note += failed.note
            if args.callgrind and m.quiet_cmd:
                m.run.instructions = count_instructions(m.quiet_cmd)
    return [m.run if isinstance(m, Method) else m for m in methods], timings["spawn"]


def score(runs: list[Run], reference: Reference, grid: np.ndarray) -> None:
    for run in runs:
        if run.xy is None:
            continue
        run.error = reference.error(run.t, run.xy)
        if len(run.t) != len(grid) or np.max(np.abs(run.t - grid)) > 1e-9:
            run.note += f"output times differ from the {len(grid)}-point grid; "


def main(argv=None) -> int:
    args = parse_args(argv)
    sys.path.insert(0, str(ROOT))
    print("\n".join(machine_facts()))
    print(f"scene:    {MODEL.relative_to(ROOT)}, scene {SCENE}: 0..{args.t_end:g} s every "
          f"{DT:g} s, dopri5 rtol {RTOL:g} atol {ATOL:g}; median of {args.repeats} runs")
    grid = output_grid(args.t_end)
    reference, check = Reference(args.t_end), Reference(args.t_end, REF_CHECK_TOL)
    print(f"reference: DOP853 rtol=atol={REF_TOL:g} ({reference.solution.nfev} rhs evals); "
          f"it differs from DOP853 at {REF_CHECK_TOL:g} by "
          f"{np.max(np.abs(reference.xy(grid) - check.xy(grid))):.1e}")
    runs, spawn = run_all(args)
    score(runs, reference, grid)
    print()
    print(table(runs, runs[-1]))
    print()
    print("\n".join(headlines(runs[0], runs[-1], runs[2], spawn)))
    if args.plot:
        plot(runs, args.plot, args.t_end)
        print(f"\nplot written to {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
