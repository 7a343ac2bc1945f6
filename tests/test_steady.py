"""`bgc steady` and bgc.steady: equilibria against closed forms (two tanks in series, the
pendulum's bottom), a family of equilibria (a free mass), and a model without one."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

import bgc
from bgc.cli import main

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = str(ROOT / "models" / "pendulum.bg")

TANKS = str(ROOT / "tests" / "models" / "two_tanks.bg")

FALLING = """\
model falling "a mass under a constant force"
parameter m = 2.0
parameter F = 3.0
v : 1
mass : I(m)
push : Se(F)
push -> v
v -> mass
signal x = integral(v.f, init = 0.5)
"""


def cli(*args):
    result = CliRunner().invoke(main, list(args))
    assert "Traceback" not in result.output
    return result


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def tank_levels(Q=0.002, rho_g=9810.0, k1=2e-5, k2=3e-5):
    """At rest the pump's flow goes through both valves: Q = k2 sqrt(p2) = k1 sqrt(p1 - p2)."""
    p2 = (Q / k2) ** 2
    p1 = p2 + (Q / k1) ** 2
    return p1 / rho_g, p2 / rho_g


def test_two_tanks_reach_their_closed_form_levels(tmp_path):
    model = TANKS
    out = tmp_path / "eq.json"
    result = cli("steady", model, "--scene", "fill", "--json", str(out))
    assert result.exit_code == 0, result.output
    values = dict(line.split(" = ") for line in result.output.splitlines())
    h1, h2 = tank_levels()
    assert float(values["tank1.q"]) / 0.5 == pytest.approx(h1, rel=1e-12)
    assert float(values["tank2.q"]) / 0.3 == pytest.approx(h2, rel=1e-12)
    assert float(values["residual"]) <= 1e-15
    d = json.loads(out.read_text())
    assert d["states"]["tank1.q"] == float(values["tank1.q"])


def test_parameters_move_the_equilibrium(tmp_path):
    model = TANKS
    eq = bgc.steady(model, params={"Q": 0.001, "k2": 4e-5})
    h1, h2 = tank_levels(Q=0.001, k2=4e-5)
    states = dict(eq.states)
    assert states["tank1.q"] / 0.5 == pytest.approx(h1, rel=1e-12)
    assert states["tank2.q"] / 0.3 == pytest.approx(h2, rel=1e-12)


def test_pendulum_hangs_with_its_multiplier():
    eq = bgc.steady(PENDULUM, scene="swing")
    s = dict(eq.states)
    m, g, l = 1.0, 9.81, 1.0
    assert s["x"] == pytest.approx(0, abs=1e-12) and s["y"] == pytest.approx(l, abs=1e-12)
    # at rest the rod carries the weight: 2 y lambda = m g (the MTF's modulus is 2y)
    assert dict(eq.multipliers)["rod.lambda"] == pytest.approx(m * g / (2 * l), rel=1e-12)
    assert abs(dict(eq.constraint_residuals)["rod.residual"]) <= 1e-12


def test_no_equilibrium_is_said(tmp_path):
    model = write(tmp_path, "falling.bg", FALLING)
    out = tmp_path / "eq.json"
    result = cli("steady", model, "--json", str(out))
    assert result.exit_code == 1
    assert "no equilibrium" in result.output and "mass.p" in result.output
    assert not out.exists()


def test_a_free_mass_rests_where_it_is(tmp_path):
    model = write(tmp_path, "falling.bg", FALLING)
    result = cli("steady", model, "-p", "F=0")
    assert result.exit_code == 0, result.output
    assert "x = 0.5\n" in result.output  # the nearest of the family: the initial position
    assert "family" in result.output


def test_errors(tmp_path):
    model = TANKS
    assert cli("steady", model, "-p", "nope=1").exit_code == 2
    assert cli("steady", model, "--scene", "nope").exit_code == 2


HANG = """\
model hang "a mass on a spring under its weight and a push, each an effect"
parameter m = 2.0
parameter k = 50.0
parameter b = 3.0
parameter g = 9.81
parameter F = 5.0
v : 1
mass : I(m)
spring : C(1/k)
damper : R(b)
weight : Se(m*g) @gravity
push : Se(F) @push
v -> mass
v -> spring
v -> damper
weight -> v
push -> v
scene weighed "the weight alone" { effects gravity; outputs spring.q; time 0 .. 1 }
"""

LADDER = str(ROOT / "models" / "ladder.bg")


@pytest.mark.parametrize("effects, load", [
    ([], 2.0 * 9.81), (["--effects", "gravity,push"], 2.0 * 9.81 + 5.0),
    (["--effects", "push"], 5.0), (["--effects", "none"], 0.0)])
def test_effects_move_the_equilibrium(tmp_path, effects, load):
    """--effects replaces the scene's as in simulate: the spring holds the load k q = m g + F
    of the sources left in."""
    model = write(tmp_path, "hang.bg", HANG)
    out = tmp_path / "rest.json"
    result = cli("steady", model, "--scene", "weighed", *effects, "--json", str(out))
    assert result.exit_code == 0, result.output
    states = json.loads(out.read_text())["states"]
    assert states["spring.q"] == pytest.approx(load / 50.0, rel=1e-12, abs=1e-15)
    assert abs(states["mass.p"]) < 1e-12
    rest = bgc.steady(model, scene="weighed", effects=effects[1] if effects else None)
    assert dict(rest.states)["spring.q"] == states["spring.q"]


@pytest.mark.parametrize("algebra", ["auto", "symbolic", "numeric"])
def test_algebra_solves_the_ladder_to_its_divider(tmp_path, algebra):
    """The ladder's resistors are an algebraic block (LU in the generated code, or solved
    symbolically): at rest no current reaches the capacitor, which holds the divider's
    voltage; linearised, its one pole is -1/(R C) with R the ladder's resistance seen from it."""
    V0, R1, R2, R3, R4, R5, Cc = 10.0, 1.0, 2.0, 1.5, 3.0, 0.5, 0.2
    par = lambda a, b: a * b / (a + b)  # noqa: E731
    shunt = par(R2, R3 + R4)
    v = V0 * shunt / (R1 + shunt) * R4 / (R3 + R4)
    out = tmp_path / "rest.json"
    result = cli("steady", LADDER, "--scene", "charge", "--algebra", algebra, "--json", str(out))
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["states"]["cap.q"] == pytest.approx(Cc * v, rel=1e-12)
    lin = tmp_path / "lin.json"
    result = cli("linearize", LADDER, "--scene", "charge", "--algebra", algebra, "-o", str(lin))
    assert result.exit_code == 0, result.output
    R = R5 + par(R4, R3 + par(R1, R2))
    assert json.loads(lin.read_text())["A"] == [[pytest.approx(-1 / (R * Cc), rel=1e-12)]]
    assert bgc.steady(LADDER, scene="charge", algebra=algebra).residual < 1e-12


OVERFLOW = """\
model fast "a first-order lag whose rate is a parameter: its rest is z = 1 whatever the rate"
parameter a = 1
signal z = integral(a*(1 - z), init = 0)
"""


@pytest.mark.parametrize("a", ["1e200", "1e308", "-1e308", "1e-300"])
def test_a_huge_rate_still_rests_at_its_equilibrium(tmp_path, a):
    """-p a=1e308: the Jacobian's squares overflowed in the least squares: numpy's
    RuntimeWarnings on stderr, then "no equilibrium ... rank 0".  dz/dt = a (1 - z) rests at
    z = 1 for every a != 0."""
    model = write(tmp_path, "fast.bg", OVERFLOW)
    result = CliRunner().invoke(main, ["steady", model, "-p", f"a={a}"])
    assert (result.exit_code, result.stdout, result.stderr) == (0, "z = 1\nresidual = 0\n", "")
