"""Units (docs/units.md, bgc.front.units): every law checked for dimensional consistency at
compile time, a mismatch a located error naming both units; undeclared quantities inferred.
The expected units are the physics' (a charge is A*s, a motor constant V*s/rad = N*m/A, a
momentum N*s), written here from the laws, not read from bgc."""
from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from click.testing import CliRunner

import bgc
from bgc import api
from bgc.base import si
from bgc.base.diagnostics import ModelError
from bgc.cli import main
from bgc.front.instantiate import front
from bgc.front.flatten import flatten
from bgc.front.resolve import resolve
from bgc.front.units import check_units

ROOT = Path(__file__).resolve().parent.parent

RC = """model rc "an RC circuit with declared units"
parameter R = 1000 unit "{R}" "the load"
parameter C = 1e-3 unit "F"
parameter V = 5 unit "V"
src : Se({source})
r : R(R)
c : C(C)
j : 1
src -> j
j -> r
j -> c
signal w = integral(c.e*r.f, init = 0)
scene run {{ outputs c.e, c.q, r.f, w
  time 0 .. 5 every 0.5 }}
"""


def _check(tmp_path, text, name="m.bg"):
    (tmp_path / name).write_text(text, encoding="utf-8")
    return CliRunner().invoke(main, ["check", str(tmp_path / name)])


def _units(text: str) -> dict:
    return dict(api.build(bgc.load("m.bg", text), program=False).graph.units)


def _dims(unit: str):
    return si.parse(unit).dims[:7]  # (rad is not checked)


def test_a_resistance_declared_in_kilograms_is_refused_naming_both_units(tmp_path):
    result = _check(tmp_path, RC.format(R="kg", source="V"))
    assert result.exit_code == 1
    err = result.stderr
    assert "Traceback" not in err
    first = err.splitlines()[0]
    assert first.startswith(f"{tmp_path / 'm.bg'}:") and ": error: unit mismatch in the law" \
        in first, err
    # both sides named: C's displacement from R's (kg) path, and C times its effort (A*s)
    assert "but 'C' times its effort is A*s" in first, first
    assert "'R' is declared 'kg' here" in err and "'C' is declared 'F' here" in err


def test_the_same_circuit_in_ohms_checks_clean_and_its_units_are_inferred():
    units = _units(RC.format(R="Ohm", source="V"))
    assert _dims(units["c.e"]) == _dims("V")
    assert _dims(units["c.q"]) == _dims("A*s")  # q = C e: F V
    assert _dims(units["r.f"]) == _dims("A")  # f = e / R
    assert _dims(units["w"]) == _dims("J")  # the integral of the power
    assert units["R"] == "Ohm" and units["C"] == "F"  # as declared


def test_a_motor_constant_is_inferred_from_the_gyrator():
    """A DC motor: e = k w on the electrical side, tau = k i on the mechanical side; with the
    voltage, the current, the torque and the speed known from the declared parameters, k is
    V*s/rad, the same dimension as N*m/A."""
    units = _units("""model motor "a DC motor"
parameter V = 12 unit "V"
parameter R = 1 unit "Ohm"
parameter L = 0.01 unit "H"
parameter J = 0.01 unit "kg*m^2"
parameter k = 0.05
u : Se(V)
ra : R(R)
la : I(L)
em : GY(k)
rotor : I(J)
ea : 1
wm : 1
u -> ea
ea -> ra
ea -> la
ea -> em -> wm
wm -> rotor
""")
    assert _dims(units["k"]) == _dims("V*s/rad") == _dims("N*m/A")
    assert _dims(units["rotor.p"]) == _dims("N*m*s")
    assert _dims(units["la.p"]) == _dims("Wb")


@pytest.mark.parametrize("source, words", [
    ("V*sin(wn*t)", ("the argument of sin()", "'t*wn' is m*s", "a number (dimensionless)")),
    ("V + I0", ("the terms of a sum", "is V", "is A")),
    ("V*(t > d)", ("the two sides of a relation", "'t' is s", "is m")),
])
def test_mismatches_inside_an_expression_are_located(tmp_path, source, words):
    text = RC.format(R="Ohm", source=source).replace(
        'parameter V = 5 unit "V"\n', 'parameter V = 5 unit "V"\nparameter wn = 2 unit "m"\n'
        'parameter I0 = 1 unit "A"\nparameter d = 1 unit "m"\n')
    if "t > d" in source:
        text = text.replace("src : Se(V*(t > d))", "src : Se(if t > d then V else 0)")
    result = _check(tmp_path, text)
    assert result.exit_code == 1, result.output
    first = result.stderr.splitlines()[0]
    assert ":8:" in first and "unit mismatch" in first, result.stderr
    for w in words:
        assert w in first, first


def test_a_resistor_of_the_library_bonded_to_an_inertia_is_refused_at_the_bond(tmp_path):
    result = _check(tmp_path, """model mixed "a resistor on a rotational inertia"
import electrical as el
import mechanics as mech
r : el.resistor(r = 2)
m : mech.inertia(j = 0.1)
g : el.ground()
n : 0
n -> r.p
n -> m.p
r.n -> g.p
""")
    assert result.exit_code == 1
    lines = result.stderr.splitlines()
    assert lines[0].startswith(f"{tmp_path / 'm.bg'}:9:1: error: unit mismatch in bond"), \
        result.stderr
    assert "its effort is V but the rotational effort is N*m" in lines[0]
    assert "port 'm.p' is declared here" in result.stderr
    assert "more unit mismatches of the same quantities follow from it" in result.stderr


def test_a_scaled_unit_is_a_warning_that_says_the_value_is_not_converted(tmp_path):
    result = _check(tmp_path, RC.format(R="kOhm", source="V"))
    assert result.exit_code == 0, result.output
    assert "warning: unit 'kOhm' of parameter 'R' is 1000 " in result.stderr
    assert "does not convert units" in result.stderr


def test_a_model_that_declares_no_unit_is_not_checked():
    """Nothing to check against but time: a law that mixes a number and a rate (the fuzz
    models' kind) is left alone, as documented."""
    units = _units("""model plain "no units declared"
parameter p = 2
u : Se(sin(t))
k : R(cosh(p))
m : I(p)
j : 1
u -> j
j -> k
j -> m
""")
    assert units == {} or all(isinstance(v, str) for v in units.values())


def _front(path: Path):
    src = api._source(str(path))
    return flatten(resolve(front(src)))


def test_every_model_of_the_repository_checks_clean():
    """models/, tests/models/, benchmarks/models/ and the regressions: no unit mismatch
    (those that the front end refuses for other reasons aside: tests/errors/, the fuzz
    regressions that are refused by design).  The standard library's components are checked
    where they are instantiated: every one is, in tests/test_library.py."""
    paths = sorted([*ROOT.glob("models/*.bg"), *ROOT.glob("tests/models/*.bg"),
                    *ROOT.glob("benchmarks/models/*.bg"), *ROOT.glob("tests/fuzz_regressions/*.bg")])
    checked = 0
    for path in paths:
        try:
            g = _front(path)
        except (ModelError, bgc.BgcModelError):
            continue
        try:
            check_units(g)
        except ModelError as exc:
            pytest.fail(f"{path.relative_to(ROOT)}: {exc}")
        checked += 1
    assert checked > 60


def test_the_units_row_of_the_csv(tmp_path):
    (tmp_path / "rc.bg").write_text(RC.format(R="Ohm", source="V"), encoding="utf-8")
    out = tmp_path / "rc.csv"
    result = CliRunner().invoke(main, ["simulate", str(tmp_path / "rc.bg"), "--scene", "run",
                                       "--units", "-o", str(out), "--backend", "python"])
    assert result.exit_code == 0, result.output
    header, units, first = out.read_text().splitlines()[:3]
    assert header == "t,c.e,c.q,r.f,w"
    cells = units.split(",")
    assert cells[0] == "s"
    assert [_dims(u) for u in cells[1:]] == [_dims("V"), _dims("A*s"), _dims("A"), _dims("J")]
    assert first.startswith("0,")
    assert len(out.read_text().splitlines()) == 2 + 11  # the rows as without --units


def test_plot_columns_carry_the_inferred_units():
    from bgc.reports import plot
    compiled = api.build(bgc.load("m.bg", RC.format(R="Ohm", source="V")), "run")
    cols = {c.name: c.unit for c in plot.columns(compiled, ["c.e", "c.q", "r.f", "w"])}
    assert _dims(cols["c.q"]) == _dims("A*s") and _dims(cols["r.f"]) == _dims("A")


def test_fmu_units_name_their_base_units():
    """FMI 2.0's UnitDefinitions: each unit with its exponents of the SI base units."""
    from bgc.codegen import fmu
    element = ET.fromstring(fmu._unit_element("V"))
    (base,) = element
    assert {k: int(v) for k, v in base.attrib.items()} == {"kg": 1, "m": 2, "s": -3, "A": -1}
    scaled = ET.fromstring(fmu._unit_element("kN")).find("BaseUnit")
    assert float(scaled.get("factor")) == 1000.0
    assert ET.fromstring(fmu._unit_element("m^3/(s*Pa^0.5)")).find("BaseUnit") is None


def test_a_parameter_defined_in_the_wrong_unit_is_refused_at_its_definition(tmp_path):
    """`parameter Q0 = C*V unit "V"`: C V is a charge (A*s), not a voltage."""
    text = RC.format(R="Ohm", source="V").replace(
        'parameter V = 5 unit "V"\n', 'parameter V = 5 unit "V"\nparameter Q0 = C*V unit "V"\n')
    result = _check(tmp_path, text)
    assert result.exit_code == 1
    first = result.stderr.splitlines()[0]
    assert ":5:" in first and "unit mismatch in the definition of 'Q0'" in first, first
    assert "is V but 'C*V' is A*s" in first, first


def test_a_sensitivity_s_unit_is_its_output_s_over_its_parameter_s(tmp_path):
    (tmp_path / "rc.bg").write_text(RC.format(R="Ohm", source="V"), encoding="utf-8")
    result = CliRunner().invoke(main, ["simulate", str(tmp_path / "rc.bg"), "--scene", "run",
                                       "--units", "--sensitivities", "R", "--backend",
                                       "python"])
    assert result.exit_code == 0, result.output
    header, units = result.stdout.splitlines()[:2]
    unit = dict(zip(header.split(","), units.split(",")))
    assert _dims(unit["d(c.e)/d(R)"]) == _dims("V/Ohm")  # = A
    assert _dims(unit["d(c.q)/d(R)"]) == _dims("A*s/Ohm")


def test_check_says_the_units_were_checked_and_gives_the_states_theirs(tmp_path):
    result = _check(tmp_path, RC.format(R="Ohm", source="V"))
    assert result.exit_code == 0, result.output
    assert "  c.q  C, integral causality, in A*s\n" in result.stdout  # q = C e: F V
    assert "\nunits: every law checked; " in result.stdout
    plain = _check(tmp_path, "model plain\nu : Se(1)\nr : R(2)\nc : C(1)\nj : 1\nu -> j\n"
                             "j -> r\nj -> c\n", "p.bg")
    assert "units:" not in plain.stdout and "c.q  C, integral causality\n" in plain.stdout
