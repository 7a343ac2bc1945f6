"""Forward sensitivities through events (bgc.codegen.sensitivity, "Through events"): the jump
conditions of S = dx/dp at a state event (the bouncing ball's impacts, a reinit), at time
events whose times move with a parameter (a PWM voltage's duty and period) and at a
switched element's mode changes (a stick-slip run).

References, independent of the augmented program: the closed forms of the ball's flights
(its impact times t_k in closed form in h0, g and e, differentiated by SymPy here) and of the
RL circuit's current (a sum of decaying exponentials from the edges), and central finite
differences of runs of the plain program at p +- h at a tight tolerance.  The C program, the
Python module and the interpreter write the same bytes."""
import io
import math

import numpy as np
import pytest
import sympy as sp

from bgc import api
from bgc.analysis import estimate
from bgc.execute import runner

from conftest import ROOT, have_cc, run_bgc
from helpers import ball, pwm_rl

BACKENDS = ["c", "vm", "python"] if have_cc() else ["python"]

BALL = ball("scene drop { time 0 .. 3 every 0.01; outputs x, b.p; "
            "solver dopri5(rtol = 1e-12, atol = 1e-12) }")

PWM = pwm_rl("scene run {\n  time 0 .. 0.0195 every 0.000137; outputs l.p; "
             "solver dopri5(rtol = 1e-12, atol = 1e-14)\n}")


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def _runs(compiled, options):
    """The augmented program's CSV from every backend (asserted equal), as arrays."""
    texts = []
    names = [p.name for p in compiled.program.params]
    for backend in BACKENDS:
        program = runner.prepare(compiled, backend, in_process=backend == "python")
        settings = runner.settings_for(compiled.program.scene, names, **options)
        if backend == "python":
            out = io.StringIO()
            program.module.simulate(out=out, **settings.options(compiled.program.scene))
            texts.append(out.getvalue())
        else:
            result = runner.run(program, settings)
            assert result.status == 0, result.stderr
            texts.append(result.csv)
    assert len(set(texts)) == 1, "the backends' bytes differ"
    rows = texts[0].splitlines()
    head = rows[0].split(",")
    return head, np.array([[float(v) for v in r.split(",")] for r in rows[1:]])


def _column(head, Y, name):
    return Y[:, head.index(name)]


def _finite_differences(path, scene, outputs, params, values, h=1e-5):
    """d outputs / d p by central differences of runs of the plain program (C, or the
    interpreter without a compiler) at p (1 +- h), at the scene's tight tolerance."""
    compiled = api.build(path, scene, outputs=outputs)
    backend = "c" if have_cc() else "python"
    program = runner.prepare(compiled, backend, in_process=backend == "python")
    names = [p.name for p in compiled.program.params]
    out = {}
    for p in params:
        runs = []
        for sign in (1, -1):
            settings = runner.settings_for(compiled.program.scene, names,
                                           params={p: values[p] * (1 + sign * h)})
            t, Y = api.arrays(runner.run(program, settings))
            runs.append(Y)
        out[p] = (runs[0] - runs[1]) / (2 * h * values[p])
    return t, out


# ---------------------------------------------------------------- the bouncing ball


def _ball_closed_form(K=12):
    """Per flight k: (start, end, x(t), p(t)) as SymPy expressions of t, e, g, h0 (m = 1):
    the drop to t1 = sqrt(2 h0 / g), then flights of 2 e^k v1 / g, v1 = g t1."""
    e, g, h0, t = sp.symbols("e g h0 t", positive=True)
    t1 = sp.sqrt(2 * h0 / g)
    v1 = g * t1
    flights = [(sp.Integer(0), t1, h0 - g * t ** 2 / 2, -g * t)]
    start = t1
    for k in range(1, K):
        u = e ** k * v1
        end = start + 2 * u / g
        flights.append((start, end, u * (t - start) - g / 2 * (t - start) ** 2,
                        u - g * (t - start)))
        start = end
    return (e, g, h0, t), flights


BALL_VALUES = {"e": 0.8, "g": 9.81, "h0": 1.0}


def _ball_reference(times, params):
    """d x / d p and d b.p / d p at `times` from the closed form (NaN within 1e-6 of an
    impact, where the rows may stand on either side of it)."""
    (e, g, h0, t), flights = _ball_closed_form()
    at = {e: BALL_VALUES["e"], g: BALL_VALUES["g"], h0: BALL_VALUES["h0"]}
    symbol = {"e": e, "g": g, "h0": h0}
    out = {(q, p): np.full(len(times), np.nan) for q in ("x", "b.p") for p in params}
    for a, b, x, mom in flights:
        a, b = float(a.subs(at)), float(b.subs(at))
        inside = (times > a + 1e-6) & (times < b - 1e-6)
        for q, expr in (("x", x), ("b.p", mom)):
            for p in params:
                d = sp.lambdify(t, sp.diff(expr, symbol[p]).subs(at), "numpy")
                out[q, p][inside] = d(times[inside])
    return out


def test_bouncing_ball_sensitivities_match_the_closed_form(tmp_path):
    """Six impacts in 3 s: d x/d p and d b.p/d p for e, g and h0 through every reinit, the
    impact time's dependence on them included, against the closed form's derivatives."""
    params = ["e", "g", "h0"]
    compiled = estimate.build(_write(tmp_path, "ball.bg", BALL), params, "drop",
                              state_outputs=True)
    head, Y = _runs(compiled, {})
    times = Y[:, 0]
    ref = _ball_reference(times, params)
    assert np.sum(np.isfinite(ref["x", "e"])) > 250  # (rows of six flights)
    for (q, p), want in ref.items():
        got = _column(head, Y, f"d({q})/d({p})")
        keep = np.isfinite(want)
        scale = np.max(np.abs(want[keep]))
        error = np.max(np.abs(got[keep] - want[keep])) / scale
        assert error < 1e-8, (q, p, error)


def test_bouncing_ball_sensitivities_match_finite_differences(tmp_path):
    path = _write(tmp_path, "ball.bg", BALL)
    params = ["e", "g", "h0"]
    compiled = estimate.build(path, params, "drop", outputs="x, b.p")
    head, Y = _runs(compiled, {})
    t, fd = _finite_differences(path, "drop", "x, b.p", params, BALL_VALUES)
    assert np.array_equal(t, Y[:, 0])
    (e, g, h0, _), flights = _ball_closed_form()
    at = {e: 0.8, g: 9.81, h0: 1.0}
    impacts = np.array([float(f[1].subs(at)) for f in flights])
    # away from the impacts (where a perturbed run is on the other side of one)
    keep = np.min(np.abs(t[:, None] - impacts[None, :]), axis=1) > 1e-3
    for p in params:
        for k, q in enumerate(("x", "b.p")):
            got = _column(head, Y, f"d({q})/d({p})")[keep]
            want = fd[p][keep, k]
            error = np.max(np.abs(got - want)) / np.max(np.abs(want))
            assert error < 1e-6, (q, p, error)


# ---------------------------------------------------------------- PWM: edges that move


PWM_VALUES = {"V": 12.0, "R": 2.0, "L": 0.01, "period": 0.001, "duty": 0.3}


def _pwm_reference(times):
    """d(l.p)/d(duty) and d(l.p)/d(period), l.p = L i: between edges S' = -(R/L) S, and at
    an edge at tau S jumps by (f- - f+) dtau/dp, f- - f+ = -V (rising) or +V (falling)
    (l.p' = V u - R i); the edges are k T (dtau/dT = k) and (k + D) T (dtau/dD = T, dtau/dT
    = k + D)."""
    V, R, L, T, D = (PWM_VALUES[k] for k in ("V", "R", "L", "period", "duty"))
    a = R / L
    d_duty, d_period = np.zeros(len(times)), np.zeros(len(times))
    for k in range(int(times[-1] / T) + 2):
        rise, fall = k * T, (k + D) * T
        past = times > fall
        d_duty[past] += V * T * np.exp(-a * (times[past] - fall))
        d_period[past] += V * (k + D) * np.exp(-a * (times[past] - fall))
        past = times > rise
        d_period[past] -= V * k * np.exp(-a * (times[past] - rise))
    return d_duty, d_period


def test_pwm_sensitivities_to_duty_and_period_match_the_closed_form(tmp_path):
    path = _write(tmp_path, "pwm.bg", PWM)
    compiled = estimate.build(path, ["duty", "period", "R"], "run")
    head, Y = _runs(compiled, {})
    d_duty, d_period = _pwm_reference(Y[:, 0])
    for name, want in (("duty", d_duty), ("period", d_period)):
        got = _column(head, Y, f"d(l.p)/d({name})")
        error = np.max(np.abs(got - want)) / np.max(np.abs(want))
        assert error < 1e-8, (name, error)
    t, fd = _finite_differences(path, "run", "l.p", ["duty", "period", "R"], PWM_VALUES)
    for name in ("duty", "period", "R"):
        got = _column(head, Y, f"d(l.p)/d({name})")
        error = np.max(np.abs(got - fd[name][:, 0])) / np.max(np.abs(fd[name]))
        assert error < 1e-6, (name, error)


LAG = """model lag "a first-order lag driven by a short pulse"
parameter tau = 0.5
parameter t0 = 1.7
parameter width = 0.05
signal x = integral(-x/tau + pulse(t0, width), init = 0)
scene run { time 0 .. 3 every 0.01; outputs x; solver dopri5(rtol = 1e-12, atol = 1e-14) }
"""


def test_a_pulse_s_start_and_width_move_its_time_events():
    """x' = -x/tau + pulse(t0, w): its closed form differentiated by SymPy (x = tau (1 -
    e^-(t - t0)/tau) during the pulse, then that at t0 + w decaying), the sensitivities to
    t0, w and tau through the two time events (t >= t0, t < t0 + w) whose times move."""
    tau, t0, w, t = sp.symbols("tau t0 w t", positive=True)
    during = tau * (1 - sp.exp(-(t - t0) / tau))
    after = during.subs(t, t0 + w) * sp.exp(-(t - t0 - w) / tau)
    values = {tau: 0.5, t0: 1.7, w: 0.05}
    compiled = estimate.build(api.Source("lag.bg", LAG), ["t0", "width", "tau"], "run")
    head, Y = _runs(compiled, {})
    times = Y[:, 0]
    for name, p in (("t0", t0), ("width", w), ("tau", tau)):
        want = np.zeros(len(times))
        for lo, hi, expr in ((1.7, 1.75, during), (1.75, 9.0, after)):
            inside = (times > lo) & (times < hi)
            want[inside] = sp.lambdify(t, sp.diff(expr, p).subs(values), "numpy")(times[inside])
        got = _column(head, Y, f"d(x)/d({name})")
        off = np.min(np.abs(times[:, None] - np.array([1.7, 1.75])), axis=1) > 1e-9
        assert np.sum(~off) == 2  # (the rows on the edges are their right limits)
        assert np.max(np.abs(got - want)[off]) < 1e-9 * np.max(np.abs(want)), name


# ---------------------------------------------------------------- impacts and switches


def test_a_pendulum_striking_a_wall_matches_finite_differences():
    """models/pendulum_wall.bg: a constrained pendulum against a unilateral junction with
    restitution, whose impacts move the momenta through the kinetic metric (the mode
    change's map h): d(x, y)/d(e, l, d) through its impacts against central differences."""
    path = ROOT / "models" / "pendulum_wall.bg"
    values = {"e": 0.7, "l": 1.0, "d": 0.2}
    compiled = estimate.build(path, list(values), "strike", outputs="x, y")
    head, Y = _runs(compiled, {})
    t, fd = _finite_differences(path, "strike", "x, y", list(values), values)
    for p in values:
        for k, q in enumerate(("x", "y")):
            got, want = _column(head, Y, f"d({q})/d({p})"), fd[p][:, k]
            error = np.max(np.abs(got - want)) / np.max(np.abs(want))
            assert error < 1e-6, (q, p, error)


def test_a_buck_converter_s_switch_and_diode_match_finite_differences():
    """models/buck.bg: an ideal switch on a square wave and a freewheeling diode, its mode
    changes state events; d(l.f, c.e)/d(duty, L, R) against central differences, away from
    the rows on an edge (where a row is the edge's right limit, the differences its mean)."""
    path = ROOT / "models" / "buck.bg"
    values = {"duty": 0.5, "L": 1e-4, "R": 5.0}
    compiled = estimate.build(path, list(values), "run", outputs="l.f, c.e")
    head, Y = _runs(compiled, {})
    t, fd = _finite_differences(path, "run", "l.f, c.e", list(values), values)
    phase = (t * 1e5) % 0.5  # edges at k/f and (k + 1/2)/f
    keep = np.minimum(phase, 0.5 - phase) > 1e-3
    assert np.sum(keep) > 700
    for p in values:
        for k, q in enumerate(("l.f", "c.e")):
            got, want = _column(head, Y, f"d({q})/d({p})")[keep], fd[p][keep, k]
            error = np.max(np.abs(got - want)) / np.max(np.abs(want))
            assert error < 1e-6, (q, p, error)


def test_the_buck_converter_s_periodic_orbit_through_its_switch_and_diode():
    """bgc periodic shoots through the switch's edges and the diode's state events with the
    monodromy matrix from the sensitivities' jumps: in continuous conduction the ideal buck's
    mean output is duty*V exactly (the coil's mean voltage is 0), its mean current that over
    R (the capacitor's mean current is 0), and its multipliers have |mu| = exp(-T/(2RC))."""
    import bgc
    orbit = bgc.periodic(ROOT / "models" / "buck.bg", "run")
    mean = {name: m for name, m, *_ in orbit.figures}
    assert mean["c.e"] == pytest.approx(0.5 * 12.0, rel=1e-9)
    assert mean["l.f"] == pytest.approx(0.5 * 12.0 / 5.0, rel=1e-9)
    assert np.abs(orbit.multipliers) == pytest.approx(math.exp(-1e-5 / (2 * 5.0 * 1e-5)),
                                                      rel=1e-9)


# ---------------------------------------------------------------- stick-slip: mode changes

STICK = """model stickslip "a block pushed by a sinusoidal force, with Coulomb friction"
parameter m = 1.0
parameter F0 = 0.6
parameter w = 2.0
parameter Fc = 0.3
parameter Fs = 0.5
f : MSe(F0*sin(w*t))
mass : I(m)
fr : Fr(Fc, Fs)
j : 1
f -> j
j -> mass
j -> fr
signal x = integral(mass.f, init = 0)
scene run {
  time 0 .. 10 every 0.01; outputs mass.f, x; solver dopri5(rtol = 1e-12, atol = 1e-12)
}
"""
STICK_VALUES = {"Fc": 0.3, "Fs": 0.5, "F0": 0.6, "m": 1.0}


def test_stick_slip_sensitivities_match_finite_differences(tmp_path):
    """Six breakaways and stops in 10 s (the friction's mode changes, a stop setting the
    momentum to 0): the sensitivities to the friction levels, the force and the mass against
    central differences (h = 1e-4: below it the differences' noise, the events' location to
    1e-12 in t divided by h, grows past the truncation)."""
    path = _write(tmp_path, "stick.bg", STICK)
    params = list(STICK_VALUES)
    compiled = estimate.build(path, params, "run")
    head, Y = _runs(compiled, {})
    t, fd = _finite_differences(path, "run", "mass.f, x", params, STICK_VALUES, h=1e-4)
    sticking = np.abs(_column(head, Y, "mass.f")) == 0.0
    assert 100 < np.sum(sticking) < len(t) - 100  # (it sticks and slips)
    for p in params:
        for k, q in enumerate(("mass.f", "x")):
            got, want = _column(head, Y, f"d({q})/d({p})"), fd[p][:, k]
            error = np.max(np.abs(got - want)) / np.max(np.abs(want))
            assert error < 1e-6, (q, p, error)


# ---------------------------------------------------------------- bgc fit through events


def _noisy_csv(path, t, columns, noise, seed):
    rng = np.random.default_rng(seed)
    with open(path, "w") as fh:
        fh.write("t," + ",".join(columns) + "\n")
        values = {c: v + noise * rng.standard_normal(len(t)) for c, v in columns.items()}
        for k, tk in enumerate(t):
            fh.write(",".join([repr(float(tk))] + [repr(float(values[c][k])) for c in columns])
                     + "\n")
    return path


def test_fit_recovers_the_ball_s_restitution_from_its_closed_form(tmp_path):
    """Heights every 0.01 s for 3 s from the closed form at e = 0.75 (the model's 0.8), with
    noise of 1 mm: bgc fit through the impacts, its 95 % interval covering the truth."""
    (e, g, h0, t), flights = _ball_closed_form()
    at = {e: 0.75, g: 9.81, h0: 1.0}
    times = np.arange(300) * 0.01
    x = np.zeros(len(times))
    for a, b, height, _ in flights:
        a, b = float(a.subs(at)), float(b.subs(at))
        inside = (times >= a) & (times < b)
        x[inside] = sp.lambdify(t, height.subs(at), "numpy")(times[inside])
    data = _noisy_csv(tmp_path / "ball.csv", times, {"x": x}, 1e-3, 5)
    result = estimate.fit(_write(tmp_path, "ball.bg", BALL), data, ["e=0.5..0.95"],
                          scene="drop", backend=BACKENDS[0])
    assert result.converged, result.stopped
    assert result.lower[0] < 0.75 < result.upper[0]
    assert result.upper[0] - result.lower[0] < 1e-3
    assert result.residual_sd == pytest.approx(1e-3, rel=0.1)


def test_fit_recovers_a_coulomb_friction_level_through_stick_slip(tmp_path):
    """The block's speed and position at Fc = 0.25, Fs = 0.5 (the model's Fc 0.3), with
    noise: bgc fit of Fc through every breakaway and stop, the interval covering it."""
    path = _write(tmp_path, "stick.bg", STICK)
    t, Y, names = api.simulate(path, "run", backend=BACKENDS[0], outputs="mass.f, x",
                               params={"Fc": 0.25})
    data = _noisy_csv(tmp_path / "stick.csv", t, {"mass.f": Y[:, 0], "x": Y[:, 1]}, 2e-3, 11)
    result = estimate.fit(path, data, ["Fc=0.05..0.45"], scene="run", backend=BACKENDS[0])
    assert result.converged, result.stopped
    assert result.lower[0] < 0.25 < result.upper[0]
    assert result.upper[0] - result.lower[0] < 0.01


PWM_MOTOR = """model pwm_motor "a DC motor driven by a PWM voltage"
parameter V = 12
parameter R = 1
parameter L = 0.005
parameter K = 0.08 "the torque constant (the back-emf's too)"
parameter J = 1e-4
parameter b = 1e-4
parameter period = 0.001
parameter duty = 0.6
u : MSe(V*square(period, duty))
ra : R(R)
la : I(L)
em : GY(K)
rotor : I(J)
fr : R(b)
ea : 1
wm : 1
u -> ea
ea -> ra
ea -> la
ea -> em -> wm
wm -> rotor
wm -> fr
scene run { time 0 .. 0.02 every 0.0001; outputs la.f, rotor.f
  solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""


def _pwm_motor_exact(times, K):
    """Current and speed of the PWM motor at torque constant K, exactly: between the edges
    (k T on, (k + D) T off) the motor is linear, L i' = V u - R i - K w, J w' = K i - b w,
    so each piece is the matrix exponential of the system augmented with its input."""
    from scipy.linalg import expm
    V, R, L, J, b, T, D = 12.0, 1.0, 0.005, 1e-4, 1e-4, 0.001, 0.6
    A = np.array([[-R / L, -K / L], [K / J, -b / J]])
    pieces = {}
    for on in (1.0, 0.0):
        M = np.zeros((3, 3))
        M[:2, :2], M[0, 2] = A, V * on / L
        pieces[on] = M
    edges = sorted({k * T for k in range(25)} | {(k + D) * T for k in range(25)})
    x, t, out = np.array([0.0, 0.0, 1.0]), 0.0, []
    for tk in times:
        while True:
            nxt = next(e for e in edges if e > t + 1e-15)
            on = 1.0 if (t + 1e-15) % T < D * T else 0.0
            if nxt > tk:
                out.append((expm(pieces[on] * (tk - t)) @ x)[:2])
                break
            x, t = expm(pieces[on] * (nxt - t)) @ x, nxt
    return np.array(out)


def test_fit_recovers_a_pwm_motor_s_torque_constant(tmp_path):
    """Current and speed of a PWM-driven DC motor from its exact piecewise solution at
    K = 0.05 (the model's 0.08), with noise: bgc fit of K through every PWM edge, its 95 %
    interval covering the truth."""
    times = np.arange(201) * 1e-4
    exact = _pwm_motor_exact(times, 0.05)
    path = _write(tmp_path, "motor.bg", PWM_MOTOR)
    t, Y, _ = api.simulate(path, "run", backend=BACKENDS[0], params={"K": 0.05})
    assert np.array_equal(t, times) or np.allclose(t, times, rtol=0, atol=1e-15)
    assert np.max(np.abs(Y - exact) / np.max(np.abs(exact), axis=0)) < 1e-8  # the model is it
    data = _noisy_csv(tmp_path / "motor.csv", times, {"la.f": exact[:, 0],
                                                      "rotor.f": exact[:, 1]}, 2e-3, 17)
    result = estimate.fit(path, data, ["K=0.01..0.2"],
                          scene="run", backend=BACKENDS[0])
    assert result.converged, result.stopped
    assert result.lower[0] < 0.05 < result.upper[0]
    assert result.upper[0] - result.lower[0] < 1e-3
    assert result.residual_sd == pytest.approx(2e-3, rel=0.15)


def test_a_time_table_before_the_square_wave_leaves_its_edges_alone(tmp_path):
    """A table of t met before the square wave (its breakpoints time events of their own,
    its value 0 throughout): the edges' jumps are the square wave's still."""
    (tmp_path / "zero.csv").write_text("t,v\n0,0\n0.0051,0\n0.013,0\n0.03,0\n")
    text = PWM.replace("u : MSe(", 'z : Se(table("zero.csv", t))\nu : MSe(').replace(
        "u -> j\n", "u -> j\nz -> j\n")
    compiled = estimate.build(_write(tmp_path, "pwm_table.bg", text), ["duty", "period"], "run")
    head, Y = _runs(compiled, {})
    assert sum(k == "table" for k in compiled.program.events.kinds) == 1
    for name, want in zip(("duty", "period"), _pwm_reference(Y[:, 0])):
        got = _column(head, Y, f"d(l.p)/d({name})")
        assert np.max(np.abs(got - want)) < 1e-8 * np.max(np.abs(want)), name


# ---------------------------------------------------------------- what stays refused


def test_a_sampled_discrete_value_is_refused_located(tmp_path):
    """A discrete value set from a state (sample and hold) that the motion reads would need
    its own sensitivity."""
    text = BALL.replace("when x < 0 {", "discrete held = 0\nwhen x < 0 {\n  held = b.p").replace(
        "w : Se(-m*g)", "w : Se(-m*g + 0.01*held)")
    path = _write(tmp_path, "held.bg", text)
    result = run_bgc("simulate", path, "--sensitivities", "e")
    assert result.returncode == 1, result.stderr
    assert "held.bg:" in result.stderr and "'held'" in result.stderr
    assert "Traceback" not in result.stderr
