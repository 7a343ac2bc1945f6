"""End-to-end: the paper's pendulum simulated by both backends against SciPy at tight
tolerance (computed here from eq. 9 / eq. 12 typed by hand), the CLI, and run-time failures."""
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import bgc
from bgc.base import toolchain
from bgc.api import Source
from conftest import run_bgc

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = ROOT / "models" / "pendulum.bg"
BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])


def pendulum_reference(t, theta0=0.5, alpha=5.0, beta=5.0, stabilised=True, m=1.0, l=1.0,
                       g=9.81):
    """Eq. (12) (or eq. (9) with alpha = beta = 0) by hand, DOP853 at rtol 1e-13."""
    a, b = (alpha, beta) if stabilised else (0.0, 0.0)

    def f(_, s):
        px, py, x, y = s
        xd, yd = px / m, py / m
        B = y * g + xd**2 + yd**2 + 2 * a * (x * xd + y * yd) + b**2 * (x * x + y * y - l * l) / 2
        return [m * (-x / (x * x + y * y) * B), m * (g - y / (x * x + y * y) * B), xd, yd]

    s0 = [0.0, 0.0, l * np.sin(theta0), l * np.cos(theta0)]
    sol = solve_ivp(f, (t[0], t[-1]), s0, method="DOP853", rtol=1e-13, atol=1e-14, t_eval=t)
    px, py, x, y = sol.y
    xd, yd = px / m, py / m
    B = y * g + xd**2 + yd**2 + 2 * a * (x * xd + y * yd) + b**2 * (x * x + y * y - l * l) / 2
    lam = m / (2 * x * x + 2 * y * y) * B                                   # eq. (8) / (11)
    return x, y, lam


def close(got, ref, rel=1e-6):
    return np.max(np.abs(got - ref)) <= rel * max(1.0, np.max(np.abs(ref)))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("scene", ["swing", "unstabilised"])
def test_pendulum_matches_reference(backend, scene):
    t, Y, names = bgc.simulate(PENDULUM, scene=scene, backend=backend)
    assert names == ["x", "y", "rod.lambda", "rod.residual"]
    assert len(t) == 1001 and t[0] == 0 and t[-1] == 10
    x, y, lam = pendulum_reference(t, stabilised=(scene == "swing"))
    assert close(Y[:, 0], x) and close(Y[:, 1], y) and close(Y[:, 2], lam)
    assert np.max(np.abs(Y[:, 3])) < 1e-8  # the residual Phi = x^2 + y^2 - l^2 stays small


@pytest.mark.parametrize("backend", BACKENDS)
def test_parameter_override_and_solver_options(backend):
    t, Y, _ = bgc.simulate(PENDULUM, scene="swing", backend=backend, t_end=2.0,
                           params={"theta0": 1.0}, rtol=1e-11, atol=1e-13)
    assert t[-1] == 2.0
    x, y, lam = pendulum_reference(t, theta0=1.0)
    assert close(Y[:, 0], x) and close(Y[:, 2], lam)


@pytest.mark.parametrize("backend", BACKENDS)
def test_fixed_step_solvers_converge(backend):
    ref = pendulum_reference(np.linspace(0, 1, 11))[0]
    errs = {}
    for solver in ("euler", "rk4"):
        for step in (1e-3, 5e-4):
            t, Y, _ = bgc.simulate(PENDULUM, scene="swing", backend=backend, t_end=1.0, dt=0.1,
                                   solver=solver, step=step)
            errs[solver, step] = np.max(np.abs(Y[:, 0] - ref))
    assert 1.6 < errs["euler", 1e-3] / errs["euler", 5e-4] < 2.4   # first order
    assert 12 < errs["rk4", 1e-3] / errs["rk4", 5e-4] < 20          # fourth order


def test_backends_agree():
    if "c" not in BACKENDS:
        pytest.skip("no C compiler")
    _, a, _ = bgc.simulate(PENDULUM, scene="swing", backend="c")
    _, b, _ = bgc.simulate(PENDULUM, scene="swing", backend="python")
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def run_cli(*args, cwd=None):
    return run_bgc(*args, cwd=cwd or ROOT)


def test_cli_simulate_to_csv(tmp_path):
    out = tmp_path / "p.csv"
    proc = run_cli("simulate", str(PENDULUM), "--scene", "swing", "--t-end", "1", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "t,x,y,rod.lambda,rod.residual"
    assert len(lines) == 102
    assert lines[1].split(",")[1] == "%.17g" % (np.sin(0.5))  # x(0) = l sin(theta0), exact


def test_cli_equations_and_check():
    eq = run_cli("equations", str(PENDULUM), "--scene", "swing")
    assert eq.returncode == 0 and "rod.lambda =" in eq.stdout
    tex = run_cli("equations", str(PENDULUM), "--format", "latex")
    assert tex.returncode == 0 and "\\frac" in tex.stdout
    chk = run_cli("check", str(PENDULUM))
    assert chk.returncode == 0 and "holonomic" in chk.stdout


def test_cli_unknown_parameter_is_a_usage_error():
    proc = run_cli("simulate", str(PENDULUM), "-p", "nope=1")
    assert proc.returncode == 2 and "unknown parameter 'nope'" in proc.stderr


BLOWUP = "model blow\nsignal z = integral(z^2, init = 1)\nscene s { time 0 .. 2 every 0.1 }\n"


@pytest.mark.parametrize("backend", BACKENDS)
def test_non_finite_value_stops_with_time_and_variable(backend, tmp_path):
    model = tmp_path / "blow.bg"
    model.write_text(BLOWUP)
    out = tmp_path / "blow.csv"
    proc = run_cli("simulate", str(model), "--scene", "s", "--backend", backend, "-o", str(out))
    assert proc.returncode != 0
    assert "'z'" in proc.stderr and "t = " in proc.stderr and "Traceback" not in proc.stderr
    rows = out.read_text().splitlines()
    assert rows[0] == "t,z" and len(rows) >= 10    # z = 1/(1 - t): rows up to t = 0.9 kept
    data = np.array([list(map(float, r.split(","))) for r in rows[1:]])
    before = data[:, 0] < 0.95
    assert before.sum() == 10 and data[-1, 0] <= 1.0
    np.testing.assert_allclose(data[before, 1], 1 / (1 - data[before, 0]), rtol=1e-5)


INCONSISTENT = """model p
parameter l = 1
vx : 1
vy : 1
mx : I(1)
my : I(1) init f = 0.3
tx : MTF(2*x)
ty : MTF(2*y)
rod : 0 constraint holonomic(init = -l^2) corrector pid(5, 5)
signal x = integral(vx.f, init = 0.5)
signal y = integral(vy.f, init = 0.9)
vx -> mx
vy -> my
vx -> tx -> rod
vy -> ty -> rod
scene s { outputs x, y, mx.f, my.f, rod.residual; time 0 .. 1 every 0.5 }
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_project_initial_moves_the_state_onto_the_constraint(backend):
    src = Source("p.bg", INCONSISTENT)
    with pytest.raises(bgc.BgcModelError, match="initial conditions violate constraint 'rod'"):
        bgc.build(src, "s")
    t, Y, names = bgc.simulate(src, scene="s", backend=backend, project_initial=True)
    x, y, vx, vy, res = Y[0]
    assert abs(x * x + y * y - 1) < 1e-9           # position level
    assert abs(x * vx + y * vy) < 1e-9             # velocity level
    # minimum-norm projection of (0.5, 0.9) onto the circle is radial
    assert abs(x / y - 0.5 / 0.9) < 1e-9
