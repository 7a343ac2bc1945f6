"""Multibond graphs: vector bonds, junction and constraint arrays, matrix transformers and vector
signals, flattened into scalar bonds.  The double pendulum in vector form against the same
system in scalar bonds and against the equations of motion in its two angles (Lagrange's
equations typed here, solved by SciPy at tight tolerance); the paper's pendulum in vector form
against its scalar form; and the errors of misused multiports."""
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bgc import api
from bgc.base import toolchain
from bgc.api import BgcModelError, Source

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])
M1, M2, L1, L2, G, TH1, TH2 = 1.0, 0.5, 1.0, 0.7, 9.81, 0.5, 1.0


def double_pendulum_angles(t):
    """Lagrange's equations in the angles from the vertical (y down):
    M(th) th'' = r(th, th'), M = [[(m1+m2) l1^2, m2 l1 l2 c], [m2 l1 l2 c, m2 l2^2]],
    r = [-m2 l1 l2 s w2^2 - (m1+m2) g l1 sin th1, m2 l1 l2 s w1^2 - m2 g l2 sin th2],
    c = cos(th1 - th2), s = sin(th1 - th2); DOP853 at rtol 1e-12.  Returns x1, y1, x2, y2."""
    def f(_, z):
        a, b, wa, wb = z
        c, s = np.cos(a - b), np.sin(a - b)
        M = np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * c], [M2 * L1 * L2 * c, M2 * L2**2]])
        r = np.array([-M2 * L1 * L2 * s * wb**2 - (M1 + M2) * G * L1 * np.sin(a),
                      M2 * L1 * L2 * s * wa**2 - M2 * G * L2 * np.sin(b)])
        return [wa, wb, *np.linalg.solve(M, r)]

    sol = solve_ivp(f, (t[0], t[-1]), [TH1, TH2, 0.0, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=t)
    a, b = sol.y[0], sol.y[1]
    x1, y1 = L1 * np.sin(a), L1 * np.cos(a)
    return np.column_stack([x1, y1, x1 + L2 * np.sin(b), y1 + L2 * np.cos(b)])


def _run(name, backend, **options):
    return api.simulate(MODELS / name, "swing", backend=backend, **options)


@pytest.mark.parametrize("backend", BACKENDS)
def test_double_pendulum_vector_equals_scalar_and_the_angle_equations(backend):
    t, Yv, names_v = _run("double_pendulum_vector.bg", backend)
    ts, Ys, names_s = _run("double_pendulum.bg", backend)
    assert names_v == ["q[0]", "q[1]", "q[2]", "q[3]", "rods.lambda[0]", "rods.lambda[1]",
                       "rods.residual[0]", "rods.residual[1]"]
    assert names_s[:4] == ["x1", "y1", "x2", "y2"]
    assert np.array_equal(t, ts) and t[-1] == 5.0
    assert np.abs(Yv - Ys).max() < 1e-9  # positions, multipliers and residuals alike
    ref = double_pendulum_angles(t)
    scale = np.abs(ref).max(axis=0)
    assert (np.abs(Yv[:, :4] - ref).max(axis=0) / scale).max() < 1e-6
    assert np.abs(Yv[:, 6:]).max() < 1e-8  # the rods keep their lengths


@pytest.mark.parametrize("backend", BACKENDS)
def test_pendulum_vector_form_is_the_scalar_pendulum(backend):
    t, Yv, names = _run("pendulum_vector.bg", backend, t_end=3.0)
    _, Ys, _ = _run("pendulum.bg", backend, t_end=3.0)
    assert names == ["q[0]", "q[1]", "rod.lambda", "rod.residual"]
    assert np.abs(Yv - Ys).max() < 1e-12


def test_vector_model_has_the_paper_equations():
    """d(mass.p[0])/dt of the vector form equals the scalar form's d(mx.p)/dt (eq. 12) after
    renaming the states."""
    import sympy as sp
    vec = api.build(MODELS / "pendulum_vector.bg", "swing", program=False).reduced
    sca = api.build(MODELS / "pendulum.bg", "swing", program=False).reduced
    from bgc.middle.reduce import explicit_forms
    fv = explicit_forms(vec, list(vec.rates))
    fs = explicit_forms(sca, list(sca.rates))
    rename = {sp.Symbol("mass.p[0]", real=True): sp.Symbol("mx.p", real=True),
              sp.Symbol("mass.p[1]", real=True): sp.Symbol("my.p", real=True),
              sp.Symbol("q[0]", real=True): sp.Symbol("x", real=True),
              sp.Symbol("q[1]", real=True): sp.Symbol("y", real=True)}
    for rv, rs in zip(vec.rates, sca.rates):
        assert sp.simplify(fv[rv].xreplace(rename) - fs[rs]) == 0


def _check(text):
    return api.check(Source("m.bg", text))


def _error(text):
    with pytest.raises(BgcModelError) as info:
        api.build(Source("m.bg", text), "s" if "scene s" in text else None)
    return str(info.value)


HEAD = "model m\nparameter k = 2\n"


def test_check_reports_one_stroke_per_vector_bond():
    report = api.check(MODELS / "double_pendulum_vector.bg", "swing")
    assert "  v->mass [4]: v -> mass\n" in report
    assert "  v->J [4]: J -> v\n" in report
    assert "  J->rods [2]: rods -> J\n" in report
    assert "J.in" not in report  # the transformer's scalar network is not shown


def test_outputs_expand_and_index():
    text = HEAD + ("v : 1[2]\nm : I[2]([1, k])\nw : Se[2]([1, 2])\nw -> v -> m\n"
                   "scene s { outputs m.p, v.f[1] }\n")
    compiled = api.build(Source("m.bg", text), "s")
    assert [o.name for o in compiled.reduced.outputs] == ["m.p[0]", "m.p[1]", "v.f[1]"]
    t, Y, names = api.simulate(Source("m.bg", text), "s", backend="python", t_end=1.0, dt=0.5)
    # m.p = (1, 2) t; v.f = m.p / (1, k)
    assert np.allclose(Y[-1], [1.0, 2.0, 1.0], rtol=1e-12)


@pytest.mark.parametrize("text, message", [
    ("v : 1[2]\nm : I[3](1)\nv -> m\n", "joins a port of dimension 2"),
    ("v : 1[2]\nm : I[2](1)\nw : Se[2]([1, 2, 3])\nw -> v -> m\n",
     "has dimension 2, but its value is a vector of 3"),
    ("signal s[2] = [1, 2] + [1, 2, 3]\n", "cannot add a vector of 3 to a vector of 2"),
    ("signal s = [1, 2]\n", "signal 's' is a scalar, but this is a vector of 2"),
    ("signal s[2] = [1, 2][2]\n", "index 2 is out of range (0 .. 1)"),
    ("parameter p = [1, 2]\n", "parameters are scalars"),
    ("signal s[2] = [[1, 2], [3]]\n", "this row has 1 entries, the first one 2"),
    ("v : 1[2]\nm : I[2](1)\nv -> m\nscene s { outputs m.p[2] }\n",
     "'m' has 2 components: index [2] is out of range"),
    ("x : 1[2->3]\n", "belongs to two-ports"),
    ("v : 1[2]\nm : I[2](1)\nt2 : MTF[2->1]([[1, 1]])\nsrc : Sf(1)\nv -> m\nv -> t2 -> src\n",
     "a multibond has one causal stroke"),
])
def test_multiport_errors_are_located(text, message):
    report = _error(HEAD + text)
    assert message in report, report
    assert report.startswith("m.bg:")


def test_square_transformer_driven_from_its_output_side():
    """Masses on the output side of MTF[2->2](T) set its output flows; the input efforts w
    reach them as e_out = T^-T w, so p(t) = T^-T w t (T^-T computed here by numpy)."""
    text = ("model sq\nw : Se[2]([1, 0])\nv : 1[2]\nT : MTF[2->2]([[1, 2], [3, 4]])\n"
            "m : I[2](1)\nw -> v -> T -> m\n")
    assert "T->m [2]: T -> m" in api.check(Source("sq.bg", text))
    t, Y, names = api.simulate(Source("sq.bg", text), backend="python", t_end=1.0, dt=0.5)
    want = np.linalg.solve(np.array([[1.0, 2.0], [3.0, 4.0]]).T, [1.0, 0.0])
    assert names == ["m.p[0]", "m.p[1]"]
    assert np.allclose(Y[-1], want, rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_four_bar_keeps_its_loop_closed(backend):
    """A closed kinematic loop (4 coordinates, 3 rods): with the correctors the rods keep their
    lengths to 1e-8 over the run; without them the loop drifts open at least ten times more.
    Independent of bgc: the energy 1/2 sum p^2/m - g (m1 y1 + m2 y2) is conserved."""
    runs = {}
    for scene in ("swing", "unstabilised"):
        t, Y, names = api.simulate(MODELS / "four_bar.bg", scene, backend=backend)
        assert names == ["q[0]", "q[1]", "q[2]", "q[3]", "mass.p[0]", "mass.p[1]",
                         "mass.p[2]", "mass.p[3]", "rods.residual[0]", "rods.residual[1]",
                         "rods.residual[2]"]
        runs[scene] = Y
    held, drift = (np.abs(runs[s][:, 8:]).max() for s in ("swing", "unstabilised"))
    assert held < 1e-8 and drift > 10 * held
    Y = runs["swing"]
    q, p = Y[:, :4], Y[:, 4:8]
    energy = 0.5 * (p**2).sum(axis=1) - 9.81 * (q[:, 1] + q[:, 3])
    assert np.abs(energy - energy[0]).max() < 1e-7 * np.abs(energy).max()
    crank = np.degrees(np.arctan2(q[:, 1], q[:, 0]))
    assert crank.max() - crank.min() > 90  # it moves through a large part of its range


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_link_arm_in_joint_coordinates_is_the_double_pendulum(backend):
    """The arm's mass matrix M(th) depends on the angles its own flows integrate: with the
    Hamiltonian correction its motion is the double pendulum's (Lagrange's equations in the
    angles, solved by SciPy here) and its energy p^T M^-1 p / 2 + V is conserved."""
    t, Y, names = api.simulate(MODELS / "two_link_arm.bg", "swing", backend=backend)
    assert names == ["th[0]", "th[1]", "arm.p[0]", "arm.p[1]"]
    a, b = Y[:, 0], Y[:, 1]
    x1, y1 = L1 * np.sin(a), L1 * np.cos(a)
    got = np.column_stack([x1, y1, x1 + L2 * np.sin(b), y1 + L2 * np.cos(b)])
    ref = double_pendulum_angles(t)
    assert (np.abs(got - ref).max(axis=0) / np.abs(ref).max(axis=0)).max() < 1e-6
    c = np.cos(a - b)
    det = (M1 + M2) * L1**2 * M2 * L2**2 - (M2 * L1 * L2 * c) ** 2
    p1, p2 = Y[:, 2], Y[:, 3]
    kinetic = (M2 * L2**2 * p1**2 - 2 * M2 * L1 * L2 * c * p1 * p2
               + (M1 + M2) * L1**2 * p2**2) / (2 * det)
    energy = kinetic - (M1 + M2) * G * L1 * np.cos(a) - M2 * G * L2 * np.cos(b)
    assert np.abs(energy - energy[0]).max() < 1e-8 * np.abs(energy).max()


def test_check_says_when_a_field_is_hamiltonian():
    report = api.check(MODELS / "two_link_arm.bg", "swing")
    assert "arm: Hamiltonian form, dp/dt = e - dT/dq" in report and "in th[0], th[1]" in report
    const = _check(HEAD + "v : 1[2]\nm : I[2]([[2, 1], [1, 2]])\nw : Se[2]([0, 1])\n"
                   "w -> v -> m\n")
    assert "m: its matrix does not depend on its own coordinates" in const


@pytest.mark.parametrize("matrix, n, m", [("[[1, 2], [3, 4]]", 2, 2), ("[[1, 2]]", 2, 1)])
def test_gyrator_matrix(matrix, n, m):
    """Sf[n](F) into MGY[n->m](G) into unit masses: e_out = G f_in, so p(t) = G F t."""
    text = (f"model gy\nsrc : Sf[{n}]([1, 1])\nv : 1[{n}]\nG : MGY[{n}->{m}]({matrix})\n"
            f"mass : I[{m}](1)\nsrc -> v -> G -> mass\n" if m > 1 else
            f"model gy\nsrc : Sf[{n}]([1, 1])\nv : 1[{n}]\nG : MGY[{n}->{m}]({matrix})\n"
            "mass : I(1)\nsrc -> v -> G -> mass\n")
    t, Y, names = api.simulate(Source("gy.bg", text), backend="python", t_end=1.0, dt=1.0)
    G = np.array(json.loads(matrix), dtype=float)
    assert np.allclose(Y[-1], G @ np.ones(n), rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dual_form_parallel_capacitors(backend):
    """The tie 1-junction keeps both charges as states; the circuit is one RC with C = C1 + C2:
    v = V0 + (v0 - V0) exp(-t / (Rs C)), and the tie's multiplier is c2's current C2 v'."""
    V0, Rs, C1, C2, v0 = 5.0, 2.0, 0.5, 1.5, 1.0
    t, Y, names = api.simulate(MODELS / "parallel_caps_dual.bg", "charge", backend=backend)
    assert names == ["c1.q", "c2.q", "c1.e", "c2.e", "tie.lambda", "tie.residual"]
    tau = Rs * (C1 + C2)
    v = V0 + (v0 - V0) * np.exp(-t / tau)
    assert np.allclose(Y[:, 2], v, rtol=1e-9) and np.allclose(Y[:, 3], v, rtol=1e-9)
    assert np.allclose(Y[:, 4], C2 * (V0 - v0) / tau * np.exp(-t / tau), rtol=1e-8, atol=1e-12)
    assert np.abs(Y[:, 5]).max() < 1e-10
    _, Z, _ = api.simulate(MODELS / "parallel_caps.bg", "charge", backend=backend)
    assert np.abs(Y[:, :4] - Z[:, :4]).max() < 1e-9  # the derivative-causality form


def test_dual_form_on_a_junction_array():
    """Two independent pairs of capacitors, each pair tied by one row of a 1[2] constraint
    array and charged by its own current source: q_a = i C1/(C1 + C2) t, q_b = i C2/(..) t."""
    text = ("model pairs\nsrc : Sf[2]([1, 2])\nn : 0[2]\na : C[2]([1, 3])\n"
            "b : C[2]([2, 1])\nties : 1[2] constraint nonholonomic corrector pd(10)\n"
            "src -> n -> a\nn -> ties -> b\nscene s { outputs a.q, b.q, ties.lambda }\n")
    assert "n->ties [2]: n -> ties" in api.check(Source("pairs.bg", text), "s")
    t, Y, names = api.simulate(Source("pairs.bg", text), "s", backend="python", t_end=1.0,
                               dt=0.5)
    i, c1, c2 = np.array([1.0, 2.0]), np.array([1.0, 3.0]), np.array([2.0, 1.0])
    assert names == ["a.q[0]", "a.q[1]", "b.q[0]", "b.q[1]", "ties.lambda[0]",
                     "ties.lambda[1]"]
    assert np.allclose(Y[-1], [*(i * c1 / (c1 + c2)), *(i * c2 / (c1 + c2)),
                               *(i * c2 / (c1 + c2))], rtol=1e-9)


ROWS = HEAD + """v : 1[2]
m : I[2](1)
w : Se[2]([0, 9.81])
J : MTF[2->2]([[2*q[0], 2*q[1]], [JROW]])
rows : 0[2] constraint holonomic(init = [-1, INIT]) corrector pid([k, 2*k], [3, 4])
signal q[2] = integral(v.f, init = [0.6, 0.8])
w -> v -> m
v -> J -> rows
"""


def test_constraint_array_rows_take_their_gains_and_are_tested_row_by_row():
    # row 1: d/dt (q0 - q1) = v0 - v1, holonomic; its init makes Phi(q0) = 0
    good = ROWS.replace("JROW", "1, -1").replace("INIT", "0.2")
    report = _check(good)
    assert "rows[0]: holonomic (declared), corrector pid(k, 3)" in report
    assert "rows[1]: holonomic (declared), corrector pid(2*k, 4)" in report
    # row 1: q1 v0 is not the derivative of a function of q: the error names the row
    bad = ROWS.replace("JROW", "q[1], 0").replace("INIT", "0")
    message = _error(bad)
    assert "constraint 'rows[1]' is declared holonomic but is not integrable" in message
    assert "rows[0]" not in message


@pytest.mark.parametrize("backend", BACKENDS)
def test_twin_motors_are_two_dc_motors(backend):
    """Component i of the multibond drive is models/dc_motor.bg with motor i's data (that model
    is checked against its own reference in test_models.py)."""
    t, Y, names = api.simulate(MODELS / "twin_motors.bg", "run", backend=backend)
    assert names == ["ind.f[0]", "ind.f[1]", "rotor.f[0]", "rotor.f[1]", "angle[0]",
                     "angle[1]"]
    data = [dict(V=12.0, Ra=2.0, La=0.5, kt=0.8, Jr=0.05, br=0.1, tau_load=0.5),
            dict(V=24.0, Ra=1.0, La=0.2, kt=0.5, Jr=0.02, br=0.05, tau_load=0.2)]
    for i, params in enumerate(data):
        _, Z, cols = api.simulate(MODELS / "dc_motor.bg", "run", backend=backend, params=params)
        assert cols[:2] == ["ind.f", "rotor.f"] and cols[4] == "angle"
        mine = Y[:, [i, 2 + i, 4 + i]]
        assert np.abs(mine - Z[:, [0, 1, 4]]).max() < 1e-9 * np.abs(Z).max()


def test_resistance_and_capacitance_matrices():
    """R[2](R): e = R f with the flows imposed, f = R^-1 e with the efforts imposed; C[2](K)
    charged by currents i: q = i t, e = K^-1 q (numpy's solve here)."""
    R = np.array([[2.0, 1.0], [1.0, 3.0]])
    K = np.array([[2.0, 0.5], [0.5, 1.0]])
    text = ("model rc\nsrc : Sf[2]([1, 2])\nv : 0[2]\nr : R[2]([[2, 1], [1, 3]])\n"
            "c : C[2]([[2, 0.5], [0.5, 1]])\nsrc -> v\nv -> r\nv -> c\n"
            "scene s { outputs c.q, c.e, r.f }\n")
    t, Y, names = api.simulate(Source("rc.bg", text), "s", backend="python", t_end=1.0,
                               dt=0.5)
    assert names == ["c.q[0]", "c.q[1]", "c.e[0]", "c.e[1]", "r.f[0]", "r.f[1]"]
    # the node voltage e = K^-1 q drives r: r.f = R^-1 e, and c charges with i - r.f
    def rhs(_, q):
        e = np.linalg.solve(K, q)
        return np.array([1.0, 2.0]) - np.linalg.solve(R, e)
    ref = solve_ivp(rhs, (0, 1), [0.0, 0.0], rtol=1e-12, atol=1e-14).y[:, -1]
    e = np.linalg.solve(K, ref)
    assert np.allclose(Y[-1], [*ref, *e, *np.linalg.solve(R, e)], rtol=1e-7, atol=1e-12)
    flows = ("model rf\nsrc : Sf[2]([1, 2])\nr : R[2]([[2, 1], [1, 3]])\nsrc -> r\n"
             "c : C(1)\nw : Sf(1)\nw -> c\nscene s { outputs r.e, c.q }\n")
    t, Y, names = api.simulate(Source("rf.bg", flows), "s", backend="python", t_end=1.0, dt=1.0)
    assert np.allclose(Y[-1, :2], R @ [1.0, 2.0], rtol=1e-12)
