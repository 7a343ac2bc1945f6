"""The hand-derived references of tests/test_models.py checked against each other.

For every case that test_models.py runs through bgc, the ODE reference (the hand-derived
right-hand side integrated with DOP853 at rtol 1e-12) must agree with the closed form far
more tightly than bgc is asked to (1e-9 against 1e-6). A few physical invariants are checked
too, so that an error shared by both references (a wrong derivation) has a chance to show.
Needs numpy and scipy only, not bgc.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import test_models as refs  # (the module pytest collects, not a second copy)

SELF_TOLERANCE = 1e-9


def _grid(case):
    t0, t_end, every = case.time
    return np.linspace(t0, t_end, int(round((t_end - t0) / every)) + 1)


@pytest.mark.parametrize("case", refs.CASES, ids=[c.id for c in refs.CASES])
def test_ode_reference_agrees_with_closed_form(case) -> None:
    model = refs.MODEL_REFS[case.model]
    t, P = _grid(case), case.reference_params()
    closed, ode = model.closed(t, P), model.ode(t, P)
    assert set(case.outputs) <= set(closed) == set(ode)
    refs.assert_columns_match(ode, closed, t, f"{case.id}: ODE vs closed form",
                              SELF_TOLERANCE)


def _derivative(y, t):
    return np.gradient(y, t, edge_order=2)


def test_rlc_closed_form_satisfies_the_circuit_equation() -> None:
    """L q'' + R q' + q/C = V0 (finite differences, so loose), and the initial values."""
    P = refs.RLC_DEFAULTS
    t = np.linspace(0, 10, 20001)
    c = refs.rlc_closed(t, P)
    q, i = c["cap.q"], c["ind.f"]
    assert q[0] == pytest.approx(P["q0"], abs=1e-15)
    assert i[0] == pytest.approx(P["i0"], abs=1e-15)
    np.testing.assert_allclose(_derivative(q, t), i, atol=1e-6)
    lhs = P["inductance"] * _derivative(i, t) + P["resistance"] * i + q / P["capacitance"]
    np.testing.assert_allclose(lhs, P["V0"], atol=1e-5)


def test_dc_motor_steady_state() -> None:
    """At steady state: V = Ra i + kt w and kt i = br w + tau_load."""
    P = refs.DC_MOTOR_DEFAULTS
    c = refs.dc_motor_closed(np.array([0.0, 200.0]), P)
    i, w = c["ind.f"][-1], c["rotor.f"][-1]
    M = np.array([[P["Ra"], P["kt"]], [P["kt"], -P["br"]]])
    i_ss, w_ss = np.linalg.solve(M, [P["V"], P["tau_load"]])
    assert (i, w) == pytest.approx((i_ss, w_ss), rel=1e-9)


def test_dc_motor_power_balance() -> None:
    """Supplied power = dissipated + load + d/dt(stored magnetic + kinetic energy)."""
    P = refs.DC_MOTOR_DEFAULTS
    t = np.linspace(0, 5, 20001)
    c = refs.dc_motor_closed(t, P)
    i, w = c["ind.f"], c["rotor.f"]
    stored = 0.5 * P["La"] * i**2 + 0.5 * P["Jr"] * w**2
    balance = (P["V"] * i - P["Ra"] * i**2 - P["br"] * w**2 - P["tau_load"] * w
               - _derivative(stored, t))
    # finite differences of a fast start-up: loose, but a wrong term would be O(1)
    assert np.max(np.abs(balance)) < 1e-5 * np.max(np.abs(P["V"] * i))


def test_parallel_caps_charge_conservation() -> None:
    """Charge delivered through the resistor equals the charge gained by both capacitors."""
    P = refs.PARALLEL_CAPS_DEFAULTS
    t = np.linspace(0, 20, 40001)
    c = refs.parallel_caps_closed(t, P)
    delivered = np.concatenate([[0.0], np.cumsum(0.5 * (c["r.f"][1:] + c["r.f"][:-1])
                                                 * np.diff(t))])
    gained = (c["c1.q"] + c["c2.q"]) - (c["c1.q"][0] + c["c2.q"][0])
    np.testing.assert_allclose(delivered, gained, atol=1e-6)


def test_ladder_kirchhoff() -> None:
    """The closed form's node voltages and currents satisfy KCL and Ohm's law at every node."""
    P = refs.LADDER_DEFAULTS
    t = np.linspace(0, 3, 301)
    c = refs.ladder_closed(t, P)
    v2, v4, vC = c["r2.e"], c["r4.e"], c["cap.e"]
    np.testing.assert_allclose(c["r1.f"], (P["V0"] - v2) / P["R1"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c["r3.f"], (v2 - v4) / P["R3"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c["r1.f"], v2 / P["R2"] + c["r3.f"], rtol=1e-12, atol=1e-12)
    i5 = (v4 - vC) / P["R5"]
    np.testing.assert_allclose(c["r3.f"], v4 / P["R4"] + i5, rtol=1e-12, atol=1e-12)
    tt = np.linspace(0, 3, 30001)
    cc = refs.ladder_closed(tt, P)
    i5 = (cc["r4.e"] - cc["cap.e"]) / P["R5"]
    np.testing.assert_allclose(_derivative(cc["cap.q"], tt), i5, atol=1e-6)


def test_knife_edge_closed_form_obeys_lagrange_equations() -> None:
    """Constraint, equations of motion with the closed-form lambda, and energy."""
    P = refs.knife_edge_params(refs.KNIFE_EDGE_DEFAULTS)
    t = np.linspace(0, 10, 100001)
    c = refs.knife_edge_closed(t, P)
    th, xd, yd, lam = c["th"], c["vx.f"], c["vy.f"], c["blade.lambda"]
    np.testing.assert_allclose(_derivative(c["x"], t), xd, atol=1e-6)
    np.testing.assert_allclose(_derivative(c["y"], t), yd, atol=1e-6)
    np.testing.assert_allclose(-np.sin(th) * xd + np.cos(th) * yd, 0.0, atol=1e-13)
    m, gs = P["m"], P["g_slope"]
    np.testing.assert_allclose(m * _derivative(xd, t), np.sin(th) * lam, atol=1e-6)
    np.testing.assert_allclose(m * _derivative(yd, t), m * gs - np.cos(th) * lam, atol=1e-6)
    # The constraint force does no work: kinetic minus gravity's work is constant.
    energy = 0.5 * m * (xd**2 + yd**2) - m * gs * (c["y"] - P["y0"])
    np.testing.assert_allclose(energy, energy[0], atol=1e-12 * max(1.0, abs(energy[0])) + 1e-12)
    # Initial conditions.
    assert (c["x"][0], c["y"][0], th[0]) == pytest.approx((P["x0"], P["y0"], P["th0"]))
    assert math.hypot(xd[0], yd[0]) == pytest.approx(P["v0"])
