"""bgc periodic (shooting on the period map with the exact monodromy matrix) and the
sensitivities through time events, against closed forms, matrix exponentials and finite
differences computed here."""
import json
import math

import numpy as np
import pytest
from scipy.linalg import expm

import bgc
from bgc.analysis.periodic import NoOrbit, common_period
from conftest import ROOT, have_cc, run_bgc

MOTOR = ROOT / "tests" / "models" / "pwm_motor.bg"
pytestmark = pytest.mark.skipif(not have_cc(), reason="no C compiler")

RL = """model rl_pwm "An RL load driven by a PWM voltage"
parameter V = 10
parameter Rl = 2
parameter Ll = 0.01
parameter T = 0.001
parameter d = 0.3
src : Se(V*square(T, d))
loop : 1
r : R(Rl)
l : I(Ll)
src -> loop
loop -> r
loop -> l
scene run {
  outputs l.f
  time 0 .. 0.01 every 0.0001
  solver dopri5(rtol = 1e-12, atol = 1e-14)
}
"""


@pytest.fixture(scope="module")
def rl(tmp_path_factory):
    path = tmp_path_factory.mktemp("periodic") / "rl.bg"
    path.write_text(RL)
    return path


def rl_orbit(V=10.0, R=2.0, L=0.01, T=1e-3, d=0.3):
    """The closed form: i rises towards V/R for d T, decays for (1 - d) T; the periodic
    current at the period's start, and the one multiplier exp(-T R / L)."""
    tau = L / R
    a, b = math.exp(-d * T / tau), math.exp(-(1 - d) * T / tau)
    i0 = V / R * (1 - a) * b / (1 - a * b)
    return i0, math.exp(-T / tau)


def test_a_pwm_driven_rl_circuit_matches_its_closed_form_periodic_solution(rl):
    orbit = bgc.periodic(rl, "run")
    i0, mu = rl_orbit()
    assert orbit.period == pytest.approx(1e-3, rel=1e-15)
    assert orbit.states == ("l.p",)
    assert orbit.x0[0] / 0.01 == pytest.approx(i0, rel=1e-10)
    assert orbit.multipliers[0].real == pytest.approx(mu, rel=1e-10)
    assert orbit.multipliers[0].imag == 0 and orbit.stable
    (name, mean, lo, hi, ripple), = orbit.figures
    # the mean of a linear circuit's periodic current is its averaged circuit's, V d / R
    # (the trapezoidal rule over 200 rows: exponential arcs, error (T/200)^2 / 12 i'')
    assert name == "l.f" and mean == pytest.approx(10 * 0.3 / 2, rel=1e-6)
    assert lo == pytest.approx(i0, rel=1e-10)
    tau = 0.005
    peak = 5 + (i0 - 5) * math.exp(-0.3e-3 / tau)  # the current at the end of the on-time
    assert hi == pytest.approx(peak, rel=1e-10) and ripple == pytest.approx(peak - i0, rel=1e-8)
    # one period of rows, the closed form at each
    t = orbit.t
    assert t[0] == 0 and t[-1] == pytest.approx(1e-3, rel=1e-14) and len(t) == 201
    on = t <= 0.3e-3
    exact = np.where(on, 5 + (i0 - 5) * np.exp(-t / tau),
                     peak * np.exp(-(t - 0.3e-3) / tau))
    assert np.max(np.abs(orbit.y[:, 0] - exact)) < 1e-10 * 5


def _motor_matrices(kt=0.8, Ra=2.0, La=0.5, Jr=0.05, br=0.1):
    """x = (ind.p, rotor.p): x' = A x + b_u u + c, u the supply voltage."""
    A = np.array([[-Ra / La, -kt / Jr], [kt / La, -br / Jr]])
    return A, np.array([1.0, 0.0]), np.array([0.0, -0.5])


def _affine_flow(A, g, h):
    """The map x -> exp(A h) x + int_0^h exp(A s) ds g, as the 3x3 exponential's blocks."""
    E = np.zeros((3, 3))
    E[:2, :2], E[:2, 2] = A, g
    F = expm(E * h)
    return F[:2, :2], F[:2, 2]


def test_a_pwm_motor_orbit_matches_matrix_exponentials_and_its_mean_the_averaged_model():
    orbit = bgc.periodic(MOTOR, "run")
    A, bu, c = _motor_matrices()
    T, d, V = 1e-3, 0.7, 12.0
    P_on, q_on = _affine_flow(A, bu * V + c, d * T)
    P_off, q_off = _affine_flow(A, c, (1 - d) * T)
    M = P_off @ P_on
    x0 = np.linalg.solve(np.eye(2) - M, P_off @ q_on + q_off)
    assert orbit.states == ("ind.p", "rotor.p", "angle")
    np.testing.assert_allclose(orbit.x0[:2], x0, rtol=1e-10)
    np.testing.assert_allclose(orbit.monodromy[:2, :2], M, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers),
                               np.sort_complex(np.linalg.eigvals(M)), rtol=1e-9)
    # the angle drifts: nothing reads it; it advances by the mean speed times the period
    kt, Ra, br, tau = 0.8, 2.0, 0.1, 0.5
    w_mean = (kt * V * d - Ra * tau) / (kt ** 2 + Ra * br)  # the averaged motor's equilibrium
    i_mean = (br * w_mean + tau) / kt
    (name, advance), = orbit.drift
    assert name == "angle" and advance == pytest.approx(w_mean * T, rel=1e-9)
    figures = {f[0]: f[1:] for f in orbit.figures}
    assert figures["rotor.f"][0] == pytest.approx(w_mean, rel=1e-9)
    assert figures["ind.f"][0] == pytest.approx(i_mean, rel=1e-9)


def test_the_command_writes_one_period_its_figures_and_the_same_bytes_in_every_backend(
        rl, tmp_path):
    texts = {}
    for backend in ("c", "python", "vm"):
        out, js = tmp_path / f"{backend}.csv", tmp_path / f"{backend}.json"
        r = run_bgc("periodic", str(rl), "--scene", "run", "--backend", backend, "-o", str(out),
                    "--json", str(js))
        assert r.returncode == 0, r.stderr
        texts[backend] = out.read_bytes()
        assert "Floquet multipliers: 0.818731" in r.stdout
        assert "l.f" in r.stdout and "stable" in r.stdout
    assert texts["c"] == texts["python"] == texts["vm"]
    rows = texts["c"].decode().splitlines()
    assert rows[0] == "t,l.f" and len(rows) == 202
    doc = json.loads(js.read_text())
    i0, mu = rl_orbit()
    assert doc["x0"]["l.p"] / 0.01 == pytest.approx(i0, rel=1e-10)
    assert doc["multipliers"][0][0] == pytest.approx(mu, rel=1e-10)
    assert doc["outputs"]["l.f"]["mean"] == pytest.approx(1.5, rel=1e-6) and doc["stable"]


@pytest.mark.parametrize("change, message", [
    ("src : Se(V*square(T, d)*step(0.002))", "not periodic: 'step(0.002)"),
    ("src : Se(V*square(T, d) + sin(2000*t))", "incommensurate"),
    ("src : Se(V*exp(-t))", "a law reads t other than through a periodic source"),
    ("src : Se(V)", "no period: the model has no periodic time source"),
])
def test_a_model_that_is_not_periodic_is_refused_saying_why(tmp_path, change, message):
    path = tmp_path / "m.bg"
    path.write_text(RL.replace("src : Se(V*square(T, d))", change))
    r = run_bgc("periodic", str(path), "--scene", "run")
    assert r.returncode == 1 and message in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_an_unstable_orbit_is_refused_with_its_multipliers(tmp_path):
    path = tmp_path / "m.bg"
    path.write_text(RL.replace("parameter Rl = 2", "parameter Rl = -2"))
    r = run_bgc("periodic", str(path), "--scene", "run")
    mu = math.exp(1e-3 * 2 / 0.01)
    assert r.returncode == 1 and "unstable" in r.stderr and f"{mu:.6g}" in r.stderr, r.stderr


def test_a_period_that_is_not_a_multiple_of_the_sources_is_refused_and_a_multiple_taken(rl):
    r = run_bgc("periodic", str(rl), "--scene", "run", "--period", "0.0015")
    assert r.returncode == 1 and "not a multiple" in r.stderr
    orbit = bgc.periodic(rl, "run", period=2e-3)
    i0, mu = rl_orbit()
    assert orbit.x0[0] / 0.01 == pytest.approx(i0, rel=1e-10)
    assert orbit.multipliers[0].real == pytest.approx(mu ** 2, rel=1e-10)


def test_a_model_whose_events_the_sensitivities_cannot_pass_is_refused_located(tmp_path):
    """A discrete value sampled from the state (its own sensitivity is not carried)."""
    path = tmp_path / "m.bg"
    path.write_text(RL.replace("loop -> l", "loop -> l\ndiscrete held = 0\n"
                                            "when l.f > 1 { held = l.f }\n"
                                            "w : Se(held)\nw -> loop"))
    r = run_bgc("periodic", str(path), "--scene", "run")
    assert r.returncode == 1 and "m.bg:" in r.stderr and "'held'" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_common_period_is_the_least_common_multiple():
    assert common_period([(2e-3, "a"), (3e-3, "b")]) == pytest.approx(6e-3, rel=1e-15)
    assert common_period([(0.02, "a"), (0.02 / 3, "b")]) == pytest.approx(0.02, rel=1e-12)
    with pytest.raises(NoOrbit, match="incommensurate"):
        common_period([(1.0, "a"), (math.sqrt(2), "b")])


def test_sensitivities_pass_the_time_events_of_a_pwm_drive_as_finite_differences_say():
    """d(speed)/d(kt) and d(speed)/d(Ra) through 10 PWM periods (20 time events), against
    central differences of runs at kt +- h (the event times do not depend on kt)."""
    s = bgc.sensitivities(MOTOR, ["kt", "Ra"], "run")
    k = s.outputs.index("rotor.f")
    for j, (name, value) in enumerate((("kt", 0.8), ("Ra", 2.0))):
        h = 1e-5 * value
        _, up, names = bgc.simulate(MOTOR, "run", params={name: value + h})
        _, down, _ = bgc.simulate(MOTOR, "run", params={name: value - h})
        fd = (up[:, names.index("rotor.f")] - down[:, names.index("rotor.f")]) / (2 * h)
        np.testing.assert_allclose(s.dy[:, k, j], fd, rtol=1e-6, atol=1e-9)


def test_sensitivities_to_the_pwm_period_and_duty_as_finite_differences_say():
    """d(speed)/d(Tp) and d(speed)/d(d): the edges move with them (S jumps by
    (f- - f+) dtau/dp at each), against central differences of runs at p +- h (at a
    tolerance tighter than the scene's, the differences' noise its error over 2h), away
    from the rows that fall on an edge: there the speed is one-sided in p (an edge moved
    past the row or not), and the differences' error is O(h)."""
    tight = {"rtol": 1e-12, "atol": 1e-14}
    s = bgc.sensitivities(MOTOR, ["Tp", "d"], "run", **tight)
    k = s.outputs.index("rotor.f")
    phase = (s.t / 1e-3) % 1.0
    keep = np.minimum(np.abs(phase - 0.7), np.minimum(phase, 1.0 - phase)) > 1e-6
    assert 70 < np.sum(keep) < len(s.t)
    for j, (name, value) in enumerate((("Tp", 1e-3), ("d", 0.7))):
        h = 1e-4 * value
        _, up, names = bgc.simulate(MOTOR, "run", params={name: value + h}, **tight)
        _, down, _ = bgc.simulate(MOTOR, "run", params={name: value - h}, **tight)
        fd = (up[:, names.index("rotor.f")] - down[:, names.index("rotor.f")]) / (2 * h)
        error = np.abs(s.dy[:, k, j] - fd)[keep]
        assert np.max(error) <= 1e-6 * np.max(np.abs(fd)), name


def test_fit_recovers_a_pwm_motor_s_torque_constant_through_its_time_events(tmp_path):
    """Data made here from the exact piecewise-affine flow (matrix exponentials of the on and
    off phases, sampled every 10 periods) at kt = 0.85, with noise; bgc fits kt from 0.8
    through the 1 000 PWM edges of the run, and its 95 % interval covers the truth."""
    from bgc.analysis.estimate import fit
    kt, T, d, V, La, Jr = 0.85, 1e-3, 0.7, 12.0, 0.5, 0.05
    A, bu, c = _motor_matrices(kt=kt)
    P_on, q_on = _affine_flow(A, bu * V + c, d * T)
    P_off, q_off = _affine_flow(A, c, (1 - d) * T)
    M, q = P_off @ P_on, P_off @ q_on + q_off
    x, rows = np.zeros(2), []
    noise = np.random.default_rng(3).standard_normal((51, 2)) * 0.005
    for k in range(51):
        rows.append(f"{k * 0.01!r},{float(x[0] / La + noise[k, 0])!r},"
                    f"{float(x[1] / Jr + noise[k, 1])!r}")
        for _ in range(10):
            x = M @ x + q
    data = tmp_path / "pwm.csv"
    data.write_text("t,ind.f,rotor.f\n" + "\n".join(rows) + "\n")
    result = fit(MOTOR, data, ["kt"], scene="run")
    assert result.converged
    (estimate,), (lo,), (hi,) = result.estimates, result.lower, result.upper
    assert lo < kt < hi and hi - lo < 0.01
    assert result.residual_sd == pytest.approx(0.005, rel=0.3)


BUCK = ROOT / "models" / "buck.bg"


def _buck_period_map(R, V=12.0, L=1e-4, C=1e-5, f=1e5, duty=0.5):
    """The buck converter's exact period map on (coil current, capacitor voltage): matrix
    exponentials of the closed switch's and the freewheeling diode's linear circuits, the
    diode blocking where the current reaches zero (brentq on the exact solution), as in
    tests/test_switching.py."""
    from scipy.optimize import brentq
    T, load = 1 / f, -1 / (R * C)
    A = np.array([[0, -1 / L], [1 / C, load]])
    modes = {"on": (A, [V / L, 0]), "free": (A, [0, 0]),
             "dcm": (np.array([[0, 0], [0, load]]), [0, 0])}

    def flow(mode, x, h):
        M = np.zeros((3, 3))
        M[:2, :2], M[:2, 2] = modes[mode]
        E = expm(M * h)
        return E[:2, :2] @ x + E[:2, 2]

    def period(x):
        x, rest = flow("on", x, duty * T), (1 - duty) * T
        if flow("free", x, rest)[0] >= 0:
            return flow("free", x, rest)
        zero = brentq(lambda s: flow("free", x, s)[0], 0, rest, xtol=1e-18, rtol=1e-15)
        x = flow("free", x, zero)
        return flow("dcm", np.array([0.0, x[1]]), rest - zero)
    return period, expm(A * T)


@pytest.mark.parametrize("R, dcm", [(5.0, False), (50.0, True)])
def test_the_buck_converter_s_orbit_is_the_fixed_point_of_its_exact_period_map(R, dcm):
    """bgc periodic of models/buck.bg as drawn (an ideal switch, a freewheeling diode), in
    continuous and in discontinuous conduction: its orbit is the fixed point of the exact
    period map (iterated here to 1e-15) within 1e-10; continuous, the multipliers are the
    eigenvalues of exp(A T) (one linear circuit on both sides of the switch); discontinuous,
    the current starts each period at zero (a multiplier 0) and the other is the map's
    derivative along the voltage (central differences of the exact map).  The monodromy
    matrix goes through the diode's blocking, a state event (issue 40)."""
    period, flow = _buck_period_map(R)
    x = np.zeros(2)
    for _ in range(5000):
        x, before = period(x), x
        if np.max(np.abs(x - before)) <= 1e-15 * np.max(np.abs(x)):
            break
    orbit = bgc.periodic(BUCK, "run", params={"R": R})
    assert orbit.states == ("l.p", "c.q")
    got = np.array(orbit.x0) / np.array([1e-4, 1e-5])
    assert np.max(np.abs(got - x)) <= 1e-10 * np.max(np.abs(x)), (got, x)
    mu = sorted(orbit.multipliers, key=lambda m: (abs(m), m.imag))
    if not dcm:
        want = sorted(np.linalg.eigvals(flow), key=lambda m: (abs(m), m.imag))
        assert np.max(np.abs(np.array(mu) - np.array(want))) < 1e-9, (mu, want)
    else:
        assert x[0] == 0.0 and abs(mu[0]) < 1e-9
        h = 1e-6 * x[1]
        slope = (period(x + [0, h])[1] - period(x - [0, h])[1]) / (2 * h)
        assert abs(mu[1] - slope) < 1e-6, (mu, slope)


@pytest.mark.parametrize("backend", ["c", "python"])
def test_the_newton_runs_session_gives_a_separate_run_s_numbers_bit_for_bit(rl, backend):
    """bgc.execute.runner.Session (the program's batch mode read from stdin, one process for
    every Newton run): each run's final values are those of a run of its own."""
    if backend == "c" and not have_cc():
        pytest.skip("no C compiler")
    from bgc import api
    from bgc.execute import runner
    compiled = bgc.build(str(rl), "run", outputs="l.f")
    prepared = runner.prepare(compiled, backend, in_process=backend == "python")
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names, {}, t_end=2e-3, dt=1e-3)
    with runner.Session(prepared, settings, ["final:l.f", "max:l.f"]) as session:
        rows = [session.run({"Rl": R}) for R in (2.0, 3.5, 2.0)]
        bad = session.run({"nope": 1.0})
    for R, row in zip((2.0, 3.5, 2.0), rows):
        alone = runner.settings_for(compiled.program.scene, names, {"Rl": R}, t_end=2e-3, dt=1e-3)
        _, Y = api.arrays(runner.run(prepared, alone))
        assert row["status"] == "ok" and row["final:l.f"] == float(Y[-1, 0])
        assert row["max:l.f"] == float(np.max(Y[:, 0]))
    assert rows[0] == {**rows[2], "cpu": rows[0]["cpu"], "run": rows[0]["run"]}
    assert bad["status"] == "invalid" and "nope" in bad["message"]


def test_the_newton_runs_weigh_the_states_alone_in_every_backend_to_the_same_bytes():
    """bgc periodic's Newton runs leave the sensitivities out of the step-size control
    (--error-states, CVODES's errconS = false): a period of the buck with its monodromy
    matrix takes the steps of the states' control, fewer than with the sensitivities
    weighed too, and C, Python and the interpreter write the same bytes.  The matrix
    the orbit reports comes from a run that weighs every state: its multipliers are those
    of the exact period map (test above); the Newton runs' matrix is within its accuracy."""
    from bgc.analysis import periodic
    from bgc.execute import runner
    shooting = periodic.build(BUCK, "run")
    program = shooting.compiled.program
    names = [p.name for p in program.params]
    n = len(shooting.states)
    texts, steps = {}, {}
    for backend in ("c", "python", "vm"):
        prepared = runner.prepare(shooting.compiled, backend)
        for weighed in (n, None):
            settings = runner.settings_for(program.scene, names, {"R": 50.0}, t_end=1e-5,
                                           dt=1e-6, error_states=weighed)
            done = runner.run(prepared, settings, stats=True)
            assert done.status == 0, done.stderr
            texts[backend, weighed] = done.csv
            steps[backend, weighed] = int(done.stats["steps"]) + int(done.stats["rejected"])
    for weighed in (n, None):
        assert texts["c", weighed] == texts["python", weighed] == texts["vm", weighed]
        assert steps["c", weighed] == steps["python", weighed] == steps["vm", weighed]
    assert steps["c", n] < steps["c", None]
    orbit = bgc.periodic(BUCK, "run", params={"R": 5.0})
    T = orbit.period
    session = periodic.open_session(shooting, {"R": 5.0}, T)
    try:
        found = periodic.newton(shooting, {"R": 5.0}, T, session)
    finally:
        session.close()
    assert np.array_equal(found.x, orbit.x0) and found.runs == found.iterations + 1
    assert np.max(np.abs(found.M - orbit.monodromy)) < 1e-6 * np.max(np.abs(orbit.monodromy))
