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


# ---------------------------------------------------------------- time sources and events
# An RC circuit driven by a source of 5 V once it is on: at rest no current flows, the
# capacitor holds the source's voltage, q = C*5 (closed form), whatever form the source has.

R_C, C_C, V_C = 2.0, 0.3, 5.0


def rc(tmp_path, source, extra=""):
    """The RC circuit with the effort source `source`, written to a file."""
    return write(tmp_path, "rc.bg", f"""model rc
parameter R = {R_C}
parameter C = {C_C}
{extra}src : Se({source})
j : 1
r : R(R)
c : C(C)
src -> j
j -> r
j -> c
""")


def steady_q(result) -> float:
    assert result.exit_code == 0, result.output
    return float(dict(line.split(" = ") for line in result.stdout.splitlines())["c.q"])


@pytest.mark.parametrize("source, at, named", [
    ("5*step(0)", None, "step(0)"),
    ("5*step(1)", "t=1", "step(1)"),
    ("5*step(1)", "t=7.5", "step(1)"),
    ("if t >= 0 then 5 else 0", None, "t >= 0"),
    ("if t < 2 then 0 else 5", "t=2", "t < 2"),
    ("5*pulse(1e308, 1e308)", "t=1e308", "pulse(1e308, 1e308)"),  # it never ends
    ("5*(1 - pulse(0, 2))", "t=2", "pulse(0, 2): end"),
    ("5*ramp(1) - 5*ramp(2)", "t=2", "ramp(2)"),  # 5 (t - 1) - 5 (t - 2) = 5: t cancels
    ("table([[0, 0], [3, 5]], t)", "t=3", "table([[0, 0], [3, 5]], t)"),  # held from its last row
    ("if exp(-t) < 0.5 then 5 else 0", "t=1", "exp(-t) < 0.5"),  # crossed at log 2
    ("5*(1 - square(1e308, 0.5))", "t=1.6e308", "square(1e308, 0.5)"),  # next edge: 2e308
    ("5*square(2, 0.5, 10)", "t=0", None),  # refused below: this is the control
])
def test_time_sources_are_evaluated_at_the_time_asked(tmp_path, source, at, named):
    """q = C*5 for each form of source that is 5 from the time asked on, with a note that
    names the sources as written."""
    model = rc(tmp_path, source)
    result = cli("steady", model, *(["--at", at] if at else []))
    if named is None:
        assert result.exit_code == 1
        return
    assert steady_q(result) == pytest.approx(C_C * V_C, rel=1e-12)
    when = "0" if at is None else at[2:]
    assert f"note: time sources evaluated at t = {float(when):.17g}" in result.stderr
    assert named in result.stderr
    eq = bgc.steady(model, at=at)
    assert dict(eq.states)["c.q"] == pytest.approx(C_C * V_C, rel=1e-12)
    assert eq.t == float(when)


def test_a_constant_source_has_no_note(tmp_path):
    result = cli("steady", rc(tmp_path, "5"))
    assert steady_q(result) == pytest.approx(C_C * V_C, rel=1e-12)
    assert "note" not in result.stderr


@pytest.mark.parametrize("source, at, where, why", [
    ("5*square(1, 0.5)", None, "square(1, 0.5)", "changes at t = 0.5"),
    ("5*square(1e308, 0.5)", None, "square(1e308, 0.5)", "changes at t = 5e+307"),
    ("5*square(2, 0.5, 10)", "t=3", "square(2, 0.5, 10)", "changes at t = 10"),
    ("5*step(1)", None, "step(1)", "changes at t = 1"),
    ("5*step(1e308)", None, "step(1e308)", "changes at t = 1e+308"),
    ("5*pulse(1e308, 1e308)", None, "pulse(1e308, 1e308)", "changes at t = 1e+308"),
    ("5*pulse(0, 2)", None, "pulse(0, 2)", "changes at t = 2"),
    ("if t >= 4 then 5 else 0", "t=3", "t >= 4", "changes at t = 4"),
    ("if sin(t) > 0.5 then 5 else 0", "t=1", "sin(t) > 0.5", "changes at t = 2.61799"),
    ("5*sin(t)", None, "src : Se(5*sin(t))", "'src' reads t"),
    ("5*ramp(0)", "t=5", "src : Se(5*ramp(0))", "'src' reads t"),
    ("table([[0, 0], [3, 5]], t)", None, "table([[0, 0], [3, 5]], t)", "changes at t = 3"),
    ("table([[0, 0], [3, 5]], t, extrapolate = linear)", "t=4",
     "table([[0, 0], [3, 5]], t, extrapolate = linear)", "varies from t = 4 on"),
    ("if c.q > sin(t) then 0 else 5", None, "c.q > sin(t)", "reads t"),
])
def test_a_driven_model_is_refused_at_its_sources(tmp_path, source, at, where, why):
    """Sources not constant from the time asked on: exit 1, each located at the source as
    written (its line, a caret under it), the model said to be driven, simulating
    suggested; no file written."""
    model = rc(tmp_path, source)
    out = tmp_path / "eq.json"
    result = cli("steady", model, "--json", str(out), *(["--at", at] if at else []))
    assert result.exit_code == 1, result.output
    lines = result.stderr.splitlines()
    col = lines[1].index(where) - lines[1].index("|") - 1  # the excerpt: "   4 | src : ..."
    assert lines[0].startswith(f"{model}:4:{col}: error: ") and why in lines[0], lines
    assert lines[2].split("|")[1].startswith(" " * col + "^"), lines
    assert "no equilibrium: the model is driven" in result.stderr
    assert "simulate" in result.stderr and "bgc periodic" in result.stderr
    assert not out.exists()
    with pytest.raises(bgc.analysis.equilibrium.Driven) as raised:
        bgc.steady(model, at=at)
    assert why in str(raised.value)


def test_every_source_is_named(tmp_path):
    result = cli("steady", rc(tmp_path, "5*step(1) + square(1, 0.5) + sin(t)"))
    assert result.exit_code == 1
    errors = [ln for ln in result.stderr.splitlines() if ": error: " in ln]
    assert len(errors) == 4 and "'src' reads t" in errors[0]  # in the order of the text
    assert "'step(1)'" in errors[1] and "'square(1, 0.5)'" in errors[2]
    assert "driven" in errors[3]


@pytest.mark.parametrize("at, status, text", [
    ("t=-1", 2, "before the scene's start"), ("soon", 2, "t=TIME"), ("t=inf", 2, "finite")])
def test_at_usage_errors(tmp_path, at, status, text):
    result = cli("steady", rc(tmp_path, "5"), "--at", at)
    assert result.exit_code == status and text in result.output


def test_modes_follow_the_equilibrium(tmp_path):
    """5 V while q < 1, then 3 V: Newton's method in the first mode ends at q = C*5 = 1.5,
    where the relation gives the second, whose equilibrium q = C*3 = 0.9 gives the first
    again: no equilibrium.  With C = 0.5 the second mode's q = 1.5 keeps it: the answer."""
    model = rc(tmp_path, "if c.q < 1 then 5 else 3")
    result = cli("steady", model)
    assert result.exit_code == 1
    assert "'c.q < 1' switches at every candidate" in result.stderr
    assert dict(bgc.steady(model, params={"C": 0.5}).states)["c.q"] == pytest.approx(1.5)


def test_a_when_block_that_would_fire_on_the_way_is_refused(tmp_path):
    """The source doubles when q passes 1 (a discrete variable set by a when-block): the
    equilibrium of the first value, q = C*5 = 1.5, is past it, so the run's discrete value
    there is not the initial one: refused at the when-block.  Past q = 2 it never fires: the
    equilibrium holds, q = C*5."""
    block = "discrete k = 1\nwhen c.q > LIMIT { k = 2 }\n"
    model = rc(tmp_path, "5*k", block.replace("LIMIT", "1"))
    result = cli("steady", model)
    assert result.exit_code == 1
    assert ":5:1: error: 'when c.q > 1' would fire on the way" in result.stderr
    model = rc(tmp_path, "5*k", block.replace("LIMIT", "2"))
    assert steady_q(cli("steady", model)) == pytest.approx(C_C * V_C, rel=1e-12)


def test_a_when_block_at_the_start_sets_the_point(tmp_path):
    """when initial() runs as at the start of a run from the time asked: k = 2, q = C*10."""
    model = rc(tmp_path, "5*k", "discrete k = 1\nwhen initial() { k = 2 }\n")
    assert steady_q(cli("steady", model)) == pytest.approx(C_C * 2 * V_C, rel=1e-12)


def test_a_when_block_on_time_that_fires_before_the_time_asked_is_refused(tmp_path):
    """k = 2 from t = 1 on (a when-block on t): at --at t=2 a run from the start has fired
    it, so the discrete value there is the run's: refused at the block; at t = 0.5 the block
    is still to come (a time event): the model is driven."""
    model = rc(tmp_path, "5*k", "discrete k = 1\nwhen t >= 1 { k = 2 }\n")
    result = cli("steady", model, "--at", "t=2")
    assert result.exit_code == 1
    assert (":5:1: error: 'when t >= 1' would fire on the way from the start (t = 0) to the "
            "equilibrium at t = 2") in result.stderr
    result = cli("steady", model, "--at", "t=0.5")
    assert result.exit_code == 1 and "'t >= 1' changes at t = 1" in result.stderr


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


SERIES = """\
model series "a source charging a capacitor through a resistor and an inductor"
parameter capacitance = 1
parameter resistance = 1
parameter inductance = 1
src : Se(5)
j : 1
r : R({law})
l : I(inductance)
c : C(capacitance)
src -> j
j -> r
j -> l
j -> c
"""


def series_rest(tmp_path, law, **params):
    text = SERIES.format(law=law)
    if law != "resistance":  # without the inductor
        text = text.replace("l : I(inductance)\n", "").replace("j -> l\n", "")
    model = write(tmp_path, "series.bg", text)
    args = [a for k, v in params.items() for a in ("-p", f"{k}={v}")]
    return cli("steady", model, *args)


@pytest.mark.parametrize("law, params", [
    ("resistance", {"capacitance": 1e300}),  # was refused: rank 1 of 2
    ("resistance", {"capacitance": 1e300, "inductance": 1e-300}),
    ("resistance", {"capacitance": 1e-300, "inductance": 1e300}),
    ("resistance", {"resistance": 1e300}),
    ("resistance", {"capacitance": 1e-308}),
    ("f = (e + e*e*e)/resistance", {"resistance": 1e300}),  # was c.q = 3.679
    ("f = (e + e*e*e)/resistance", {"capacitance": 1e-300, "resistance": 1e300}),
    ("f = (e + e*e*e)/resistance", {"capacitance": 1e300, "resistance": 1e-300}),
])
def test_the_rest_of_a_series_circuit_at_extreme_magnitudes(tmp_path, law, params):
    """At rest no current flows and the capacitor holds the source's 5 V: q = C V, p = 0,
    whatever the units' magnitudes (the residual and the rank are judged relative to the
    terms and to the equilibrated Jacobian, not against 1)."""
    result = series_rest(tmp_path, law, **params)
    assert result.exit_code == 0, result.output
    values = {k: float(v) for k, v in (line.split(" = ") for line in result.stdout.splitlines())}
    C = params.get("capacitance", 1.0)
    assert values["c.q"] == pytest.approx(5 * C, rel=1e-12)
    if "l.p" in values:  # the current p / L, against the circuit's 5 V / R
        R, L = params.get("resistance", 1.0), params.get("inductance", 1.0)
        assert abs(values["l.p"] / L) <= 1e-12 * 5 / R
    assert result.stderr == ""


def test_an_equilibrium_beyond_double_is_refused_not_printed(tmp_path):
    """C = 1e308: q = C V = 5e308 is not a double; steady says so (exit 1, no number)."""
    result = series_rest(tmp_path, "resistance", capacitance=1e308)
    assert result.exit_code == 1 and result.stdout == ""
    assert "leaves the range of double" in result.stderr, result.stderr
