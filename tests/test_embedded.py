"""The embedded C target (bgc compile --target embedded, docs/embedded.md): the generated code
compiles warning-free, holds no heap, stdio or mutable global, and steps to the bytes of
`bgc simulate` at the same fixed-step solver and step (double), within float's resolution
(float), on the host and on a Cortex-M4 under QEMU; the motions themselves checked against
the closed forms and SciPy computed here; refusals located."""
from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from bgc import api
from bgc.cli import main

ROOT = Path(__file__).resolve().parent.parent
HARNESS = ROOT / "tests" / "embedded_harness.c"
M4 = ROOT / "tests" / "embedded_m4"
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Wconversion", "-Werror", "-pedantic", "-O2"]
H = 0.001
STEPS = 1000
MODELS = {"pendulum": ("models/pendulum.bg", "swing"), "dc_motor": ("models/dc_motor.bg", "run"),
          "double_pendulum": ("models/double_pendulum.bg", None),  # a linear block (LU) per step
          "diode": ("models/diode.bg", None),  # a Newton block
          # events: a when-block's reinit, a switched element (dry friction), PWM edges and an
          # end stop's impacts; (their step, and the steps a run takes)
          "ball_when": ("tests/models/ball_when.bg", "drop"),
          "stick_slip": ("tests/models/stick_slip.bg", "run"),
          "pwm_motor_stop": ("tests/models/pwm_motor_stop.bg", "run"),
          # impacts of a two-link arm on a stop, its multipliers an LU block per step
          "two_link_arm_stop": ("tests/models/two_link_arm_stop.bg", "strike"),
          # the 16-link chain (constant N = 16): 32 states, a 16-row LU block per evaluation
          "chain16": ("models/pendulum_chain.bg", "swing"),
          # the fixed-step Rosenbrock method ros2: a stiff nonlinear non-autonomous plant, the
          # linear stiff RC pair, and through a Newton block
          "stiff_rc": ("tests/models/stiff_rc.bg", "run"),
          "rc_pair_ros2": ("models/rc_pair.bg", "step"),
          "diode_ros2": ("models/diode.bg", None)}
CONSTS = {"chain16": (("N", 16),)}  # the model's constants, as --const gives them
SOLVER = {"stiff_rc": "ros2", "rc_pair_ros2": "ros2", "diode_ros2": "ros2"}  # else rk4
STEP = {"pwm_motor_stop": (1e-4, 10000), "stick_slip": (H, 10000), "ball_when": (H, 3000),
        "chain16": (H, 200), "stiff_rc": (0.01, 200), "rc_pair_ros2": (0.01, 500)}
BUILDS = [("pendulum", "double"), ("pendulum", "float"), ("dc_motor", "double"),
          ("dc_motor", "float"), ("double_pendulum", "double"), ("double_pendulum", "float"),
          ("diode", "double"), ("ball_when", "double"), ("stick_slip", "double"),
          ("pwm_motor_stop", "double"), ("two_link_arm_stop", "double"),
          ("ball_when", "float"), ("stick_slip", "float"), ("pwm_motor_stop", "float"),
          ("chain16", "double"), ("chain16", "float"), ("stiff_rc", "double"),
          ("rc_pair_ros2", "double"), ("rc_pair_ros2", "float"), ("diode_ros2", "double")]
FORBIDDEN = ("malloc", "calloc", "realloc", "free", "printf", "fprintf", "sprintf",
             "snprintf", "puts", "fputs", "fwrite", "putchar", "fopen", "exit", "abort")

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc on this machine")


def _source(model):
    """The model's file, with its constants (CONSTS) as --const gives them."""
    path = str(ROOT / MODELS[model][0])
    if model not in CONSTS:
        return path
    src = api.read_source(path)
    return api.Source(src.path, src.text, CONSTS[model])


def _emit(model, real, tmp):
    scene = MODELS[model][1]
    files = api.compile(_source(model), "embedded", scene=scene,
                        embedded={"real": real, "solver": SOLVER.get(model, "rk4"),
                                  "step": STEP.get(model, (H,))[0]})
    for name, text in files.items():
        (tmp / name).write_text(text)
    return files


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """(model, real) -> the directory with NAME.h, NAME.c, NAME.o and the harness `run`
    (one gcc compile of the model, one of the harness)."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    out = {}
    for model, real in BUILDS:
        tmp = tmp_path_factory.mktemp(f"{model}-{real}")
        _emit(model, real, tmp)
        name = _ident(model)
        subprocess.run(["gcc", *FLAGS, "-c", f"{name}.c", "-o", f"{name}.o"], cwd=tmp,
                       check=True)
        subprocess.run(["gcc", *FLAGS[:-1], "-O0", "-I.", f"-DBGC_MODEL={name}",
                        f'-DBGC_HEADER="{name}.h"', str(HARNESS), f"{name}.o", "-lm",
                        "-o", "run"], cwd=tmp, check=True)
        out[model, real] = tmp
    return out


def _ident(model):
    """The generated files' name: the model's own (chain16's file names itself chain8)."""
    return "chain8" if model == "chain16" else model.removesuffix("_ros2")


def _rows(directory, steps=STEPS, *params):
    text = subprocess.run([str(directory / "run"), str(steps), *params], capture_output=True,
                          text=True, check=True).stdout
    return text


def _simulated(model, steps=STEPS, backend="vm"):
    """`bgc simulate --solver rk4 --step H --dt H` (or the model's SOLVER) as CSV text (the
    numbers as the CSV writes them, %.17g)."""
    scene = MODELS[model][1]
    h = STEP.get(model, (H,))[0]
    t, Y, names = api.simulate(_source(model), scene, backend=backend,
                               solver=SOLVER.get(model, "rk4"),
                               step=h, dt=h, t_end=steps * h)
    assert steps * h == t[-1]  # the last row is on the grid too
    lines = [",".join(["t", *names])]
    lines += [",".join("%.17g" % v for v in (tk, *row)) for tk, row in zip(t, Y)]
    return "\n".join(lines) + "\n"


def _table(text):
    lines = text.strip().split("\n")
    return lines[0].split(","), np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])


@pytest.mark.parametrize("model", list(MODELS))
def test_double_is_the_bytes_of_simulate(built, model):
    """Also through algebraic blocks: the double pendulum's linear one, the diode's Newton
    iterations (each starting from the last step's solution, as in simulate); and through
    events: crossings located inside the step and the step split there, time events stepped
    onto, reinits, a switched element's modes, impacts."""
    steps = STEP.get(model, (H, STEPS))[1]
    assert _rows(built[model, "double"], steps) == _simulated(model, steps)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc on this machine")
def test_events_are_the_bytes_of_the_c_backend(built):
    """simulate built in C (its runtime's bgc_find_event) as well as in the interpreter."""
    assert _rows(built["pwm_motor_stop", "double"], 3000) == _simulated(
        "pwm_motor_stop", 3000, backend="c")


@pytest.mark.parametrize("model", ["pendulum", "dc_motor", "double_pendulum", "chain16",
                                   "ball_when", "rc_pair_ros2"])
def test_float_within_its_resolution(built, model):
    """max |float - double| / max |double| per output over the run, below 1e-5; the double
    rows are simulate's bytes (test_double_is_the_bytes_of_simulate).  The ball: events in
    float, its bounces located on float's interpolant."""
    steps = STEP.get(model, (H, STEPS))[1]
    names, single = _table(_rows(built[model, "float"], steps))
    _, double = _table(_rows(built[model, "double"], steps))
    assert single.shape == double.shape
    assert np.array_equal(single[:, 0], double[:, 0])
    for j, name in enumerate(names[1:], 1):
        scale = np.max(np.abs(double[:, j]))
        if name == "rod.residual":  # x^2 + y^2 - l^2: zero up to the rounding of l^2 = 1
            assert np.max(np.abs(single[:, j])) < 1e-5
            continue
        assert np.max(np.abs(single[:, j] - double[:, j])) <= 1e-5 * scale, name


def test_pendulum_swings_as_the_pendulum_equation(built):
    """x = l sin(theta), y = l cos(theta) with theta'' = -(g/l) sin(theta), theta(0) = 0.5:
    SciPy at tight tolerance; the Baumgarte-stabilised constraint holds at the fixed step."""
    names, rows = _table(_rows(built["pendulum", "double"]))
    g, l, th0 = 9.81, 1.0, 0.5
    sol = solve_ivp(lambda t, z: [z[1], -g / l * math.sin(z[0])], (0, STEPS * H), [th0, 0.0],
                    t_eval=rows[:, 0], rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(rows[:, 1] - l * np.sin(sol.y[0]))) < 1e-8
    assert np.max(np.abs(rows[:, 2] - l * np.cos(sol.y[0]))) < 1e-8
    assert np.max(np.abs(rows[:, 4])) < 1e-10


def test_dc_motor_follows_its_linear_equations(built):
    """La di/dt = V - Ra i - kt w, Jr dw/dt = kt i - br w - tau, angle' = w from rest: the
    matrix exponential of the affine system."""
    names, rows = _table(_rows(built["dc_motor", "double"]))
    V, Ra, La, kt, Jr, br, tau = 12.0, 2.0, 0.5, 0.8, 0.05, 0.1, 0.5
    A = np.array([[-Ra / La, -kt / La, 0, V / La], [kt / Jr, -br / Jr, 0, -tau / Jr],
                  [0, 1, 0, 0], [0, 0, 0, 0]])
    rows = rows[::50]
    z = np.array([expm(A * t) @ [0, 0, 0, 1] for t in rows[:, 0]])
    got = {n: rows[:, j] for j, n in enumerate(names)}
    assert np.max(np.abs(got["ind.f"] - z[:, 0])) < 1e-9
    assert np.max(np.abs(got["rotor.f"] - z[:, 1])) < 1e-9
    assert np.max(np.abs(got["angle"] - z[:, 2])) < 1e-9


def test_no_heap_no_stdio_no_mutable_global(built):
    for (model, real), directory in built.items():
        obj = str(directory / f"{_ident(model)}.o")
        undefined = subprocess.run(["nm", "-u", obj], capture_output=True, text=True,
                                   check=True).stdout.split()
        names = {u for u in undefined if u != "U"}
        assert not names & set(FORBIDDEN), (model, real, names)
        libm = {"sin", "cos", "sinf", "cosf", "sqrt", "sqrtf", "exp", "expf", "log", "logf",
                "floor", "floorf",
                "sincos", "sincosf"}  # (gcc's fusion of a sin and a cos of one argument)
        # what gcc may call for a loop that zeroes or copies an array, even freestanding
        compiler = {"memset", "memcpy", "memmove"}
        assert names <= libm | compiler, (model, real, names - libm - compiler)
        sizes = subprocess.run(["size", "-A", obj], capture_output=True, text=True,
                               check=True).stdout
        for line in sizes.splitlines():
            parts = line.split()
            if parts and parts[0] in (".data", ".bss"):
                assert parts[1] == "0", (model, real, line)


def test_fault_leaves_the_state_unchanged(tmp_path):
    """A step whose derivative is not finite returns NAME_FAULT_NONFINITE with the state and
    the outputs as they were."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    _emit("dc_motor", "double", tmp_path)
    (tmp_path / "main.c").write_text("""
#include <math.h>
#include <string.h>
#include "dc_motor.h"
int main(void)
{
    dc_motor_state s, before;
    dc_motor_params p;
    dc_motor_inputs u;
    dc_motor_outputs y, ybefore;
    memset(&u, 0, sizeof u);
    memset(&y, 0, sizeof y);
    dc_motor_params_default(&p);
    dc_motor_init(&s, &p);
    if (dc_motor_step(&s, &p, &u, &y) != dc_motor_OK)
        return 1;
    before = s;
    ybefore = y;
    p.p_V = NAN;
    dc_motor_params_update(&p);
    if (dc_motor_step(&s, &p, &u, &y) != dc_motor_FAULT_NONFINITE)
        return 2;
    if (memcmp(&s, &before, sizeof s) != 0 || memcmp(&y, &ybefore, sizeof y) != 0)
        return 3;
    return dc_motor_time(&s) == 0.001 ? 0 : 4;
}
""")
    subprocess.run(["gcc", *FLAGS, "main.c", "dc_motor.c", "-lm", "-o", "fault"],
                   cwd=tmp_path, check=True)
    assert subprocess.run([str(tmp_path / "fault")]).returncode == 0


@pytest.mark.skipif(shutil.which("clang") is None, reason="no clang on this machine")
def test_clang_warning_free(built):
    for (model, real), directory in built.items():
        subprocess.run(["clang", *FLAGS, "-fsyntax-only", f"{_ident(model)}.c"],
                       cwd=directory, check=True)


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None,
                    reason="no arm-none-eabi-gcc (apt-get install gcc-arm-none-eabi)")
def test_arm_none_eabi_warning_free(built):
    cpu = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]
    for (model, real), directory in built.items():
        subprocess.run(["arm-none-eabi-gcc", *cpu, *FLAGS, "-c", f"{_ident(model)}.c", "-o",
                        "arm.o"], cwd=directory, check=True)


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None
                    or shutil.which("qemu-system-arm") is None,
                    reason="no arm-none-eabi-gcc or qemu-system-arm (apt-get install "
                           "gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)")
@pytest.mark.parametrize("model, real, steps", [
    ("pendulum", "double", 200), ("pendulum", "float", 200),
    ("stick_slip", "double", 1000),  # through its first stick and breakaway
    ("pwm_motor_stop", "double", 4000),  # 400 PWM periods, its impacts on the stop
    ("pwm_motor_stop", "float", 4000), ("stick_slip", "float", 1000),
    ("chain16", "double", 20), ("chain16", "float", 20),  # (20 steps: 2 s under QEMU)
    # ros2 (not stiff_rc: its source's sin(w t) at every step is newlib's on the M4, which
    # differs from glibc's in the last bit at 3 % of the arguments)
    ("rc_pair_ros2", "double", 500), ("rc_pair_ros2", "float", 500)])
def test_cortex_m4_under_qemu_is_the_host(built, model, real, steps):
    """Cross-compiled for a Cortex-M4F (MPS2-AN386), run under QEMU with its output by
    semihosting: the host's rows, byte for byte."""
    directory = built[model, real]
    cpu = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]
    subprocess.run(["arm-none-eabi-gcc", *cpu, *FLAGS, "-c", f"{_ident(model)}.c", "-o",
                    "m4.o"], cwd=directory, check=True)
    subprocess.run(["arm-none-eabi-gcc", *cpu, "-O2", "-I.", f"-DBGC_MODEL={_ident(model)}",
                    f'-DBGC_HEADER="{_ident(model)}.h"', f"-DBGC_STEPS={steps}",
                    "--specs=rdimon.specs", "-nostartfiles", "-T", str(M4 / "mps2_an386.ld"),
                    str(M4 / "startup.c"), str(HARNESS), "m4.o", "-lm", "-o", "m4.elf"],
                   cwd=directory, check=True)
    run = subprocess.run(["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor",
                          "none", "-serial", "none", "-semihosting-config",
                          "enable=on,target=native", "-kernel", "m4.elf"], cwd=directory,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout == _rows(directory, steps)


TIME_EVENTS = """model rc_events "an RC circuit driven by a step and a pulse, a counter of resets"
parameter R = 1.0
parameter C = 0.5
u : Se(2*step(0.3) + pulse(0.55, 0.2))
r : R(R)
c : C(C)
u -> j
j : 1
j -> r
j -> c
discrete n = 0
when c.q > 0.4 {
  n = n + 1
  reinit c.q = 0.1
}
signal count = n
scene run { time 0 .. 2 every 0.01; outputs c.q, count
  solver rk4(step = 0.001) }
"""


def test_time_sources_and_a_discrete_counter(tmp_path):
    """step and pulse stepped onto, a when-block's reinit and discrete variable: the bytes of
    simulate; between the events the charge is the RC's exponential toward C u."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    model = tmp_path / "rc_events.bg"
    model.write_text(TIME_EVENTS)
    files = api.compile(str(model), "embedded", scene="run",
                        embedded={"real": "double", "solver": "rk4", "step": H})
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    subprocess.run(["gcc", *FLAGS, "-I.", "-DBGC_MODEL=rc_events",
                    '-DBGC_HEADER="rc_events.h"', str(HARNESS), "rc_events.c", "-lm", "-o",
                    "run"], cwd=tmp_path, check=True)
    rows = _rows(tmp_path, 2000)
    t, Y, names = api.simulate(str(model), "run", backend="vm", solver="rk4", step=H, dt=H,
                               t_end=2.0)
    assert rows == "\n".join([",".join(["t", *names])] + [
        ",".join("%.17g" % v for v in (tk, *row)) for tk, row in zip(t, Y)]) + "\n"
    _, table = _table(rows)
    q, count = table[:, 1], table[:, 2]
    assert np.all(q[table[:, 0] < 0.3] == 0.0)  # nothing before the step
    assert count[-1] >= 3 and np.all(np.diff(count) >= 0) and np.all(q <= 0.4 + 1e-12)
    # from the last reset on: q = C u + (q0 - C u) exp(-(t - t0) / (R C)), u = 2 (pulse over)
    last = np.flatnonzero(np.diff(count))[-1] + 1
    seg = table[last:]
    want = 1.0 + (seg[0, 1] - 1.0) * np.exp(-(seg[:, 0] - seg[0, 0]) / 0.5)
    assert seg[0, 0] > 0.75 and np.max(np.abs(seg[:, 1] - want)) < 1e-9


@pytest.mark.parametrize("model", ["stick_slip", "ball_when"])
def test_events_with_euler_are_the_bytes_of_simulate(model, tmp_path):
    """The other fixed-step method: one stage, the same location on its step's interpolant."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    path, scene = MODELS[model]
    files = api.compile(str(ROOT / path), "embedded", scene=scene,
                        embedded={"real": "double", "solver": "euler", "step": H})
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    subprocess.run(["gcc", *FLAGS, "-I.", f"-DBGC_MODEL={model}", f'-DBGC_HEADER="{model}.h"',
                    str(HARNESS), f"{model}.c", "-lm", "-o", "run"], cwd=tmp_path, check=True)
    t, Y, names = api.simulate(str(ROOT / path), scene, backend="vm", solver="euler", step=H,
                               dt=H, t_end=2000 * H)
    assert _rows(tmp_path, 2000) == "\n".join([",".join(["t", *names])] + [
        ",".join("%.17g" % v for v in (tk, *row)) for tk, row in zip(t, Y)]) + "\n"


def test_ball_bounces_as_the_parabolas(built):
    """Free fall from 1 m, each crossing of the floor reversing the speed scaled by e: the
    flights' closed forms, x = v0 (t - tk) - g (t - tk)^2 / 2 after the k-th bounce at tk."""
    names, rows = _table(_rows(built["ball_when", "double"], 3000))
    g, e = 9.81, 0.8
    t = rows[:, 0]
    want = np.empty_like(t)
    tk, v0, x0 = 0.0, 0.0, 1.0
    bounces = 0
    while tk < t[-1]:
        flight = (v0 + math.sqrt(v0 * v0 + 2 * g * x0)) / g  # to the floor
        mask = (t >= tk) & (t < tk + flight)
        want[mask] = x0 + v0 * (t[mask] - tk) - 0.5 * g * (t[mask] - tk) ** 2
        tk, v0, x0 = tk + flight, e * (g * flight - v0), 0.0
        bounces += 1
    assert bounces >= 4
    assert np.max(np.abs(rows[:, 1] - want)) < 1e-9


def test_stick_slip_as_the_scipy_reference(built):
    """The mass sticks to the belt and breaks away as SciPy's piecewise reference has it
    (tests/test_contact.py: sliding M v' = -K x -+ Fc, stuck x' = vb while K |x| <= Fs)."""
    from test_contact import stick_slip_reference
    names, rows = _table(_rows(built["stick_slip", "double"], 10000))
    ref, sticks = stick_slip_reference(rows[::10, 0])
    assert len(sticks) >= 4
    assert np.max(np.abs(rows[::10, 1] - ref)) <= 1e-7 * np.max(np.abs(ref))
    stuck = np.abs(rows[:, 2] - 0.5) < 1e-9  # m.p / M on the belt
    assert stuck.sum() > 1000 and np.all(np.abs(rows[stuck, 3]) <= 3.0 + 1e-9)


def test_pwm_motor_rests_on_its_stop_as_a_locked_rotor(built):
    """Driven into the stop, the rotor strikes it and comes to rest there (angle qmax, speed
    0); from then on the armature is the locked rotor's RL circuit under the PWM voltage,
    La i' = V square(Tp, d) - Ra i (exponentials between the edges, its closed form from the
    current at t = 0.5), and the stop holds the torque kt i."""
    names, rows = _table(_rows(built["pwm_motor_stop", "double"], 10000))
    col = {n: j for j, n in enumerate(names)}
    V, Tp, d, Ra, La, kt, qmax = 12.0, 0.001, 0.7, 2.0, 0.05, 0.8, 0.5
    assert np.max(rows[:, col["angle"]]) <= qmax + 1e-9
    late = rows[rows[:, 0] >= 0.5]
    assert np.max(np.abs(late[:, col["angle"]] - qmax)) < 1e-9
    assert np.max(np.abs(late[:, col["rotor.f"]])) < 1e-9
    i, t = late[0, col["ind.f"]], late[0, 0]
    want = [i]
    for t_next in late[1:, 0]:
        while t < t_next:  # piece by piece between the PWM edges
            k = math.floor(t / Tp + 1e-9)
            up, down = k * Tp, (k + d) * Tp
            on = up - 1e-12 <= t < down - 1e-12
            end = min(t_next, down if on else (k + 1) * Tp)
            target = V / Ra if on else 0.0
            i = target + (i - target) * math.exp(-Ra / La * (end - t))
            t = end
        want.append(i)
    assert np.max(np.abs(late[:, col["ind.f"]] - want)) < 1e-8
    assert np.max(np.abs(late[:, col["stop.lambda"]] + kt * late[:, col["ind.f"]])) < 1e-8


# ---------------------------------------------------------------- the fixed-step Rosenbrock method


def _stiff_rc_reference():
    """tests/models/stiff_rc.bg's equations written out here, solved by SciPy's Radau at
    rtol 1e-12 with their Jacobian (dense output)."""
    R1, R2, w = 1e-4, 1.0, 3.0

    def f(t, y):
        e, e2 = math.sin(w * t) - y[0], y[1] + 0.2 * y[1] ** 3
        i2 = (y[0] - e2) / R2
        return [(e + e ** 3) / R1 - i2, i2]

    def jac(t, y):
        e = math.sin(w * t) - y[0]
        g1, g2 = (1 + 3 * e * e) / R1, (1 + 0.6 * y[1] ** 2) / R2
        return [[-g1 - 1 / R2, g2], [1 / R2, -g2]]
    return solve_ivp(f, (0.0, 2.0), [0.0, 0.0], method="Radau", rtol=1e-12, atol=1e-14,
                     jac=jac, dense_output=True).sol


def test_ros2_is_of_order_2_on_a_stiff_plant():
    """bgc simulate --solver ros2 --step H on the stiff RC pair (h |lambda| from 25 to 400 and
    beyond: rk4 diverges at these steps) against SciPy's Radau: the error at the step ends
    falls by 2^2 as the step halves, and rk4 at the coarsest step is not finite."""
    sol = _stiff_rc_reference()
    path = str(ROOT / "tests" / "models" / "stiff_rc.bg")
    errors = []
    for h in (0.04, 0.02, 0.01, 0.005):
        t, Y, _ = api.simulate(path, "run", backend="vm", solver="ros2", step=h, dt=0.2,
                               t_end=2.0)
        errors.append(np.max(np.abs(Y - sol(t).T)))
    ratios = [a / b for a, b in zip(errors, errors[1:])]
    assert all(2 ** 1.8 < r < 2 ** 2.3 for r in ratios), (errors, ratios)
    assert errors[-1] < 1e-4
    with pytest.raises(Exception):
        api.simulate(path, "run", backend="vm", solver="rk4", step=0.04, dt=0.2, t_end=2.0)


def test_ros2_backends_write_the_same_bytes():
    """C, Python and the interpreter: the same numbers, bit for bit, on fixed steps."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    path = str(ROOT / "tests" / "models" / "stiff_rc.bg")
    runs = [api.simulate(path, "run", backend=b, solver="ros2", step=0.01, dt=0.05, t_end=2.0)
            for b in ("c", "python", "vm")]
    for t, Y, _ in runs[1:]:
        assert np.array_equal(t, runs[0][0]) and np.array_equal(Y, runs[0][1])


def test_ros2_embedded_follows_the_reference(built):
    """The target's rows (simulate's bytes, test_double_is_the_bytes_of_simulate) are the
    stiff plant's motion: within 1e-3 of SciPy's at a step of 0.01 s."""
    names, rows = _table(_rows(built["stiff_rc", "double"], 200))
    sol = _stiff_rc_reference()
    assert np.max(np.abs(rows[:, 1:] - sol(rows[:, 0]).T)) < 1e-3


def test_rosenbrock_with_events_refused(tmp_path, capsys):
    code, out = _compile(capsys, str(ROOT / "tests" / "models" / "ball_when.bg"), "-s", "drop",
                         "--target", "embedded", "--solver", "ros2", "--step", "0.001",
                         "-o", str(tmp_path))
    assert code == 1 and "the solver 'ros2' with events" in out.err, out.err
    assert "--solver rk4" in out.err and list(tmp_path.iterdir()) == []


def test_rosenbrock_in_float_reading_t_refused(tmp_path, capsys):
    code, out = _compile(capsys, str(ROOT / "tests" / "models" / "stiff_rc.bg"), "-s", "run",
                         "--target", "embedded", "--solver", "ros2", "--step", "0.01",
                         "--real", "float", "-o", str(tmp_path))
    assert code == 1 and "read the time" in out.err and "--real double" in out.err, out.err
    assert list(tmp_path.iterdir()) == []


def test_scene_rodas4_without_a_step_refused_as_adaptive(tmp_path, capsys):
    """rc_pair's scene names rodas4 with tolerances and no step: an adaptive run in simulate,
    so not the target's; --step H makes it simulate's fixed-step run, which the target takes."""
    code, out = _compile(capsys, str(ROOT / "models" / "rc_pair.bg"), "-s", "step",
                         "--target", "embedded", "-o", str(tmp_path))
    assert code == 1 and "rc_pair.bg:34:3: error: embedded target: the solver 'rodas4' is " \
        "adaptive" in out.err and "--solver ros2" in out.err, out.err
    code, out = _compile(capsys, str(ROOT / "models" / "rc_pair.bg"), "-s", "step",
                         "--target", "embedded", "--step", "0.01", "-o", str(tmp_path))
    assert code == 0, out.err
    assert "rodas4 at a fixed step of 0.01" in (tmp_path / "rc_pair.c").read_text()


def test_rosenbrock_on_a_sparse_iteration_matrix_refused():
    """A 6 x 6 thermal grid (36 states): bgc simulate factors its iteration matrix by the
    sparse plan, which the target's dense LU would not reproduce: refused, naming the way out."""
    from helpers import families
    with pytest.raises(api.BgcModelError) as exc:
        api.compile(api.Source("grid.bg", families.thermal_grid(6)), "embedded", scene="cool",
                    embedded={"solver": "ros2", "step": 0.01})
    assert "the solver 'ros2' on a model of 36 states" in str(exc.value)
    assert "sparse plan" in str(exc.value) and "--solver rk4" in str(exc.value)


# ---------------------------------------------------------------- inputs


def _sample(m, j=0):
    """The harness's input samples with -DBGC_INPUT_SEQUENCE: s(m, j) at t_m, exact in binary."""
    return ((m * 37 + 5 * j) % 11) * 0.25 - 1.0


def _input_data(default, h, steps):
    """simulate's --input rows for samples held from each step's end: the default over
    [t0, t1), then s(m) over [t_m, t_(m+1)), each change a repeated t (a jump)."""
    t, v = [0.0, h], [default, default]
    for m in range(1, steps + 1):
        t += [m * h, (m + 1) * h]
        v += [_sample(m), _sample(m)]
    return np.array(t), np.array(v)


def test_inputs_are_the_bytes_of_simulate_with_its_input_file(tmp_path):
    """An input is a field of NAME_inputs, the caller's sample at the step's end, held from
    there: the bytes of bgc simulate --input with those samples as rows held between them
    (C backend and interpreter), through the when-block's resets located inside the steps; the
    charge between two rows is the RC's exponential toward C v under the held v."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    path = ROOT / "tests" / "models" / "rc_input.bg"
    h, steps = 0.01, 100
    files = api.compile(str(path), "embedded", scene="run",
                        embedded={"real": "double", "solver": "rk4", "step": h})
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    subprocess.run(["gcc", *FLAGS, "-c", "rc_input.c"], cwd=tmp_path, check=True)
    if shutil.which("clang"):
        subprocess.run(["clang", *FLAGS, "-fsyntax-only", "rc_input.c"], cwd=tmp_path,
                       check=True)
    if shutil.which("arm-none-eabi-gcc"):
        subprocess.run(["arm-none-eabi-gcc", "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard",
                        "-mfpu=fpv4-sp-d16", *FLAGS, "-c", "rc_input.c", "-o", "arm.o"],
                       cwd=tmp_path, check=True)
    subprocess.run(["gcc", *FLAGS[:-1], "-O0", "-I.", "-DBGC_INPUT_SEQUENCE",
                    "-DBGC_MODEL=rc_input", '-DBGC_HEADER="rc_input.h"', str(HARNESS),
                    "rc_input.o", "-lm", "-o", "run"], cwd=tmp_path, check=True)
    rows = _rows(tmp_path, steps)
    for backend in ("c", "vm"):
        t, Y, names = api.simulate(str(path), "run", backend=backend, solver="rk4", step=h,
                                   dt=h, t_end=steps * h,
                                   inputs={"v": _input_data(0.25, h, steps)})
        assert rows == "\n".join([",".join(["t", *names])] + [
            ",".join("%.17g" % v for v in (tk, *row)) for tk, row in zip(t, Y)]) + "\n"
    _, table = _table(rows)
    q, v = table[:, 1], table[:, 2]
    assert v[0] == 0.25 and all(v[m] == _sample(m) for m in range(1, steps + 1))
    want = 0.5 * v[:-1] + (q[:-1] - 0.5 * v[:-1]) * np.exp(-h / 0.5)
    reset = np.abs(q[1:] - want) > 1e-9  # the steps with a reset inside
    assert 5 <= reset.sum() <= 30 and np.all(q[1:][reset] < want[reset])
    assert np.max(np.abs(q[1:][~reset] - want[~reset])) < 1e-9
    # float: the same samples, every output within 1e-5 of its size (the resets in the same
    # steps)
    single = tmp_path / "float"
    single.mkdir()
    files = api.compile(str(path), "embedded", scene="run",
                        embedded={"real": "float", "solver": "rk4", "step": h})
    for name, text in files.items():
        (single / name).write_text(text)
    subprocess.run(["gcc", *FLAGS, "-I.", "-DBGC_INPUT_SEQUENCE", "-DBGC_MODEL=rc_input",
                    '-DBGC_HEADER="rc_input.h"', str(HARNESS), "rc_input.c", "-lm", "-o",
                    "run"], cwd=single, check=True)
    _, ftable = _table(_rows(single, steps))
    err = np.max(np.abs(ftable - table), axis=0) / np.max(np.abs(table), axis=0)
    assert np.max(err) < 1e-5, err
    # --report's bytes: sizeof of the structs, the held samples in the state
    from bgc.codegen import embedded
    want_bytes = embedded.memory(api.build(str(path), "run").program, "double", "rk4")
    (tmp_path / "sizes.c").write_text("""#include <stdio.h>
#include "rc_input.h"
int main(void)
{
    printf("%d %d\\n", (int)sizeof(rc_input_state), (int)sizeof(rc_input_inputs));
    return 0;
}
""")
    subprocess.run(["gcc", "-std=c99", "sizes.c", "-o", "sizes"], cwd=tmp_path, check=True)
    got = subprocess.run([str(tmp_path / "sizes")], capture_output=True, text=True,
                         check=True).stdout.split()
    assert [int(g) for g in got] == [want_bytes["state"], want_bytes["inputs"]]


# ---------------------------------------------------------------- the command and refusals


def _compile(capsys, *args):
    with pytest.raises(SystemExit) as exc:
        main(["compile", *args], standalone_mode=True)
    return exc.value.code, capsys.readouterr()


def test_command_writes_both_files(tmp_path, capsys):
    code, out = _compile(capsys, str(ROOT / "models" / "pendulum.bg"), "-s", "swing",
                         "--target", "embedded", "--solver", "rk4", "--step", "0.001",
                         "-o", str(tmp_path), "--report")
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pendulum.c", "pendulum.h"]
    assert "#define pendulum_STEP 0.001" in (tmp_path / "pendulum.h").read_text()
    assert out.err.startswith("memory (bytes): state=")
    assert "stack (bytes" in out.err and "pendulum_step=" in out.err


def test_long_functions_in_parts(tmp_path):
    """A model function split into parts (each a C function, the values between them in the
    work area) steps to the same bytes."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on this machine")
    from bgc.codegen import embedded
    program = api.build(str(ROOT / "models" / "double_pendulum.bg")).program
    files = embedded.emit_embedded(program, "double", "rk4", H, chunk_ops=40)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert files["double_pendulum.c"].count("static int bgc_rhs_") > 2
    subprocess.run(["gcc", *FLAGS, "-I.", "-DBGC_MODEL=double_pendulum",
                    '-DBGC_HEADER="double_pendulum.h"', str(HARNESS), "double_pendulum.c",
                    "-lm", "-o", "run"], cwd=tmp_path, check=True)
    assert _rows(tmp_path, 300) == _simulated("double_pendulum", 300)


@pytest.mark.parametrize("model, real", [
    ("pendulum", "double"), ("double_pendulum", "double"), ("stick_slip", "double"),
    ("pwm_motor_stop", "double"), ("pendulum", "float"), ("pwm_motor_stop", "float"),
    ("stiff_rc", "double"), ("rc_pair_ros2", "float")])
def test_report_is_what_the_compiler_lays_out(built, model, real):
    """--report's struct sizes are sizeof of the structs (x86-64, natural alignment)."""
    from bgc.codegen import embedded
    directory = built[model, real]
    path, scene = MODELS[model]
    program = api.build(str(ROOT / path), scene).program
    want = embedded.memory(program, real, SOLVER.get(model, "rk4"))
    name = _ident(model)
    (directory / "sizes.c").write_text(f"""#include <stdio.h>
#include "{name}.h"
int main(void)
{{
    printf("%d %d %d %d\\n", (int)sizeof({name}_state), (int)sizeof({name}_params),
           (int)sizeof({name}_outputs), (int)sizeof({name}_inputs));
    return 0;
}}
""")
    subprocess.run(["gcc", "-std=c99", "sizes.c", "-o", "sizes"], cwd=directory, check=True)
    got = subprocess.run([str(directory / "sizes")], capture_output=True, text=True,
                         check=True).stdout.split()
    assert [int(v) for v in got] == [want[k] for k in ("state", "params", "outputs", "inputs")]


def test_adaptive_solver_refused_at_the_scene(tmp_path, capsys):
    code, out = _compile(capsys, str(ROOT / "models" / "pendulum.bg"), "-s", "swing",
                         "--target", "embedded", "-o", str(tmp_path))
    assert code == 1
    assert "pendulum.bg:36:3: error: embedded target: the solver 'dopri5' is adaptive" in out.err
    assert "--solver rk4" in out.err and "^~~" in out.err
    assert list(tmp_path.iterdir()) == []
    code, out = _compile(capsys, str(ROOT / "models" / "pendulum.bg"), "--target",
                         "embedded", "--solver", "dopri5", "-o", str(tmp_path))
    assert code == 2 and "not a fixed-step method" in out.err


def _float_errors(built, model, steps, *params):
    """Per output, max |float - double| / max |double| over the run, and the rows."""
    names, single = _table(_rows(built[model, "float"], steps, *params))
    _, double = _table(_rows(built[model, "double"], steps, *params))
    assert np.array_equal(single[:, 0], double[:, 0])
    err = np.max(np.abs(single - double), axis=0) / np.max(np.abs(double), axis=0)
    return dict(zip(names[1:], err[1:])), names, single, double


def test_pwm_motor_in_float(built):
    """The PWM edges are time events in double (the driver's clock), so every period's duty is
    float's own; the current and the angle within 1e-5 over the run.  The speed and the stop's
    torque jump at the impacts: where the rotor settles on the stop, each bounce slower than
    the last, the impact's time is resolved only to float's resolution of the angle over the
    approach speed (ulp(qmax) / v: 3e-8 / 0.01 s), and the rebound by |Phi''| (1 + e) times
    that; the last bounces and the rest decision follow, and the rows between the first
    bounce slower than 2 % of the first impact's (0.12 rad/s, where (1 + e) |Phi''| ulp(qmax)
    / v exceeds 1e-5 of the speed's size) and the later of the two rests are left out (27
    rows of 10000).  A plastic stop (e = 0) rests at its first strike: every output
    within 1e-5 over the run."""
    err, names, single, double = _float_errors(built, "pwm_motor_stop", 10000)
    assert err["ind.f"] < 1e-5 and err["angle"] < 1e-5, err
    col = {n: j for j, n in enumerate(names)}
    v, lam = double[:, col["rotor.f"]], double[:, col["stop.lambda"]]
    strikes = np.flatnonzero((v[:-1] > 0) & (v[1:] <= 0))  # rows before an impact
    slow = strikes[v[strikes] < 2e-2 * v[strikes[0]]][0]
    rest = max(np.flatnonzero(lam != 0)[0], np.flatnonzero(single[:, col["stop.lambda"]])[0])
    assert 1 <= rest - slow <= 40
    keep = np.ones(len(v), bool)
    keep[slow:rest + 1] = False
    for name in ("rotor.f", "stop.lambda"):
        j = col[name]
        assert np.max(np.abs(single[keep, j] - double[keep, j])) \
            <= 1e-5 * np.max(np.abs(double[:, j])), name
    err, *_ = _float_errors(built, "pwm_motor_stop", 10000, "e=0")
    assert max(err.values()) < 1e-5, err


def test_stick_slip_in_float(built):
    """Float's sticks and breakaways are double's: the same number of each, each within a
    step, and every output within 1e-5 over the ten seconds.  Stuck, the mass moves with the
    belt, x' = vb, a pure integrator: without the compensated sum of each step's increment
    h vb (5e-4) onto x (0.2), its rounding to float's resolution of x accumulated, 6e-5 of
    the speed's size after ten seconds."""
    err, names, single, double = _float_errors(built, "stick_slip", 10000)
    assert max(err.values()) < 1e-5, err
    stuck_f, stuck_d = (np.abs(r[:, 2] - 0.5) < 1e-6 for r in (single, double))
    edges_f, edges_d = (np.flatnonzero(np.diff(s.astype(int))) for s in (stuck_f, stuck_d))
    assert len(edges_f) == len(edges_d) >= 8 and np.max(np.abs(edges_f - edges_d)) <= 1


def test_table_beyond_its_bound_refused_at_the_table(tmp_path, capsys):
    from bgc.codegen.embedded import MAX_TABLE_ROWS
    rows = MAX_TABLE_ROWS + 1
    (tmp_path / "r.csv").write_text("t,r\n" + "".join(f"{k / rows!r},1.5\n"
                                                       for k in range(rows)))
    model = tmp_path / "tab.bg"
    model.write_text("""model tab
c : C(1) init q = 1
r : R(R)
signal R = table("r.csv", t, interp = linear)
j : 1
j -> c
j -> r
scene run { time 0 .. 1 every 0.01; outputs c.q
  solver rk4(step = 0.001) }
""")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, out = _compile(capsys, str(model), "-s", "run", "--target", "embedded", "-o",
                         str(out_dir))
    assert code == 1, out.err
    assert f"tab.bg:4:12: error: embedded target: the table 'r.csv' has {rows} rows, more " \
           f"than the {MAX_TABLE_ROWS} the target carries in flash: resample it to " \
           f"{MAX_TABLE_ROWS} rows or fewer" in out.err and "^~~" in out.err
    assert list(out_dir.iterdir()) == []


def test_a_max_step_below_the_step_refused(tmp_path, capsys):
    model = tmp_path / "rc.bg"
    model.write_text("""model rc
c : C(1) init q = 1
r : R(1)
c -> j
j : 1
j -> r
scene run { time 0 .. 1 every 0.1; outputs c.q
            solver rk4(step = 0.01, hmax = 0.001) }
""")
    code, out = _compile(capsys, str(model), "-s", "run", "--target", "embedded",
                         "-o", str(tmp_path))
    assert code == 1, out.err
    assert "rc.bg:8:13: error: embedded target: the scene's max_step 0.001 is below the step " \
           "0.01" in out.err and "--step 0.001 or less" in out.err


def test_newton_in_float_refused(tmp_path, capsys):
    code, out = _compile(capsys, str(ROOT / "models" / "diode.bg"), "--target", "embedded",
                         "--solver", "rk4", "--real", "float", "-o", str(tmp_path))
    assert code == 1 and "Newton's method" in out.err and "--real double" in out.err
    assert list(tmp_path.iterdir()) == []


def test_options_of_the_embedded_target_only(capsys):
    code, out = _compile(capsys, str(ROOT / "models" / "pendulum.bg"), "--real", "float")
    assert code == 2 and "--real is an option of --target embedded" in out.err
