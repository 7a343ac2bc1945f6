"""The unit algebra of bgc.base.si against SI identities (the SI brochure's derived units)."""
import glob
import re

import pytest

from bgc.base import si


def same(a, b):
    return si.parse(a).same_dimension(si.parse(b))


@pytest.mark.parametrize("a,b", [
    ("V*A", "W"), ("N*m", "J"), ("Ohm*F", "s"), ("H/Ohm", "s"), ("V*s", "Wb"), ("Wb/m^2", "T"),
    ("A*s", "C"), ("C/V", "F"), ("1/Ohm", "S"), ("N/m^2", "Pa"), ("J/s", "W"), ("1/s", "Hz"),
    ("Pa*m^3/s", "W"), ("N*m*rad/s", "W"), ("N*m/rad", "J"), ("kg*m/s^2", "N"), ("V/A", "Ohm"),
    ("kg*m^2", "kg*m*m"), ("m^3/(s*Pa^0.5)", "m^3.5/s^0/kg^0.5"), ("m/s^2", "m*s^-2"), ("(m/s)^2", "m^2/s^2"), ("\u03a9", "Ohm"),
])
def test_identities(a, b):
    assert same(a, b)


@pytest.mark.parametrize("a,b", [("V*s", "C"), ("N", "J"), ("m/s", "m/s^2"), ("W", "J")])
def test_distinct(a, b):
    assert not same(a, b)


def test_prefixes_scale():
    assert si.parse("kN").scale == pytest.approx(1e3)
    assert si.parse("mA").scale == pytest.approx(1e-3)
    assert si.parse("uF").scale == pytest.approx(1e-6)
    assert si.parse("\u00b5F").scale == pytest.approx(1e-6)
    assert si.parse("mg").scale == pytest.approx(1e-6) and si.parse("mg").same_dimension(si.kg)
    assert si.parse("m").scale == 1.0 and si.parse("m").dims == si.m.dims   # metre, not milli
    assert si.parse("MPa").scale == pytest.approx(1e6)


def test_rad_is_dimensionless_but_shown():
    assert si.parse("rad/s").same_dimension(si.parse("1/s"))
    assert si.show(si.parse("rad/s")) == "rad/s"
    assert si.show(si.parse("V")) == "m^2*kg/s^3/A"


@pytest.mark.parametrize("text,offset,words", [
    ("N*mm*Kelvin", 5, ["unknown unit 'Kelvin'"]),
    ("Ohms", 0, ["unknown unit 'Ohms'", "did you mean 'Ohm'"]),
    ("m/", 2, ["expected a unit"]),
    ("m^", 2, ["number exponent"]),
    ("(m/s", 4, ["expected ')'"]),
    ("m s", 2, ["unexpected 's'"]),
])
def test_errors_located(text, offset, words):
    with pytest.raises(si.UnitError) as e:
        si.parse(text)
    assert e.value.offset == offset
    for w in words:
        assert w in str(e.value)


def test_every_shipped_unit_parses():
    texts = glob.glob("models/**/*.bg", recursive=True) + glob.glob("bgc/library/*.bg") + \
        glob.glob("docs/*.md")
    seen = 0
    for path in texts:
        for u in re.findall(r'\bunit\s+"([^"]*)"', open(path, encoding="utf-8").read()):
            if u in ("UNIT", "STRING", "...", "kg*Kelvn") and path.startswith("docs"):
                continue   # the grammar's placeholders in the manual, and its error example
            si.parse(u)
            seen += 1
    assert seen > 0


def test_unknown_unit_in_a_model_is_located():
    from bgc.base.diagnostics import ModelError
    from bgc.front.parser import parse
    src = 'model ball\nparameter m  = 1.0 unit "kg*Kelvn"\nw : Se(-m)\nb : I(m)\nw -> b\n'
    with pytest.raises(ModelError) as e:
        parse(src)
    d = e.value.diagnostics[0]
    assert "unknown unit 'Kelvn'" in d.message
    assert (d.span.line, d.span.col) == (2, src.splitlines()[1].index("Kelvn") + 1)
    parse(src.replace("Kelvn", "K"))
