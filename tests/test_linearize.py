"""`bgc linearize` and bgc.linearize: A, B, C, D against closed forms, against finite differences
of the generated right side (computed here), and against python-control's frequency response;
the paper's pendulum in independent coordinates with its corrector's modes apart."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import bgc
from bgc.base import processes
from bgc.execute import runner
from bgc.api import Source
from bgc.cli import main

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = str(ROOT / "models" / "pendulum.bg")

M, K, CD = 2.0, 50.0, 3.0


@pytest.fixture
def msd():
    return str(ROOT / "tests" / "models" / "msd.bg")


def cli(*args):
    result = CliRunner().invoke(main, list(args))
    assert "Traceback" not in result.output
    return result


def test_mass_spring_damper_is_exact(msd, tmp_path):
    out = tmp_path / "msd.json"
    result = cli("linearize", msd, "--scene", "motion", "--inputs", "F", "-o", str(out))
    assert result.exit_code == 0, result.output
    d = json.loads(out.read_text())
    assert d["inputs"] == ["F"] and d["outputs"] == ["spring.q", "v.f"]
    assert sorted(d["states"]) == ["mass.p", "spring.q"]
    ip, iq = d["states"].index("mass.p"), d["states"].index("spring.q")
    # dp/dt = F - k q - c p/m, dq/dt = p/m; outputs q and p/m
    A = np.zeros((2, 2))
    A[ip, ip], A[ip, iq], A[iq, ip] = -CD / M, -K, 1 / M
    B = np.zeros((2, 1))
    B[ip, 0] = 1.0
    C = np.zeros((2, 2))
    C[0, iq], C[1, ip] = 1.0, 1 / M
    assert np.array_equal(d["A"], A) and np.array_equal(d["B"], B)
    assert np.array_equal(d["C"], C) and np.array_equal(d["D"], np.zeros((2, 1)))
    # the point: the initial state
    assert d["at"] == {"t": 0.0, "mass.p": 0.4, "spring.q": 0.0}
    roots = np.roots([M, CD, K])  # m s^2 + c s + k
    eig = [complex(*z) for z in d["eigenvalues"]]
    assert np.allclose(sorted(eig, key=lambda z: z.imag), sorted(roots, key=lambda z: z.imag),
                       rtol=1e-14)
    wn, zeta = math.sqrt(K / M), CD / (2 * math.sqrt(K * M))
    assert f"{wn:.6g}" in result.output and f"{zeta:.6g}" in result.output


def test_no_inputs_gives_empty_columns(msd):
    lin = bgc.linearize(msd, scene="motion")
    assert lin.inputs == () and lin.B.shape == (2, 0) and lin.D.shape == (2, 0)


def test_npz_and_csv_hold_the_same(msd, tmp_path):
    lin = bgc.linearize(msd, scene="motion", inputs=["F"])
    npz, csv = tmp_path / "l.npz", tmp_path / "l.csv"
    for f in (npz, csv):
        assert cli("linearize", msd, "--scene", "motion", "--inputs", "F", "-o",
                   str(f)).exit_code == 0
    z = np.load(npz)
    for key in "ABCD":
        assert np.array_equal(z[key], getattr(lin, key))
    assert list(z["states"]) == list(lin.states)
    first = npz.read_bytes()
    cli("linearize", msd, "--scene", "motion", "--inputs", "F", "-o", str(npz))
    assert npz.read_bytes() == first  # deterministic, time stamps included
    rows = [line.split(",") for line in csv.read_text().splitlines()[1:]]
    a = {(r[1], r[2]): float(r[3]) for r in rows if r[0] == "A"}
    for i, si in enumerate(lin.states):
        for j, sj in enumerate(lin.states):
            assert a[si, sj] == lin.A[i, j]


def test_npz_holds_every_array_of_the_json_the_pendulum_its_constraint_rows(tmp_path):
    """The NPZ has every key of the JSON (`at` as at_t, at_states, at_values), the rod's two
    rows (its length and its rate) among them; the basis N spans the null space of those rows'
    Jacobian, computed here from Phi = x^2 + y^2 - l^2 at the initial state."""
    npz, js = tmp_path / "p.npz", tmp_path / "p.json"
    for f in (npz, js):
        assert cli("linearize", PENDULUM, "--scene", "swing", "-o", str(f)).exit_code == 0
    d, z = json.loads(js.read_text()), np.load(npz)
    assert sorted(z.keys()) == sorted([k for k in d if k != "at"] + ["at_t", "at_states",
                                                                      "at_values"])
    assert list(z["constraint_rows"]) == d["constraint_rows"] == ["rod (position)",
                                                                  "rod (velocity)"]
    for key in ("A", "B", "C", "D", "basis", "eigenvalues", "corrector_eigenvalues"):
        assert np.array_equal(z[key], np.array(d[key], dtype=float).reshape(z[key].shape)), key
    m, l, theta0 = 1.0, 1.0, 0.5
    x, y, px, py = l * math.sin(theta0), l * math.cos(theta0), 0.0, 0.0
    rows = {"mx.p": (0, 2 * x / m), "my.p": (0, 2 * y / m), "x": (2 * x, 2 * px / m),
            "y": (2 * y, 2 * py / m)}  # d(Phi), d(dPhi/dt) by each state
    G = np.array([[rows[s][k] for s in z["full_states"]] for k in (0, 1)])
    assert np.abs(G @ z["basis"]).max() < 1e-12 and z["basis"].shape == (4, 2)


def _pendulum_checks(lin, g=9.81, l=1.0, alpha=5.0, beta=4.0):
    assert len(lin.states) == 2 and len(lin.full_states) == 4
    w = math.sqrt(g / l)
    eig = lin.eigenvalues
    assert np.allclose(eig, [1j * w, -1j * w], atol=1e-9)
    # s^2 + 2 alpha s + beta^2 = 0, the Baumgarte corrector's error dynamics (eq. 2)
    root = math.sqrt(alpha ** 2 - beta ** 2)
    assert np.allclose(sorted(lin.corrector_eigenvalues.real), [-alpha - root, -alpha + root],
                       atol=1e-9)
    assert lin.coupling < 1e-9


def test_pendulum_bottom_equilibrium_in_independent_coordinates():
    lin = bgc.linearize(PENDULUM, scene="swing", at="steady", params={"beta": 4.0})
    _pendulum_checks(lin)
    assert dict(lin.point)["y"] == pytest.approx(1.0, abs=1e-12)  # y points down
    assert lin.states == ("mx.p", "x")  # y and my.p follow from the rod


def test_pendulum_balanced_at_the_top():
    """Started near the top, the nearest equilibrium is the inverted one: +-sqrt(g/l), real."""
    lin = bgc.linearize(PENDULUM, scene="swing", at="steady", params={"theta0": 3.0})
    assert dict(lin.point)["y"] == pytest.approx(-1.0, abs=1e-12)
    w = math.sqrt(9.81)
    assert np.allclose(lin.eigenvalues, [-w, w], atol=1e-9)
    assert np.allclose(lin.corrector_eigenvalues, [-5, -5], atol=1e-6)  # a double root


def test_pendulum_started_at_the_bottom_other_parameters(tmp_path):
    out = tmp_path / "p.json"
    result = cli("linearize", PENDULUM, "--scene", "swing", "-p", "theta0=0", "-p", "l=2",
                 "-p", "beta=3", "-o", str(out))
    assert result.exit_code == 0, result.output
    assert "corrector modes" in result.output
    d = json.loads(out.read_text())
    w = math.sqrt(9.81 / 2)
    assert np.allclose(sorted(z[1] for z in d["eigenvalues"]), [-w, w], atol=1e-9)
    assert np.allclose([z[0] for z in d["eigenvalues"]], 0, atol=1e-9)
    assert np.allclose(sorted(z[0] for z in d["corrector_eigenvalues"]), [-9, -1], atol=1e-9)


def _module(model, scene, outputs):
    (text,) = bgc.compile(model, target="python", scene=scene, outputs=list(outputs)).values()
    return processes.load_python_module(text)


def _central(f, x, h):
    cols = []
    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = h * max(1.0, abs(x[j]))
        cols.append((f(x + e) - f(x - e)) / (2 * e[j]))
    return np.array(cols).T


def test_agrees_with_finite_differences_of_the_generated_code():
    """Away from an equilibrium (t = 1.3 of the swing) with an input: A, B, C, D against
    central differences of the generated module's rhs and outputs, through lin's basis."""
    lin = bgc.linearize(PENDULUM, scene="swing", at="t=1.3", inputs=["g"])
    mod = _module(PENDULUM, "swing", lin.outputs)
    assert list(mod.STATES) == list(lin.full_states)
    x = np.array([v for _, v in lin.point])
    names = list(mod.PARAMETERS)
    p = np.array(list(mod.PARAMETERS.values()))
    ig = names.index("g")
    h = 1e-6
    J = _central(lambda y: mod.rhs(lin.t, y, p), x, h)
    Jy = _central(lambda y: mod.outputs(lin.t, y, p), x, h)
    dp = np.zeros(len(p))
    dp[ig] = h * p[ig]
    Bf = (mod.rhs(lin.t, x, p + dp) - mod.rhs(lin.t, x, p - dp)) / (2 * dp[ig])
    Df = (mod.outputs(lin.t, x, p + dp) - mod.outputs(lin.t, x, p - dp)) / (2 * dp[ig])
    ind = [list(lin.full_states).index(s) for s in lin.states]
    N = lin.basis
    assert np.allclose(lin.A, J[ind] @ N, rtol=1e-6, atol=1e-6)
    assert np.allclose(lin.C, Jy @ N, rtol=1e-6, atol=1e-6)
    assert np.allclose(lin.B[:, 0], Bf[ind], rtol=1e-6, atol=1e-6)
    assert np.allclose(lin.D[:, 0], Df, rtol=1e-6, atol=1e-6)
    # N spans the constraints' tangent space: the independent states are its identity rows
    assert np.array_equal(N[ind], np.eye(len(ind)))


def test_python_control_frequency_response(msd):
    control = pytest.importorskip("control")
    lin = bgc.linearize(msd, scene="motion", inputs=["F"])
    sys_ = lin.state_space()
    assert isinstance(sys_, control.StateSpace)
    w = np.logspace(-1, 2, 30)
    H = lin.frequency_response(w)
    resp = sys_.frequency_response(w)
    Hc = np.asarray(resp.magnitude) * np.exp(1j * np.asarray(resp.phase))
    assert np.allclose(H, Hc.reshape(H.shape), rtol=1e-10)
    s = 1j * w  # closed form: q/F = 1/(m s^2 + c s + k), v/F = s q/F
    assert np.allclose(H[0, 0], 1 / (M * s ** 2 + CD * s + K), rtol=1e-12)
    assert np.allclose(H[1, 0], s / (M * s ** 2 + CD * s + K), rtol=1e-12)


def test_bode_plot(msd, tmp_path):
    pytest.importorskip("matplotlib")
    png = tmp_path / "bode.png"
    result = cli("linearize", msd, "--scene", "motion", "--inputs", "F", "--bode", str(png))
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args, status, text", [
    (["--outputs", "nope"], 2, "--outputs:1:1: error: unknown output 'nope'"),
    (["--at", "t=soon"], 2, "--at"),
    (["--at", "later"], 2, "--at"),
    (["--at", "t=-1"], 2, "before the scene's start"),
    (["-o", "out.txt"], 2, ".json, .npz, .csv"),
    (["--inputs", "u"], 2, "unknown input 'u'"),
    (["--bode", "b.png"], 2, "--bode needs an input"),
    (["-p", "nope=1"], 2, "nope"),
])
def test_usage_errors(msd, tmp_path, monkeypatch, args, status, text):
    monkeypatch.chdir(tmp_path)
    result = cli("linearize", msd, "--scene", "motion", *args)
    assert result.exit_code == status, result.output
    assert text in result.output
    assert not (tmp_path / "out.txt").exists() and not (tmp_path / "b.png").exists()


def test_model_error_is_located(tmp_path):
    bad = tmp_path / "bad.bg"
    bad.write_text("model bad\nx : Q(1)\n", encoding="utf-8")
    out = tmp_path / "l.json"
    result = cli("linearize", str(bad), "-o", str(out))
    assert result.exit_code == 1
    assert f"{bad}:2:" in result.output and "error:" in result.output
    assert not out.exists()


def test_an_input_reaches_the_parameters_computed_from_it(tmp_path):
    """c = 2 zeta sqrt(k m): with zeta the input, B = d(dp/dt)/d zeta = -2 sqrt(k m) p/m."""
    path = tmp_path / "damped.bg"
    path.write_text("model damped; parameter m = 2.0; parameter k = 50.0; parameter zeta = 0.1\n"
                    "parameter c = 2*zeta*sqrt(k*m); v : 1; mass : I(m) init p = 0.4\n"
                    "spring : C(1/k); damper : R(c); v -> mass; v -> spring; v -> damper\n",
                    encoding="utf-8")
    lin = bgc.linearize(str(path), inputs=["zeta"], outputs=["v.f"])
    ip = lin.states.index("mass.p")
    expected = np.zeros(2)
    expected[ip] = -2 * math.sqrt(K * M) * 0.4 / M
    assert np.allclose(lin.B[:, 0], expected, rtol=1e-14, atol=0)
    assert np.array_equal(lin.D, [[0.0]])
    # overridden, c no longer follows zeta
    assert not np.any(bgc.linearize(str(path), inputs=["zeta"], params={"c": 1.0}).B)


# ---------------------------------------------------------------- far in time, time sources

FORCED = """model forced "a mass under a constant force, and a capacitor charged through R"
parameter m = 2.0
parameter F = 3.0
parameter V = 5.0
v : 1
mass : I(m) init p = 0.5
push : Se(F)
push -> v
v -> mass
signal x = integral(v.f, init = 1.0)
src : Se(V)
j : 1
r : R(1)
c : C(1)
src -> j
j -> r
j -> c
scene run { outputs x, c.q; time 0 .. 10 every 0.01 }
"""


def write_model(tmp_path, name, text) -> str:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def test_far_in_time_a_linear_model_is_exact(tmp_path):
    """At t = 1e6 (1e8 rows of the scene's grid, which a run to one time does not write):
    p = p0 + F t, x = x0 + p0 t/m + F t^2/(2m) (a polynomial, which the solver's steps
    follow to the rounding of their 3e5 steps, which the capacitor's stability bounds), the
    capacitor charged to V; A is the closed form's."""
    model = write_model(tmp_path, "forced.bg", FORCED)
    out = tmp_path / "far.json"
    result = cli("linearize", model, "--scene", "run", "--at", "t=1e6", "-o", str(out))
    assert result.exit_code == 0, result.output
    d = json.loads(out.read_text())
    T, m, F, p0, x0 = 1e6, 2.0, 3.0, 0.5, 1.0
    at = d["at"]
    assert at["t"] == T
    assert at["mass.p"] == pytest.approx(p0 + F * T, rel=1e-12)
    assert at["x"] == pytest.approx(x0 + p0 * T / m + F * T ** 2 / (2 * m), rel=1e-12)
    assert at["c.q"] == pytest.approx(5.0, rel=1e-5)  # the scene's tolerances
    A = np.zeros((3, 3))
    ip, ix, iq = (d["states"].index(s) for s in ("mass.p", "x", "c.q"))
    A[ix, ip], A[iq, iq] = 1 / m, -1.0
    assert np.array_equal(d["A"], A)


@pytest.mark.parametrize("scene, at, text", [
    ("", "t=1e10", "solver dopri5 is explicit, its steps bounded by its stability "
                   "(|lambda| = 1 at the start, h |lambda| <= 3.3): reaching t = 1e+10 takes "
                   "at least 3.03e+09 of them, more than the 10000000"),
    ("solver rk4; ", "t=1e10", "the scene's steps are fixed (h = 0.01): reaching t = 1e+10 "
                               "takes 1e+12 of them, more than the 10000000"),
    ("", "t=1e200", "at least 3.03e+199"),
    ("", "t=1e308", "at least 3.03e+307"),
    ("solver rk4; ", "t=1.7e308", "the scene's steps are fixed (h = 0.01): reaching t = "
                                  "1.7e+308 takes more of them than a double counts"),
])
def test_a_time_too_far_is_refused_before_the_run(tmp_path, monkeypatch, scene, at, text):
    """The steps to the time, known before the run (fixed steps; an explicit solver's
    stability bound from the Jacobian at the start), beyond the budget: a run that cannot be
    done, exit 1 with a plain error that says why (as simulate's spent step budget; it was a
    usage error, exit 2, and 1.7e308 fixed steps an OverflowError), and no run started (the
    run to 1e10 on the scene's grid was a traceback)."""
    model = write_model(tmp_path, "rc.bg", FORCED.replace("scene run { ", "scene run { "
                                                          + scene))
    monkeypatch.setattr(runner, "run", lambda *a, **k: pytest.fail("the run started"))
    result = cli("linearize", model, "--scene", "run", "--at", at)
    assert result.exit_code == 1 and text in result.stderr, result.output
    assert result.stderr.startswith("bgc: error: --at t=") and "Usage:" not in result.stderr


def test_the_step_budget_of_a_run_to_one_time(tmp_path):
    """--max-steps bounds the run to --at: spent, exit 1 and where."""
    model = write_model(tmp_path, "forced.bg", FORCED)
    # (the stability bound is 91 steps, the run takes 116)
    result = cli("linearize", model, "--scene", "run", "--at", "t=300", "--max-steps", "100")
    assert result.exit_code == 1
    assert "the run to t = 300 failed: at t = " in result.output
    assert "step budget spent: 100 steps" in result.output
    lin = bgc.linearize(model, scene="run", at=300, max_steps=0)
    assert dict(lin.point)["c.q"] == pytest.approx(5.0, rel=1e-5)


SWITCHED = """model switched "a lag whose rate doubles at t = 1, and triples once x passes 0.5"
discrete a = 1
signal x = integral(-a*(1 + step(1))*x + 2, init = 0)
when x > 0.5 { a = 3 }
scene run { outputs x; time 0 .. 5 every 0.5 }
"""


def test_the_discrete_values_at_the_point_are_the_runs():
    """A reads the time source and the discrete variable as the run holds them at the
    point: -1 at the start, -3 once x passed 0.5 (at t1 = ln(4/3), x = 2 (1 - e^-t) before),
    -6 after t = 1; x at t = 0.8 from the closed form."""
    source = Source("switched.bg", SWITCHED)
    assert bgc.linearize(source, scene="run").A.tolist() == [[-1.0]]
    t1 = math.log(4 / 3)
    lin = bgc.linearize(source, scene="run", at="t=0.8")
    assert lin.A.tolist() == [[-3.0]]
    x = 2 / 3 + (0.5 - 2 / 3) * math.exp(-3 * (0.8 - t1))
    assert dict(lin.point)["x"] == pytest.approx(x, rel=1e-5)
    assert bgc.linearize(source, scene="run", at="t=2").A.tolist() == [[-6.0]]
