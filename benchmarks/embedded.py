"""The embedded target on a Cortex-M4F: instructions per step under QEMU, beside CasADi's
generated code for the same step, and the memory each needs, in one run.

    python benchmarks/embedded.py [--steps N] [--only pendulum,pwm,chain16,rc_pair]

Models (each at the fixed step and method of its row, `bgc compile --target embedded`):
  pendulum  models/pendulum.bg, scene swing: the paper's pendulum with its Baumgarte PID
            corrector, rk4 at 1 ms (its multiplier solved in closed form).
  pwm       tests/models/pwm_motor_stop.bg, scene run: a PWM-driven DC motor against an end
            stop, rk4 at 0.1 ms; each step checks the stop's and the edges' events, and some
            locate an impact or step onto an edge (the steps counted from the start: the
            strikes, the settling and the rest on the stop).
  chain16   models/pendulum_chain.bg with constant N = 16, scene swing: 16 links, 32 states,
            rk4 at 1 ms; every derivative solves the 16 multipliers' LU block.
  rc_pair   models/rc_pair.bg, scene step: the stiff RC pair (time constants 1e-6 s and 1 s),
            ros2 at 10 ms (10^4 fast time constants): per step two right sides, the 2 x 2
            Jacobian by jvp, one LU and two solves.
Each in double (software floating point: the M4F's FPU is single precision) and in float (the
FPU), cross-compiled with arm-none-eabi-gcc -O2 -mcpu=cortex-m4 -mthumb -mfloat-abi=hard
-mfpu=fpv4-sp-d16 and run under qemu-system-arm -M mps2-an386 (benchmarks/embedded_m4.c).

The figure: QEMU does not model the M4's cycles (nor its DWT cycle counter).  With
`-icount shift=0,sleep=off` its virtual clock advances one nanosecond per guest instruction,
deterministically; the SysTick timer counts that clock, so the ticks over BATCH steps, less a
measurement of nothing, times the instructions per tick calibrated in the same run on a loop
of known length, are the instructions the steps executed.  The same binary gives the same
count on every run and machine.  Instructions are not cycles: on a Cortex-M4 most take one
cycle, loads two, a taken branch two to four, a float divide 14, and libgcc's soft double
operations are sequences of them; cycles per step on the chip are about 1.2-1.6 times these
counts (zero-wait-state memory), which only the hardware can settle.

CasADi: the pendulum's eq. (12) (benchmarks/pendulum.py) and the chain's equations
(_chain_casadi: its multipliers by CasADi's symbolic solve in every evaluation; its rows are
bgc simulate's to 4e-16 over 200 steps) as SX expressions, one rk4 step of each as a
casadi.Function, its C from casadi's CodeGenerator (casadi_real double or float, casadi_int
int), built and counted the same way.  The PWM motor is not expressed: CasADi's generated
code has no event location (its edges and impacts).

Columns:  insns/step  instructions per step (the mean over the run's steps);  flash  the
model object's .text + .rodata (arm-none-eabi-size);  stack  the deepest frame chain of one
step by gcc's -fstack-usage (the sum over the object's functions: nothing recurses), bgc only;
state, step locals  bgc's --report.  Times are printed, never asserted.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]

M4 = ROOT / "tests" / "embedded_m4"
HARNESS = HERE / "embedded_m4.c"
CPU = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]
CFLAGS = ["-std=c99", "-O2", *CPU]
MODELS = {  # name: (file, scene, constants, step, steps[, solver: rk4 unless given])
    "pendulum": ("models/pendulum.bg", "swing", (), 1e-3, 1000),
    "pwm": ("tests/models/pwm_motor_stop.bg", "run", (), 1e-4, 4000),
    "chain16": ("models/pendulum_chain.bg", "swing", (("N", 16),), 1e-3, 100),
    "rc_pair": ("models/rc_pair.bg", "step", (), 1e-2, 500, "ros2"),
}
QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial",
        "none", "-semihosting-config", "enable=on,target=native", "-icount",
        "shift=0,sleep=off"]


def run(cmd, cwd, **kw):
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=True, **kw)


def link_and_count(directory: Path, objects: list[str], defines: list[str]) -> float:
    """Build the harness with objects and run it under QEMU: instructions per step."""
    run(["arm-none-eabi-gcc", *CFLAGS, "-I.", *defines, "--specs=rdimon.specs",
         "-nostartfiles", "-T", str(M4 / "mps2_an386.ld"), str(M4 / "startup.c"),
         str(HARNESS), *objects, "-lm", "-o", "bench.elf"], directory)
    out = run(QEMU + ["-kernel", "bench.elf"], directory, timeout=900).stdout.split("\n")
    facts = {line.split()[0]: [int(v) for v in line.split()[1:]] for line in out if line}
    insns, ticks = facts["calib"]
    steps, total = facts["steps"]
    batches = -(-steps // 10)
    return (total - batches * facts["empty"][0]) * insns / ticks / steps


def flash(directory: Path, obj: str) -> int:
    """.text + .rodata of an object (arm-none-eabi-size -A)."""
    sizes = run(["arm-none-eabi-size", "-A", obj], directory).stdout
    return sum(int(p[1]) for p in (ln.split() for ln in sizes.splitlines())
               if p and p[0].startswith((".text", ".rodata")))


def stack(directory: Path, name: str) -> int:
    """The sum of the object's stack frames (gcc -fstack-usage): a bound on a step's chain."""
    su = (directory / f"{name}.su").read_text().splitlines()
    return sum(int(line.split("\t")[1]) for line in su)


def bgc_row(model: str, real: str, steps: int | None, work: Path) -> dict:
    from bgc import api
    from bgc.codegen import embedded
    path, scene, consts, h, default = MODELS[model][:5]
    solver = MODELS[model][5] if len(MODELS[model]) > 5 else "rk4"
    src = api.read_source(str(ROOT / path))
    src = api.Source(src.path, src.text, consts)
    compiled = api.build(src, scene)
    files = api.compile_embedded(compiled, real, solver, h)
    directory = work / f"bgc-{model}-{real}"
    directory.mkdir()
    for name, text in files.items():
        (directory / name).write_text(text)
    ident = next(iter(files)).rsplit(".", 1)[0]
    run(["arm-none-eabi-gcc", *CFLAGS, "-fstack-usage", "-c", f"{ident}.c", "-o",
         f"{ident}.o"], directory)
    n = steps or default
    per = link_and_count(directory, [f"{ident}.o"],
                         [f"-DBGC_MODEL={ident}", f'-DBGC_HEADER="{ident}.h"',
                          f"-DBGC_STEPS={n}"])
    mem = embedded.memory(compiled.program, real, solver)
    return {"model": model, "real": real, "method": "bgc", "steps": n, "insns": per,
            "flash": flash(directory, f"{ident}.o"), "stack": stack(directory, ident),
            "state": mem["state"], "locals": mem["step_locals"]}


def _pendulum_casadi(ca):
    """The pendulum's eq. (12) (benchmarks/pendulum.py): (s, f(s)), s = (px, py, x, y), and
    s(0)."""
    from pendulum import PARAMS
    m, l, g, alpha, beta = (PARAMS[k] for k in ("m", "l", "g", "alpha", "beta"))
    s = ca.SX.sym("s", 4)
    px, py, x, y = s[0], s[1], s[2], s[3]
    xd, yd = px / m, py / m
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    f = ca.vertcat(m * (-x / (x**2 + y**2) * bracket), m * (g - y / (x**2 + y**2) * bracket),
                   xd, yd)
    theta0 = PARAMS["theta0"]
    return s, f, [0.0, 0.0, l * math.sin(theta0), l * math.cos(theta0)]


def _chain_casadi(ca, n=16, m=1.0, l=1.0, g=9.81, alpha=5.0, beta=5.0, theta0=0.5,
                  dtheta=0.15):
    """models/pendulum_chain.bg's equations written out: n point masses (x_i, y_i), momenta
    p, rods phi_i = (x_i - x_{i-1})^2 + (y_i - y_{i-1})^2 - l^2 (x_0 = y_0 = 0) held by the
    Baumgarte corrector phi'' + 2 alpha phi' + beta^2 phi = 0: p' = F + G^T lambda with
    (G G^T / m) lambda = -(G F / m + G' v + 2 alpha G v + beta^2 phi), solved by CasADi's
    own symbolic solve in every evaluation.  (s, f(s)), s = (q, p), and s(0)."""
    q, p = ca.SX.sym("q", 2 * n), ca.SX.sym("p", 2 * n)
    v = p / m
    G = ca.SX.zeros(n, 2 * n)
    phi, curve = [], []
    for i in range(n):
        prev = (0, 0, 0, 0) if i == 0 else (q[2 * i - 2], q[2 * i - 1], v[2 * i - 2],
                                             v[2 * i - 1])
        dx, dy = q[2 * i] - prev[0], q[2 * i + 1] - prev[1]
        dvx, dvy = v[2 * i] - prev[2], v[2 * i + 1] - prev[3]
        phi.append(dx * dx + dy * dy - l * l)
        curve.append(2 * (dvx * dvx + dvy * dvy))
        G[i, 2 * i], G[i, 2 * i + 1] = 2 * dx, 2 * dy
        if i > 0:
            G[i, 2 * i - 2], G[i, 2 * i - 1] = -2 * dx, -2 * dy
    F = ca.vertcat(*[ca.vertcat(0, m * g) for _ in range(n)])
    lam = ca.solve(G @ G.T / m, -(G @ F / m + ca.vertcat(*curve) + 2 * alpha * (G @ v)
                                  + beta**2 * ca.vertcat(*phi)))
    x0, x, y = [], 0.0, 0.0
    for i in range(n):
        x, y = x + l * math.sin(theta0 + i * dtheta), y + l * math.cos(theta0 + i * dtheta)
        x0 += [x, y]
    return ca.vertcat(q, p), ca.vertcat(v, F + G.T @ lam), x0 + [0.0] * (2 * n)


def casadi_row(model: str, real: str, steps: int | None, work: Path) -> dict:
    import casadi as ca
    if model == "pwm":
        return {"model": model, "real": real, "method": "casadi",
                "note": "no event location (PWM edges, impacts)"}
    if model == "rc_pair":
        return {"model": model, "real": real, "method": "casadi",
                "note": "not expressed (its rk4 step is unstable at 10 ms)"}
    s, rhs, x0 = (_pendulum_casadi if model == "pendulum" else _chain_casadi)(ca)
    f = ca.Function("f", [s], [rhs])
    h = MODELS[model][3]
    k1 = f(s)
    k2 = f(s + h / 2 * k1)
    k3 = f(s + h / 2 * k2)
    k4 = f(s + h * k3)
    step = ca.Function("casadi_step", [s], [s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    directory = work / f"casadi-{model}-{real}"
    directory.mkdir()
    gen = ca.CodeGenerator("casadi_step.c", {"with_header": True, "casadi_real": real,
                                             "casadi_int": "int"})
    gen.add(step)
    gen.generate(str(directory) + os.sep)
    run(["arm-none-eabi-gcc", *CFLAGS, "-c", "casadi_step.c", "-o", "casadi_step.o"],
        directory)
    n = steps or MODELS[model][4]
    per = link_and_count(directory, ["casadi_step.o"],
                         ["-DBGC_CASADI=casadi_step", f"-DBGC_N={len(x0)}",
                          f"-DBGC_REAL={real}", "-DBGC_X0={" + ", ".join(map(repr, x0)) + "}",
                          f"-DBGC_NW={step.sz_w()}", f"-DBGC_NIW={step.sz_iw()}",
                          '-DBGC_HEADER="casadi_step.h"', f"-DBGC_STEPS={n}"])
    return {"model": model, "real": real, "method": f"CasADi {ca.__version__}", "steps": n,
            "insns": per, "flash": flash(directory, "casadi_step.o")}


def fmt(row: dict, key: str, spec: str) -> str:
    if row.get(key) is None:
        return "-".rjust(int(spec.rstrip("dfs").split(".")[0]))
    return format(row[key], spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, help="steps of every run (default: the model's)")
    ap.add_argument("--only", default="pendulum,pwm,chain16")
    args = ap.parse_args(argv)
    missing = [t for t in ("arm-none-eabi-gcc", "qemu-system-arm") if shutil.which(t) is None]
    if missing:
        print(f"needs {', '.join(missing)} (apt-get install gcc-arm-none-eabi "
              "libnewlib-arm-none-eabi qemu-system-arm)")
        return 1
    try:
        import casadi  # noqa: F401
    except ImportError:
        casadi = None
    print(f"date:  {datetime.datetime.now().isoformat(timespec='seconds')}")
    print("cc:    " + run(["arm-none-eabi-gcc", "--version"], ROOT).stdout.split("\n")[0]
          + "  " + " ".join(CFLAGS))
    print("qemu:  " + run(["qemu-system-arm", "--version"], ROOT).stdout.split("\n")[0]
          + "  -M mps2-an386 -icount shift=0,sleep=off")
    print("casadi: " + (casadi.__version__ if casadi else "not installed (pip install casadi): "
                        "its rows are left out"))
    rows = []
    with tempfile.TemporaryDirectory(prefix="bgc-embedded-") as tmp:
        for model in args.only.split(","):
            for real in ("double", "float"):
                rows.append(bgc_row(model, real, args.steps, Path(tmp)))
                if casadi:
                    rows.append(casadi_row(model, real, args.steps, Path(tmp)))
    head = (f"{'model':9} {'real':6} {'method':13} {'steps':>6} {'insns/step':>11} "
            f"{'flash':>7} {'stack':>6} {'state':>6} {'locals':>7}")
    print()
    print(head)
    print("-" * len(head))
    for r in rows:
        if "note" in r:
            print(f"{r['model']:9} {r['real']:6} {r['method']:13} n/a: {r['note']}")
            continue
        print(f"{r['model']:9} {r['real']:6} {r['method']:13} {r['steps']:6d} "
              f"{fmt(r, 'insns', '11.0f')} {fmt(r, 'flash', '7d')} {fmt(r, 'stack', '6d')} "
              f"{fmt(r, 'state', '6d')} {fmt(r, 'locals', '7d')}")
    print("\ninsns/step: instructions under QEMU's -icount (not M4 cycles: see the header); "
          "flash, stack, state, locals in bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
