"""Scenes of one model, models/gantry_crane.bg: a DC drive, a trolley with a load swinging on a
rigid cable (a Baumgarte-stabilised constraint junction), the winding's heating and a swing
sensor, each subsystem an effect, each scene taking what it needs.

What is checked, and against what (nothing here is a number read off bgc's output):
- each scene's generated module integrates exactly the states its outputs need, listed here by
  hand from the physics (the heating and the sensor read the drive and the mechanism but act on
  nothing, so they are pruned when not asked for; the drive and the mechanism are coupled
  through the drum, so neither goes without the other);
- the scenes with the same effects as `everything` reproduce its columns with a fixed-step
  solver (same steps, same arithmetic on the states kept: agreement to rounding);
- `drive` (the motor alone) against the closed form of the two-state linear system;
- `mechanism` (a given torque) against Lagrange's equations in (s, theta), typed here and
  solved by SciPy's DOP853 at rtol 1e-12.

The parameters are typed here and passed to every run, and checked against the model file's
numbers (parsed here), so that a change of the file shows up as that, not as a wrong physics.
"""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bgc import api
from bgc.base import processes
from bgc.codegen.emit import emit_python

MODEL = Path(__file__).resolve().parent.parent / "models" / "gantry_crane.bg"

# The model's data (models/gantry_crane.bg).
P = dict(V=24.0, Ra=1.2, La=0.012, kt=0.35, Jr=0.002, br=0.001, tau0=1.0,
         rd=0.01, mt=20.0, bt=10.0, m=50.0, l=2.0, g=9.81, theta0=0.2, alpha=5.0, beta=5.0,
         T_amb=20.0, Cw=100.0, Rwh=0.5, Ch=2000.0, Rha=0.8,
         Lf=0.1, Rf=2.8, Cf=0.025)

ALL_EFFECTS_SCENES = ("thermal", "sensor", "swing")  # the effects of `everything`

# The states, in the order the model declares them (storage elements and integral signals):
# drive: the inductor's flux linkage ind.p and the rotor's momentum rotor.p; mechanism: the
# load's momenta mx.p, my.p and the coordinates s, x, y (the trolley's momentum is not a state:
# the drum ties it to the rotor's, mt v = mt rd w); thermal: the two heats cw.q, ch.q; sensor:
# the filter's lf.p and cf.q.
DRIVE = ["ind.p", "rotor.p"]
MECHANISM = ["mx.p", "my.p", "s", "x", "y"]
THERMAL = ["cw.q", "ch.q"]
SENSOR = ["lf.p", "cf.q"]
EXPECTED = {
    # everything: every subsystem
    "everything": (DRIVE + MECHANISM + THERMAL + SENSOR,
                   ["ind.f", "rotor.f", "s", "x", "y", "rod.lambda", "cw.e", "ch.e", "cf.e"]),
    # the motor alone: mechanism, friction, heating and sensor left out
    "drive": (DRIVE, ["ind.f", "rotor.f"]),
    # a given torque instead of the armature circuit: the rotor and the mechanism
    "mechanism": (["rotor.p"] + MECHANISM, ["s", "x", "y", "rod.lambda"]),
    # temperatures: the Joule heat needs the current, the current the whole drive train
    "thermal": (DRIVE + MECHANISM + THERMAL, ["cw.e", "ch.e"]),
    # the filtered x - s: the mechanism, hence the drive; no heating
    "sensor": (DRIVE + MECHANISM + SENSOR, ["cf.e"]),
    # the trolley and the load: neither heating nor sensor
    "swing": (DRIVE + MECHANISM, ["x", "y", "s"]),
}


@lru_cache(maxsize=None)
def module(scene):
    """The scene's generated Python module (built once per test session)."""
    (text,) = emit_python(api.build(MODEL, scene).program).values()
    return processes.load_python_module(text)


def run(scene, **options):
    t, Y = module(scene).simulate(params=dict(P), **options)
    t, Y = np.asarray(t, float), np.asarray(Y, float)
    return t, {name: Y[:, k] for k, name in enumerate(module(scene).OUTPUTS)}


def assert_close(got, ref, rel, what):
    """max|got - ref| <= rel * max(1, max|ref|)."""
    err = float(np.max(np.abs(got - ref)))
    bound = rel * max(1.0, float(np.max(np.abs(ref))))
    assert err <= bound, f"{what}: max|got - ref| = {err:.3e} > {bound:.3e}"


def test_parameters_are_the_model_files():
    numbers = re.findall(r"^parameter\s+(\w+)\s*=\s*(-?[0-9.]+(?:[eE][-+]?\d+)?)\s*\"",
                         MODEL.read_text(encoding="utf-8"), re.MULTILINE)
    assert {name: float(value) for name, value in numbers} == P


@pytest.mark.parametrize("scene", list(EXPECTED))
def test_each_scene_integrates_what_its_outputs_need(scene):
    states, outputs = EXPECTED[scene]
    assert module(scene).STATES == states
    assert module(scene).OUTPUTS == outputs


@lru_cache(maxsize=None)
def fixed_step(scene):
    """1 s of the scene by RK4 with a fixed step of 2 ms (outputs every 10 ms)."""
    return run(scene, solver="rk4", step=2e-3, t_end=1.0, dt=0.01)


@pytest.mark.parametrize("scene", ALL_EFFECTS_SCENES)
def test_pruned_scene_reproduces_everything(scene):
    """The same effects as `everything`, fewer outputs: the states left out act on none of
    those kept, so with the same steps the kept ones take the same values."""
    t, cols = fixed_step(scene)
    t_all, all_cols = fixed_step("everything")
    assert np.array_equal(t, t_all) and len(t) == 101 and t[-1] == 1.0
    assert list(cols) == EXPECTED[scene][1]
    for name, column in cols.items():
        assert_close(column, all_cols[name], 1e-12, f"{scene}: {name}")
    # the run is not trivial: the motor turns, the load swings, the winding warms
    assert all_cols["rotor.f"].max() > 10 and np.ptp(all_cols["x"] - all_cols["s"]) > 0.1
    assert all_cols["cw.e"][-1] > P["T_amb"] + 0.05 and np.ptp(all_cols["cf.e"]) > 0.1


def drive_closed_form(t):
    """L di/dt = V - R i - k w, J dw/dt = k i, from rest: w'' + (R/L) w' + k^2/(L J) w =
    k V/(L J), w(0) = w'(0) = 0.  With s1, s2 the roots of s^2 + (R/L) s + k^2/(L J):
    w = V/k (1 - (s2 e^(s1 t) - s1 e^(s2 t))/(s2 - s1)), and i = (J/k) w' = V/L (e^(s2 t) -
    e^(s1 t))/(s2 - s1) (s1 s2 = k^2/(L J)); i'(0) = V/L."""
    V, R, L, k, J = P["V"], P["Ra"], P["La"], P["kt"], P["Jr"]
    s1, s2 = np.roots([1.0, R / L, k * k / (L * J)]).astype(complex)
    e1, e2 = np.exp(s1 * t), np.exp(s2 * t)
    w = V / k * (1 - (s2 * e1 - s1 * e2) / (s2 - s1))
    i = V / L * (e2 - e1) / (s2 - s1)
    return i.real, w.real


def test_drive_is_the_motor_alone():
    t, cols = run("drive", rtol=1e-12, atol=1e-14)
    assert len(t) == 501 and t[-1] == 0.5
    i, w = drive_closed_form(t)
    assert_close(cols["ind.f"], i, 1e-8, "ind.f")
    assert_close(cols["rotor.f"], w, 1e-8, "rotor.f")
    # 0.5 s is 25 electrical time constants: the unloaded, frictionless motor at V/kt, no current
    assert abs(w[-1] - P["V"] / P["kt"]) < 1e-6 and abs(i[-1]) < 1e-6


def crane_lagrange(t):
    """Lagrange's equations of the trolley (position s) and the load (cable angle theta from the
    downward vertical; x = s + l sin(theta), y = l cos(theta)) under the given motor torque:
    T = (Ms + m) s'^2/2 + m l cos(theta) s' theta' + m l^2 theta'^2/2, Ms = mt + Jr/rd^2 (the
    rotor turns at s'/rd), V = -m g l cos(theta), generalized forces Qs = tau0/rd - (br/rd^2 +
    bt) s', Qtheta = 0:
        (Ms + m) s'' + m l cos(theta) theta'' = Qs + m l sin(theta) theta'^2
        cos(theta) s'' + l theta'' = -g sin(theta).
    From rest at s = 0, theta = theta0; DOP853 at rtol 1e-12.  Returns s, x, y and the rod's
    multiplier: the cable tension over 2 l, the tension from the load's radial equation in the
    trolley's frame, T = m (g cos(theta) - s'' sin(theta) + l theta'^2)."""
    mt, m, l, g, rd = P["mt"], P["m"], P["l"], P["g"], P["rd"]
    Ms = mt + P["Jr"] / rd**2
    damping = P["br"] / rd**2 + P["bt"]

    def accelerations(th, v, w):
        c, sn = np.cos(th), np.sin(th)
        a11, a12, b1 = Ms + m, m * l * c, P["tau0"] / rd - damping * v + m * l * sn * w * w
        a21, a22, b2 = c, l, -g * sn
        det = a11 * a22 - a12 * a21
        return (b1 * a22 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det

    def f(_, z):
        _s, th, v, w = z
        return [v, w, *accelerations(th, v, w)]

    sol = solve_ivp(f, (t[0], t[-1]), [0.0, P["theta0"], 0.0, 0.0], method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=t)
    assert sol.success, sol.message
    s, th, v, w = sol.y
    sdd, _ = accelerations(th, v, w)
    tension = m * (g * np.cos(th) - sdd * np.sin(th) + l * w * w)
    return {"s": s, "x": s + l * np.sin(th), "y": l * np.cos(th), "rod.lambda": tension / (2 * l)}


def test_mechanism_is_the_crane_under_a_given_torque():
    t, cols = run("mechanism", t_end=2.0, rtol=1e-11, atol=1e-12)
    assert len(t) == 201 and t[-1] == 2.0
    ref = crane_lagrange(t)
    for name in ("s", "x", "y", "rod.lambda"):
        assert_close(cols[name], ref[name], 1e-6, name)
    # the trolley has moved and the load swings relative to it
    assert ref["s"][-1] > 0.5 and np.ptp(ref["x"] - ref["s"]) > 0.3
