"""Forward sensitivities (bgc.codegen.sensitivity, bgc.analysis.estimate.sensitivities) and `bgc
fit`.

The sensitivities are checked against central finite differences of the model's own solution
with the parameter perturbed (`-p`), computed here with the classical Runge-Kutta method on a
fine fixed step (no step-size control whose choices would differ between the perturbed runs):
on a linear model (the DC motor), a constrained one (the paper's pendulum: its length enters
the initial state and the constraint) and one with a Newton block (the diode, whose augmented
Jacobian is the block-diagonal approximation), each with an explicit and a stiff solver, the
C program's and the Python module's CSV compared byte for byte.  The fits recover parameter
values chosen here; Student's t quantile is checked against SciPy's."""
import io
import json
import math

import numpy as np
import pytest

from bgc import api
from bgc.analysis import estimate
from bgc.execute import runner
from conftest import MODELS, have_cc, run_bgc

needs_cc = pytest.mark.skipif(not have_cc(), reason="no C compiler")


def test_t_quantile_matches_scipy():
    special = pytest.importorskip("scipy.special")  # (stdtrit is scipy.stats.t.ppf)
    for df in (1, 2, 3.5, 7, 30, 998, 1e5):
        for q in (0.5001, 0.6, 0.9, 0.975, 0.995, 0.9999, 0.025, 1e-4):
            ref = special.stdtrit(df, q)
            assert estimate.t_quantile(q, df) == pytest.approx(ref, rel=1e-10, abs=1e-13)
    assert estimate.t_quantile(0.5, 4) == 0.0
    with pytest.raises(ValueError):
        estimate.t_quantile(1.0, 3)


def _finite_differences(model, scene, outputs, params, t_end, h=1e-4):
    """d outputs / d p by central differences of rk4 runs of the plain program (C)."""
    compiled = api.build(model, scene, outputs=outputs)
    program = runner.prepare(compiled, "c")
    names = [p.name for p in compiled.program.params]
    columns = []
    for p in params:
        value = estimate._default(compiled, p, {})
        runs = []
        for sign in (1, -1):
            settings = runner.settings_for(compiled.program.scene, names,
                                           params={p: value * (1 + sign * h)}, solver="rk4",
                                           t_end=t_end, step=t_end / 20000)
            runs.append(api.arrays(runner.run(program, settings))[1])
        columns.append((runs[0] - runs[1]) / (2 * h * value))
    return np.stack(columns, axis=2)  # (times, outputs, params)


CASES = [  # model, scene, outputs, parameters, span, the stiff solver's rtol
    ("dc_motor.bg", "run", "ind.f, rotor.f, angle", ["kt", "Jr"], 0.5, 1e-10),
    ("pendulum.bg", "swing", "x, y, rod.lambda", ["l", "m", "theta0"], 0.5, 1e-10),
    ("diode.bg", "charge", "cap.e, d1.e, d1.f", ["Rs", "Vt"], 0.02, 1e-12),
]


@needs_cc
@pytest.mark.parametrize("model, scene, outputs, params, t_end, stiff_rtol", CASES,
                         ids=[c[0] for c in CASES])
def test_sensitivities_match_finite_differences(model, scene, outputs, params, t_end,
                                                stiff_rtol):
    reference = _finite_differences(MODELS / model, scene, outputs, params, t_end)
    compiled = estimate.build(MODELS / model, params, scene, outputs=outputs)
    program = compiled.program
    m, M = len(params), len(outputs.split(","))
    assert program.outputs[M:M + 2] == (f"d({outputs.split(', ')[0]})/d({params[0]})",
                                        f"d({outputs.split(', ')[1]})/d({params[0]})")
    names = [p.name for p in program.params]
    c_prog = runner.prepare(compiled, "c")
    module = runner.prepare(compiled, "python", in_process=True).module
    # the scale of an output's sensitivities: the largest to any of the parameters
    scale = np.abs(reference).max(axis=(0, 2))[:, None]
    for solver, rtol in (("dopri5", 1e-12), ("radau5", stiff_rtol)):
        settings = runner.settings_for(program.scene, names, solver=solver, rtol=rtol,
                                       atol=rtol * 1e-2, t_end=t_end)
        c_run = runner.run(c_prog, settings)
        assert c_run.status == 0, c_run.stderr
        csv = io.StringIO()
        module.simulate(out=csv, **settings.options(program.scene))
        assert csv.getvalue() == c_run.csv
        t, Y = api.arrays(c_run)
        S = np.moveaxis(Y.reshape(len(t), 1 + m, M)[:, 1:, :], 1, 2)
        error = np.abs(S - reference).max(axis=0) / scale
        assert error.max() < 1e-6, (solver, error)


def test_augmented_jacobian_is_exact_through_a_linear_block():
    """The double pendulum's multipliers are a linear block: the augmented system's Jacobian
    (second derivatives through the block's factors) against central differences of its
    right side at a point off the trajectory."""
    compiled = estimate.build(MODELS / "double_pendulum.bg", ["l1", "m2"], "swing")
    assert any(b.method == "lu" for b in compiled.program.blocks)
    m = runner.prepare(compiled, "python", in_process=True).module
    n = len(compiled.program.states)
    p = m._param_values(m._overrides({}))
    x = np.array(m._initial_state(m._settings(), m._with_constants(p), False))
    x = x + 0.1 * np.random.default_rng(0).standard_normal(n)
    J = np.asarray(m.jacobian(0.3, list(x), p))
    fd = np.zeros((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = h = 1e-6 * max(1.0, abs(x[j]))
        fd[:, j] = (np.array(m._public(m._rhs, 0.3, list(x + e), p, n))
                    - np.array(m._public(m._rhs, 0.3, list(x - e), p, n))) / (2 * h)
    assert np.abs(J[n // 3:, :n // 3]).max() > 1e-3  # (the second derivatives are there)
    assert np.abs(J - fd).max() < 1e-7 * np.abs(fd).max()


def test_sensitivities_api_returns_states_and_outputs():
    """bgc.sensitivities: x and S of the states, y and dy of the outputs; the RLC circuit's
    initial sensitivities are those of its initial values (q(0) = q0: dq/dq0 = 1)."""
    import bgc
    r = bgc.sensitivities(MODELS / "rlc.bg", ["q0", "resistance"], backend="python",
                          t_end=0.01, dt=0.005)
    assert r.params == ("q0", "resistance") and len(r.states) == 2
    assert r.x.shape == (3, 2) and r.S.shape == (3, 2, 2)
    assert r.y.shape[:1] == (3,) and r.dy.shape == r.y.shape + (2,)
    q = next(i for i, s in enumerate(r.states) if s.endswith(".q"))
    assert r.S[0, q, 0] == 1.0 and r.S[0, q, 1] == 0.0


def test_sensitivities_refuse_unknown_parameters_and_the_projection():
    """(Models with events: tests/test_sensitivities_events.py.)"""
    result = run_bgc("simulate", MODELS / "dc_motor.bg", "--sensitivities", "kt,nope")
    assert result.returncode == 2 and "unknown parameter 'nope'" in result.stderr
    result = run_bgc("simulate", MODELS / "pendulum.bg", "--sensitivities", "l",
                     "--project-initial")
    assert result.returncode == 2 and "--project-initial" in result.stderr


TRUE = {"kt": 0.9, "Ra": 2.5, "Jr": 0.04, "br": 0.12}  # the model's own: 0.8, 2, 0.05, 0.1


def _motor_data(path, noise=0.0, seed=0):
    """ind.f and rotor.f of the DC motor at TRUE, 1000 samples, noise of s.d. `noise`."""
    t, Y, _ = api.simulate(MODELS / "dc_motor.bg", "run", backend="c", outputs="ind.f, rotor.f",
                           params=TRUE, t_end=1.998, dt=0.002)
    Y = Y + noise * np.random.default_rng(seed).standard_normal(Y.shape)
    with open(path, "w") as fh:
        fh.write("t,ind.f,rotor.f\n")
        for ti, (a, b) in zip(t, Y):
            fh.write(f"{float(ti)!r},{float(a)!r},{float(b)!r}\n")
    return path


@needs_cc
def test_fit_recovers_parameters_from_noise_free_data(tmp_path):
    data = _motor_data(tmp_path / "motor.csv")
    result = estimate.fit(MODELS / "dc_motor.bg", data, ["kt", "Ra=0.1..10", "Jr=0..", "br"],
                          scene="run")
    assert result.converged
    for name, value in zip(result.names, result.estimates):
        assert value == pytest.approx(TRUE[name], rel=1e-6)
    assert list(result.start) == [0.8, 2.0, 0.05, 0.1]


@needs_cc
def test_fit_on_noisy_data_brackets_the_true_values(tmp_path):
    data = _motor_data(tmp_path / "noisy.csv", noise=0.05, seed=7)
    out = tmp_path / "fit.json"
    result = run_bgc("fit", MODELS / "dc_motor.bg", "-s", "run", "--data", data,
                     "--vary", "kt", "--vary", "Ra=0.1..10", "--vary", "Jr", "--vary", "br",
                     "-o", out)
    assert result.returncode == 0, result.stderr
    assert "95% interval" in result.stdout and "correlation" in result.stdout
    fitted = json.loads(out.read_text())
    assert fitted["converged"] and fitted["residuals"] == 2000
    assert fitted["residual_sd"] == pytest.approx(0.05, rel=0.1)
    for name, p in fitted["parameters"].items():
        lo, hi = p["ci95"]
        assert lo < TRUE[name] < hi, name
        assert p["stderr"] > 0 and hi - lo == pytest.approx(2 * 1.9612 * p["stderr"], rel=1e-3)
    corr = np.array(fitted["correlation"])
    assert np.allclose(np.diag(corr), 1.0) and np.allclose(corr, corr.T)


@pytest.mark.parametrize("rows, args, status, message", [
    ("t,ind.f\n0,1\n0.002,nan\n", ["--vary", "kt"], 2, "bad.csv:3: column ind.f is not finite"),
    ("t,ind.f\n0,1\n", ["--vary", "kt", "--vary", "Ra"], 2, "too few samples"),
    ("t,ind.f,foo\n0,1,2\n0.002,1,2\n", ["--vary", "kt"], 2, "unknown output 'foo'"),
    ("t,ind.f\n0,1\n0.002,1\n0.005,1\n", ["--vary", "kt"], 2, "not on one uniform grid"),
    ("ind.f\n1\n", ["--vary", "kt"], 2, "no column 't'"),
    ("t,ind.f\n0,1\n0.002,1\n0.004,1\n", ["--vary", "nope"], 2, "unknown parameter 'nope'"),
    ("t,ind.f\n0,1\n0.002,1\n0.004,1\n", ["--vary", "kt=3..1"], 2, "bounds 3..1 are empty"),
    ("t,ind.f\n0,1\n0.002,1\n0.004,1\n", ["--vary", "kt", "--vary", "Jr=-1e-300..0"], 1,
     "the run failed at kt=0.8, Jr=0: at t = 0"),
])
def test_fit_errors_are_for_people(tmp_path, rows, args, status, message):
    data = tmp_path / "bad.csv"
    data.write_text(rows)
    result = run_bgc("fit", MODELS / "dc_motor.bg", "-s", "run", "--data", data,
                     "--backend", "python", *args)
    assert result.returncode == status, result.stderr
    assert message in result.stderr and "Traceback" not in result.stderr


def test_levenberg_marquardt_on_a_closed_form():
    """Exponential decay y = a exp(-b t) fitted exactly, from far, b kept in its box."""
    t = np.linspace(0, 2, 50)

    def f(x):
        a, b = x
        e = np.exp(-b * t)
        return a * e - 3 * np.exp(-1.5 * t), np.stack([e, -a * t * e], axis=1), None

    x, r, J, _, iterations, why, converged = estimate.levenberg_marquardt(
        f, [1.0, 0.1], np.array([0.0, 0.0]), np.array([10.0, 1.2]))
    assert converged and x[1] == 1.2 and iterations < 100  # on its bound: 1.5 is outside
    x, *_, converged = estimate.levenberg_marquardt(f, [1.0, 0.1], np.full(2, -math.inf),
                                                    np.full(2, math.inf))
    assert converged and x == pytest.approx([3.0, 1.5], rel=1e-10)
    calls = []

    def fails_once(x):  # the model cannot run at the first trial point: a shorter step
        calls.append(x)
        if len(calls) == 2:
            raise estimate.FitError("no run there")
        return f(x)

    x, *_, converged = estimate.levenberg_marquardt(fails_once, [1.0, 0.1],
                                                    np.full(2, -math.inf), np.full(2, math.inf))
    assert converged and x == pytest.approx([3.0, 1.5], rel=1e-10)
    assert np.abs(calls[2] - calls[0]).max() < np.abs(calls[1] - calls[0]).max()
    started = []

    def runs_only_at_the_start(x):  # every shorter step fails too: the fit's error
        if started:
            raise estimate.FitError("no run there")
        started.append(x)
        return f(x)

    with pytest.raises(estimate.FitError, match="no run there"):
        estimate.levenberg_marquardt(runs_only_at_the_start, [1.0, 0.1], np.full(2, -math.inf),
                                     np.full(2, math.inf))


RC_FIT = """model rc "an RC decay: c.e = q0/C exp(-t/(R C))"
parameter R = 1.5
parameter C = 0.8
parameter q0 = 1.0
c : C(C) init q = q0
r : R(R)
j : 0
j -> c
j -> r
scene run { outputs c.e; time 0 .. 4 every 0.02; solver SOLVER }
"""


def _rc_reference(t, e):
    """The least-squares R, C of the closed form q0/C exp(-t/(R C)) to the data, by SciPy."""
    optimize = pytest.importorskip("scipy.optimize")

    def residuals(x):
        R, C = x
        return np.exp(-t / (R * C)) / C - e

    fitted = optimize.least_squares(residuals, [1.5, 0.8], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return fitted.x


@pytest.mark.parametrize("scene_solver, option", [
    ("euler", ["--solver", "radau5"]),  # (euler's steps of dt: estimates off by a percent)
    ("dopri5(rtol = 1e-2, atol = 1e-14)", ["--rtol", "1e-11"]),
    ("dopri5(rtol = 1e-12, atol = 1e-2)", ["--atol", "1e-12"]),
])
def test_fit_takes_the_solver_and_its_tolerances(tmp_path, scene_solver, option):
    """--solver, --rtol and --atol reach the fit's runs: with them the estimates are the
    closed form's least-squares fit (SciPy's) to the digits the run resolves; with the scene's
    own solver or tolerance alone they are not."""
    model = tmp_path / "rc.bg"
    model.write_text(RC_FIT.replace("SOLVER", scene_solver))
    t = np.round(np.arange(201) * 0.02, 10)
    e = np.exp(-t / (2.0 * 0.5)) / 0.5 + 0.01 * np.random.default_rng(3).standard_normal(t.size)
    data = tmp_path / "rc.csv"
    data.write_text("t,c.e\n" + "".join(f"{float(a)!r},{float(b)!r}\n"
                                         for a, b in zip(t, e)))
    reference = _rc_reference(t, e)

    def fitted(*extra):
        out = tmp_path / "fit.json"
        result = run_bgc("fit", model, "--scene", "run", "--data", data, "--vary", "R",
                         "--vary", "C", "--backend", "python", "-o", out, *extra)
        assert result.returncode == 0, result.stderr
        assert "Traceback" not in result.stderr
        fit = json.loads(out.read_text())
        return np.array([fit["parameters"][n]["estimate"] for n in ("R", "C")])

    assert fitted(*option) == pytest.approx(reference, rel=1e-7)
    assert np.max(np.abs(fitted() / reference - 1)) > 1e-6


def test_fit_takes_the_effects(tmp_path):
    """--effects replaces the scene's: the RC circuit's source left out, the data are its
    decay alone, and the estimates the closed form's least squares (SciPy's)."""
    model = tmp_path / "rc.bg"
    model.write_text(RC_FIT.replace("SOLVER", "dopri5(rtol = 1e-11, atol = 1e-13)")
                     .replace("r : R(R)", "r : R(R)\nsrc : Se(0.3) @drive\nk : 1")
                     .replace("j -> r", "j -> k\nk -> r\nsrc -> k"))
    t = np.round(np.arange(201) * 0.02, 10)
    e = np.exp(-t / (2.0 * 0.5)) / 0.5 + 0.01 * np.random.default_rng(5).standard_normal(t.size)
    data = tmp_path / "rc.csv"
    data.write_text("t,c.e\n" + "".join(f"{float(a)!r},{float(b)!r}\n"
                                         for a, b in zip(t, e)))
    out = tmp_path / "fit.json"
    args = ("fit", model, "--scene", "run", "--data", data, "--vary", "R", "--vary", "C",
            "--backend", "python", "-o", out)
    result = run_bgc(*args, "--effects", "none")
    assert result.returncode == 0, result.stderr
    fit = json.loads(out.read_text())["parameters"]
    assert [fit[n]["estimate"] for n in ("R", "C")] == pytest.approx(_rc_reference(t, e),
                                                                      rel=1e-7)
    assert run_bgc(*args).returncode == 0  # with the source: another fit
    fit = json.loads(out.read_text())["parameters"]
    assert abs(fit["R"]["estimate"] / _rc_reference(t, e)[0] - 1) > 1e-3
