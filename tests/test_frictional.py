"""Frictional contacts (LANGUAGE 10b, docs/hybrid.md section 7): an Fr whose forces are
proportional to a unilateral junction's normal force takes part in that contact's impacts with
a tangential impulse, sticking (no slip after the impact, |P_t| <= mu0 P_n) or sliding
(|P_t| = mu P_n against the slip); in contact, it is the dry friction of section 10.  Checked
against the closed forms of a disc with backspin landing on a floor (rigid-body impulse
dynamics, worked out here)."""
import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest

import bgc
from bgc.api import Source
from bgc.execute import runner
from bgc.api import BgcModelError

from conftest import have_cc

ROOT = Path(__file__).resolve().parent.parent
DISC = (ROOT / "tests" / "models" / "spinning_disc.bg").read_text()
BACKENDS = ("c", "python", "vm") if have_cc() else ("python", "vm")
DEFAULTS = dict(m=0.5, R=0.1, g=9.81, mu=0.2, mu0=0.3, h=0.5, v0=1.0, w0=30.0, e=0.0)


def disc(t, m, R, g, mu, mu0, h, v0, w0, e=0.0):
    """The disc's horizontal velocity and spin at the times t, through its first landing and
    after (e = 0: it stays down), by the impulse law and the sliding phase in closed form;
    and the landing's and the rolling's start times."""
    J = 0.5 * m * R ** 2
    t1 = math.sqrt(2 * h / g)
    Pn = (1 + e) * m * g * t1  # the normal impulse: the fall's momentum stopped, and reversed
    slip = v0 + R * w0
    stick = -slip / (1 / m + R ** 2 / J)  # the impulse that stops the slip at once
    Pt = stick if abs(stick) <= mu0 * Pn else -mu * Pn * math.copysign(1, slip)
    v1, w1 = v0 + Pt / m, w0 + R * Pt / J
    s1 = v1 + R * w1
    decel = mu * g * (1 + m * R ** 2 / J)  # the slip's rate while sliding on the floor
    t2 = t1 + (abs(s1) / decel if e == 0 else 0.0)
    v, w = np.full_like(t, v0), np.full_like(t, w0)
    after = t >= t1
    if e == 0:
        sliding = np.clip(t - t1, 0, t2 - t1)  # (then rolling: no force)
        way = math.copysign(1, s1) if s1 else 0.0
        v[after] = (v1 - mu * g * way * sliding)[after]
        w[after] = (w1 - R * mu * m * g * way * sliding / J)[after]
    return v, w, t1, t2, (v1, w1)


def simulate(backend="python", text=DISC, **params):
    compiled = bgc.build(Source("spinning_disc.bg", text), "run")
    program = runner.prepare(compiled, backend)
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names,
                                   params={k: float(v) for k, v in params.items()})
    result = runner.run(program, settings)
    assert result.status == 0, result.stderr
    rows = list(csv.reader(io.StringIO(result.csv)))
    head = rows[0]
    data = np.array([[float(x) for x in r] for r in rows[1:]])
    return result.csv, {h: data[:, k] for k, h in enumerate(head)}


@pytest.mark.parametrize("case", [
    {},  # the default: it lands sliding (the impulse that would stop its slip is outside
    #      the cone), slides, then rolls back
    {"mu0": 2.0},  # a cone wide enough: the landing stops the slip, it rolls at once
    {"w0": -5.0, "v0": 2.0},  # topspin, slipping backward: slides the other way
])
def test_a_disc_lands_with_friction(case):
    p = {**DEFAULTS, **case}
    _, out = simulate(**case)
    t = out["t"]
    v, w, t1, t2, _ = disc(t, **p)
    near = np.zeros_like(t, dtype=bool)
    for te in (t1, t2):
        near |= abs(t - te) < 2e-3
    assert np.max(abs(out["mx.f"] - v)[~near]) < 1e-8
    assert np.max(abs(out["spin.f"] - w)[~near]) < 1e-7
    late = t > t2 + 0.01
    assert np.all(out["grip.stick"][late] == 1)  # rolling: the friction sticks
    assert np.allclose(abs(out["floor.lambda"][t > t1 + 0.01]), p["m"] * p["g"], rtol=1e-8)


def test_the_landing_impulse_is_the_closed_forms(tmp_path):
    """The event log's jump of the momenta at the landing: the tangential impulse mu P_n
    (sliding), and with a wide cone the one that stops the slip (sticking)."""
    for case in ({}, {"mu0": 2.0}, {"e": 0.5}):
        p = {**DEFAULTS, **case}
        text = DISC if "e" not in case else DISC.replace(
            "unilateral(phi = y)", "unilateral(phi = y) restitution(0.5)")
        compiled = bgc.build(Source("spinning_disc.bg", text), "run")
        program = runner.prepare(compiled, "python")
        names = [q.name for q in compiled.program.params]
        log = tmp_path / "events.csv"
        params = {k: float(v) for k, v in case.items() if k != "e"}
        settings = runner.settings_for(compiled.program.scene, names, events=str(log),
                                       params=params)
        assert runner.run(program, settings).status == 0
        events = list(csv.reader(open(log)))[1:]
        first = float(events[0][0])
        jumps = {name: float(change.split(" -> ")[1]) for tt, name, change in events
                 if float(tt) == first and name in ("mx.p", "spin.p")}
        _, _, t1, _, (v1, w1) = disc(np.array([0.0]), **p)
        assert abs(first - t1) < 1e-10
        J = 0.5 * p["m"] * p["R"] ** 2
        assert abs(jumps["mx.p"] - p["m"] * v1) < 1e-12
        assert abs(jumps["spin.p"] - J * w1) < 1e-12


def test_the_backends_agree_to_the_byte():
    outs = [simulate(b)[0] for b in BACKENDS]
    assert all(o == outs[0] for o in outs[1:])


def test_it_converges_as_the_tolerance_tightens():
    p = dict(DEFAULTS)
    errors = []
    for rtol in (1e-6, 1e-8, 1e-10):
        text = DISC.replace("rtol = 1e-10, atol = 1e-12", f"rtol = {rtol}, atol = {rtol * 1e-2}")
        _, out = simulate(text=text)
        t = out["t"]
        v, _, t1, t2, _ = disc(t, **p)
        far = (abs(t - t1) > 2e-3) & (abs(t - t2) > 2e-3)
        errors.append(np.max(abs(out["mx.f"] - v)[far]))
    assert errors[2] < 1e-8 and errors[2] <= errors[0]


def _error(text):
    with pytest.raises(BgcModelError) as err:
        bgc.build(Source("disc.bg", text), "run")
    return str(err.value)


def test_a_friction_not_proportional_to_the_normal_force_is_refused():
    text = DISC.replace("grip : Fr(mu*abs(floor.lambda), mu0*abs(floor.lambda))",
                        "grip : Fr(mu*abs(floor.lambda) + 0.1, mu0*abs(floor.lambda))")
    message = _error(text)
    assert "disc.bg:37:1: error: friction 'grip'" in message
    assert "proportional to abs(floor.lambda)" in message


def test_an_impact_of_too_many_contacts_is_refused():
    """Four contacts on the same storages, each with its friction: four normal rows, more
    than an impulse takes; refused at the contact, before the work.  Two contacts with their
    frictions (four rows, tests/test_woodpecker.py) are built."""
    extra = "".join(f"grip{k} : Fr(mu*abs(roof{k}.lambda), mu0*abs(roof{k}.lambda))\n"
                    f"horizontal -> grip{k}\nroof{k} -> vertical\n"
                    f"roof{k} : 0 constraint unilateral(phi = {k + 2} - y)\n" for k in range(3))
    message = _error(DISC.replace("rim -> grip\n", "rim -> grip\n" + extra))
    assert "disc.bg:26:1: error: 'floor': 4 constraint rows take part in its impulse; at " \
        "most 3 are supported" in message
