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
