"""Unilateral constraint junctions (docs/hybrid.md): impacts by Newton's law of restitution
through the kinetic metric, contact that stays closed, release; against closed forms and a
SciPy reference integrated here."""
import csv
import functools
import io
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from click.testing import CliRunner

import bgc
from bgc.execute import runner
from bgc.api import Source
from bgc.cli import main

from conftest import have_cc
from test_events import BALL as WHEN_BALL

ROOT = Path(__file__).resolve().parent.parent
BACKENDS = ["c", "python"] if have_cc() else ["python"]

# the when-block's ball (test_events.py) with a floor that pushes instead of its reinit
BALL = WHEN_BALL.replace(
    "when x < 0 {\n  reinit b.p = -e*b.p\n}\n",
    "j -> floor\nfloor : 0 constraint unilateral(phi = x) restitution(e) corrector pid(10, 10)\n"
).replace("time 0 .. 3 every 0.01; outputs x, b.p", "time 0 .. 6 every 0.01; outputs x, b.p, "
          "floor.lambda")
assert "unilateral" in BALL and "reinit" not in BALL


@functools.lru_cache(maxsize=None)
def built(name: str, text: str | None, scene: str):
    """bgc.build of a text (or of the file `name` if text is None), once for the tests of
    this file that take it with other run settings (a build is a value: frozen stages)."""
    return bgc.build(Source(name, text) if text is not None else Path(name), scene)


def run(compiled, backend, log, stats=False, **options):
    program = runner.prepare(compiled, backend)
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names, events=str(log), **options)
    result = runner.run(program, settings, stats=stats)
    assert result.status == 0, result.stderr
    rows = list(csv.reader(io.StringIO(result.csv)))
    with open(log, newline="") as f:
        events = list(csv.reader(f))[1:]
    y = np.array([[float(v) for v in r] for r in rows[1:]])
    return (result.csv, y, events, result.stats) if stats else (result.csv, y, events)


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_a_ball_bounces_then_rests_on_the_floor(solver, tmp_path):
    compiled = built("ball.bg", BALL, "drop")
    outs = [run(compiled, b, tmp_path / f"{b}.csv", solver=solver, rtol=1e-10, atol=1e-12)
            for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1  # the same bytes in both backends
    _, y, events = outs[0]
    impacts = [(float(t), c) for t, what, c in events if what == "b.p"]
    g, e = 9.81, 0.8
    t_ref = math.sqrt(2 / g)
    v = g * t_ref
    for t, change in impacts[:20]:  # closed form: flights of 2 e^k v1 / g
        before, after = (float(s) for s in change.split(" -> "))
        assert abs(t - t_ref) <= 1e-9 * t_ref
        assert abs(before + v) <= 1e-6 * v and abs(after - e * v) <= 1e-6 * v
        v *= e
        t_ref += 2 * v / g
    # the bounces pile up before t1 + 2 v1 e / (g (1 - e)); then the floor holds the ball
    t1 = math.sqrt(2 / g)
    t_rest = t1 + 2 * g * t1 * e / (g * (1 - e))
    rest = [float(t) for t, what, c in events if what == "floor.active" and c == "0 -> 1"]
    assert len(rest) == 1 and 0 < t_rest - rest[0] < 1e-4
    late = y[y[:, 0] > t_rest + 1.5]  # (the corrector closes the last gap by its law)
    assert np.all(np.abs(late[:, 1]) < 1e-8)  # on the floor
    assert np.allclose(late[:, 3], -9.81, rtol=1e-6)  # the floor carries m g


@pytest.mark.parametrize("solver", ["rk4", "euler"])
def test_a_fixed_step_ball_lands_every_time(solver, tmp_path):
    """With a fixed step of 0.01 the last flights are shorter than a step: the ball rises
    and lands inside one.  Each landing must still be an impact (the contact's relation is
    false as soon as the ball moves away), never a fall through the floor.  rk4 is exact on a
    free fall: its impacts keep the closed form, and it rests where the rebounds fall below
    its tolerance's resolution, just before the bounces' accumulation point.  Euler lands
    each flight g h faster than it left, so its bounces settle where e (v + g h) = v."""
    compiled = built("ball.bg", BALL, "drop")
    outs = [run(compiled, b, tmp_path / f"{b}.csv", solver=solver) for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    assert np.all(y[:, 1] > -1e-6)  # never through the floor
    g, e, h = 9.81, 0.8, 0.01
    t1 = math.sqrt(2 / g)
    impacts = [(float(t), c) for t, what, c in events if what == "b.p"]
    if solver == "euler":
        after = float(impacts[-1][1].split(" -> ")[1])
        assert abs(after - e * g * h / (1 - e)) <= 0.05 * after
        return
    t_ref, v = t1, g * t1
    for t, _ in impacts[:20]:
        assert abs(t - t_ref) <= 1e-9 * t_ref
        v *= e
        t_ref += 2 * v / g
    t_rest = t1 + 2 * g * t1 * e / (g * (1 - e))
    rest = [float(t) for t, what, c in events if what == "floor.active" and c == "0 -> 1"]
    assert len(rest) == 1 and 0 < t_rest - rest[0] < 1e-3
    late = y[y[:, 0] > t_rest + 1.5]
    assert np.all(np.abs(late[:, 1]) < 1e-6) and np.allclose(late[:, 3], -9.81, rtol=1e-6)


def pendulum_reference(t_out, theta0=0.5, l=1.0, g=9.81, d=0.2, e=0.7):
    """The rigid pendulum in its angle, with the wall at l sin(theta) = -d: SciPy at tight
    tolerance, stopped at each impact and restarted with theta' reversed times e."""
    wall = math.asin(-d / l)

    def f(t, s):
        return [s[1], -g / l * math.sin(s[0])]

    def hit(t, s):
        return s[0] - wall
    hit.terminal, hit.direction = True, -1
    t0, s, impacts, xs = 0.0, [theta0, 0.0], [], []
    grid = list(t_out)
    while t0 < t_out[-1]:
        sol = solve_ivp(f, (t0, t_out[-1]), s, events=hit, rtol=1e-12, atol=1e-12,
                        dense_output=True, method="DOP853")
        end = sol.t[-1]
        while grid and grid[0] <= end:
            xs.append(l * math.sin(sol.sol(grid.pop(0))[0]))
        if sol.status != 1:
            break
        t0, s = end, [wall, -e * sol.y_events[0][0][1]]
        impacts.append(t0)
    return np.array(xs), impacts


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_the_papers_pendulum_strikes_a_wall(solver, tmp_path):
    """The rod stays rigid at each impact: theta' reverses times e (and the rod's own
    Baumgarte junction keeps its length)."""
    compiled = built(str(ROOT / "models" / "pendulum_wall.bg"), None, "strike")
    outs = [run(compiled, b, tmp_path / f"{b}.csv", solver=solver) for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    x_ref, impacts_ref = pendulum_reference(list(y[:, 0]))
    assert np.max(np.abs(y[:, 1] - x_ref)) <= 1e-6
    impacts = sorted({float(t) for t, what, c in events if what == "mx.p"})
    assert len(impacts) == len(impacts_ref) >= 3
    assert np.allclose(impacts, impacts_ref, rtol=1e-8)
    assert np.allclose(y[:, 1] ** 2 + y[:, 2] ** 2, 1.0, atol=1e-8)  # the rod, rigid
    assert np.all(y[:, 1] >= -0.2 - 1e-9)  # never through the wall


def test_unilateral_misuse_is_located():
    def error(text):
        with pytest.raises(bgc.BgcModelError) as info:
            bgc.build(Source("m.bg", "model m\nsignal x = integral(1, init = 1)\n" + text))
        return str(info.value)
    assert "a unilateral constraint gives its gap" in error(
        "j : 0 constraint unilateral restitution(0.5)\n")
    assert "restitution(E) belongs to unilateral constraints" in error(
        "j : 0 constraint holonomic(phi = x) restitution(0.5)\n")
    assert "the coefficient of restitution is from 0 to 1" in error(
        "j : 0 constraint unilateral(phi = x) restitution(2)\n")


RECTIFIER = """model rectifier "a half-wave rectifier: an ideal diode and an RL load"
parameter V = 10.0
parameter w = 314.159
parameter R = 10.0
parameter L = 0.05
u : MSe(V*sin(w*t))
d : D
r : R(R)
l : I(L)
u -> j
j : 1
j -> d
j -> r
j -> l
scene run { time 0 .. 0.06 every 0.0005; outputs l.p, d.e, d.f
            solver SOLVER(rtol = 1e-10, atol = 1e-12, hmax = 0.001) }
"""
# (hmax: while the diode blocks the state is at rest and a stiff solver's steps grow long; the
# source's sign, which turns the diode on, must not change twice within one of them)


def _piece(rhs, t0, y0, event, t_out, out):
    """One piece of a piecewise reference: SciPy at tight tolerance from t0 until the event,
    its first component written into out at the output times it covers; the solution."""
    sol = solve_ivp(rhs, (t0, t_out[-1]), y0, events=event, rtol=1e-12, atol=1e-14,
                    dense_output=True, first_step=1e-6)
    mask = (t_out >= t0) & (t_out <= sol.t[-1])
    if mask.any():
        out[mask] = sol.sol(t_out[mask])[0]
    return sol


def rectifier_reference(t_out, V=10.0, w=314.159, R=10.0, L=0.05):
    """Conducting, L i' = V sin(w t) - R i, until i falls to zero; then blocking until the
    source turns positive again (i = 0 there): SciPy at tight tolerance, piece by piece."""
    t0, out = 0.0, np.zeros(len(t_out))
    while t0 < t_out[-1]:
        def zero(t, y):
            return y[0]
        zero.terminal, zero.direction = True, -1
        sol = _piece(lambda t, y: [(V * math.sin(w * t) - R * y[0]) / L], t0, [0.0], zero,
                     t_out, out)
        if sol.status != 1:
            break
        t0 = 2 * math.pi * (math.floor(sol.t[-1] * w / (2 * math.pi)) + 1) / w
    return out


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_a_half_wave_rectifier_with_an_ideal_diode(solver, tmp_path):
    """The diode conducts while the current flows forward, blocks when it would reverse (the
    inductor's current held at zero), and conducts again when the source turns positive."""
    compiled = bgc.build(Source("rect.bg", RECTIFIER.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    i = y[:, 1] / 0.05
    ref = rectifier_reference(y[:, 0])
    assert np.max(np.abs(i - ref)) <= 1e-6 * np.max(ref)
    blocking = [float(t) for t, what, c in events if what == "d.blocking" and c == "0 -> 1"]
    assert len(blocking) == 3  # once per period
    on = i > 1e-9
    assert np.all(np.abs(y[on, 2]) <= 1e-12)  # conducting: e = 0
    assert np.all(y[~on, 2] <= 1e-9)  # blocking: e <= 0
    assert np.all(i >= -1e-9)  # never backwards


STICK_SLIP = """model stickslip "a mass on a spring, dragged by a moving belt through dry friction"
parameter M = 1.0
parameter K = 10.0
parameter vb = 0.5 "belt speed"
parameter Fc = 2.0 "sliding friction"
parameter Fs = 3.0 "sticking friction"
m : I(M)
k : C(1/K)
belt : Sf(-vb)
fr : Fr(Fc, Fs)
v : 1
v -> m
v -> k
v -> s
s : 0
belt -> s
s -> fr
scene run { time 0 .. 10 every 0.01; outputs k.q, m.p, fr.e
            solver SOLVER(rtol = 1e-10, atol = 1e-12, hmax = 0.05) }
"""


def stick_slip_reference(t_out, M=1.0, K=10.0, vb=0.5, Fc=2.0, Fs=3.0):
    """Sliding, M v' = -K x - Fc sign(v - vb), until v meets the belt; stuck, x' = vb while
    the spring's pull K |x| stays within Fs, then sliding the way the spring pulls."""
    out = np.zeros(len(t_out))
    t0, x, v, sticks = 0.0, 0.0, 0.0, []
    s = -1.0 if v < vb else 1.0
    while t0 < t_out[-1]:
        def meet(t, y):
            return y[1] - vb
        meet.terminal, meet.direction = True, (1 if s < 0 else -1)  # (not where it leaves)
        sol = _piece(lambda t, y: [y[1], (-K * y[0] - Fc * s) / M], t0, [x, v], meet, t_out,
                     out)
        if sol.status != 1:
            break
        t0, x = sol.t[-1], sol.y[0][-1]
        if abs(K * x) > Fs:  # passes the belt's speed without sticking
            v, s = vb, -s
            continue
        sticks.append(t0)
        t1 = t0 + (math.copysign(Fs, vb) / K - x) / vb  # stuck until K x reaches Fs
        mask = (t_out >= t0) & (t_out <= t1)
        out[mask] = x + vb * (t_out[mask] - t0)
        t0, x, v = t1, math.copysign(Fs, vb) / K, vb
        s = -math.copysign(1.0, x)
    return out, sticks


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_stick_slip_on_a_moving_belt(solver, tmp_path):
    compiled = bgc.build(Source("stick.bg", STICK_SLIP.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    ref, sticks = stick_slip_reference(y[:, 0])
    assert np.max(np.abs(y[:, 1] - ref)) <= 1e-6 * np.max(np.abs(ref))
    got = [float(t) for t, what, c in events if what == "fr.stick" and c == "0 -> 1"]
    assert len(got) == len(sticks) >= 4
    assert np.allclose(got, sticks, rtol=1e-8)
    stuck = np.abs(y[:, 2] / 1.0 - 0.5) < 1e-9  # m.p / M on the belt
    assert np.all(np.abs(y[stuck, 3]) <= 3.0 + 1e-9)  # held within Fs


def test_stick_slip_converges_as_the_tolerance_tightens(tmp_path):
    """Down to rtol 1e-13 and atol 1e-16, where 10 atol is below what the located stick can
    resolve of the flow (its time to 1e-12 relative: |f'| 1e-12 t): each run sticks and
    breaks away as the SciPy reference does (no false chattering), its error falling to the
    reference's own; the first stick at its closed-form time."""
    compiled = bgc.build(Source("stick.bg", STICK_SLIP.replace("SOLVER", "dop853").replace(
        ", hmax = 0.05", "")), "run")
    errors, ref = [], None
    for rtol, atol in ((1e-5, 1e-8), (1e-8, 1e-11), (1e-11, 1e-14), (1e-13, 1e-16)):
        csv_text, y, events = run(compiled, BACKENDS[0], tmp_path / "log.csv", rtol=rtol,
                                  atol=atol)
        if ref is None:
            ref, sticks = stick_slip_reference(y[:, 0])
        got = [float(t) for t, what, c in events if what == "fr.stick" and c == "0 -> 1"]
        assert len(got) == len(sticks)
        errors.append(np.max(np.abs(y[:, 1] - ref)) / np.max(np.abs(ref)))
    assert errors[0] > errors[1] > errors[2] and errors[3] < 1e-10, errors
    w = math.sqrt(10.0)  # from rest, x = (Fc/K)(1 - cos(w t)) until m.p / M reaches vb
    assert abs(got[0] - math.asin(0.5 / (0.2 * w)) / w) < 1e-12
    if len(BACKENDS) > 1:  # the other backend: the same bytes
        assert run(compiled, BACKENDS[1], tmp_path / "log.csv", rtol=1e-13,
                   atol=1e-16)[0] == csv_text


CAPACITORS = """model caps "two capacitors joined through a resistor by a switch that closes at t = 1"
parameter C1 = 1.0
parameter C2 = 2.0
parameter R = 0.5
parameter V0 = 3.0
c1 : C(C1) init e = V0
c2 : C(C2) init e = 0
r : R(R)
sw : Sw(t >= 1)
a : 0
b : 0
j : 1
a -> c1
b -> c2
a -> j
j -> r
j -> sw
j -> b
scene run { time 0 .. 5 every 0.01; outputs c1.q, c2.q, r.f
            solver SOLVER(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_two_capacitors_joined_by_a_switch(solver, tmp_path):
    """Open, nothing flows; closed at t = 1 (a time event), the charge flows through R with
    time constant R C1 C2 / (C1 + C2), the total charge is kept and the energy lost is
    C1 C2 V0^2 / (2 (C1 + C2)), whatever R."""
    compiled = bgc.build(Source("caps.bg", CAPACITORS.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    C1, C2, R, V0 = 1.0, 2.0, 0.5, 3.0
    tau = R * C1 * C2 / (C1 + C2)
    q2_end = C2 * C1 * V0 / (C1 + C2)
    t = y[:, 0]
    q2 = np.where(t < 1, 0.0, q2_end * (1 - np.exp(-(t - 1) / tau)))
    assert np.max(np.abs(y[:, 2] - q2)) <= 1e-6 * q2_end
    assert np.max(np.abs(y[:, 1] + y[:, 2] - C1 * V0)) <= 1e-12  # charge kept
    energy = y[:, 1] ** 2 / (2 * C1) + y[:, 2] ** 2 / (2 * C2)
    lost = C1 * V0 ** 2 / 2 - energy[-1]
    assert abs(lost - C1 * C2 * V0 ** 2 / (2 * (C1 + C2))) <= 1e-4  # (e^-12 still to go)
    assert [r[1:] for r in events] == [["t >= 1", "0 -> 1"], ["sw.open", "1 -> 0"]]


SHORTED = """model caps "two capacitors joined by a switch with no resistor; a current source charges the first"
parameter C1 = 1.0
parameter C2 = 2.0
parameter V0 = 3.0
parameter I0 = 0.5
c1 : C(C1) init e = V0
c2 : C(C2) init e = 0
sw : Sw(t >= 1 and t < 1.5)
i : Sf(I0)
a : 0
b : 0
j : 1
i -> a
a -> c1
b -> c2
a -> j
j -> sw
j -> b
scene run { time 0 .. 2 every 0.01; outputs c1.q, c2.q, sw.f, sw.e
            solver SOLVER(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_two_capacitors_joined_by_a_switch_with_no_resistor(solver, tmp_path):
    """Closing the switch joins the capacitors with nothing to limit the flow: their charges
    jump at once to equal voltages, the total charge kept and C1 C2 V^2 / (2 (C1 + C2)) of
    the energy lost (V the voltage difference before); joined, the source's current divides as
    C1 : C2 and flows through the switch; opened at t = 1.5, the second keeps its charge."""
    compiled = bgc.build(Source("shorted.bg", SHORTED.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    C1, C2, V0, I0 = 1.0, 2.0, 3.0, 0.5
    t = y[:, 0]
    q = C1 * V0 + I0 * np.minimum(t, 1)  # the total charge at the closing, and before it
    q1_at, q2_at = C1 * q[-1] / (C1 + C2), C2 * q[-1] / (C1 + C2)
    joined = (t >= 1) & (t < 1.5)
    q1 = np.where(t < 1, q, np.where(joined, q1_at + I0 * C1 / (C1 + C2) * (t - 1),
                                     q1_at + I0 * C1 / (C1 + C2) * 0.5 + I0 * (t - 1.5)))
    q2 = np.where(t < 1, 0.0, q2_at + I0 * C2 / (C1 + C2) * (np.minimum(t, 1.5) - 1))
    assert np.max(np.abs(y[:, 1] - q1)) <= 1e-9 * np.max(q1)
    assert np.max(np.abs(y[:, 2] - q2)) <= 1e-9 * np.max(q2)
    assert np.max(np.abs(y[:, 1] + y[:, 2] - (C1 * V0 + I0 * t))) <= 1e-12 * 5  # charge kept
    assert np.allclose(y[joined, 3], I0 * C2 / (C1 + C2), rtol=1e-9)  # through the switch
    assert np.all(np.abs(y[joined, 4]) <= 1e-12) and np.all(y[t < 1, 3] == 0)
    jumps = {what: [float(v) for v in c.split(" -> ")] for tt, what, c in events
             if what in ("c1.q", "c2.q")}
    assert [float(tt) for tt, what, _ in events if what == "c1.q"] == [1.0]
    (a1, b1), (a2, b2) = jumps["c1.q"], jumps["c2.q"]
    assert abs(a1 - q[-1]) <= 1e-12 * q[-1] and a2 == 0  # before: all on the first
    lost = a1 ** 2 / (2 * C1) - (b1 ** 2 / (2 * C1) + b2 ** 2 / (2 * C2))
    V = a1 / C1
    assert abs(lost - C1 * C2 * V ** 2 / (2 * (C1 + C2))) <= 1e-12 * lost


CLAMP = """model clamp "an ideal diode across a capacitor charged through a resistor"
parameter C1 = 0.5
parameter R1 = 2.0
u : Se(sin(t))
r : R(R1)
c : C(C1)
d : D
a : 0
j : 1
u -> j
j -> r
j -> a
a -> c
a -> d
scene run { time 0 .. 10 every 0.01; outputs c.q, d.f
            solver SOLVER(rtol = 1e-10, atol = 1e-12, hmax = 0.1) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_an_ideal_diode_across_a_capacitor(solver, tmp_path):
    """The diode holds the capacitor's voltage at or below zero: conducting (e = 0, the
    source's current R^-1 sin t through it) while the source is positive, blocking while the
    capacitor charges negative through R; against SciPy piece by piece."""
    compiled = bgc.build(Source("clamp.bg", CLAMP.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    C1, R1 = 0.5, 2.0
    t = y[:, 0]
    ref = np.zeros(len(t))
    t0 = 0.0
    while t0 < t[-1]:  # conducting while sin t >= 0 (q = 0), blocking until q/C1 reaches 0
        t0 = math.pi * (math.floor(t0 / math.pi + 1e-12) + 1)  # the source turns negative

        def back(tt, z):
            return z[0]
        back.terminal, back.direction = True, 1
        sol = _piece(lambda tt, z: [(math.sin(tt) - z[0] / C1) / R1], t0, [0.0], back, t,
                     ref)
        if sol.status != 1:
            break
        t0 = sol.t[-1]
    assert np.max(np.abs(y[:, 1] - ref)) <= 1e-6 * np.max(np.abs(ref))
    assert np.all(y[:, 1] <= 1e-12)  # e = q / C <= 0
    on = np.abs(y[:, 1]) <= 1e-12
    assert np.allclose(y[on, 2], np.sin(t[on]) / R1, atol=1e-9)  # the source's current
    blocking = [float(tt) for tt, what, c in events if what == "d.blocking" and c == "0 -> 1"]
    assert np.allclose(blocking, [math.pi, 3 * math.pi], rtol=1e-10)


JUNCTIONS = """model js "an RL circuit behind a switched 1-junction, a capacitor behind a switched 0-junction"
parameter V = 2.0
parameter L = 0.5
parameter C1 = 2.0
parameter R2 = 4.0
u : Se(V)
r : R(1)
l : I(L)
j : 1 switch(t < 1)
u -> j
j -> r
j -> l
s : Sf(1)
c : C(C1)
g : R(R2)
k : 0 switch(t >= 0.5 and t < 1.5)
s -> k
k -> c
k -> g
scene run { time 0 .. 2 every 0.01; outputs l.f, c.e, g.f
            solver SOLVER(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_switched_junctions(solver, tmp_path):
    """`1 switch(COND)`: on, a plain 1-junction (the RL circuit's current rises as
    (V/R)(1 - e^(-R t/L))); off, its flow zero on every bond (the current stops at once).
    `0 switch(COND)`: off, its effort zero on every bond (the capacitor held empty, the source
    shorted); on from t = 0.5, the capacitor charges through R2 (e = R2 (1 - e^(-t/(R2 C1))));
    off again at t = 1.5, its charge gone at once."""
    compiled = bgc.build(Source("js.bg", JUNCTIONS.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    V, R, L, C1, R2 = 2.0, 1.0, 0.5, 2.0, 4.0
    t = y[:, 0]
    i = np.where(t < 1, V / R * (1 - np.exp(-R * t / L)), 0.0)
    e = np.where((t >= 0.5) & (t < 1.5), R2 * (1 - np.exp(-(t - 0.5) / (R2 * C1))), 0.0)
    assert np.max(np.abs(y[:, 1] - i)) <= 1e-8 * V / R
    assert np.max(np.abs(y[:, 2] - e)) <= 1e-8 * R2
    assert np.allclose(y[:, 3], e / R2, rtol=0, atol=1e-8)
    changes = [(float(tt), what, c) for tt, what, c in events if what.endswith(".open")]
    assert changes == [(0.5, "k.switch.open", "0 -> 1"), (1.0, "j.switch.open", "0 -> 1"),
                       (1.5, "k.switch.open", "1 -> 0")]


def test_switched_elements_misuse_is_located():
    def error(text):
        with pytest.raises(bgc.BgcModelError) as info:
            bgc.build(Source("m.bg", "model m\nsignal x = integral(1, init = 1)\n" + text))
        return str(info.value)
    assert "a constraint junction cannot also be switched" in error(
        "j : 0 constraint holonomic(phi = x) switch(t < 1)\n")
    assert "a switched junction is scalar" in error("j : 1[2] switch(t < 1)\n")
    assert "m.bg:3:14: error: a condition is needed here" in error("j : 1 switch(2)\n")


IMPOSED = """model imposed "a flow source in series with a switched one-port and a resistor"
u : SOURCE
j : 1
d : ELEMENT
r : R(1)
u -> j
j -> d
j -> r
scene run { time 0 .. 1 every 0.05; outputs r.f; solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("source, element, message", [
    ("MSf(sin(6*t))", "D", "ideal diode 'd' cannot block: its flow is imposed by 'u' whatever "
     "its effort, and blocking (f = 0) would contradict it: a current source forcing flow "
     "through a blocking diode"),
    ("Sf(-1)", "D", "ideal diode 'd' cannot block"),
    ("Sf(1)", "Sw(t < 0.5)", "ideal switch 'd' cannot open: its flow is imposed by 'u'"),
    ("MSf(sin(6*t))", "Fr(1, 2)", "dry friction 'd' cannot stick: its flow is imposed by 'u'"),
])
def test_a_flow_source_through_a_switched_element_is_located(source, element, message):
    """A flow source in series with a diode, a switch or dry friction: the mode that holds
    the flow at zero contradicts it (the multiplier's law divided by zero: an error without a
    place, 'the generated equations are not finite ... (zoo)'); located at the element, with a
    note at the source."""
    text = IMPOSED.replace("SOURCE", source).replace("ELEMENT", element)
    with pytest.raises(bgc.BgcModelError) as info:
        bgc.build(Source("m.bg", text), "run")
    said = str(info.value)
    assert said.startswith("m.bg:4:1: error: " + message), said
    assert "m.bg:2:1: note: 'u' imposes the flow here, whatever the effort of 'd'" in said
    assert "zoo" not in said and "not finite" not in said


def test_a_flow_source_through_a_switched_junction_is_located():
    with pytest.raises(bgc.BgcModelError) as info:
        bgc.build(Source("m.bg", "model m\nu : Sf(1)\nj : 1 switch(t < 1)\nr : R(2)\nu -> j\n"
                                 "j -> r\n"))
    assert str(info.value).startswith("m.bg:3:1: error: switched junction 'j' cannot switch: "
                                      "its flow is imposed by 'u' whatever its effort")


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_current_source_through_a_diode_with_a_resistance_across_it(backend, tmp_path):
    """The remedy the message gives: a resistance Rp across the diode takes the source's
    current while it blocks, so the diode's effort is Rp min(i, 0), its flow max(i, 0), with
    i = sin(6 t); and a current that stays positive needs no remedy."""
    text = IMPOSED.replace("SOURCE", "MSf(sin(6*t))").replace("j -> d", "j -> k\nk -> d\n"
                                                              "k -> rp").replace(
        "d : ELEMENT", "d : D\nk : 0\nrp : R(2)").replace("outputs r.f", "outputs d.e, d.f")
    _, y, _ = run(bgc.build(Source("fixed.bg", text), "run"), backend, tmp_path / "ev.csv")
    i = np.sin(6 * y[:, 0])
    assert np.allclose(y[:, 1], 2 * np.minimum(i, 0), rtol=0, atol=1e-9)
    assert np.allclose(y[:, 2], np.maximum(i, 0), rtol=0, atol=1e-9)
    forward = IMPOSED.replace("SOURCE", "Sf(1)").replace("ELEMENT", "D")
    _, y, _ = run(bgc.build(Source("forward.bg", forward), "run"), backend, tmp_path / "f.csv")
    assert np.all(y[:, 1] == 1.0)


def test_the_equations_of_each_mode(tmp_path):
    """`bgc equations` shows each mode's equations, the conditionals decided: the clamp's
    capacitor charges through R while the diode blocks and is held while it conducts."""
    path = tmp_path / "clamp.bg"
    path.write_text(CLAMP.replace("SOLVER", "dopri5"))
    result = CliRunner().invoke(main, ["equations", str(path), "--scene", "run"])
    assert result.exit_code == 0, result.output
    modes = result.output.split("modes (")[1]
    blocking, conducting = modes.split("d.blocking = 1:")[1].split("d.blocking = 0:")
    assert "d(c.q)/dt = (C1*sin(t) - c.q)/(C1*R1)" in blocking
    assert "d.lambda = 0" in blocking
    assert "d(c.q)/dt = 0" in conducting
    assert "d.lambda = (C1*sin(t) - c.q)/(C1*R1)" in conducting  # (c.q held at 0)


BOX = """model box "a ball bouncing between two walls: a unilateral junction array of two gaps"
parameter m = 1.0
parameter v0 = 2.0
parameter e = 0.8
b : I(m) init f = v0
v : 1
walls : 0[2] constraint unilateral(phi = [x, 1 - x]) restitution(e) corrector pid(10, 10)
g : MTF[1->2]([[1], [-1]])
signal x = integral(v.f, init = 0.5)
v -> b
v -> g -> walls
scene run { time 0 .. 3 every 0.01; outputs x, b.p; solver SOLVER(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_an_array_of_gaps(solver, tmp_path):
    """`0[2] constraint unilateral(phi = [x, 1 - x])`: one gap per row, each with its own
    impacts (the two rows are dependent, but never both closed: bgc accepts them).  With no
    force the ball crosses the unit box at v0, v0 e, v0 e^2 ...: impacts at closed-form times,
    alternately on each wall."""
    compiled = bgc.build(Source("box.bg", BOX.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    v0, e = 2.0, 0.8
    hits = [(float(tt), what) for tt, what, c in events if what.endswith("contact (phi < 0)")
            and c == "0 -> 1"]
    t_ref, v, wall = 0.5 / v0, v0, 1
    for tt, what in hits:
        assert abs(tt - t_ref) <= 1e-10 * t_ref and what.startswith(f"walls[{wall}]")
        v *= e
        t_ref += 1 / v
        wall = 1 - wall
    assert len(hits) == 4  # (the fifth is after t = 3)
    x = np.interp(y[:, 0], [0, 0.25], [0.5, 1.0])  # the first flight
    first = y[:, 0] <= 0.25
    assert np.max(np.abs(y[first, 1] - x[first])) <= 1e-9


BAR = """model bar "a bar falling flat onto two supports: two gaps close at the same instant"
parameter m = 1.0
parameter J = 0.1
parameter L = 1.0
parameter g = 9.81
parameter e = 0.5
parameter h = 1.0
vy : 1
vth : 1
my : I(m)
jt : I(J)
w : Se(-m*g)
signal y = integral(vy.f, init = h)
signal th = integral(vth.f, init = 0)
a : 0 constraint unilateral(phi = y - L/2*sin(th)) restitution(e) corrector pid(10, 10)
b : 0 constraint unilateral(phi = y + L/2*sin(th)) restitution(e) corrector pid(10, 10)
ta : MTF(-L/2*cos(th))
tb : MTF(L/2*cos(th))
vy -> my
vth -> jt
w -> vy
vy -> a
vth -> ta -> a
vy -> b
vth -> tb -> b
scene run { time 0 .. 2 every 0.01; outputs y, th, my.p, jt.p; solver SOLVER(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("solver", ["dopri5", "radau5"])
def test_a_bar_lands_flat_on_two_supports(solver, tmp_path):
    """Two gaps that close at the same instant take one impulse together: the bar falling
    flat bounces flat (its angular momentum stays zero), its centre's speed reversed times e,
    as a ball's; handled one after the other, the first support's impulse alone would spin
    it."""
    compiled = bgc.build(Source("bar.bg", BAR.replace("SOLVER", solver)), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1
    _, y, events = outs[0]
    g, e, h = 9.81, 0.5, 1.0
    # (one support or both log the contact: the other's gap may be closed to rounding only)
    hits = sorted({float(tt) for tt, what, c in events if what.endswith(": contact (phi < 0)")
                   and c == "0 -> 1"})
    assert len(hits) >= 10
    t_ref, v = math.sqrt(2 * h / g), math.sqrt(2 * g * h)
    for tt in hits[:10]:
        assert abs(tt - t_ref) <= 1e-9 * t_ref
        v *= e
        t_ref += 2 * v / g
    assert np.max(np.abs(y[:, 2])) <= 1e-12 and np.max(np.abs(y[:, 4])) <= 1e-12  # no spin


def test_the_drawing_names_the_switched_elements():
    """bgc draw shows a diode as D, friction as Fr(Fc, Fs), a switch as Sw(COND) and a gap as
    a unilateral constraint junction (each a constraint junction underneath)."""
    from bgc.reports import draw
    cases = [(RECTIFIER.replace("SOLVER", "dopri5"), "d", "D", "ideal diode"),
             (STICK_SLIP.replace("SOLVER", "dopri5"), "fr", "Fr(Fc, Fs)", "dry friction"),
             (CAPACITORS.replace("SOLVER", "dopri5"), "sw", "Sw(t &gt;= 1)", "ideal switch"),
             (BALL, "floor", "0", "unilateral constraint")]
    for text, name, kind, what in cases:
        dot = draw.draw_dot(bgc.build(Source("m.bg", text), None, program=False))
        node = next(line for line in dot.splitlines() if line.strip().startswith(f'"{name}" ['))
        assert f"<FONT>{kind}</FONT>" in node and f"{name} ({what})" in node


MOTOR = (ROOT / "tests" / "models" / "motor_stop.bg").read_text()


def motor_reference(t_out, V=12.0, R=1.0, L=0.01, k=0.1, J=0.001, b=1e-4, Fc=0.02, Fs=0.03,
                    qmax=1.0, e=0.5, t_switch=0.5, atol=1e-12):
    """The motor of tests/models/motor_stop.bg as a hybrid automaton integrated by SciPy at
    tight tolerance, phase by phase: sliding (M w' = k i - b w - Fc s), stuck (w = 0 while
    |k i| <= Fs), resting against the stop (w = 0, q = qmax, while the torque k i pushes into
    it; the friction then carries nothing), with Newton's restitution at each impact and rest
    once a rebound is below 1e-6 of the fastest impact or its apex below 10 atol (the rule of
    docs/hybrid.md).  Returns q, w, i at t_out and the
    times of the phase changes."""
    out = np.zeros((3, len(t_out)))
    t0, y, mode, vmax = 0.0, [0.0, 0.0, 0.0], "stick", 0.0
    log = []

    def u(t):
        return V if t < t_switch else -V

    while t0 < t_out[-1]:
        t1 = t_switch if t0 < t_switch else t_out[-1]
        s = {"slide+": 1.0, "slide-": -1.0}.get(mode, 0.0)
        if s:
            def rhs(t, z):
                return [(u(t) - R * z[0] - k * z[1]) / L, (k * z[0] - b * z[1] - Fc * s) / J,
                        z[1]]

            def stops(t, z):
                return z[1]
            stops.terminal, stops.direction = True, -s

            def hits(t, z):
                return z[2] - qmax
            hits.terminal, hits.direction = True, 1
            events = [stops, hits]
        else:
            def rhs(t, z):
                return [(u(t) - R * z[0]) / L, 0.0, 0.0]

            def breaks(t, z):
                return abs(k * z[0]) - Fs
            breaks.terminal, breaks.direction = True, 1

            def pulls(t, z):
                return k * z[0]
            pulls.terminal, pulls.direction = True, -1
            events = [breaks] if mode == "stick" else [pulls]
        sol = solve_ivp(rhs, (t0, t1), y, events=events, rtol=1e-12, atol=1e-14,
                        dense_output=True, first_step=1e-7)
        mask = (t_out >= t0) & (t_out <= sol.t[-1])
        if mask.any():
            out[:, mask] = sol.sol(t_out[mask])
        t0, y = sol.t[-1], list(sol.y[:, -1])
        if sol.status != 1:
            continue  # the time event: the same phase goes on
        fired = [j for j, te in enumerate(sol.t_events) if len(te)][0]
        if s and fired == 0:  # w reached zero: it sticks, or the load turns it round
            mode = "stick" if abs(k * y[0]) <= Fs else ("slide+" if y[0] > 0 else "slide-")
            y[1] = 0.0
            log.append((t0, "stops"))
        elif s:  # an impact
            vmax = max(vmax, abs(y[1]))
            accel = (k * y[0] - b * y[1] - Fc * s) / J  # into the stop
            if e * abs(y[1]) <= 1e-6 * vmax or (e * y[1]) ** 2 <= 20 * atol * accel:
                mode, y[1], y[2] = "rest", 0.0, qmax
                log.append((t0, "rest"))
            else:
                y[1] = -e * y[1]
                mode = "slide-"
                log.append((t0, "impact"))
        elif mode == "stick":
            mode = "slide+" if y[0] > 0 else "slide-"
            log.append((t0, "breaks"))
        else:
            mode = "stick"
            log.append((t0, "release"))
    return out, log


@pytest.mark.parametrize("solver", ["auto", "radau5"])
def test_a_motor_against_its_end_stop_with_dry_friction(solver, tmp_path):
    """The end stop (unilateral) and the friction (Fr) on the same shaft: resting against the
    stop, the two multipliers would share one load; bgc lets the contact carry it and the
    friction take over when the contact releases.  With the default solver the run takes a
    few hundred steps (the penalty formulation of the same motor needs millions); against the
    hybrid automaton above, and the phase changes against their closed forms (the default
    solver and radau5, both backends)."""
    compiled = bgc.build(Source("motor_stop.bg", MOTOR), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv", stats=True, solver=solver)
            for b in BACKENDS]
    assert len({o[0] for o in outs}) == 1  # the same bytes in both backends
    _, y, events, stats = outs[0]
    assert int(stats["steps"]) < 5000 and int(stats["events"]) < 100
    t = y[:, 0]
    ref, log = motor_reference(t)
    V, R, L, k, Fs = 12.0, 1.0, 0.01, 0.1, 0.03
    # closed forms of the phase changes: the current's rise from rest, its fall after the
    # voltage reverses (i = 0: the stop releases), and the friction giving way backwards
    first = -L / R * math.log(1 - Fs * R / (k * V))
    release = 0.5 + L / R * math.log(2)
    again = 0.5 + L / R * math.log(2 * V / R / (V / R - Fs / k))
    kinds = [what for _, what in log]
    assert kinds[0] == "breaks" and kinds.count("rest") == 1 and kinds.count("release") == 1
    assert abs(log[0][0] - first) < 1e-10 and abs(dict(map(reversed, log))["release"]
                                                    - release) < 1e-10
    got = {what: [float(s) for s, w, c in events if w == what and c == "0 -> 1"] for what in
           ("fr: breaks away (|e| > Fs)", "stop: release (lambda would pull)",
            "stop: contact (phi < 0)")}
    assert abs(got["fr: breaks away (|e| > Fs)"][0] - first) < 1e-10
    assert abs(got["fr: breaks away (|e| > Fs)"][-1] - again) < 1e-10
    assert len(got["stop: release (lambda would pull)"]) == 1
    assert abs(got["stop: release (lambda would pull)"][0] - release) < 1e-10
    impacts = [s for s, what in log if what == "impact"]
    assert np.allclose(got["stop: contact (phi < 0)"][:10], impacts[:10], rtol=1e-7, atol=0)
    # q and the current everywhere; the speed away from the impacts, where it jumps
    assert np.max(np.abs(y[:, 1] - ref[2])) <= 1e-6 * np.max(np.abs(ref[2]))
    assert np.max(np.abs(y[:, 3] / 1 - ref[0])) <= 1e-6 * np.max(np.abs(ref[0]))
    far = np.all(np.abs(t[:, None] - np.array(impacts)[None, :]) > 1e-6, axis=1)
    assert np.max(np.abs(y[far, 2] - ref[1][far])) <= 1e-6 * np.max(np.abs(ref[1]))
    # resting against the stop it carries the torque k i; the friction then carries nothing
    resting = (t > 0.2) & (t < 0.5)
    assert np.allclose(-y[resting, 4], k * ref[0][resting], rtol=1e-6)
    assert np.all(y[resting, 5] == 0)


CLOSED_AT_START = """model rl "an RL loop through a switch, the coil at 1 A"
parameter L = 1.0
parameter R = 2.0
parameter on = 1
discrete d = 0.25
signal x = integral(1, init = 1)
sw : Sw(COND)
coil : I(L) init f = 1
res : R(R)
loop : 1
loop -> sw
loop -> coil
loop -> res
scene run { outputs coil.f; time 0 .. 1 every 0.125; solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("cond", [
    "t >= 0", "t > -1", "t < 5", "t <= 5 or t > 6", "on > 0", "1 > 0", "x > 0.5",
    "d < 0.5", "square(4, 0.5) > 0.5", "step(0) > 0.5", "pulse(0, 2) > 0.5",
    "not (t < 0)", "t >= 0 and x > 0"])
def test_a_switch_whose_condition_holds_at_t0_starts_closed(cond, tmp_path):
    """Every initial mode is taken from the conditions at t0 (docs/hybrid.md): closed from
    the start, the coil's current decays as exp(-R t / L) from 1 A, in every backend (it
    read 0 from t = 0 where the condition depended on t, a state or a discrete value)."""
    compiled = bgc.build(Source("rl.bg", CLOSED_AT_START.replace("COND", cond)), "run")
    backends = BACKENDS + ["vm"]
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in backends]
    assert len({o[0] for o in outs}) == 1, backends  # the same bytes
    y = outs[0][1]
    assert np.max(np.abs(y[:, 1] - np.exp(-2.0 * y[:, 0]))) <= 1e-8


def test_a_switch_open_at_t0_cuts_the_coils_current_at_once(tmp_path):
    """Open at t0 (its condition false then), the coil's initial current has no path: the
    initial state is made consistent with the mode (the current stops), then the switch
    closes at t = 0.5 onto a coil at rest."""
    compiled = bgc.build(Source("rl.bg", CLOSED_AT_START.replace("COND", "t >= 0.5")), "run")
    outs = [run(compiled, b, tmp_path / f"{b}.csv") for b in BACKENDS + ["vm"]]
    assert len({o[0] for o in outs}) == 1
    assert np.all(outs[0][1][:, 1] == 0.0)
