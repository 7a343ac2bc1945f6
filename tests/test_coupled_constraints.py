"""Constraint junctions on coupled inertia fields: the source paper's general form
M(q) q'' = Q - G(q)^T lambda, with the field's flows solving M(q) f = p and the multipliers
solving the augmented system [M G^T; G 0] in the generated code.

References, each independent of bgc:
- Andrews' squeezing mechanism against the IVP Test Set's published solution at t = 0.03
  (computed by its authors with PSIDE at tolerance 1e-14), and against the same mechanism
  written as seven free bodies with diagonal masses and twenty pin constraints;
- the two-link arm with its tip on a vertical line against Lagrange's equations with the
  multiplier, typed here and integrated by SciPy at tight tolerance;
- a start off the constraint against the corrector's own law in closed form.
"""
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bgc import api
from bgc.base import toolchain
from conftest import run_bgc


def _replaced(text: str, pattern: str, new: str) -> str:
    """text with the one match of pattern (a line's start: re.M) replaced, whatever the
    blanks bgc fmt's alignment put in it."""
    text, n = re.subn(pattern, new, text, flags=re.M)
    assert n == 1, pattern
    return text


def _arm_moving(p: str) -> str:
    """models/two_link_arm_wall.bg with its inertia's initial momenta `init p = P` (where its
    doc string was)."""
    return _replaced((MODELS / "two_link_arm_wall.bg").read_text(), r'"the links\' inertia"',
                     f"init p = {p}")

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
TEST_MODELS = Path(__file__).parent / "models"
needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")

# The IVP Test Set, problem "andrews": q(0.03), the seven joint angles, and lambda(0.03).
ANDREWS_Q = [0.1581077119629904e+2, -0.1575637105984298e+2, 0.4082224013073101e-1,
             -0.5347301163226948e+0, 0.5244099658805304e+0, 0.5347301163226948e+0,
             0.1048080741042263e+1]
ANDREWS_LAMBDA = [0.1991753333731910e+3, -0.2975531228015052e+2, 0.2306654119098399e+2,
                  0.3145271365475927e+2, 0.2264249232082739e+2, 0.1161740700019673e+2]


def _columns(csv_text: str):
    lines = csv_text.strip().splitlines()
    names = lines[0].split(",")
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return names, data


def _simulate(tmp_path, model, *args, backend="c"):
    out = tmp_path / f"{model.stem}-{backend}-{len(list(tmp_path.iterdir()))}.csv"
    r = run_bgc("simulate", str(model), "--backend", backend, "-o", str(out), *args)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    return out.read_bytes()


@needs_cc
@pytest.mark.parametrize("solver", ["radau5", "dopri5"])
def test_andrews_in_relative_angles_matches_the_test_set(tmp_path, solver):
    """The 7 x 7 M(q) on one I field, six holonomic constraints through G(q): every angle at
    t = 0.03 within 1e-6 relative of the published solution, with a stiff and an explicit
    solver; the multipliers within 1e-5 (the reference's own accuracy in lambda, an index-3
    variable, is about 1e-6)."""
    text = _simulate(tmp_path, MODELS / "andrews.bg", "--scene", "squeeze", "--solver", solver)
    names, data = _columns(text.decode())
    assert data[-1, 0] == pytest.approx(0.03, abs=1e-15)
    q = data[-1, [names.index(f"q[{i}]") for i in range(7)]]
    lam = data[-1, [names.index(f"c.lambda[{i}]") for i in range(6)]]
    assert np.max(np.abs(q - ANDREWS_Q) / np.abs(ANDREWS_Q)) < 1e-6
    assert np.max(np.abs(lam - ANDREWS_LAMBDA) / np.abs(ANDREWS_LAMBDA)) < 1e-5
    residual = data[:, [names.index(f"c.residual[{i}]") for i in range(6)]]
    assert np.abs(residual).max() < 1e-9  # the loops stay closed (lengths ~ 0.03 m)


@needs_cc
def test_andrews_backends_write_the_same_bytes(tmp_path):
    c = _simulate(tmp_path, MODELS / "andrews.bg", "--scene", "squeeze", "--solver", "dopri5")
    py = _simulate(tmp_path, MODELS / "andrews.bg", "--scene", "squeeze", "--solver", "dopri5",
                   backend="python")
    assert c == py


@needs_cc
def test_andrews_with_a_field_equals_andrews_with_point_masses(tmp_path):
    """The same mechanism written twice: 7 joint angles with M(q) and 6 constraints, and 21
    absolute coordinates with diagonal masses and 20 pin constraints.  The joint angles agree
    to 1e-8 over the whole run."""
    tight = ("--scene", "squeeze", "--rtol", "1e-12", "--atol", "1e-12")
    names_r, rel = _columns(_simulate(tmp_path, MODELS / "andrews.bg", *tight).decode())
    names_b, bod = _columns(_simulate(tmp_path, TEST_MODELS / "andrews_bodies.bg",
                                      *tight).decode())
    assert np.array_equal(rel[:, 0], bod[:, 0]) and len(rel) == 31
    q = rel[:, [names_r.index(f"q[{i}]") for i in range(7)]]
    angles = bod[:, [names_b.index(f"angles[{i}]") for i in range(7)]]
    assert np.abs(q - angles).max() < 1e-8


# ---------------------------------------------------------------- the arm on a line

M1, M2, L1, L2, G, TH1, TH2, GAIN = 1.0, 0.5, 1.0, 0.7, 9.81, 0.2, 1.2, 10.0


def _arm_reference(t, corrector: str):
    """Lagrange's equations of the double pendulum in its angles with the tip held on the line
    x = x0 (Phi = l1 sin th1 + l2 sin th2 - x0): [M G^T; G 0] [a; lambda] = [r; c], with
    c = -dG/dt w minus the corrector's terms; DOP853 at rtol 1e-12."""
    x0 = float(L1 * np.sin(TH1) + L2 * np.sin(TH2))

    def f(_, z):
        a, b, wa, wb = z
        c, s = np.cos(a - b), np.sin(a - b)
        M = np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * c], [M2 * L1 * L2 * c, M2 * L2**2]])
        r = np.array([-M2 * L1 * L2 * s * wb**2 - (M1 + M2) * G * L1 * np.sin(a),
                      M2 * L1 * L2 * s * wa**2 - M2 * G * L2 * np.sin(b)])
        Gq = np.array([L1 * np.cos(a), L2 * np.cos(b)])
        phi = L1 * np.sin(a) + L2 * np.sin(b) - x0
        dphi = Gq @ [wa, wb]
        rhs = L1 * np.sin(a) * wa**2 + L2 * np.sin(b) * wb**2  # -dG/dt w
        if corrector == "pid":
            rhs -= 2 * GAIN * dphi + GAIN**2 * phi
        elif corrector == "pd":
            rhs -= GAIN * dphi
        K = np.zeros((3, 3))
        K[:2, :2], K[:2, 2], K[2, :2] = M, Gq, Gq
        acc = np.linalg.solve(K, [*r, rhs])
        return [wa, wb, acc[0], acc[1]]

    sol = solve_ivp(f, (t[0], t[-1]), [TH1, TH2, 0.0, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=t)
    return sol.y[:2].T


@needs_cc
@pytest.mark.parametrize("model, scene, corrector", [
    ("two_link_arm_wall.bg", "held", "pid"),
    ("two_link_arm_wall.bg", "unstabilised", "none"),
    ("two_link_arm_slot.bg", "held", "pd"),
    ("two_link_arm_slot.bg", "unstabilised", "none"),
])
def test_arm_with_its_tip_on_a_line(tmp_path, model, scene, corrector):
    """Holonomic (PID corrector, or none) and non-holonomic (PD, or none): the angles follow
    Lagrange's equations with the multiplier, and the drift stays within the tolerance's
    reach."""
    path = (MODELS if model == "two_link_arm_wall.bg" else TEST_MODELS) / model
    names, data = _columns(_simulate(tmp_path, path, "--scene", scene).decode())
    th = data[:, [names.index("th[0]"), names.index("th[1]")]]
    ref = _arm_reference(data[:, 0], corrector)
    assert np.abs(th - ref).max() < 1e-7
    assert th[:, 1].max() - th[:, 1].min() > 0.5  # it does move
    assert np.abs(data[:, names.index("wall.residual")]).max() < 1e-9


@needs_cc
def test_arm_projected_onto_the_constraint_in_both_backends(tmp_path):
    """Momenta that violate dPhi/dt = 0 (init p = [1, 0.2]) projected before the run by the
    kinetic metric, the least change of kinetic energy: p = p0 - G^T mu, where
    mu = G M^-1 p0 / (G M^-1 G^T) (an impulse of the guide), so that the flows f = M^-1 p give
    G f = 0; and the backends agree byte for byte."""
    text = _arm_moving("[1, 0.2]")
    model = tmp_path / "arm_moving.bg"
    model.write_text(text)
    r = run_bgc("check", str(model))
    assert r.returncode == 1 and "initial conditions violate constraint 'wall'" in r.stderr
    c = _simulate(tmp_path, model, "--scene", "held", "--project-initial")
    py = _simulate(tmp_path, model, "--scene", "held", "--project-initial", backend="python")
    assert c == py
    names, data = _columns(c.decode())
    a, b = data[0, names.index("th[0]")], data[0, names.index("th[1]")]
    p = data[0, [names.index("arm.p[0]"), names.index("arm.p[1]")]]
    M = np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * np.cos(a - b)],
                  [M2 * L1 * L2 * np.cos(a - b), M2 * L2**2]])
    f = np.linalg.solve(M, p)
    assert (a, b) == (TH1, TH2)  # the positions already held
    assert abs(L1 * np.cos(a) * f[0] + L2 * np.cos(b) * f[1]) < 1e-9 * np.abs(f).max()
    Gq, p0 = np.array([L1 * np.cos(a), L2 * np.cos(b)]), np.array([1.0, 0.2])
    mu = Gq @ np.linalg.solve(M, p0) / (Gq @ np.linalg.solve(M, Gq))
    assert np.abs(p - (p0 - mu * Gq)).max() < 1e-12


@needs_cc
@pytest.mark.parametrize("backend", ["c", "python"])
def test_arm_started_off_the_constraint_follows_the_correctors_law(tmp_path, backend):
    """--allow-inconsistent with a velocity that violates the constraint: with the PID
    corrector (alpha = beta = 10, critically damped) Phi'' + 2 alpha Phi' + beta^2 Phi = 0 from
    Phi = 0, Phi' = v0 gives Phi = v0 t exp(-10 t)."""
    text = _arm_moving("[1, 0.2]")
    model = tmp_path / "arm_moving.bg"
    model.write_text(text)
    names, data = _columns(_simulate(tmp_path, model, "--scene", "held", "--allow-inconsistent",
                                     backend=backend).decode())
    a, b = TH1, TH2
    M = np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * np.cos(a - b)],
                  [M2 * L1 * L2 * np.cos(a - b), M2 * L2**2]])
    f = np.linalg.solve(M, [1.0, 0.2])
    v0 = L1 * np.cos(a) * f[0] + L2 * np.cos(b) * f[1]
    t = data[:, 0]
    phi = data[:, names.index("wall.residual")]
    assert np.abs(phi - v0 * t * np.exp(-GAIN * t)).max() < 1e-8 * abs(v0)


@needs_cc
def test_a_constant_full_mass_matrix_under_a_constraint(tmp_path):
    """I[2]([[2, .5], [.5, 1]]) with one linear constraint x1 + 2 x2 = 0 and forces
    (1, 0): the motion stays on the line, and its acceleration is constant, from the
    augmented system solved here: [M g^T; g 0] [a; lambda] = [F; 0]."""
    model = tmp_path / "full.bg"
    model.write_text("""model full
v : 1[2]
mass : I[2]([[2, 0.5], [0.5, 1]])
push : Se[2]([1, 0])
line : MTF[2->1]([[1, 2]])
c : 0[1] constraint holonomic(init = [0]) corrector pid(3, 3)
signal x[2] = integral(v.f, init = [0, 0])
push -> v -> mass
v -> line -> c
scene run { outputs x, c.lambda
  time 0 .. 1 every 0.25
  solver dopri5(rtol = 1e-10, atol = 1e-12) }
""")
    names, data = _columns(_simulate(tmp_path, model, "--scene", "run").decode())
    K = np.array([[2, 0.5, 1], [0.5, 1, 2], [1, 2, 0]])
    a = np.linalg.solve(K, [1, 0, 0])
    t = data[:, 0]
    x = data[:, [names.index("x[0]"), names.index("x[1]")]]
    assert np.abs(x - 0.5 * np.outer(t**2, a[:2])).max() < 1e-10
    assert np.abs(data[:, names.index("c.lambda")] - a[2]).max() < 1e-10


def test_rows_through_the_field_are_checked_at_compile_time(tmp_path):
    """The initial-value check evaluates dPhi/dt through M(q) f = p at compile time and names
    the constraint."""
    text = _arm_moving("[1, 0.2]")
    model = tmp_path / "arm_moving.bg"
    model.write_text(text)
    with pytest.raises(api.BgcModelError) as err:
        api.build(model)
    assert "initial conditions violate constraint 'wall': dPhi/dt = " in str(err.value)


# ---------------------------------------------------------------- the slider-crank

SC = dict(r=0.05, l=0.2, Jc=2e-3, mr=0.5, ms=1.0, tau=0.5, c=20.0, theta0=0.3, gain=100.0)


def _slider_crank_reference(t):
    """Lagrange's equations in (theta, phi, x) with the two loop constraints and their
    multipliers, typed here: M a = Q - (dM/dt) q' + 1/2 q'^T (dM/dq) q' - G^T lambda, G a = -(dG/dt)
    q' - 2 alpha dPhi/dt - beta^2 Phi; DOP853 at rtol 1e-12."""
    r, l, Jc, mr, ms = SC["r"], SC["l"], SC["Jc"], SC["mr"], SC["ms"]
    Jr, k = mr * l**2 / 12, SC["gain"]

    def f(_, z):
        th, ph, x, wt, wp, wx = z
        m12 = -mr * r * l / 2 * np.cos(th + ph)
        s = mr * r * l / 2 * np.sin(th + ph)  # d m12 / d theta = d m12 / d phi
        M = np.array([[Jc + mr * r**2, m12, 0], [m12, Jr + mr * l**2 / 4, 0], [0, 0, ms]])
        w = np.array([wt, wp, wx])
        dM = np.array([[0, s * (wt + wp), 0], [s * (wt + wp), 0, 0], [0, 0, 0]])
        Q = np.array([SC["tau"], 0, -SC["c"] * wx]) - dM @ w + np.array(
            [s * wt * wp, s * wt * wp, 0])  # 1/2 q'^T dM/dq q' = s theta' phi' for both angles
        G = np.array([[-r * np.sin(th), -l * np.sin(ph), -1], [r * np.cos(th), -l * np.cos(ph), 0]])
        phi = np.array([r * np.cos(th) + l * np.cos(ph) - x, r * np.sin(th) - l * np.sin(ph)])
        dG_w = np.array([-r * np.cos(th) * wt**2 - l * np.cos(ph) * wp**2,
                         -r * np.sin(th) * wt**2 + l * np.sin(ph) * wp**2])
        K = np.zeros((5, 5))
        K[:3, :3], K[:3, 3:], K[3:, :3] = M, G.T, G
        acc = np.linalg.solve(K, [*Q, *(-dG_w - 2 * k * (G @ w) - k**2 * phi)])
        return [wt, wp, wx, *acc[:3]]

    th0 = SC["theta0"]
    ph0 = np.arcsin(r * np.sin(th0) / l)
    sol = solve_ivp(f, (t[0], t[-1]), [th0, ph0, r * np.cos(th0) + l * np.cos(ph0), 0, 0, 0],
                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=t)
    return sol.y[:3].T


@needs_cc
def test_slider_crank_in_joint_coordinates(tmp_path):
    """The crank spins up against the slider's friction: the coordinates follow Lagrange's
    equations with the multipliers, and the slider sits where the crank's angle puts it,
    x = r cos theta + sqrt(l^2 - r^2 sin^2 theta)."""
    names, data = _columns(_simulate(tmp_path, MODELS / "slider_crank.bg", "--scene",
                                     "run").decode())
    q = data[:, [names.index(f"q[{i}]") for i in range(3)]]
    assert q[-1, 0] > 30  # several turns of the crank
    ref = _slider_crank_reference(data[:, 0])
    assert np.abs(q - ref).max() < 1e-6 * np.abs(ref).max()
    r, l = SC["r"], SC["l"]
    x = r * np.cos(q[:, 0]) + np.sqrt(l**2 - (r * np.sin(q[:, 0]))**2)
    assert np.abs(q[:, 2] - x).max() < 1e-10


# ---------------------------------------------------------------- a moving line, a sliding block

ARM = """model arm
parameter m1 = 1.0
parameter m2 = 0.5
parameter l1 = 1.0
parameter l2 = 0.7
parameter g = 9.81
w : 1[2]
arm : I[2]([[(m1 + m2)*l1^2, m2*l1*l2*cos(th[0] - th[1])],
            [m2*l1*l2*cos(th[0] - th[1]), m2*l2^2]])
gravity : MSe[2]([-(m1 + m2)*g*l1*sin(th[0]), -m2*g*l2*sin(th[1])])
tip : MTF[2->1]([[l1*cos(th[0]), l2*cos(th[1])]])
signal th[2] = integral(w.f, init = [0.2, 1.2])
gravity -> w -> arm
w -> tip -> wall
"""


def _arm_with(extra_coordinates, constraint, t):
    """The arm's Lagrange equations with extra point masses (their masses, forces) and one
    constraint Phi(q, t) given as (phi, G(q), dG/dt w, d2phi/dt2 at fixed q, dphi/dt at fixed
    q); PID corrector 10, 10; DOP853 at rtol 1e-12."""
    masses = [m for m, _ in extra_coordinates]

    def f(time, z):
        n = 2 + len(masses)
        q, w = z[:n], z[n:]
        a, b = q[0], q[1]
        c, s = np.cos(a - b), np.sin(a - b)
        M = np.zeros((n, n))
        M[:2, :2] = [[(M1 + M2) * L1**2, M2 * L1 * L2 * c], [M2 * L1 * L2 * c, M2 * L2**2]]
        for k, m in enumerate(masses):
            M[2 + k, 2 + k] = m
        r = np.zeros(n)
        r[:2] = [-M2 * L1 * L2 * s * w[1]**2 - (M1 + M2) * G * L1 * np.sin(a),
                 M2 * L1 * L2 * s * w[0]**2 - M2 * G * L2 * np.sin(b)]
        phi, Gq, dGw, phi_tt, phi_t = constraint(time, q, w)
        dphi = Gq @ w + phi_t
        K = np.zeros((n + 1, n + 1))
        K[:n, :n], K[:n, n], K[n, :n] = M, Gq, Gq
        acc = np.linalg.solve(K, [*r, -dGw - phi_tt - 2 * GAIN * dphi - GAIN**2 * phi])
        return [*w, *acc[:n]]

    z0 = [TH1, TH2] + [x for _, x in extra_coordinates]
    sol = solve_ivp(f, (t[0], t[-1]), z0 + [0.0] * len(z0), method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=t)
    return sol.y[:len(z0)].T


@needs_cc
def test_a_time_dependent_constraint_on_a_coupled_field(tmp_path):
    """The line moves: x = x0 + A (1 - cos w t), its rate given by a flow source on the
    junction (the paper's Phi(q; t)); the annotation gives Phi with its time term."""
    A, W = 0.1, 3.0
    x0 = float(L1 * np.sin(TH1) + L2 * np.sin(TH2))
    model = tmp_path / "moving.bg"
    model.write_text(ARM + f"""parameter x0 = {x0!r}
parameter A = {A!r}
parameter omega = {W!r}
wall : 0 constraint holonomic(phi = l1*sin(th[0]) + l2*sin(th[1]) - x0 - A*(1 - cos(omega*t))) corrector pid(10, 10)
line : MSf(A*omega*sin(omega*t))
wall -> line
scene run {{ outputs th, wall.residual
  time 0 .. 2 every 0.02
  solver dopri5(rtol = 1e-10, atol = 1e-12) }}
""")
    names, data = _columns(_simulate(tmp_path, model, "--scene", "run").decode())

    def constraint(time, q, w):
        a, b = q
        Gq = np.array([L1 * np.cos(a), L2 * np.cos(b)])
        phi = L1 * np.sin(a) + L2 * np.sin(b) - x0 - A * (1 - np.cos(W * time))
        dGw = -L1 * np.sin(a) * w[0]**2 - L2 * np.sin(b) * w[1]**2
        return phi, Gq, dGw, -A * W**2 * np.cos(W * time), -A * W * np.sin(W * time)

    ref = _arm_with([], constraint, data[:, 0])
    th = data[:, [names.index("th[0]"), names.index("th[1]")]]
    assert np.abs(th - ref).max() < 1e-7
    assert np.abs(data[:, names.index("wall.residual")]).max() < 1e-9


@needs_cc
def test_a_field_and_a_point_mass_on_one_junction(tmp_path):
    """The arm's tip pinned (horizontally) to a block of mass 2 that slides freely: one
    junction whose balance holds the field's flows and the block's velocity."""
    x0 = float(L1 * np.sin(TH1) + L2 * np.sin(TH2))
    model = tmp_path / "block.bg"
    model.write_text(ARM + f"""vb : 1
block : I(2)
signal xb = integral(vb.f, init = {x0!r})
wall : 0 constraint corrector pid(10, 10)
vb -> block
wall -> vb
scene run {{ outputs th, xb, wall.residual
  time 0 .. 2 every 0.02
  solver dopri5(rtol = 1e-10, atol = 1e-12) }}
""")
    r = run_bgc("check", str(model))
    assert r.returncode == 0 and "wall: holonomic (detected)" in r.stdout, r.stdout + r.stderr
    names, data = _columns(_simulate(tmp_path, model, "--scene", "run").decode())

    def constraint(time, q, w):
        a, b, xb = q
        Gq = np.array([L1 * np.cos(a), L2 * np.cos(b), -1.0])
        phi = L1 * np.sin(a) + L2 * np.sin(b) - xb
        dGw = -L1 * np.sin(a) * w[0]**2 - L2 * np.sin(b) * w[1]**2
        return phi, Gq, dGw, 0.0, 0.0

    ref = _arm_with([(2.0, x0)], constraint, data[:, 0])
    got = data[:, [names.index("th[0]"), names.index("th[1]"), names.index("xb")]]
    assert np.abs(got - ref).max() < 1e-7
    assert np.abs(got[:, 2] - x0).max() > 0.01  # the block moves


@needs_cc
def test_point_masses_and_a_coupled_field_project_alike(tmp_path):
    """The kinetic metric does not depend on the coordinates: the arm in joint angles (a
    coupled field, the tip constraint only) and the same arm as two point masses in Cartesian
    coordinates (two rods and the tip), started with the same joint rates, which move the tip
    sideways, project onto the same velocities of the masses."""
    w0 = np.array([0.8, -0.3])
    a, b = TH1, TH2
    M = np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * np.cos(a - b)],
                  [M2 * L1 * L2 * np.cos(a - b), M2 * L2**2]])
    p0 = M @ w0
    joint = tmp_path / "joint.bg"
    joint.write_text(_arm_moving(f"[{float(p0[0])!r}, {float(p0[1])!r}]"))
    v1 = np.array([L1 * np.cos(a) * w0[0], -L1 * np.sin(a) * w0[0]])
    v2 = v1 + [L2 * np.cos(b) * w0[1], -L2 * np.sin(b) * w0[1]]
    text = (MODELS / "double_pendulum.bg").read_text()
    text = _replaced(text, r"theta1( *)= 0\.5", rf"theta1\1= {TH1!r}")
    text = _replaced(text, r"theta2( *)= 1\.0", rf"theta2\1= {TH2!r}")
    for name, mass, v in (("mx1", "m1", v1[0]), ("my1", "m1", v1[1]), ("mx2", "m2", v2[0]),
                          ("my2", "m2", v2[1])):
        text = _replaced(text, rf"^{name}( *): I\({mass}\)",
                         rf"{name}\1: I({mass}) init f = {float(v)!r}")
    text = text.replace("scene swing", """tip : 0 constraint holonomic(init = -l1*sin(theta1) - l2*sin(theta2)) corrector pid(alpha, beta)
t2 : TF(1)
vx2 -> t2 -> tip
scene projected { outputs mx1.f, my1.f, mx2.f, my2.f; time 0 .. 0.01 every 0.01 }
scene swing""")
    cartesian = tmp_path / "cartesian.bg"
    cartesian.write_text(text)
    names_c, cart = _columns(_simulate(tmp_path, cartesian, "--scene", "projected",
                                       "--project-initial").decode())
    names_j, arm = _columns(_simulate(tmp_path, joint, "--scene", "held", "--t-end", "0.01",
                                      "--project-initial").decode())
    pa = arm[0, [names_j.index("arm.p[0]"), names_j.index("arm.p[1]")]]
    w = np.linalg.solve(M, pa)
    u1 = np.array([L1 * np.cos(a) * w[0], -L1 * np.sin(a) * w[0]])
    u2 = u1 + [L2 * np.cos(b) * w[1], -L2 * np.sin(b) * w[1]]
    got = cart[0, [names_c.index(n) for n in ("mx1.f", "my1.f", "mx2.f", "my2.f")]]
    assert abs(u2[0]) < 1e-9 and abs(got[2]) < 1e-9  # the tip no longer moves sideways
    assert np.abs(got - [*u1, *u2]).max() < 1e-9
    assert np.abs(got - [*v1, *v2]).max() > 0.1  # and the projection did move them


def test_the_jacobian_goes_through_the_field_and_the_augmented_solve():
    """J v of Andrews' right side, derived symbolically through M(q) f = p and the augmented
    system [M G^T; G 0], against central differences of the right side itself (the generated
    Python module, at the start and at a state off it)."""
    from bgc.base.processes import load_python_module
    from bgc.codegen.emit import emit_python

    compiled = api.build(MODELS / "andrews.bg", "squeeze")
    (source,) = emit_python(compiled.program).values()
    mod = load_python_module(source)
    p = mod._with_constants(mod._param_values({}))
    n = mod._N
    rng = np.random.default_rng(7)
    x0 = np.array(mod._init(p))
    for x in (x0, x0 + 1e-3 * rng.standard_normal(n) * np.maximum(np.abs(x0), 1e-3)):
        v = rng.standard_normal(n) * np.maximum(np.abs(x), 1e-4)
        w = mod._Work()
        jv = [0.0] * n
        mod._jvp(0.0, list(x), p, w, list(v), jv)

        def rhs(y):
            out = [0.0] * n
            mod._rhs(0.0, list(y), p, mod._Work(), out)
            return np.array(out)

        h = 1e-6
        fd = (rhs(x + h * v) - rhs(x - h * v)) / (2 * h)
        assert np.abs(np.array(jv) - fd).max() < 1e-6 * np.abs(fd).max()


# ---------------------------------------------------------------- the arm striking a wall


def _arm_strike_reference(t, e=0.5, gap=0.8):
    """Lagrange's equations of the free double pendulum (DOP853 at rtol 1e-12) until the tip
    reaches the wall, Phi = l1 sin th1 + l2 sin th2 - (x0 - gap) = 0; there Newton's impact
    law through the mass matrix, (J M^-1 J^T) Lambda = -(1 + e) J w, w+ = w + M^-1 J^T Lambda;
    and on.  Returns the angles at t and the impact times."""
    x0 = float(L1 * np.sin(TH1) + L2 * np.sin(TH2))

    def mass(a, b):
        c = np.cos(a - b)
        return np.array([[(M1 + M2) * L1**2, M2 * L1 * L2 * c], [M2 * L1 * L2 * c, M2 * L2**2]])

    def f(_, z):
        a, b, wa, wb = z
        s = np.sin(a - b)
        r = np.array([-M2 * L1 * L2 * s * wb**2 - (M1 + M2) * G * L1 * np.sin(a),
                      M2 * L1 * L2 * s * wa**2 - M2 * G * L2 * np.sin(b)])
        return [wa, wb, *np.linalg.solve(mass(a, b), r)]

    def hits(_, z):
        return L1 * np.sin(z[0]) + L2 * np.sin(z[1]) - (x0 - gap)
    hits.terminal, hits.direction = True, -1
    out, impacts = np.zeros((len(t), 2)), []
    t0, z = t[0], [TH1, TH2, 0.0, 0.0]
    while True:
        sol = solve_ivp(f, (t0, t[-1]), z, method="DOP853", rtol=1e-12, atol=1e-12,
                        events=hits, dense_output=True)
        mask = (t >= t0) & (t <= sol.t[-1])
        out[mask] = sol.sol(t[mask])[:2].T
        if sol.status != 1:
            return out, impacts
        t0, z = sol.t[-1], sol.y[:, -1].copy()
        impacts.append(t0)
        J = np.array([L1 * np.cos(z[0]), L2 * np.cos(z[1])])
        Minv_JT = np.linalg.solve(mass(z[0], z[1]), J)
        lam = -(1 + e) * (J @ z[2:]) / (J @ Minv_JT)
        z[2:] += Minv_JT * lam


@needs_cc
def test_an_arm_strikes_a_wall_through_its_mass_matrix(tmp_path):
    """A unilateral junction on a coupled field I[2](M(q)): at each impact the joint momenta
    jump by J^T Lambda with (J M^-1 J^T) Lambda = -(1 + e) Phi'; the angles follow the
    Lagrangian reference (impacts included), in both backends with the same bytes."""
    path = TEST_MODELS / "two_link_arm_stop.bg"
    texts = [_simulate(tmp_path, path, "--scene", "strike", backend=b) for b in ("c", "python")]
    assert texts[0] == texts[1]
    names, data = _columns(texts[0].decode())
    t = data[:, 0]
    ref, impacts = _arm_strike_reference(t)
    assert len(impacts) == 2
    for k in range(2):
        got = data[:, names.index(f"th[{k}]")]
        assert np.max(np.abs(got - ref[:, k])) <= 1e-6
