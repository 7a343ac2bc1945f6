"""The source paper's pendulum: the derived equations are eq. (9) and eq. (12), typed from the
paper (Favre & Scavarda 1998, section 4) with xd = px/m, yd = py/m."""
from pathlib import Path

import sympy as sp

import bgc
from bgc.front.graph import var
from bgc.middle.reduce import explicit_forms

PENDULUM = Path(__file__).parent.parent / "models" / "pendulum.bg"

m, l, g, alpha, beta = (var(n) for n in ("m", "l", "g", "alpha", "beta"))
x, y, px, py = var("x"), var("y"), var("mx.p"), var("my.p")
xd, yd = px / m, py / m


def _rates(scene):
    compiled = bgc.build(PENDULUM, scene)
    r = compiled.reduced
    forms = explicit_forms(r, r.rates)
    return {st.name: forms[d] for st, d in zip(r.states, r.rates)}, compiled


def _multiplier(compiled):
    (rod,) = compiled.reduced.constraints
    return explicit_forms(compiled.reduced, [rod.multiplier])[rod.multiplier]


def _same(a, b):
    return sp.simplify(a - b) == 0


def test_eq9_classical_lagrange_equations():
    rates, _ = _rates("unstabilised")
    common = (y * g + xd**2 + yd**2)
    assert _same(rates["mx.p"] / m, -x / (x**2 + y**2) * common)        # eq. (9), x''
    assert _same(rates["my.p"] / m, g - y / (x**2 + y**2) * common)     # eq. (9), y''
    assert _same(rates["x"], xd) and _same(rates["y"], yd)


def test_eq8_multiplier():
    _, compiled = _rates("unstabilised")
    assert _same(_multiplier(compiled), m / (2 * x**2 + 2 * y**2) * (y * g + xd**2 + yd**2))


def test_eq12_baumgarte_stabilised_equations():
    rates, _ = _rates("swing")
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    assert _same(rates["mx.p"] / m, -x / (x**2 + y**2) * bracket)       # eq. (12), x''
    assert _same(rates["my.p"] / m, g - y / (x**2 + y**2) * bracket)    # eq. (12), y''


def test_eq11_multiplier_and_geometric_constraint():
    _, compiled = _rates("swing")
    (rod,) = compiled.reduced.constraints
    bracket = (y * g + xd**2 + yd**2 + 2 * alpha * (x * xd + y * yd)
               + beta**2 * (x**2 + y**2 - l**2) / 2)
    assert _same(_multiplier(compiled), m / (2 * x**2 + 2 * y**2) * bracket)   # eq. (11)
    assert rod.kind == "holonomic"
    assert _same(rod.phi, x**2 + y**2 - l**2)                           # eq. (4), init = -l^2
    assert _same(rod.balance, 2 * x * xd + 2 * y * yd)                  # eq. (5)
