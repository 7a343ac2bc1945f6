"""The notebook API (bgc.model): bgc.load(...) gives a Model with its states, parameters,
initial state, right side and runs, checked against the pendulum's closed forms and SciPy."""
import math

import numpy as np
import pytest

import bgc
from conftest import MODELS, have_cc

PENDULUM = MODELS / "pendulum.bg"


@pytest.fixture(scope="module")
def pendulum():
    return bgc.load(PENDULUM, scene="swing", backend="python")


def test_states_parameters_and_the_initial_state(pendulum):
    assert pendulum.states == ("mx.p", "my.p", "x", "y")
    # the declared defaults of models/pendulum.bg
    assert pendulum.parameters == {"m": 1.0, "l": 1.0, "g": 9.81, "theta0": 0.5, "alpha": 5.0,
                                   "beta": 5.0}
    th = 0.5  # at rest, at angle theta0 from the vertical (y points down)
    assert pendulum.x0 == pytest.approx([0.0, 0.0, math.sin(th), math.cos(th)], abs=1e-15)
    x0 = pendulum.initial_state({"theta0": 1.0, "l": 2.0})
    assert x0[2:] == pytest.approx([2 * math.sin(1.0), 2 * math.cos(1.0)], rel=1e-15)
    assert pendulum.outputs == ("x", "y", "rod.lambda", "rod.residual")


def test_the_right_side_at_rest_is_the_tangential_weight(pendulum):
    """At rest on the constraint the corrector is silent and the rod cancels the radial part of
    the weight: dp/dt = m g sin(th) (-cos(th), sin(th)), dq/dt = p/m = 0."""
    m, g, th = 2.0, 9.81, 0.7
    params = {"m": m, "theta0": th}
    f = pendulum.rhs(0.0, pendulum.initial_state(params), params)
    expected = [-m * g * math.sin(th) * math.cos(th), m * g * math.sin(th) ** 2, 0.0, 0.0]
    assert f == pytest.approx(expected, rel=1e-12, abs=1e-12)
    J = pendulum.jacobian(0.0, pendulum.x0)
    assert J.shape == (4, 4) and np.allclose(J[2:, :2], np.eye(2))  # dq/dt = p/m, m = 1


def test_simulate_returns_named_columns_that_match_scipy(pendulum):
    from scipy.integrate import solve_ivp
    th0, g = 1.0, 9.81
    tr = pendulum.simulate({"theta0": th0}, t_end=2.0, dt=0.5, solver="dop853", rtol=1e-11,
                           atol=1e-12)
    assert tr.keys() == ["t", "x", "y", "rod.lambda", "rod.residual"] and len(tr) == 5
    ref = solve_ivp(lambda t, s: [s[1], -g * math.sin(s[0])], (0, 2), [th0, 0.0],
                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=tr["t"])
    assert tr["x"] == pytest.approx(np.sin(ref.y[0]), abs=1e-8)
    assert tr["y"] == pytest.approx(np.cos(ref.y[0]), abs=1e-8)
    rec = tr.to_records()
    assert rec.dtype.names == tuple(tr.keys()) and np.array_equal(rec["rod.lambda"],
                                                                  tr["rod.lambda"])
    with pytest.raises(KeyError, match="no output named 'z'"):
        tr["z"]
    if have_cc():
        c = pendulum.simulate({"theta0": th0}, t_end=2.0, dt=0.5, solver="dop853",
                              rtol=1e-11, atol=1e-12, backend="c")
        assert np.abs(c.values - tr.values).max() < 1e-12


def test_to_csv_writes_what_it_holds(pendulum, tmp_path):
    tr = pendulum.simulate(t_end=0.5)
    tr.to_csv(tmp_path / "p.csv")
    data = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)
    assert np.array_equal(data[:, 0], tr.t) and np.array_equal(data[:, 1:], tr.values)
    assert (tmp_path / "p.csv").read_text().splitlines()[0] == "t,x,y,rod.lambda,rod.residual"


def test_arguments_are_checked_at_the_call():
    with pytest.raises(ValueError, match="backend must be one of"):
        bgc.load(PENDULUM, backend="fortran")
    with pytest.raises(ValueError, match="algebra must be one of"):
        bgc.load(PENDULUM, algebra="magic")
    m = bgc.load(PENDULUM, scene="swing", backend="python")
    with pytest.raises(ValueError, match="unknown parameter 'zz'"):
        m.simulate({"zz": 1.0})
    with pytest.raises(ValueError, match="backend must be one of"):
        m.simulate(backend="fortran")
    with pytest.raises(ValueError, match="rtol must be a positive finite number"):
        m.simulate(rtol=-1.0)
    with pytest.raises(ValueError, match="format must be one of"):
        m.equations("html")
    with pytest.raises(bgc.BgcArgumentError, match="no scene named 'swimg'"):
        bgc.load(PENDULUM, scene="swimg").states


def test_a_model_is_a_source_and_its_errors_come_at_first_use():
    bad = bgc.load("bad.bg", text="model bad\nmass : I(mm)\n")
    assert (bad.path, bad.text) == ("bad.bg", "model bad\nmass : I(mm)\n")
    with pytest.raises(bgc.BgcModelError, match=r"bad\.bg:2:10: error: unknown name 'mm'"):
        bad.states
    with pytest.raises(bgc.BgcModelError):
        bgc.check(bad)
    m = bgc.load(PENDULUM, scene="swing")
    assert bgc.check(m, scene="swing") == m.check()
    latex = m.equations("latex")
    assert latex._repr_latex_().startswith("$$") and "rod" in repr(m)


def test_draw_gives_the_dot_text_and_an_svg_jupyter_shows(pendulum):
    import shutil

    from bgc.reports import draw
    dot = pendulum.draw("dot")
    assert dot == draw.draw_dot(pendulum.compiled)
    if shutil.which("dot"):
        svg = pendulum.draw()
        assert "<svg" in svg._repr_svg_() and "rod" in svg
    with pytest.raises(ValueError, match="format must be one of"):
        pendulum.draw("pdf")
