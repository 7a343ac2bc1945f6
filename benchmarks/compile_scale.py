"""How bgc's compile time grows with the size of a model, beside CasADi (and BondGraphTools).

    python benchmarks/compile_scale.py [--quick] [--families a,b] [--repeats N]
                                       [--plot FILE.png] [--bondgraphtools PYTHON]

The models are the families of benchmarks/families.py (the chains compiled with their scene
"swing", the others with the default scene), each at a range of sizes; link_chain_field is the
constraint on a coupled field: an n-link chain in its link angles, one full n x n M(q), its end
held on a line; rc_ladder_components is the RC ladder written with a component and a `for`
loop, measured beside its flat twin rc_ladder_flat_twin (the ratio of the two is printed,
the target <= 1.2 at 1000 instances); thermal_grid_cells is the n x n thermal grid of
benchmarks/stiff_scale.py by its number of cells (states), whose stiff solvers factor by the
sparse LU the compiler plans (its ordering and fill are part of lower).  For every model:

  stages   bgc.build(...).timings (parse, instantiate, resolve, flatten, units, scene,
           causality, equations, reduce, lower)
           and emit_c, timed inside a fresh Python process (this script run with the hidden
           option --one FAMILY N DIR, which prints JSON): SymPy caches what it has seen, so sizes
           built in one process would warm each other.  Median over the repeats.
  command  wall clock of `python -m bgc compile FILE --target c -o OUT` (with `--scene swing`
           for the chains), what a user waits for, Python's start-up and imports included; for
           the RC ladder also of `python -m bgc check FILE`.  Median over the repeats.
  cc       wall clock of `cc -O2 -std=c99 model.c -o model -lm` (the program, runtime
           included).  Median over the repeats.
  part     wall clock of `cc FLAGS -std=c99 -c` of the model part alone, as `bgc simulate` builds
           it to link with the runtime built once: FLAGS are bgc.base.toolchain.model_part_flags's
           (-O1 for a part larger than bgc.base.toolchain.LARGE_PART, else -O2); "to .o" is the
           in-process total plus this, the model's build to an object file, as CasADi's is
           measured (build + codegen + cc -O2 -c).  Median over the repeats.
  scene    the same build (in process, then cc -c of the model part) of the program as `bgc
           simulate` builds it for the scene's solver: for an explicit one (the chains' dopri5)
           without jvp, the Jacobian only the implicit solvers call ("scene .o"; the columns
           above are the full program, as `bgc compile` writes it).  The targets against
           CasADi, whose right side is all its build has, are read on this one.
  simulate wall clock of a cold `python -m bgc simulate FILE -o OUT.csv` (the scene's run): the
           compile cache emptied of everything but the runtime object and the parser's tables
           (so the model is compiled, built and run; the runtime is not built again).  What a
           modeller waits for after an edit.  Median over the repeats.
  ops      the right side's arithmetic in the program IR: add + mul + div + call + neg from
           bgc.ir.count_ops(program, names=("rhs",)); "flops" are those of the LU
           factorisations and solves it runs (solve_flops), counted apart.
  rhs/jac  time per call of the generated bgc_rhs and bgc_jacobian: a driver appended to the
           generated C (built with -DBGC_NO_MAIN) calls them through a function pointer,
           changing one state slightly between calls so that no call repeats the last; the
           number of calls is raised until a loop takes --min-time (0.2 s), then the best of
           three loops is reported.  Twice: the standalone program at -O2, and the model
           part built as `bgc simulate` builds it (FLAGS above) linked with the runtime at -O2
           ("as built"), so that -O1's price at run time is measured in the same run.
  fit      the growth exponent: least squares of log(time) against log(size) over the larger
           half of a family's sizes (the sizes are printed); the target is <= 1.05 for the
           in-process total, the whole command and the build to an object file.  Reported,
           never asserted.

Baselines in the same run, in the same tables:

  CasADi (if importable) builds the right side of the same N-link chain by hand, index-reduced
  with the same Baumgarte law: q = (x, y), v = p/m, Phi_k = |r_k - r_(k-1)|^2 - l^2 (r_0 = 0),
  J = jacobian(Phi, q), (J M^-1 J^T) lambda = -(J M^-1 F + d(Jv)/dq v + 2 alpha J v +
  beta^2 Phi) (d(Jv)/dq v by jtimes), dp/dt = F + J^T lambda, dq/dt = v; two ways: "MX+QR",
  an MX graph whose solve is casadi.solve(A, b, "qr"), a sparse QR node run by the generated
  code, and "SX", all scalar (casadi.solve on SX, QR unrolled into the expressions).  The
  resistor ladder the same two ways: its n node voltages from the tridiagonal nodal equations
  A(R) e = b(R, V0, u) (u = q/Cc the capacitor's voltage), dq/dt = (e_n - u)/Rs1, every
  resistance a parameter.  And an SX right side of the mass chain.  The parameters are an input vector of the function, as
  in bgc's code.  Build time (expressions and Function), code generation time
  (CodeGenerator.add + generate), cc -O2 of the generated file (-c: it has no main), time per
  call from the same driver, and for SX the operation count: every instruction of the
  function's algorithm except inputs, outputs, constants, parameters and copies (a square or a
  doubling counts one, as bgc counts x**2 as one mul).  Each CasADi right side is compared with
  bgc's generated Python module at random states near the initial one and, from both
  generated C files, at the initial state: "vs bgc" is the largest relative difference.

  BondGraphTools (--bondgraphtools PYTHON, an interpreter that has it: slow, off by default)
  builds the 20-mass chain of mass_chain(20) with symbolic parameters and times its
  constitutive_relations (the reduction) in a subprocess, with a timeout; its equations are
  checked against bgc's at one state.

Timings are medians of measurements made in this run, printed, never asserted.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))  # families.py and machine.py, beside this file
sys.path.insert(0, str(ROOT))  # bgc, from this checkout

import families  # noqa: E402
import machine  # noqa: E402

SIZES = {
    "pendulum_chain": (1, 2, 4, 8, 16, 32, 64),
    "pendulum_chain_vector": (1, 2, 4, 8, 16, 32, 64),
    "mass_chain": (10, 30, 100, 300, 1000),
    "rc_ladder": (10, 30, 100, 300, 600, 1000),
    "resistor_ladder": (2, 4, 8, 16, 32, 64),
    "link_chain_field": (2, 4, 8, 16, 32),
    "rc_ladder_components": (10, 30, 100, 300, 1000),
    "rc_ladder_flat_twin": (10, 30, 100, 300, 1000),
    "thermal_grid_cells": (16, 64, 256, 1024),
}
QUICK_SIZES = {
    "pendulum_chain": (2, 8, 16),
    "pendulum_chain_vector": (2, 8, 16),
    "mass_chain": (10, 100),
    "rc_ladder": (10, 100),
    "resistor_ladder": (4, 16),
    "link_chain_field": (2, 8),
    "rc_ladder_components": (10, 100),
    "rc_ladder_flat_twin": (10, 100),
    "thermal_grid_cells": (16, 64),
}
SCENES = {"pendulum_chain": "swing", "pendulum_chain_vector": "swing", "link_chain_field": "swing"}
STAGES = ("parse", "instantiate", "resolve", "flatten", "units", "scene", "causality",
          "equations", "reduce", "lower", "emit")
ARITHMETIC = ("add", "mul", "div", "call", "neg")
CFLAGS = ("-O2", "-std=c99")
DRIVER_FLAGS = ("-D_POSIX_C_SOURCE=199309L",)
TARGET_EXPONENT = 1.05
TARGET_BUILDS = (("pendulum_chain", 4), ("pendulum_chain", 16), ("pendulum_chain", 64),
                 ("resistor_ladder", 32))  # bgc's build to .o <= CasADi MX+QR's
TARGET_MASSES = ("mass_chain", 1000, 5.0)  # bgc's build to .o under 5 s
TWINS = ("rc_ladder_components", "rc_ladder_flat_twin")  # components, their flat twin
TARGET_TWIN_RATIO = 1.2  # the issue: 1000 instances compile within 1.2x their flat twin
CHECK_TARGET = ("rc_ladder", 600, 3.0)  # the issue: `bgc check` under 3 s at 600 sections
BGT_MASSES, BGT_TIMEOUT = 20, 600.0
BGT_REPORTED = ("BondGraphTools 0.4.6, 20-mass chain: 151 s reported by the issue that asked "
                "for this benchmark; not measured in this run (use --bondgraphtools "
                "PYTHON, an interpreter that has BondGraphTools)")
AGREEMENT = 1e-9  # relative; anything above is flagged in the table


@dataclass
class Row:
    """One compiled model, bgc's or a baseline's: what was measured (None: not measured)."""
    family: str
    size: int
    tool: str
    states: int | None = None
    stages: dict = field(default_factory=dict)  # bgc: stage -> median seconds
    build: float | None = None    # bgc: parse .. lower; CasADi: expressions + Function
    codegen: float | None = None  # bgc: emit_c; CasADi: CodeGenerator
    command: float | None = None  # python -m bgc compile
    check: float | None = None    # python -m bgc check (RC ladder)
    cc: float | None = None
    part_cc: float | None = None  # bgc: cc -c of the model part, as bgc simulate builds it
    part_flags: str = ""
    scene_total: float | None = None  # bgc: in process, the program bgc simulate builds for
    scene_cc: float | None = None     # the scene's solver (no jvp for an explicit one), its cc -c
    scene_jacobian: bool = True       # ... and whether it has jvp
    simulate: float | None = None  # bgc: cold python -m bgc simulate
    ops: int | None = None
    flops: int | None = None
    rhs_ns: float | None = None
    jac_ns: float | None = None
    rhs_part_ns: float | None = None  # bgc: the model part as built, linked with the runtime
    jac_part_ns: float | None = None
    error: float | None = None    # baselines: largest relative difference from bgc
    dx0: list | None = None       # the generated C's right side at the initial state
    note: str = ""

    @property
    def total(self) -> float | None:
        if self.build is None or self.codegen is None:
            return None
        return self.build + self.codegen

    @property
    def to_object(self) -> float | None:
        """The model's build to an object file: bgc in process + its model part's cc -c;
        CasADi build + codegen + cc -O2 -c."""
        cc = self.part_cc if self.tool == "bgc" else self.cc
        if self.total is None or cc is None:
            return None
        return self.total + cc

    @property
    def scene_object(self) -> float | None:
        """bgc: the build to an object file of the program bgc simulate builds for the scene
        (the full one's for a baseline)."""
        if self.tool != "bgc":
            return self.to_object
        if self.scene_total is None or self.scene_cc is None:
            return None
        return self.scene_total + self.scene_cc


# ---------------------------------------------------------------- running things

def model_name(family: str, n: int) -> str:
    return f"{family}{n}"


def c_compiler() -> list[str]:
    """$CC split like a shell word list, else cc (as bgc does)."""
    return shlex.split(os.environ.get("CC") or "cc")


def python_env() -> dict:
    """The environment for child Pythons: this checkout's bgc first."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def run(cmd: list[str], timeout: float | None = None, **kwargs) -> tuple[float, str]:
    """Run a command; (wall seconds, stdout).  A failure raises with its stderr."""
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kwargs)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} exited {proc.returncode}:\n"
                           f"{proc.stderr.strip()[-2000:]}")
    return elapsed, proc.stdout


def compile_c(source: Path, output: Path, *flags: str) -> float:
    """cc -O2 -std=c99 [flags] source -o output -lm; returns the wall seconds."""
    link = () if "-c" in flags else ("-lm",)
    return run([*c_compiler(), *CFLAGS, *flags, str(source), "-o", str(output), *link])[0]


def median(values) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- the timing driver (C)

DRIVER_MAIN = r"""
/* ---- appended by benchmarks/compile_scale.py: time the model functions ---- */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef int (*bench_fn)(const double *x, double *out);
static volatile double bench_sink;

static double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Seconds for `calls` calls of f, x[0] changed slightly before each, so that no call repeats
   the last and nothing can be hoisted out of the loop; -1 if a call failed. */
static double bench_loop(bench_fn f, double *x, double *out, long calls)
{
    double x0 = x[0], acc = 0.0, start = bench_now(), elapsed;
    long k;
    for (k = 0; k < calls; ++k) {
        x[0] = x0 + 1e-9 * (double)(k & 7);
        if (f(x, out) != 0)
            return -1.0;
        acc += out[0];
    }
    elapsed = bench_now() - start;
    bench_sink = acc;
    x[0] = x0;
    return elapsed;
}

/* Nanoseconds per call: more calls until one loop takes min_time, then the best of repeats. */
static double bench_per_call(bench_fn f, double *x, double *out, double min_time, int repeats)
{
    long calls = 1;
    double t, best;
    int r;
    for (;;) {
        t = bench_loop(f, x, out, calls);
        if (t < 0.0)
            return -1.0;
        if (t >= min_time)
            break;
        calls = t * 100.0 < min_time ? calls * 10 : (long)((double)calls * 1.1 * min_time / t) + 1;
    }
    best = t;
    for (r = 1; r < repeats; ++r) {
        t = bench_loop(f, x, out, calls);
        if (t >= 0.0 && t < best)
            best = t;
    }
    return 1e9 * best / (double)calls;
}

int main(int argc, char **argv)
{
    double min_time = argc > 1 ? atof(argv[1]) : 0.2;
    int repeats = argc > 2 ? atoi(argv[2]) : 3, i;
    double *x = malloc(BENCH_N * sizeof *x), *dx = malloc(BENCH_N * sizeof *dx);
    if (!x || !dx || bench_setup(x) != 0 || bench_rhs(x, dx) != 0) {
        fprintf(stderr, "driver: setup or the first right-side call failed\n");
        return 1;
    }
    printf("dx");
    for (i = 0; i < BENCH_N; ++i)
        printf(" %.17g", dx[i]);
    printf("\nrhs_ns %.6g\n", bench_per_call(bench_rhs, x, dx, min_time, repeats));
#if BENCH_JAC
    {
        double *jac = malloc((size_t)BENCH_N * BENCH_N * sizeof *jac);
        if (!jac)
            return 1;
        printf("jac_ns %.6g\n", bench_per_call(bench_jac, x, jac, min_time, repeats));
    }
#endif
    return 0;
}
"""

BGC_ADAPTER = r"""
/* ---- appended by benchmarks/compile_scale.py: the bgc model behind the driver ---- */
#if defined(__GNUC__)
#define BENCH_NOINLINE __attribute__((noinline))
#else
#define BENCH_NOINLINE
#endif
#define BENCH_N BGC_DIM(BGC_NUM_STATES)
#define BENCH_JAC 1
static bgc_params bench_p;
static bgc_work *bench_w;

static int bench_setup(double *x)
{
    bgc_params_defaults(&bench_p, NULL);
    bench_w = bgc_work_new();
    if (!bench_w)
        return 1;
    bgc_init(&bench_p, x);
    return 0;
}

static BENCH_NOINLINE int bench_rhs(const double *x, double *dx)
{
    return bgc_rhs(0.0, x, &bench_p, bench_w, dx);
}

static BENCH_NOINLINE int bench_jac(const double *x, double *J)
{
    return bgc_jacobian(0.0, x, &bench_p, bench_w, J);
}
"""

CASADI_ADAPTER = r"""
/* ---- appended by benchmarks/compile_scale.py: the CasADi function behind the driver ---- */
#include <stdlib.h>
#include <string.h>
#define BENCH_N {n}
#define BENCH_JAC 0
static const double bench_x0[BENCH_N] = {{{x0}}};
static const double bench_params[] = {{{params}}};
static const casadi_real **bench_arg;
static casadi_real **bench_res, *bench_w;
static casadi_int *bench_iw;
static int bench_mem;

static int bench_setup(double *x)
{{
    casadi_int n_arg, n_res, n_iw, n_w;
    if ({name}_work(&n_arg, &n_res, &n_iw, &n_w) != 0)
        return 1;
    bench_arg = malloc((size_t)(n_arg + 1) * sizeof *bench_arg);
    bench_res = malloc((size_t)(n_res + 1) * sizeof *bench_res);
    bench_iw = malloc((size_t)(n_iw + 1) * sizeof *bench_iw);
    bench_w = malloc((size_t)(n_w + 1) * sizeof *bench_w);
    if (!bench_arg || !bench_res || !bench_iw || !bench_w)
        return 1;
    {name}_incref();
    bench_mem = {name}_checkout();
    memcpy(x, bench_x0, sizeof bench_x0);
    return 0;
}}

static int bench_rhs(const double *x, double *dx)
{{
    bench_arg[0] = x;
    bench_arg[1] = bench_params;
    bench_res[0] = dx;
    return {name}(bench_arg, bench_res, bench_iw, bench_w, bench_mem);
}}
"""


def time_calls(c_text: str, adapter: str, stem: Path, args) -> dict:
    """Build the generated C with the driver appended and run it: {"dx": [...], "rhs_ns": ...,
    "jac_ns": ...}."""
    source = stem.with_name(stem.name + "_driver.c")
    source.write_text(c_text + adapter + DRIVER_MAIN, encoding="utf-8")
    exe = stem.with_name(stem.name + "_driver")
    compile_c(source, exe, *DRIVER_FLAGS, "-DBGC_NO_MAIN")
    out = run([str(exe), repr(args.min_time), "3"])[1]
    result = {}
    for line in out.splitlines():
        key, *values = line.split()
        numbers = [float(v) for v in values]
        result[key] = numbers if key == "dx" else numbers[0]
    return result


# ---------------------------------------------------------------- bgc, one model

def one(family: str, n: int, outdir: Path, with_python: bool, scene: bool = False) -> None:
    """The --one mode, in a fresh process: build and emit one model, print JSON.  scene: the
    program bgc simulate builds for the scene's solver, its model part only."""
    import bgc
    from bgc import ir
    from bgc.api import Source
    from bgc.codegen.emit import emit_c, emit_python

    name = model_name(family, n)
    source = Source(f"{name}.bg", families.FAMILIES[family](n))
    if scene:
        compiled = bgc.build(source, SCENES.get(family), jacobian=None)
        start = time.perf_counter()
        (part_text,) = emit_c(compiled.program, linked=True).values()
        emit = time.perf_counter() - start
        (outdir / f"{name}_scene_part.c").write_text(part_text, encoding="utf-8")
        print(json.dumps({"stages": {**dict(compiled.timings), "emit": emit},
                          "jacobian": compiled.program.has_jacobian}))
        return
    compiled = bgc.build(source, SCENES.get(family))
    start = time.perf_counter()
    (c_text,) = emit_c(compiled.program).values()
    emit = time.perf_counter() - start
    ops = ir.count_ops(compiled.program, names=("rhs",))
    (outdir / f"{name}.c").write_text(c_text, encoding="utf-8")
    (part_text,) = emit_c(compiled.program, linked=True).values()  # as bgc simulate builds it
    (outdir / f"{name}_part.c").write_text(part_text, encoding="utf-8")
    if with_python:  # untimed, for checking the baselines against
        (py_text,) = emit_python(compiled.program).values()
        (outdir / f"{name}.py").write_text(py_text, encoding="utf-8")
    print(json.dumps({"stages": {**dict(compiled.timings), "emit": emit},
                      "states": len(compiled.program.states),
                      "ops": sum(ops[k] for k in ARITHMETIC), "flops": ops["solve_flops"]}))


def build_in_fresh_process(family: str, n: int, workdir: Path, with_python: bool,
                           scene: bool = False) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", family, str(n),
           str(workdir)] + (["--with-python"] if with_python else []) + \
        (["--scene-build"] if scene else [])
    return json.loads(run(cmd, env=python_env())[1].strip().splitlines()[-1])


def bgc_command(*args: str, workdir: Path) -> float:
    return run([sys.executable, "-m", "bgc", *args], cwd=workdir, env=python_env())[0]


def part_flags(part: Path) -> tuple[str, ...]:
    """The flags bgc simulate compiles this model part with (bgc.base.toolchain.model_part_flags)."""
    from bgc.base import toolchain

    rule = getattr(toolchain, "model_part_flags", None)  # (a bgc from before the rule: -O2)
    size = len(part.read_text(encoding="utf-8"))
    return rule(toolchain.C_FLAGS, size) if rule else tuple(toolchain.C_FLAGS)


def compile_part(part: Path, flags: tuple[str, ...]) -> float:
    """cc FLAGS -c of a model part; the wall seconds."""
    return run([*c_compiler(), *flags, "-c", str(part), "-o", str(part.with_suffix(".o"))])[0]


def simulate_env(cache: Path) -> dict:
    """bgc simulate's environment: this checkout's bgc, the benchmark's own compile cache, the
    C backend's default flags."""
    env = python_env()
    env["BGC_CACHE_DIR"] = str(cache)
    env.pop("BGC_CFLAGS", None)
    return env


def cold_simulate(model: Path, scene: list[str], workdir: Path) -> float:
    """Wall seconds of `python -m bgc simulate` with the compile cache emptied of everything
    but the runtime object and the parser's tables (built by warm_runtime)."""
    cache = workdir / "cache"
    for entry in cache.iterdir():
        if entry.name.startswith(("bgc-runtime-", "lark-")):
            continue
        if entry.is_dir():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    return run([sys.executable, "-m", "bgc", "simulate", model.name, *scene, "-o",
                f"{model.stem}_sim.csv"], cwd=workdir, env=simulate_env(cache))[0]


def warm_runtime(workdir: Path) -> None:
    """Builds the runtime object (and the parser's tables) into the benchmark's cache, as a
    first `bgc simulate` on the machine does, with a two-section RC ladder; untimed."""
    model = workdir / "warmup.bg"
    model.write_text(families.rc_ladder(2), encoding="utf-8")
    (workdir / "cache").mkdir(exist_ok=True)
    run([sys.executable, "-m", "bgc", "simulate", model.name, "-o", "warmup.csv"], cwd=workdir,
        env=simulate_env(workdir / "cache"))


_RUNTIME_DRIVER_OBJECT: list[Path] = []


def runtime_driver_object(workdir: Path) -> Path:
    """The runtime unit (bgc.codegen.emit.c_runtime_unit) at -O2 without its main, for the drivers
    of
    linked model parts; built once per run."""
    if not _RUNTIME_DRIVER_OBJECT:
        from bgc.codegen.emit import c_runtime_unit

        source = workdir / "runtime_driver.c"
        source.write_text(c_runtime_unit(), encoding="utf-8")
        obj = source.with_suffix(".o")
        run([*c_compiler(), *CFLAGS, *DRIVER_FLAGS, "-DBGC_NO_MAIN", "-c", str(source), "-o",
             str(obj)])
        _RUNTIME_DRIVER_OBJECT.append(obj)
    return _RUNTIME_DRIVER_OBJECT[0]


def time_part_calls(part: Path, flags: tuple[str, ...], workdir: Path, args) -> dict:
    """time_calls for the model part built with `flags` and linked with the runtime at -O2."""
    source = part.with_name(part.stem + "_driver.c")
    source.write_text(part.read_text(encoding="utf-8") + BGC_ADAPTER + DRIVER_MAIN,
                      encoding="utf-8")
    exe = part.with_name(part.stem + "_driver")
    run([*c_compiler(), *flags, *DRIVER_FLAGS, "-DBGC_NO_MAIN", str(source),
         str(runtime_driver_object(workdir)), "-o", str(exe), "-lm"])
    out = run([str(exe), repr(args.min_time), "3"])[1]
    return {line.split()[0]: float(line.split()[1]) for line in out.splitlines()
            if not line.startswith("dx")}


def measure_bgc(family: str, n: int, workdir: Path, args) -> Row:
    """Every measurement of one bgc model, the repeats interleaved so that a change of load on
    the machine hits them alike."""
    name = model_name(family, n)
    model = workdir / f"{name}.bg"
    model.write_text(families.FAMILIES[family](n), encoding="utf-8")
    scene = ["--scene", SCENES[family]] if family in SCENES else []
    builds, commands, checks, ccs, parts, sims = [], [], [], [], [], []
    scene_builds, scene_ccs = [], []
    part = workdir / f"{name}_part.c"
    scene_part = workdir / f"{name}_scene_part.c"
    for r in range(args.repeats):
        builds.append(build_in_fresh_process(family, n, workdir, with_python=r == 0))
        scene_builds.append(build_in_fresh_process(family, n, workdir, False, scene=True))
        scene_ccs.append(compile_part(scene_part, part_flags(scene_part)))
        commands.append(bgc_command("compile", model.name, *scene, "--target", "c",
                                    "-o", f"{name}_cmd.c", workdir=workdir))
        if family == CHECK_TARGET[0]:
            checks.append(bgc_command("check", model.name, *scene, workdir=workdir))
        ccs.append(compile_c(workdir / f"{name}.c", workdir / name))
        flags = part_flags(part)
        parts.append(compile_part(part, flags))
        if not args.no_simulate:
            sims.append(cold_simulate(model, scene, workdir))
    stages = {s: median(b["stages"][s] for b in builds) for s in STAGES}
    row = Row(family, n, "bgc", states=builds[0]["states"], stages=stages,
              build=sum(stages[s] for s in STAGES if s != "emit"), codegen=stages["emit"],
              command=median(commands), check=median(checks), cc=median(ccs),
              part_cc=median(parts), part_flags=flags[0], simulate=median(sims),
              ops=builds[0]["ops"], flops=builds[0]["flops"],
              scene_total=median(sum(b["stages"].values()) for b in scene_builds),
              scene_cc=median(scene_ccs), scene_jacobian=scene_builds[0]["jacobian"])
    calls = time_calls((workdir / f"{name}.c").read_text(encoding="utf-8"), BGC_ADAPTER,
                       workdir / name, args)
    row.rhs_ns, row.jac_ns, row.dx0 = calls.get("rhs_ns"), calls.get("jac_ns"), calls.get("dx")
    calls = time_part_calls(part, flags, workdir, args)
    row.rhs_part_ns, row.jac_part_ns = calls.get("rhs_ns"), calls.get("jac_ns")
    return row


def bgc_module(family: str, n: int, workdir: Path):
    """bgc's generated Python module of a model measured before (written by --one)."""
    from bgc.base import processes

    return processes.load_python_module(
        (workdir / f"{model_name(family, n)}.py").read_text(encoding="utf-8"))


# ---------------------------------------------------------------- CasADi baselines

def casadi_chain(ca, n: int, scalar: bool, name: str):
    """The n-link chain's right side as a CasADi Function (x, params) -> dx, x = (px_1..px_n,
    py_1..py_n, x_1..x_n, y_1..y_n), params = (m, l, g, alpha, beta); y points down."""
    sym = ca.SX if scalar else ca.MX
    momenta, positions = sym.sym("p", 2 * n), sym.sym("q", 2 * n)
    params = sym.sym("params", 5)
    m, l, g, alpha, beta = ca.vertsplit(params)
    x, y = positions[:n], positions[n:]
    if n > 1:
        x_prev, y_prev = ca.vertcat(sym.zeros(1), x[:n - 1]), ca.vertcat(sym.zeros(1), y[:n - 1])
    else:  # an empty slice does not concatenate in MX
        x_prev, y_prev = sym.zeros(1), sym.zeros(1)
    v = momenta / m
    force = ca.vertcat(sym.zeros(n), m * g * sym.ones(n))
    phi = (x - x_prev) ** 2 + (y - y_prev) ** 2 - l ** 2
    jac = ca.jacobian(phi, positions)
    jv = ca.mtimes(jac, v)
    lhs = ca.mtimes(jac, jac.T) / m
    rhs = -(ca.mtimes(jac, force) / m + ca.jtimes(jv, positions, v) + 2 * alpha * jv
            + beta ** 2 * phi)
    lam = ca.solve(lhs, rhs) if scalar else ca.solve(lhs, rhs, "qr")
    dx = ca.vertcat(force + ca.mtimes(jac.T, lam), v)
    return ca.Function(name, [ca.vertcat(momenta, positions), params], [ca.densify(dx)])


def chain_states(n: int) -> list[str]:
    """bgc's names of casadi_chain's states, in its order."""
    return [f"{prefix}{k}{suffix}" for prefix, suffix in (("mx", ".p"), ("my", ".p"),
                                                           ("x", ""), ("y", ""))
            for k in range(1, n + 1)]


def casadi_masses(ca, n: int, name: str):
    """The n-mass chain's right side, SX: x = (p_1, q_1, .., p_n, q_n) as bgc orders it
    (momentum of mass i, compression of spring-damper i), params = (m, k, b, F)."""
    x, params = ca.SX.sym("x", 2 * n), ca.SX.sym("params", 4)
    m, k, b, push = ca.vertsplit(params)
    momenta, springs = x[0::2], x[1::2]
    v = momenta / m
    flow = ca.vertcat(0, v[:n - 1]) - v  # into spring-damper i: v_(i-1) - v_i, v_0 = 0
    effort = k * springs + b * flow
    dp = effort - ca.vertcat(effort[1:], 0) + ca.vertcat(ca.SX.zeros(n - 1), push)
    dx = ca.reshape(ca.horzcat(dp, flow).T, 2 * n, 1)  # interleave
    return ca.Function(name, [x, params], [dx])


def mass_states(n: int) -> list[str]:
    return [f"{kind}{i}.{var}" for i in range(1, n + 1) for kind, var in (("mass", "p"),
                                                                          ("spring", "q"))]


def casadi_resistors(ca, n: int, scalar: bool, name: str):
    """The n-section resistor ladder's right side (x = (q), params = (V0, Cc, Rs1, Rp1, ..,
    Rsn, Rpn) as bgc orders them): the node voltages e from the nodal equations A e = b,
    tridiagonal, conductances 1/R, the capacitor behind Rs1 at u = q/Cc; dq/dt = (e_n - u)/Rs1.
    MX with casadi.solve(A, b, "qr"), or SX (n >= 2)."""
    sym = ca.SX if scalar else ca.MX
    q, params = sym.sym("q", 1), sym.sym("params", 2 + 2 * n)
    v0, cc = params[0], params[1]
    gs = 1 / params[2::2]  # series conductances, node k-1 -> node k
    gp = 1 / params[3::2]  # shunt conductances, node k -> ground
    gl = 1 / params[2]     # the capacitor's resistor rl (Rs1)
    u = q / cc
    ahead = ca.vertcat(gs[1:], gl)  # the series conductance on each node's right
    upper = ca.vertcat(ca.horzcat(sym.zeros(n - 1, 1), ca.diag(gs[1:])), sym.zeros(1, n))
    lhs = ca.diag(gs + gp + ahead) - upper - upper.T
    rhs = sym.zeros(n, 1)
    rhs[0] = gs[0] * v0
    rhs[n - 1] = rhs[n - 1] + gl * u
    e = ca.solve(lhs, rhs) if scalar else ca.solve(lhs, rhs, "qr")
    return ca.Function(name, [q, params], [(e[n - 1] - u) * gl])


def resistor_params(n: int) -> tuple[str, ...]:
    return ("V0", "Cc") + tuple(f"R{kind}{i}" for i in range(1, n + 1) for kind in ("s", "p"))


def count_sx_ops(ca, f) -> int:
    """Instructions of an SX function that compute: all but inputs, outputs, constants,
    parameters and copies."""
    skip = {ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_PARAMETER, ca.OP_ASSIGN}
    return sum(1 for k in range(f.n_instructions()) if f.instruction_id(k) not in skip)


@dataclass(frozen=True)
class Baseline:
    """A CasADi right side of a bgc family: how to build it and which bgc parameters and states
    its inputs are."""
    family: str
    tool: str
    build: object       # (ca, n, name) -> Function
    states: object      # n -> bgc's state names in the Function's order
    params: object      # bgc's parameter names in the Function's order (or n -> them)
    scalar: bool


BASELINES = (
    Baseline("pendulum_chain", "CasADi MX+QR",
             lambda ca, n, name: casadi_chain(ca, n, False, name), chain_states,
             ("m", "l", "g", "alpha", "beta"), False),
    Baseline("pendulum_chain", "CasADi SX",
             lambda ca, n, name: casadi_chain(ca, n, True, name), chain_states,
             ("m", "l", "g", "alpha", "beta"), True),
    Baseline("mass_chain", "CasADi SX", casadi_masses, mass_states, ("m", "k", "b", "F"), True),
    Baseline("resistor_ladder", "CasADi MX+QR",
             lambda ca, n, name: casadi_resistors(ca, n, False, name), lambda n: ["cap.q"],
             resistor_params, False),
    Baseline("resistor_ladder", "CasADi SX",
             lambda ca, n, name: casadi_resistors(ca, n, True, name), lambda n: ["cap.q"],
             resistor_params, True),
)


def relative_difference(got, ref) -> float:
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    return float(np.max(np.abs(got - ref)) / max(np.max(np.abs(ref)), 1e-300))


def difference_from_bgc(f, module, names: list[str], params: list[float], rng) -> float:
    """Largest relative difference of f from bgc's rhs at random states near the initial one."""
    p = list(module.PARAMETERS.values())
    perm = [module.STATES.index(s) for s in names]
    x0 = np.asarray(module._init(module._with_constants(p)), float)
    worst = 0.0
    for _ in range(3):
        x = x0 + 0.05 * rng.standard_normal(x0.size)
        ref = np.asarray(module.rhs(0.0, x, p), float)[perm]
        worst = max(worst, relative_difference(np.asarray(f(x[perm], params)).ravel(), ref))
    return worst


def c_array(values) -> str:
    return ", ".join(repr(float(v)) for v in values)


def measure_casadi(ca, base: Baseline, n: int, bgc_row: Row, workdir: Path, args, rng) -> Row:
    name = f"{base.tool.split()[-1].replace('+', '').lower()}_{model_name(base.family, n)}"
    builds, codegens, ccs = [], [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        f = base.build(ca, n, name)
        builds.append(time.perf_counter() - start)
        start = time.perf_counter()
        generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        generator.add(f)
        source = Path(generator.generate(str(workdir) + os.sep))
        codegens.append(time.perf_counter() - start)
        ccs.append(compile_c(source, workdir / f"{name}.o", "-c"))
    row = Row(base.family, n, base.tool, states=f.size1_in(0), build=median(builds),
              codegen=median(codegens), cc=median(ccs),
              ops=count_sx_ops(ca, f) if base.scalar else None)
    module = bgc_module(base.family, n, workdir)
    names = base.states(n)
    perm = [module.STATES.index(s) for s in names]
    params = [module.PARAMETERS[p] for p in (base.params(n) if callable(base.params)
                                             else base.params)]
    x0 = np.asarray(module._init(module._with_constants(list(module.PARAMETERS.values()))))
    adapter = CASADI_ADAPTER.format(n=len(names), x0=c_array(x0[perm]),
                                    params=c_array(params), name=name)
    calls = time_calls(source.read_text(encoding="utf-8"), adapter, workdir / name, args)
    row.rhs_ns = calls.get("rhs_ns")
    row.error = difference_from_bgc(f, module, names, params, rng)
    if bgc_row.dx0 is not None and calls.get("dx") is not None:  # the two generated C files
        row.error = max(row.error, relative_difference(calls["dx"],
                                                       np.asarray(bgc_row.dx0)[perm]))
    if row.error > AGREEMENT:
        row.note = f"DIFFERS FROM bgc by {row.error:.1e} (relative)"
    return row


# ---------------------------------------------------------------- BondGraphTools

BGT_SCRIPT = r"""
import json, sys, time
import sympy as sp
import BondGraphTools as bgt
from BondGraphTools.version import __version__ as version

n, state, values = int(sys.argv[1]), json.loads(sys.argv[2]), json.loads(sys.argv[3])
m, c, b, F = sp.symbols("m c b F")  # c = 1/k: BondGraphTools takes a symbol, not 1/k
start = time.perf_counter()
model = bgt.new(name=f"masses{n}")
wall, push = bgt.new("Sf", value=0, name="wall"), bgt.new("Se", value=F, name="push")
bgt.add(model, wall, push)
left = wall
for i in range(1, n + 1):
    v, mass = bgt.new("1", name=f"v{i}"), bgt.new("I", value=m, name=f"mass{i}")
    node, pair = bgt.new("0", name=f"n{i}"), bgt.new("1", name=f"d{i}")
    spring = bgt.new("C", value=c, name=f"spring{i}")
    damper = bgt.new("R", value=b, name=f"damper{i}")
    bgt.add(model, v, mass, node, pair, spring, damper)
    for tail, head in ((v, mass), (left, node), (node, v), (node, pair), (pair, spring),
                       (pair, damper)):
        bgt.connect(tail, head)
    left = v
bgt.connect(push, left)
built = time.perf_counter()
relations = model.constitutive_relations
reduced = time.perf_counter()
names = {x: f"{comp.name}.{var.split('_')[0]}" for x, (comp, var) in model.state_vars.items()}
numbers = {sp.Symbol(x): state[name] for x, name in names.items()}
numbers.update({sp.Symbol(k): v for k, v in values.items()})
dx = [sp.Symbol("d" + x) for x in names]
solution, = sp.linsolve([r.subs(numbers) for r in relations], dx)
print(json.dumps({"version": version, "sympy": sp.__version__, "build": built - start,
                  "reduce": reduced - built, "relations": len(relations),
                  "dx": {names[str(d)[1:]]: float(v) for d, v in zip(dx, solution)}}))
"""


def measure_bondgraphtools(python: str, workdir: Path, args) -> list[str]:
    """The 20-mass chain in BondGraphTools (one run, in its own interpreter) and in bgc."""
    n = BGT_MASSES
    bgc_row = measure_bgc("mass_chain", n, workdir, args)
    module = bgc_module("mass_chain", n, workdir)
    rng = np.random.default_rng(2)
    x = rng.standard_normal(len(module.STATES))
    p = list(module.PARAMETERS.values())
    ref = dict(zip(module.STATES, np.asarray(module.rhs(0.0, x, p), float)))
    values = dict(module.PARAMETERS)
    values = {"m": values["m"], "c": 1.0 / values["k"], "b": values["b"], "F": values["F"]}
    progress(f"[BondGraphTools] {n}-mass chain, timeout {BGT_TIMEOUT:g} s ...")
    try:
        out = run([python, "-c", BGT_SCRIPT, str(n), json.dumps(dict(zip(module.STATES, x))),
                   json.dumps(values)], timeout=BGT_TIMEOUT, cwd=workdir)[1]
        bgt = json.loads(out.strip().splitlines()[-1])
    except subprocess.TimeoutExpired:
        return [f"BondGraphTools, {n}-mass chain: no result within {BGT_TIMEOUT:g} s "
                "(timed out)"]
    except (RuntimeError, OSError, ValueError, IndexError) as exc:
        return [f"BondGraphTools, {n}-mass chain: FAILED: {str(exc).strip()[:300]}"]
    names = list(bgt["dx"])
    diff = relative_difference([bgt["dx"][s] for s in names], [ref[s] for s in names])
    agree = "agree" if diff <= AGREEMENT and len(names) == len(ref) else "DISAGREE"
    return [f"BondGraphTools {bgt['version']} (sympy {bgt['sympy']}), {n}-mass chain with "
            f"symbolic m, 1/k, b, F: building {bgt['build']:.3g} s, constitutive_relations "
            f"(the reduction) {bgt['reduce']:.4g} s, one run; its {bgt['relations']} "
            f"relations and bgc's right side {agree} at a random state (relative "
            f"difference {diff:.1e})",
            f"bgc, the same chain: {bgc_row.total:.3g} s in process (median of "
            f"{args.repeats}), {bgc_row.command:.3g} s for the whole command; "
            f"BondGraphTools / bgc in process: {bgt['reduce'] / bgc_row.total:.0f}x"]


# ---------------------------------------------------------------- fits and tables

def fitted_sizes(sizes: list[int]) -> list[int]:
    """The larger half of the sizes (at least two)."""
    return sizes[max(0, min(len(sizes) // 2, len(sizes) - 2)):]


def exponent(points: list[tuple[int, float]]) -> tuple[float | None, list[int]]:
    """Least-squares slope of log(time) on log(size) over the larger half of the sizes."""
    points = sorted((n, t) for n, t in points if t)
    chosen = fitted_sizes([n for n, _ in points])
    if len(chosen) < 2:
        return None, chosen
    times = dict(points)
    slope = np.polyfit(np.log(chosen), np.log([times[n] for n in chosen]), 1)[0]
    return float(slope), chosen


def fmt(value, spec: str, width: int) -> str:
    """value formatted by spec, right-aligned in width, always after at least one space."""
    text = "-" if value is None else format(value, spec)
    return " " + format(text, f">{width - 1}")


def stage_table(rows: list[Row]) -> str:
    head = f"{'family':<22}{'size':>5}{'states':>7}" + "".join(
        f"{s[:9]:>10}" for s in STAGES) + f"{'total':>9}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.family:<22}{r.size:>5}{r.states:>7}"
                     + "".join(fmt(r.stages.get(s), ".3f", 10) for s in STAGES)
                     + fmt(r.total, ".3f", 9))
    return "\n".join(lines)


def side_by_side_table(rows: list[Row]) -> str:
    head = (f"{'family':<22}{'size':>5} {'tool':<13}{'states':>7}{'build':>8}{'codegen':>8}"
            f"{'total':>8}{'command':>8}{'check':>7}{'cc':>7}{'ops':>7}{'flops':>7}"
            f"{'rhs µs':>10}{'jac µs':>10}{'vs bgc':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.family:<22}{r.size:>5} {r.tool:<13}{fmt(r.states, 'd', 7)}"
            f"{fmt(r.build, '.3g', 8)}{fmt(r.codegen, '.3g', 8)}{fmt(r.total, '.3g', 8)}"
            f"{fmt(r.command, '.3g', 8)}{fmt(r.check, '.3g', 7)}{fmt(r.cc, '.3g', 7)}"
            f"{fmt(r.ops, 'd', 7)}{fmt(r.flops, 'd', 7)}"
            f"{fmt(None if r.rhs_ns is None else r.rhs_ns / 1e3, '.3g', 10)}"
            f"{fmt(None if r.jac_ns is None else r.jac_ns / 1e3, '.3g', 10)}"
            f"{fmt(r.error, '.0e', 8)}" + (f"  {r.note}" if r.note else ""))
    return "\n".join(lines)


def build_table(rows: list[Row]) -> str:
    """The build to an object file, the cold run, and the price of the part's flags."""
    head = (f"{'family':<22}{'size':>5} {'tool':<13}{'total':>8}{'cc -c':>8}{'flags':>6}"
            f"{'to .o':>8}{'scene':>7}{'cc -c':>7}{'to .o':>7}{'simulate':>9}{'rhs -O2':>9}"
            f"{'as built':>9}{'jac -O2':>10}{'as built':>10}")
    lines = [head, "-" * len(head)]
    for r in rows:
        cc = r.part_cc if r.tool == "bgc" else r.cc
        flags = r.part_flags if r.tool == "bgc" else "-O2"
        lines.append(
            f"{r.family:<22}{r.size:>5} {r.tool:<13}{fmt(r.total, '.3g', 8)}"
            f"{fmt(cc, '.3g', 8)}{flags:>6}{fmt(r.to_object, '.3g', 8)}"
            + (f"{fmt(r.scene_total, '.3g', 7)}{fmt(r.scene_cc, '.3g', 7)}"
               f"{fmt(r.scene_object, '.3g', 6)}{'' if r.scene_jacobian else '*'}"
               f"{' ' if r.scene_jacobian else ''}" if r.tool == "bgc" else " " * 21)
            + f"{fmt(r.simulate, '.3g', 9)}"
            + "".join(fmt(None if v is None else v / 1e3, '.3g', w) for v, w in (
                (r.rhs_ns, 9), (r.rhs_part_ns, 9), (r.jac_ns, 10), (r.jac_part_ns, 10))))
    return "\n".join(lines)


def target_lines(rows: list[Row]) -> list[str]:
    """The issue's targets for the build to an object file."""
    mine = {(r.family, r.size, r.tool): r for r in rows}
    lines = []
    for family, n in TARGET_BUILDS:
        a, b = mine.get((family, n, "bgc")), mine.get((family, n, "CasADi MX+QR"))
        if a is None or b is None or a.scene_object is None or b.to_object is None:
            continue
        verdict = "met" if a.scene_object <= b.to_object else "NOT MET"
        lines.append(f"{family} {n}: bgc {a.scene_object:.3g} s to .o as bgc simulate builds "
                     f"it ({a.to_object:.3g} s with the Jacobian, as bgc compile), CasADi MX+QR "
                     f"{b.to_object:.3g} s (target: at most CasADi's: {verdict})")
    family, n, limit = TARGET_MASSES
    a = mine.get((family, n, "bgc"))
    if a is not None and a.to_object is not None:
        lines.append(f"{family} {n}: bgc {a.to_object:.3g} s to .o (target < {limit:g} s: "
                     f"{'met' if a.to_object < limit else 'NOT MET'})")
    return lines


def fit_lines(rows: list[Row]) -> list[str]:
    lines = [f"{'family':<22}{'tool':<13}{'fitted sizes':<22}{'in process':>11}"
             f"{'command':>9}{'cc':>7}{'to .o':>7}{'simulate':>9}  target <= "
             f"{TARGET_EXPONENT:g} (bgc: in process, command, to .o)"]
    lines.append("-" * len(lines[0]))
    keys = dict.fromkeys((r.family, r.tool) for r in rows)
    for family, tool in keys:
        mine = [r for r in rows if (r.family, r.tool) == (family, tool)]
        total, sizes = exponent([(r.size, r.total) for r in mine])
        command, _ = exponent([(r.size, r.command) for r in mine])
        cc, _ = exponent([(r.size, r.cc) for r in mine])
        to_object, _ = exponent([(r.size, r.to_object) for r in mine])
        simulate, _ = exponent([(r.size, r.simulate) for r in mine])
        verdicts = [v for v in (total, command, to_object) if v is not None]
        verdict = ("-" if tool != "bgc" or not verdicts else
                   "met" if all(v <= TARGET_EXPONENT for v in verdicts) else "NOT MET")
        lines.append(f"{family:<22}{tool:<13}{', '.join(map(str, sizes)):<22}"
                     f"{fmt(total, '.2f', 11)}{fmt(command, '.2f', 9)}{fmt(cc, '.2f', 7)}"
                     f"{fmt(to_object, '.2f', 7)}{fmt(simulate, '.2f', 9)}  {verdict}")
    return lines


def twin_lines(rows: list[Row]) -> list[str]:
    """The component model against its flat twin, size by size: in process and command."""
    mine = {(r.family, r.size): r for r in rows if r.tool == "bgc" and r.family in TWINS}
    sizes = sorted({n for f, n in mine if (TWINS[0], n) in mine and (TWINS[1], n) in mine})
    if not sizes:
        return []
    lines = [f"{TWINS[0]} against {TWINS[1]} (target <= {TARGET_TWIN_RATIO:g} at the "
             f"largest size):",
             f"{'instances':>9}{'components':>12}{'flat':>8}{'ratio':>7}{'command':>9}"
             f"{'flat':>8}{'ratio':>7}"]
    for n in sizes:
        a, b = mine[(TWINS[0], n)], mine[(TWINS[1], n)]
        lines.append(f"{n:>9}{fmt(a.total, '.3f', 12)}{fmt(b.total, '.3f', 8)}"
                     f"{fmt(a.total / b.total, '.2f', 7)}{fmt(a.command, '.3f', 9)}"
                     f"{fmt(b.command, '.3f', 8)}{fmt(a.command / b.command, '.2f', 7)}")
    a, b = mine[(TWINS[0], sizes[-1])], mine[(TWINS[1], sizes[-1])]
    met = a.total <= TARGET_TWIN_RATIO * b.total
    lines.append(f"at {sizes[-1]} instances: {a.total / b.total:.2f}x in process "
                 f"({'met' if met else 'NOT MET'})")
    return lines


def check_line(rows: list[Row]) -> str | None:
    family, size, limit = CHECK_TARGET
    row = next((r for r in rows if (r.family, r.size, r.tool) == (family, size, "bgc")), None)
    if row is None or row.check is None:
        return None
    verdict = "met" if row.check < limit else "NOT MET"
    return (f"`python -m bgc check` on the {size}-section RC ladder: {row.check:.3g} s "
            f"(target < {limit:g} s: {verdict})")


def plot(rows: list[Row], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_compile, ax_cc) = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    colors = dict(zip(SIZES, ("tab:blue", "tab:purple", "tab:orange", "tab:green", "tab:red",
                              "tab:brown", "tab:olive", "tab:cyan", "tab:gray")))
    for (family, tool) in dict.fromkeys((r.family, r.tool) for r in rows):
        mine = sorted((r for r in rows if (r.family, r.tool) == (family, tool)),
                      key=lambda r: r.size)
        sizes = [r.size for r in mine]
        color = colors.get(family, "gray")
        if tool == "bgc":
            ax_compile.plot(sizes, [r.total for r in mine], "o-", color=color,
                            label=f"{family}, in process")
            ax_compile.plot(sizes, [r.command for r in mine], "s:", color=color,
                            label=f"{family}, whole command")
            ax_cc.plot(sizes, [r.cc for r in mine], "o-", color=color, label=f"{family}, bgc")
        else:
            style = "^--" if "SX" in tool else "v-."
            ax_compile.plot(sizes, [r.total for r in mine], style, color=color, alpha=0.6,
                            label=f"{family}, {tool} (build + codegen)")
            ax_cc.plot(sizes, [r.cc for r in mine], style, color=color, alpha=0.6,
                       label=f"{family}, {tool} (-c)")
    ax_compile.set_title("compile time: bgc (model -> C) and CasADi")
    ax_cc.set_title("cc -O2 of the generated C")
    for ax in (ax_compile, ax_cc):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("size n (links, masses, sections)")
        ax.grid(which="both", alpha=0.3)
        ax.legend(fontsize=6.5)
    ax_compile.set_ylabel("seconds (median)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def machine_facts(ca, args) -> list[str]:
    import scipy
    import sympy

    cc_line, processor, load = (machine.cc_version(c_compiler()), machine.processor(),
                                machine.load_average())
    import bgc

    casadi = ca.__version__ if ca else "not installed"
    return [f"date:     {datetime.datetime.now().isoformat(timespec='seconds')}",
            f"cc:       {cc_line}  (flags: {' '.join(CFLAGS)} ... -lm)",
            f"python:   {sys.version.split()[0]}  bgc {bgc.__version__}  numpy {np.__version__}"
            f"  scipy {scipy.__version__}  sympy {sympy.__version__}  casadi {casadi}",
            f"machine:  {processor}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, load average {load}",
            f"timing:   medians of {args.repeats} (bgc stages: a fresh process each); "
            f"rhs/jac: best of 3 loops of >= {args.min_time:g} s; times in seconds"]


# ---------------------------------------------------------------- main

def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="fewer and smaller sizes, one repeat (about a minute)")
    parser.add_argument("--families", default=",".join(SIZES),
                        help=f"comma-separated, of {', '.join(SIZES)}")
    parser.add_argument("--repeats", type=int, help="measurements per number (median); "
                        "default 3, 1 with --quick")
    parser.add_argument("--min-time", type=float, default=0.2,
                        help="seconds of one timing loop of the generated C (default 0.2)")
    parser.add_argument("--sizes", action="append", default=[], metavar="FAMILY=N,N,..",
                        help="the sizes of a family, instead of its default ones (repeatable)")
    parser.add_argument("--no-simulate", action="store_true",
                        help="skip the cold `bgc simulate` runs")
    parser.add_argument("--plot", metavar="FILE.png", help="log-log plot of the times")
    parser.add_argument("--bondgraphtools", metavar="PYTHON",
                        help="an interpreter with BondGraphTools: time its reduction of the "
                             f"{BGT_MASSES}-mass chain (slow)")
    parser.add_argument("--one", nargs=3, metavar=("FAMILY", "N", "DIR"), help=argparse.SUPPRESS)
    parser.add_argument("--with-python", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--scene-build", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        return args
    args.families = [f.strip() for f in args.families.split(",") if f.strip()]
    unknown = [f for f in args.families if f not in SIZES]
    if unknown or not args.families:
        parser.error(f"unknown families {', '.join(unknown)}; choose from {', '.join(SIZES)}")
    args.chosen_sizes = {}
    for given in args.sizes:
        family, _, numbers = given.partition("=")
        try:
            args.chosen_sizes[family.strip()] = tuple(int(n) for n in numbers.split(","))
        except ValueError:
            parser.error(f"--sizes {given}: expected FAMILY=N,N,...")
        if family.strip() not in SIZES:
            parser.error(f"--sizes {given}: unknown family")
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    if args.repeats < 1 or not args.min_time > 0:
        parser.error("--repeats must be >= 1 and --min-time > 0")
    return args


def import_casadi():
    try:
        import casadi
    except ImportError:
        return None
    return casadi


def run_all(args, ca, workdir: Path) -> list[Row]:
    sizes = {**(QUICK_SIZES if args.quick else SIZES), **args.chosen_sizes}
    rows, rng = [], np.random.default_rng(1)
    if not args.no_simulate:
        warm_runtime(workdir)
    for family in args.families:
        for n in sizes[family]:
            progress(f"[bgc] {family} {n} ...")
            bgc_row = measure_bgc(family, n, workdir, args)
            rows.append(bgc_row)
            for base in (b for b in BASELINES if ca and b.family == family):
                progress(f"[{base.tool}] {family} {n} ...")
                rows.append(measure_casadi(ca, base, n, bgc_row, workdir, args, rng))
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.one:
        family, n, outdir = args.one
        one(family, int(n), Path(outdir), args.with_python, args.scene_build)
        return 0
    ca = import_casadi()
    print("\n".join(machine_facts(ca, args)))
    with tempfile.TemporaryDirectory(prefix="bgc-scale-") as tmp:
        rows = run_all(args, ca, Path(tmp))
        bgt_lines = (measure_bondgraphtools(args.bondgraphtools, Path(tmp), args)
                     if args.bondgraphtools else [BGT_REPORTED])
    bgc_rows = [r for r in rows if r.tool == "bgc"]
    print("\nbgc's stages, in process [s]:")
    print(stage_table(bgc_rows))
    print("\nbgc and the baselines [s, µs]: build + codegen = total; command = python -m bgc "
          "compile;\ncheck = python -m bgc check; cc -O2 (CasADi: -c); ops, flops: the right "
          "side's;\nrhs, jac: per call; vs bgc: relative difference of the right sides")
    print(side_by_side_table(rows))
    print("\nthe build to an object file and the cold run [s, µs]: total = in process (CasADi: "
          "build + codegen);\ncc -c = the model part as bgc simulate compiles it, at flags "
          "(CasADi: its file at -O2); to .o = total + cc -c;\nsimulate = a cold `python -m bgc "
          "simulate` (runtime object cached); rhs, jac per call: the standalone\nprogram at "
          "-O2, and the model part as built linked with the runtime at -O2;\nscene, cc -c, "
          "to .o: the same for the program bgc simulate builds for the scene's solver\n(*: "
          "without jvp, the scene's solver being explicit)")
    print(build_table(rows))
    targets = target_lines(rows)
    if targets:
        print("\n" + "\n".join(targets))
    print("\ngrowth exponents, log(time) on log(size) over the larger half of the sizes:")
    print("\n".join(fit_lines(rows)))
    line = check_line(rows)
    if line:
        print(f"\n{line}")
    twins = twin_lines(rows)
    if twins:
        print("\n" + "\n".join(twins))
    if not ca:
        print("\nCasADi: not importable, its baselines were skipped")
    print()
    print("\n".join(bgt_lines))
    if args.plot:
        try:
            plot(rows, args.plot)
            print(f"\nplot written to {args.plot}")
        except ImportError:
            print("\n--plot: matplotlib is not installed, no plot")
    return 0


if __name__ == "__main__":
    sys.exit(main())
