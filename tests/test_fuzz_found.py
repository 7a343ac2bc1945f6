"""Defects tools/fuzz.py --full-every found, each with the model it was minimised to
(tests/fuzz_regressions/): the commands beyond check must keep what they promise there."""
import math

import pytest

from conftest import ROOT, have_cc, run_bgc

FOUND = ROOT / "tests" / "fuzz_regressions"


@pytest.mark.skipif(not have_cc(), reason="no C compiler")
def test_a_libm_function_of_numbers_gives_the_same_bytes_in_every_backend(tmp_path):
    """p1 = tanh(cos(9)): a C compiler folds it with exact rounding, libm rounds it one bit
    apart; the C backend now computes it at run time as Python's math (libm) and the
    interpreter do."""
    texts = []
    for backend in ("c", "python", "vm"):
        out = tmp_path / f"{backend}.csv"
        r = run_bgc("simulate", str(FOUND / "backends_differ_on_a_folded_constant.bg"),
                    "--backend", backend, "--t-end", "0.05", "--outputs", "p1", "-o", str(out))
        assert r.returncode == 0, r.stderr
        texts.append(out.read_text())
    assert texts[0] == texts[1] == texts[2]
    assert float(texts[0].splitlines()[1].split(",")[1]) == math.tanh(math.cos(9))


def test_linearize_of_a_law_without_a_finite_derivative_says_so(tmp_path):
    out = tmp_path / "lin.json"
    r = run_bgc("linearize", str(FOUND / "linearize_not_finite.bg"), "-o", str(out))
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert "at t = 0 the linearisation is not finite: A[0, 0]" in r.stderr, r.stderr
    assert not out.exists()


def test_a_constant_that_divides_by_zero_is_inf_in_every_backend(tmp_path):
    """1/R with R = min(p1, 0) = 0: IEEE division gives inf (C's 1.0/0.0), so every backend
    stops at t = 0 with the same located message and the same rows, none with a traceback."""
    model = FOUND / "python_constant_divides_by_zero.bg"
    backends = ("c", "python", "vm") if have_cc() else ("python", "vm")
    texts, errors = [], []
    for backend in backends:
        out = tmp_path / f"{backend}.csv"
        r = run_bgc("simulate", model, "--backend", backend, "--t-end", "0.1", "-o", out)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        errors.append(r.stderr.splitlines()[0])
        texts.append(out.read_bytes())
    assert errors[0] == "error: at t = 0: derivative of state 'c.q' is not finite"
    assert all(e == errors[0] for e in errors) and all(t == texts[0] for t in texts)
    for command in ("linearize", "steady"):
        r = run_bgc(command, model)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        assert "not finite" in r.stderr, r.stderr



def test_a_switch_whose_condition_reads_a_discrete_variable(tmp_path):
    """Sw(d < 16) with d = 0: the switch is closed (no effort across it), so the source
    charges the capacitor through the resistor: q = 1 - exp(-t) (R = C = 1, 1 V), the
    linearisation A = -1/(R C) = -1 and the equilibrium q = C V = 1, the same bytes in every
    backend (all were a traceback)."""
    import json

    model = FOUND / "switch_reads_a_discrete_variable.bg"
    backends = ("c", "python", "vm") if have_cc() else ("python", "vm")
    texts = []
    for backend in backends:
        out = tmp_path / f"{backend}.csv"
        r = run_bgc("simulate", model, "--backend", backend, "--t-end", "2", "--dt", "0.5",
                    "--rtol", "1e-10", "--atol", "1e-12", "-o", out)
        assert r.returncode == 0, r.stderr
        texts.append(out.read_text())
    assert all(t == texts[0] for t in texts)
    rows = [[float(v) for v in line.split(",")] for line in texts[0].splitlines()[1:]]
    for t, q in rows:
        assert q == pytest.approx(1 - math.exp(-t), rel=1e-8, abs=1e-12)
    lin = tmp_path / "lin.json"
    r = run_bgc("linearize", model, "-o", lin)
    assert r.returncode == 0, r.stderr
    assert json.loads(lin.read_text())["A"] == [[pytest.approx(-1.0, rel=1e-12)]]
    r = run_bgc("steady", model)
    assert r.returncode == 0, r.stderr
    assert "c.q = 1\n" in r.stdout
