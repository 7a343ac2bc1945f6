"""Sensitivities, fits and linearisations of models driven by --input data (issue 40).

The references are closed forms: an RC circuit driven by a tabulated voltage (a ramp, then
held) has a capacitor voltage of exponentials whose derivatives with respect to R and C are
written out here; a fit of R to noisy samples of that closed form brackets the truth; and the
linearisation of x' = -u x about a point of a run driven by a piecewise-linear u is A = -u(T),
B = -x(T) with x(T) = exp(-(the integral of u)).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import bgc
from bgc.analysis import estimate, linear
from bgc.analysis.operating import AnalysisArgumentError
from conftest import run_bgc

RC = """model rc_data "an RC circuit driven by a measured voltage"
parameter R = 2.0
parameter C = 0.25
input v = 0 "the source voltage"
src : Se(v)
r   : R(R)
c   : C(C)
j   : 1
src -> j
j -> r
j -> c
scene run {
  time 0 .. 1.5 every 0.05
  outputs c.e
  solver dopri5(rtol = 1e-11, atol = 1e-13)
}
"""

# the measured voltage: 0 V at t = 0 up to 1 V at t = 0.5, then held (the last row at 1.5)
T1, V1 = 0.5, 1.0
DATA = {"v": ((0.0, T1, 1.5), (0.0, V1, V1))}


def _rc(t, R, C):
    """The capacitor's voltage and its derivatives with respect to R and C."""
    tau, a = R * C, V1 / T1
    t = np.asarray(t, dtype=float)
    on = t <= T1
    e_ramp = a * (t - tau) + a * tau * np.exp(-t / tau)
    de_ramp = -a + a * np.exp(-t / tau) + a * t / tau * np.exp(-t / tau)
    e1 = a * (T1 - tau) + a * tau * math.exp(-T1 / tau)
    de1 = -a + a * math.exp(-T1 / tau) + a * T1 / tau * math.exp(-T1 / tau)
    s = t - T1
    decay = np.exp(-s / tau)
    e_after = V1 + (e1 - V1) * decay
    de_after = de1 * decay + (e1 - V1) * decay * s / tau ** 2
    e = np.where(on, e_ramp, e_after)
    de_dtau = np.where(on, de_ramp, de_after)
    return e, de_dtau * C, de_dtau * R


@pytest.fixture(scope="module")
def rc(tmp_path_factory):
    path = tmp_path_factory.mktemp("inputs") / "rc_data.bg"
    path.write_text(RC)
    return path


def test_sensitivities_through_input_data_match_the_closed_form(rc):
    r = bgc.sensitivities(str(rc), ["R", "C"], scene="run", inputs=DATA)
    e, de_dR, de_dC = _rc(r.t, 2.0, 0.25)
    k = r.outputs.index("c.e")
    assert np.max(np.abs(r.y[:, k] - e)) < 1e-9
    assert np.max(np.abs(r.dy[:, k, 0] - de_dR)) < 1e-8
    assert np.max(np.abs(r.dy[:, k, 1] - de_dC)) < 1e-8
    again = bgc.sensitivities(str(rc), ["R", "C"], scene="run", inputs=DATA, backend="python")
    assert again.S.tobytes() == r.S.tobytes() and again.dy.tobytes() == r.dy.tobytes()


def test_simulate_sensitivities_reads_the_input_file(rc, tmp_path):
    data = tmp_path / "v.csv"
    data.write_text("t,v\n0,0\n0.5,1\n1.5,1\n")
    out = tmp_path / "sens.csv"
    result = run_bgc("simulate", rc, "--scene", "run", "--input", data,
                     "--sensitivities", "R", "-o", out)
    assert result.returncode == 0, result.stderr
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    _, de_dR, _ = _rc(rows[:, 0], 2.0, 0.25)
    assert np.max(np.abs(rows[:, 2] - de_dR)) < 1e-8


def test_fit_through_input_data_recovers_R(rc, tmp_path):
    R_true = 2.6
    t = np.round(np.arange(0, 1.5 + 1e-9, 0.05), 10)
    e, _, _ = _rc(t, R_true, 0.25)
    noisy = e + 0.002 * np.random.default_rng(3).standard_normal(len(t))
    measured = tmp_path / "measured.csv"
    measured.write_text("t,c.e\n" + "".join(f"{a:.2f},{float(b)!r}\n" for a, b in zip(t, noisy)))
    data = tmp_path / "v.csv"
    data.write_text("t,v\n0,0\n0.5,1\n1.5,1\n")
    out = tmp_path / "fit.json"
    result = run_bgc("fit", rc, "--scene", "run", "--data", measured, "--input", data,
                     "--vary", "R=0.1..10", "-o", out)
    assert result.returncode == 0, result.stderr
    fitted = json.loads(out.read_text())
    lo, hi = fitted["parameters"]["R"]["ci95"]
    assert fitted["converged"] and lo < R_true < hi and hi - lo < 0.1
    assert fitted["residual_sd"] == pytest.approx(0.002, rel=0.3)
    # the same fit from Python, the data as numbers
    again = estimate.fit(str(rc), estimate.read_data(measured), ["R=0.1..10"], scene="run",
                         inputs=DATA)
    assert float(again.estimates[0]) == fitted["parameters"]["R"]["estimate"]


DECAY = """model decay "x' = -u x, u a measured rate"
input u = 1
signal x = integral(-x*u, init = 1)
scene run {
  time 0 .. 1 every 0.1
  outputs x
  solver dopri5(rtol = 1e-12, atol = 1e-14)
}
"""


def test_linearize_about_a_point_of_a_run_driven_by_data(tmp_path):
    model = tmp_path / "decay.bg"
    model.write_text(DECAY)
    data = {"u": ((0.0, 1.0), (1.0, 3.0))}  # u = 1 + 2 t
    T = 0.5
    lin = linear.linearize(str(model), "run", at=f"t={T}", input_data=data)
    u, x = 1 + 2 * T, math.exp(-(T + T ** 2))
    assert lin.input_values == (("u", u),)
    assert lin.A[0, 0] == pytest.approx(-u, rel=1e-14)
    assert lin.B[0, 0] == pytest.approx(-x, rel=1e-9)
    assert dict(lin.point)["x"] == pytest.approx(x, rel=1e-9)
    at_start = linear.linearize(str(model), "run", input_data=data)
    assert at_start.input_values == (("u", 1.0),) and at_start.A[0, 0] == -1.0
    csv = tmp_path / "u.csv"
    csv.write_text("t,u\n0,1\n1,3\n")
    out = tmp_path / "lin.json"
    result = run_bgc("linearize", model, "--scene", "run", "--at", "t=0.5", "--input", csv,
                     "-o", out)
    assert result.returncode == 0, result.stderr
    assert "inputs from their data at t = 0.5: u = 2" in result.stdout
    d = json.loads(out.read_text())
    assert d["input_values"] == {"u": 2.0} and d["A"] == [[-2.0]]
    with pytest.raises(AnalysisArgumentError, match="no equilibrium"):
        linear.linearize(str(model), "run", at="steady", input_data=data)
    with pytest.raises(AnalysisArgumentError, match="unknown input 'w'"):
        linear.linearize(str(model), "run", input_data={"w": ((0.0,), (1.0,))})


@pytest.mark.parametrize("command", ["fit", "linearize"])
def test_an_output_onto_the_input_data_is_refused(tmp_path, command):
    """`-o` naming the --input file: one line, exit 1, the data as it was."""
    model = tmp_path / "decay.bg"
    model.write_text(DECAY)
    csv = tmp_path / "u.csv"
    csv.write_text("t,u\n0,1\n1,3\n")
    measured = tmp_path / "x.csv"
    measured.write_text("t,x\n0,1\n0.5,0.5\n1,0.1\n")
    extra = ["--data", measured, "--vary", "u=0..1"] if command == "fit" else []
    result = run_bgc(command, model, "--scene", "run", "--input", csv, *extra, "-o", csv)
    assert result.returncode == 1, result.stderr
    assert "u.csv" in result.stderr and "Traceback" not in result.stderr
    assert csv.read_text() == "t,u\n0,1\n1,3\n"
