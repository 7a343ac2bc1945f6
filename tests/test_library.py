"""The standard library (bgc/library, docs/library.md): every component in a small model,
against a closed form or SciPy's solve_ivp at tight tolerance computed here (the switched
parts, diode, switch, friction and end stops, against their piecewise closed forms); two
four-bars against models/four_bar.bg, one of point-mass bodies and rods, one of rigid links
and revolute joints; and a slider-crank of bodies and joints against its one-coordinate
Lagrangian equation."""
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from scipy import signal as scipy_signal

import bgc
from bgc.api import Source
from helpers import simulated

ROOT = Path(__file__).resolve().parent.parent
TIGHT = dict(rtol=1e-11, atol=1e-13)


def simulate(text, outputs, t_end=1.0, dt=0.05, **kw):
    """The inline model's outputs (Python backend): t and one column per output."""
    kw = {"rtol": 1e-10, "atol": 1e-12, **kw}
    t, Y, names = bgc.simulate(Source("inline.bg", text), None, backend="python",
                               outputs=outputs, t_end=t_end, dt=dt, **kw)
    assert names == list(outputs)
    return t, Y


def reference(rhs, y0, t):
    """SciPy's solution of y' = rhs(t, y) at the times t."""
    sol = solve_ivp(rhs, (t[0], t[-1]), y0, t_eval=t, method="DOP853", **TIGHT)
    assert sol.success
    return sol.y.T


# ------------------------------------------------------------------ electrical
ELECTRICAL = """model circuits
import electrical as el
# a series RLC driven by a step of 2 V
src : el.voltage_source(v = 2)
r1 : el.resistor(r = 3)
l1 : el.inductor(l = 0.25, i0 = 0.1)
c1 : el.capacitor(c = 0.5, v0 = 0.2)
gnd : el.ground()
n1 : 0; n2 : 0; n3 : 0
src.p -> n1; n1 -> r1.p; r1.n -> n2; n2 -> l1.p; l1.n -> n3; n3 -> c1.p; c1.n -> gnd.p
# a transformer feeding an RC: the capacitor charges towards 6/n
src2 : el.voltage_source(v = 6)
tr : el.transformer(n = 3)
r2 : el.resistor(r = 2)
c2 : el.capacitor(c = 0.25)
gnd2 : el.ground()
m1 : 0; m2 : 0
src2.p -> tr.p; tr.s -> m1; m1 -> r2.p; r2.n -> m2; m2 -> c2.p; c2.n -> gnd2.p
# a current source into a parallel RC
isrc : el.current_source(i = 0.5)
r3 : el.resistor(r = 4)
c3 : el.capacitor(c = 0.125, v0 = 1)
gnd3 : el.ground(); gnd4 : el.ground()
k : 0
isrc.p -> k; k -> r3.p; r3.n -> gnd3.p; k -> c3.p; c3.n -> gnd4.p
"""


def test_electrical_parts_against_closed_forms_and_scipy():
    outs = ["c1.store.e", "l1.store.f", "c2.store.e", "c3.store.e", "r3.i.f"]
    t, Y = simulate(ELECTRICAL, outs)
    # series RLC: L di/dt = 2 - R i - v, C dv/dt = i
    ref = reference(lambda _, y: [y[1] / 0.5, (2 - 3 * y[1] - y[0]) / 0.25], [0.2, 0.1], t)
    np.testing.assert_allclose(Y[:, :2], ref, rtol=0, atol=1e-8)
    # transformer: the secondary is at 6/3 = 2 V; RC = 0.5
    np.testing.assert_allclose(Y[:, 2], 2 * (1 - np.exp(-t / 0.5)), rtol=0, atol=1e-8)
    # current source: v = I R + (v0 - I R) exp(-t/RC), RC = 0.5; the resistor takes v/R
    v = 2 + (1 - 2) * np.exp(-t / 0.5)
    np.testing.assert_allclose(Y[:, 3], v, rtol=0, atol=1e-8)
    np.testing.assert_allclose(Y[:, 4], v / 4, rtol=0, atol=1e-8)


DC_MACHINE = """model drive
import electrical as el
import mechanics as mech
supply : el.voltage_source(v = 12)
motor : el.dc_machine(r = 1.5, l = 0.05, k = 0.2, j = 0.02, b = 0.001)
load : mech.rotational_damper(d = 0.01)
wall : mech.rotational_fixed()
supply.p -> motor.a; motor.shaft -> load.a; load.b -> wall.p
"""


def test_dc_machine_against_scipy():
    t, Y = simulate(DC_MACHINE, ["motor.ind.f", "motor.rotor.f"])
    ref = reference(lambda _, y: [(12 - 1.5 * y[0] - 0.2 * y[1]) / 0.05,
                                  (0.2 * y[0] - 0.011 * y[1]) / 0.02], [0, 0], t)
    np.testing.assert_allclose(Y, ref, rtol=0, atol=1e-8)


def test_ports_of_different_domains_cannot_be_bonded():
    text = DC_MACHINE.replace("load : mech.rotational_damper(d = 0.01)", "load : el.resistor()")
    with pytest.raises(bgc.BgcModelError, match=r"different domains: 'motor.shaft' "
                                                r"\(rotational\) and 'load.p' \(electrical\)"):
        bgc.build(Source("inline.bg", text.replace("load.a", "load.p").replace("load.b",
                                                                                "load.n")),
                  program=False)


# ------------------------------------------------------------------ mechanics
MECHANICS = """model mechanisms
import mechanics as mech
# a mass on a spring and a damper, pushed by a constant force
push : mech.force(f = 2)
cart : mech.mass(m = 0.5, v0 = 0.3)
spring : mech.spring(k = 8, x0 = 0.1)
damper : mech.damper(d = 0.6)
w1 : mech.fixed(); w2 : mech.fixed()
v : 1
push.p -> v; v -> cart.p; v -> spring.a; spring.b -> w1.p; v -> damper.a; damper.b -> w2.p
# a torque through a gear onto an inertia held by a torsion spring and a damper
drive : mech.torque(tau = 1.5)
gear : mech.gear(n = 4)
fly : mech.inertia(j = 0.2)
tsp : mech.torsion_spring(k = 3)
tdamp : mech.rotational_damper(d = 0.4)
rw1 : mech.rotational_fixed(); rw2 : mech.rotational_fixed()
w : 1
drive.p -> gear.a; gear.b -> w; w -> fly.p; w -> tsp.a; tsp.b -> rw1.p
w -> tdamp.a; tdamp.b -> rw2.p
# a velocity source stretching a spring, and a speed source driving a rack into another
pull : mech.velocity(v = 0.7)
s2 : mech.spring(k = 5); w3 : mech.fixed()
pull.p -> s2.a; s2.b -> w3.p
spin : mech.speed(w = 2)
rack : mech.rack(r = 0.05)
s3 : mech.spring(k = 5); w4 : mech.fixed()
spin.p -> rack.a; rack.b -> s3.a; s3.b -> w4.p
"""


def test_mechanics_against_closed_forms_and_scipy():
    outs = ["spring.store.q", "cart.body.f", "tsp.store.q", "fly.body.f", "s2.store.q",
            "s3.store.q", "drive.src.f"]
    t, Y = simulate(MECHANICS, outs)
    ref = reference(lambda _, y: [y[1], (2 - 8 * y[0] - 0.6 * y[1]) / 0.5], [0.1, 0.3], t)
    np.testing.assert_allclose(Y[:, :2], ref, rtol=0, atol=1e-8)
    # the gear multiplies the torque by n: j dw/dt = n tau - k phi - d w
    ref = reference(lambda _, y: [y[1], (4 * 1.5 - 3 * y[0] - 0.4 * y[1]) / 0.2], [0, 0], t)
    np.testing.assert_allclose(Y[:, 2:4], ref, rtol=0, atol=1e-8)
    np.testing.assert_allclose(Y[:, 4], 0.7 * t, rtol=0, atol=1e-10)
    np.testing.assert_allclose(Y[:, 5], 0.05 * 2 * t, rtol=0, atol=1e-10)
    np.testing.assert_allclose(Y[:, 6], 4 * Y[:, 3], rtol=0, atol=1e-10)  # the input shaft


# ------------------------------------------------------------------ hydraulics
HYDRAULICS = """model circuits
import hydraulic as hyd
import mechanics as mech
# Torricelli: a tank drains through an orifice to the atmosphere
tank : hyd.tank(area = 2, h0 = 1.5)
hole : hyd.orifice(k = 2e-4)
atm : hyd.pressure_source(p = 0)
atm.a -> hole.a; hole.b -> tank.p
# a supply through a pipe into an accumulator
supply : hyd.pressure_source(p = 2e5)
line : hyd.pipe(r = 1e8, l = 1e7, q0 = 1e-4)
acc : hyd.accumulator(c = 1e-10, p0 = 1e5)
supply.a -> line.a; line.b -> acc.p
# a pump turned at constant speed fills a tank
motor : mech.speed(w = 100)
pump : hyd.pump(disp = 2e-6)
tank2 : hyd.tank(area = 0.5, h0 = 0.2)
motor.p -> pump.shaft; pump.b -> tank2.p
# a cylinder pushes a spring
supply2 : hyd.pressure_source(p = 1e5)
cyl : hyd.cylinder(area = 2e-3, m = 4, d = 50)
spring : mech.spring(k = 2e4)
wall : mech.fixed()
supply2.a -> cyl.a; cyl.rod -> spring.a; spring.b -> wall.p
"""


def test_hydraulics_against_closed_forms_and_scipy():
    outs = ["tank.fluid.q", "line.fluid.f", "acc.store.e", "tank2.fluid.q", "spring.store.q",
            "cyl.body.f"]
    t, Y = simulate(HYDRAULICS, outs, t_end=2.0, dt=0.1)
    rho_g = 1000 * 9.81
    # dV/dt = -k sqrt(rho g V / A): sqrt(V) falls linearly
    sqrt_v = math.sqrt(3.0) - 2e-4 / 2 * np.sqrt(rho_g / 2) * t
    np.testing.assert_allclose(Y[:, 0], sqrt_v ** 2, rtol=1e-9)
    ref = reference(lambda _, y: [(2e5 - 1e8 * y[0] - y[1]) / 1e7, y[0] / 1e-10], [1e-4, 1e5], t)
    np.testing.assert_allclose(Y[:, 1], ref[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(Y[:, 2], ref[:, 1], rtol=1e-8)
    np.testing.assert_allclose(Y[:, 3], 0.5 * 0.2 + 2e-6 * 100 * t, rtol=1e-12)
    ref = reference(lambda _, y: [y[1], (1e5 * 2e-3 - 50 * y[1] - 2e4 * y[0]) / 4], [0, 0], t)
    np.testing.assert_allclose(Y[:, 4:6], ref, rtol=0, atol=1e-9)


# ------------------------------------------------------------------ thermal
THERMAL = """model heat
import thermal as th
heater : th.heat_flow(q = 50)
core : th.heat_capacity(c = 400, t0 = 300)
wall : th.conductor(g = 2)
shell : th.heat_capacity(c = 900, t0 = 295)
air : th.convection(h = 12, area = 0.5)
ambient : th.temperature(temp = 290)
n1 : 0; n2 : 0; n3 : 0
heater.p -> n1; n1 -> core.p; n1 -> wall.a; wall.b -> n2; n2 -> shell.p; n2 -> air.a
air.b -> n3; ambient.p -> n3
# a hot plate cooling by radiation alone
plate : th.heat_capacity(c = 50, t0 = 900)
glow : th.radiation(eps = 0.8, area = 0.1, t_amb = 300)
k : 0
k -> plate.p; k -> glow.a
"""


def test_thermal_against_scipy():
    t, Y = simulate(THERMAL, ["core.store.e", "shell.store.e", "plate.store.e"], t_end=200,
                    dt=10)
    ref = reference(lambda _, y: [(50 - 2 * (y[0] - y[1])) / 400,
                                  (2 * (y[0] - y[1]) - 6 * (y[1] - 290)) / 900], [300, 295], t)
    np.testing.assert_allclose(Y[:, :2], ref, rtol=1e-10)
    sigma = 5.670374419e-8
    ref = reference(lambda _, y: [-0.8 * sigma * 0.1 * (y[0] ** 4 - 300 ** 4) / 50], [900], t)
    np.testing.assert_allclose(Y[:, 2], ref[:, 0], rtol=1e-9)


# ------------------------------------------------------------------ signal blocks
SIGNALS = """model blocks
import blocks as sig
signal u = sin(2*t)
g : sig.gain(k = 3, u = u)
d : sig.sum(u1 = u, u2 = g.y, k2 = -1)
s3 : sig.sum(u1 = u, u2 = u, u3 = u, k3 = 0.5)
i : sig.integrator(u = u, k = 2, y0 = 1)
lag : sig.lag(u = 1, k = 2, tau = 0.5)
c : sig.pid_controller(u = u, kp = 2, ki = 0.5, kd = 0.3, tf = 0.1)
h : sig.transfer_function(u = 1, b0 = 3, b1 = 1, b2 = 0.5, a0 = 4, a1 = 2)
"""


def test_signal_blocks_against_closed_forms_and_scipy():
    outs = ["g.y", "d.y", "s3.y", "i.y", "lag.y", "c.y", "h.y"]
    t, Y = simulate(SIGNALS, outs, t_end=2.0)
    u = np.sin(2 * t)
    np.testing.assert_allclose(Y[:, 0], 3 * u, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Y[:, 1], -2 * u, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Y[:, 2], 2.5 * u, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Y[:, 3], 1 + (1 - np.cos(2 * t)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(Y[:, 4], 2 * (1 - np.exp(-t / 0.5)), rtol=0, atol=1e-9)
    # PID: kp u + ki (1 - cos 2t)/2 + kd times the derivative through 1/(tf s + 1), from u = 0
    filt = reference(lambda s, y: [(2 * math.cos(2 * s) - y[0]) / 0.1], [0.0], t)[:, 0]
    np.testing.assert_allclose(Y[:, 5], 2 * u + 0.5 * (1 - np.cos(2 * t)) / 2 + 0.3 * filt,
                               rtol=0, atol=1e-8)
    # the transfer function's step response, by SciPy's own realisation
    _, step = scipy_signal.step(([0.5, 1, 3], [1, 2, 4]), T=t)
    np.testing.assert_allclose(Y[:, 6], step, rtol=0, atol=1e-9)


# ------------------------------------------------------------------ planar multibody
FOUR_BAR = """model four_bar_library "the four-bar of models/four_bar.bg from library parts"
import planar as mb
parameter m1 = 1.0; parameter m2 = 1.0
parameter a = 1.0; parameter b = 2.0; parameter c = 1.5; parameter d = 2.0
parameter g = 9.81; parameter phi0 = 0.3
parameter alpha = 10.0; parameter beta = 10.0
parameter ax = a*cos(phi0); parameter ay = a*sin(phi0)
parameter D = sqrt((d - ax)^2 + ay^2)
parameter ux = (d - ax)/D; parameter uy = -ay/D
parameter e = (b^2 - c^2 + D^2)/(2*D); parameter h = sqrt(b^2 - e^2)
parameter bx = ax + e*ux - h*uy; parameter by = ay + e*uy + h*ux
A : mb.body(m = m1, x0 = ax, y0 = ay, g = g) "the mass at joint A"
B : mb.body(m = m2, x0 = bx, y0 = by, g = g) "the mass at joint B"
crank : mb.rod_ground(l = a, xa = A.q[0], ya = A.q[1], alpha = alpha, beta = beta)
coupler : mb.rod(l = b, xa = A.q[0], ya = A.q[1], xb = B.q[0], yb = B.q[1], alpha = alpha,
                 beta = beta)
rocker : mb.rod_ground(l = c, xa = B.q[0], ya = B.q[1], x = d, alpha = alpha, beta = beta)
A.a -> crank.a; A.b -> coupler.a; B.a -> coupler.b; B.b -> rocker.a
"""


def test_a_four_bar_of_library_parts_matches_models_four_bar():
    """Point-mass bodies and massless rods (a rod: a link between two revolute joints)
    against the hand-written multibond model: the same trajectory to 1e-9."""
    kw = dict(t_end=2.0, dt=0.05, rtol=1e-10, atol=1e-12, backend="python")
    t, Y, _ = bgc.simulate(Source("inline.bg", FOUR_BAR), None,
                           outputs=["A.q[0]", "A.q[1]", "B.q[0]", "B.q[1]"], **kw)
    t0, Y0, _ = bgc.simulate(ROOT / "models" / "four_bar.bg", None, outputs=["q"], **kw)
    np.testing.assert_array_equal(t, t0)
    assert np.abs(Y - Y0).max() < 1e-9


FOUR_BAR_RIGID = FOUR_BAR.split("A : mb.body")[0].replace("four_bar_library", "four_bar_rigid") + """
parameter sa = m2*b/(m1 + m2) "from the coupler's centre back to A"
parameter sb = m1*b/(m1 + m2) "from the coupler's centre on to B"
crank : mb.body(m = m1, j = m1*a^2/4, x0 = ax/2, y0 = ay/2, th0 = phi0, g = g)
coupler : mb.body(m = (m1 + m2)/2, j = m1*m2*b^2/(2*(m1 + m2)), x0 = (m1*ax + m2*bx)/(m1 + m2),
                  y0 = (m1*ay + m2*by)/(m1 + m2), th0 = atan2(by - ay, bx - ax), g = g)
rocker : mb.body(m = m2, j = m2*c^2/4, x0 = (d + bx)/2, y0 = by/2, th0 = atan2(by, bx - d), g = g)
o1 : mb.revolute_ground(th = crank.q[2], ax = -a/2, alpha = alpha, beta = beta)
pa : mb.revolute(tha = crank.q[2], thb = coupler.q[2], ax = a/2, bx = -sa, alpha = alpha,
                 beta = beta)
pb : mb.revolute(tha = coupler.q[2], thb = rocker.q[2], ax = sb, bx = c/2, alpha = alpha,
                 beta = beta)
o2 : mb.revolute_ground(th = rocker.q[2], ax = -c/2, x = d, alpha = alpha, beta = beta)
crank.a -> o1.a; crank.b -> pa.a; coupler.a -> pa.b; coupler.b -> pb.a
rocker.a -> pb.b; rocker.b -> o2.a
"""


def test_a_four_bar_of_rigid_links_and_revolute_joints_matches_models_four_bar():
    """Three rigid bodies and four revolute joints (9 coordinates, 8 constraint rows). Each
    link carries half the mass of each moving joint it ends at: the crank is m1/2 at O1 and
    m1/2 at A (mass m1 at its middle, inertia m1 a^2/4), the coupler m1/2 at A and m2/2 at B,
    the rocker m2/2 at B and m2/2 at O2. Rigidly joined, these masses move as the point
    masses m1 at A and m2 at B do, so kinetic and potential energy are those of
    models/four_bar.bg in every position of the loop: the joints' paths agree to 1e-9."""
    kw = dict(t_end=2.0, dt=0.05, rtol=1e-10, atol=1e-12, backend="python")
    t, Y, _ = bgc.simulate(Source("inline.bg", FOUR_BAR_RIGID), None,
                           outputs=["crank.q", "coupler.q", "rocker.q"], **kw)
    t0, Y0, _ = bgc.simulate(ROOT / "models" / "four_bar.bg", None, outputs=["q"], **kw)
    np.testing.assert_array_equal(t, t0)
    a, b, c = 1.0, 2.0, 1.5

    def point(body, s):  # the point (s, 0) of a body, in the plane
        x, y, th = Y[:, 3 * body], Y[:, 3 * body + 1], Y[:, 3 * body + 2]
        return np.c_[x + s * np.cos(th), y + s * np.sin(th)]
    A, B = point(0, a / 2), point(2, c / 2)
    assert np.abs(A - Y0[:, :2]).max() < 1e-9 and np.abs(B - Y0[:, 2:]).max() < 1e-9
    # the coupler's ends are the same joints
    assert np.abs(point(1, -b / 2) - A).max() < 1e-9 and np.abs(point(1, b / 2) - B).max() < 1e-9
    assert np.ptp(Y0[:, 0]) > 1.0  # the loop swings through a large angle


def _lagrange(positions, angles, masses, inertias, q0, t, g=9.81):
    """The motion in the coordinates q (sympy symbols, q0 their initial values, at rest) of
    bodies with centres positions(q) and angles(q), from Lagrange's equations (y down)."""
    q = sp.symbols(f"q0:{len(q0)}")
    dq = sp.symbols(f"dq0:{len(q0)}")
    r, a = positions(q), angles(q)
    vel = [sp.Matrix(ri).jacobian(q) * sp.Matrix(dq) for ri in r]
    w = [sp.Matrix([ai]).jacobian(q) * sp.Matrix(dq) for ai in a]
    T = sum(m * (v.T * v)[0] / 2 + j * om[0] ** 2 / 2
            for m, j, v, om in zip(masses, inertias, vel, w))
    V = -g * sum(m * ri[1] for m, ri in zip(masses, r))
    L = T - V
    M = sp.hessian(T, dq)
    rest = sp.Matrix([L.diff(d) for d in dq]).jacobian(q) * sp.Matrix(dq) \
        - sp.Matrix([L.diff(x) for x in q])
    f_M, f_rest = sp.lambdify([q, dq], M, "numpy"), sp.lambdify([q, dq], rest, "numpy")
    n = len(q0)

    def rhs(_, y):
        acc = np.linalg.solve(np.array(f_M(y[:n], y[n:]), float),
                              -np.array(f_rest(y[:n], y[n:]), float).ravel())
        return np.concatenate([y[n:], acc])
    return reference(rhs, list(q0) + [0.0] * n, t)


def _rot(th, x, y):
    return [sp.cos(th) * x - sp.sin(th) * y, sp.sin(th) * x + sp.cos(th) * y]


SLIDER_CRANK = """model slider_crank_library "a slider-crank of three bodies, three pins and a guide"
import planar as mb
parameter r = 0.3; parameter l = 1.0; parameter g = 9.81; parameter theta0 = 0.4
parameter phi0 = asin(-r*sin(theta0)/l) "the rod's angle"
parameter ax = r*cos(theta0); parameter ay = r*sin(theta0) "the crank pin"
crank : mb.body(m = 2, j = 0.02, x0 = ax/2, y0 = ay/2, th0 = theta0, g = g)
rod : mb.body(m = 1, j = 0.1, x0 = ax + l/2*cos(phi0), y0 = ay + l/2*sin(phi0), th0 = phi0,
              g = g)
slider : mb.body(m = 3, j = 0.05, x0 = ax + l*cos(phi0), y0 = 0, g = g)
pivot : mb.revolute_ground(th = crank.q[2], ax = -r/2)
pin : mb.revolute(tha = crank.q[2], thb = rod.q[2], ax = r/2, bx = -l/2)
wrist : mb.revolute(tha = rod.q[2], thb = slider.q[2], ax = l/2)
guide : mb.prismatic_ground()
crank.a -> pivot.a; crank.b -> pin.a; rod.a -> pin.b; rod.b -> wrist.a
slider.a -> wrist.b; slider.b -> guide.a
"""


def _slider_crank_reference(t):
    """The crank angle from Lagrange's equation in that one coordinate (y down, gravity +y),
    the rod's angle and the slider's position functions of it."""
    r, l = 0.3, 1.0

    def positions(q):
        phi = sp.asin(-r * sp.sin(q[0]) / l)
        a = [r * sp.cos(q[0]), r * sp.sin(q[0])]
        return [[a[0] / 2, a[1] / 2], [a[0] + l / 2 * sp.cos(phi), a[1] + l / 2 * sp.sin(phi)],
                [a[0] + l * sp.cos(phi), sp.Integer(0)]]
    return _lagrange(positions, lambda q: [q[0], sp.asin(-r * sp.sin(q[0]) / l), sp.Integer(0)],
                     [2, 1, 3], [0.02, 0.1, 0.05], [0.4], t)[:, 0]


def test_a_slider_crank_of_library_parts_matches_its_lagrangian():
    t, Y = simulate(SLIDER_CRANK, ["crank.q[2]", "slider.q[0]", "guide.guide.residual[0]"],
                    t_end=1.5, dt=0.05, rtol=1e-11, atol=1e-13)
    theta = _slider_crank_reference(t)
    np.testing.assert_allclose(Y[:, 0], theta, rtol=0, atol=1e-8)
    phi = np.arcsin(-0.3 * np.sin(theta))
    np.testing.assert_allclose(Y[:, 1], 0.3 * np.cos(theta) + np.cos(phi), rtol=0, atol=1e-8)
    assert np.abs(Y[:, 2]).max() < 1e-9


DOUBLE = """model double_compound "two bodies, pins off their axes in both directions"
import planar as mb
parameter th1 = 0.4; parameter th2 = -0.3
parameter x1 = 0.1 - (cos(th1)*(-0.3) - sin(th1)*0.2)
parameter y1 = -0.05 - (sin(th1)*(-0.3) + cos(th1)*0.2)
parameter x2 = x1 + cos(th1)*0.25 - sin(th1)*(-0.15) - (cos(th2)*(-0.2) - sin(th2)*0.1)
parameter y2 = y1 + sin(th1)*0.25 + cos(th1)*(-0.15) - (sin(th2)*(-0.2) + cos(th2)*0.1)
upper : mb.body(m = 1.5, j = 0.04, x0 = x1, y0 = y1, th0 = th1, g = 9.81)
lower : mb.body(m = 0.8, j = 0.02, x0 = x2, y0 = y2, th0 = th2, g = 9.81)
top : mb.revolute_ground(th = upper.q[2], ax = -0.3, ay = 0.2, x = 0.1, y = -0.05)
knee : mb.revolute(tha = upper.q[2], thb = lower.q[2], ax = 0.25, ay = -0.15, bx = -0.2,
                   by = 0.1)
free : mb.force()
upper.a -> top.a; upper.b -> knee.a; lower.a -> knee.b; lower.b -> free.a
"""


def test_revolute_joints_off_the_axes_match_lagrange():
    """Pins at points with both coordinates nonzero on both bodies: every term of the
    revolute joints' Jacobians at work, against Lagrange's equations in the two angles."""
    t, Y = simulate(DOUBLE, ["upper.q[2]", "lower.q[2]", "lower.q[0]"], t_end=1.0,
                    rtol=1e-11, atol=1e-13)

    def positions(q):
        p1 = [0.1 - u for u in _rot(q[0], -0.3, 0.2)]
        knee = [p + u for p, u in zip(p1, _rot(q[0], 0.25, -0.15))]
        return [p1, [k - u for k, u in zip(knee, _rot(q[1], -0.2, 0.1))]]
    ref = _lagrange(positions, lambda q: [q[0], q[1]], [1.5, 0.8], [0.04, 0.02],
                    [0.4, -0.3], t)
    np.testing.assert_allclose(Y[:, :2], ref[:, :2], rtol=0, atol=1e-8)
    x2 = np.array([float(positions([a, b])[1][0]) for a, b in ref[:, :2]])
    np.testing.assert_allclose(Y[:, 2], x2, rtol=0, atol=1e-8)


INCLINE = """model incline
import planar as mb
parameter dir = 0.3; parameter s0 = 0.5
block : mb.body(m = 2, j = 0.1, x0 = 0.2 + s0*cos(dir), y0 = -0.1 + s0*sin(dir), th0 = 0.25,
                g = 9.81)
guide : mb.prismatic_ground(x = 0.2, y = -0.1, dir = dir, th0 = 0.25)
push : mb.force(fx = -3, fy = 1, tau = 5)
block.a -> guide.a; block.b -> push.a
"""


def test_a_body_on_an_inclined_guide_slides_as_a_closed_form():
    t, Y = simulate(INCLINE, ["block.q[0]", "block.q[1]", "block.q[2]"])
    d = 0.3
    acc = 9.81 * math.sin(d) + (-3 * math.cos(d) + 1 * math.sin(d)) / 2
    s = 0.5 + acc * t ** 2 / 2
    np.testing.assert_allclose(Y[:, 0], 0.2 + s * math.cos(d), rtol=0, atol=1e-9)
    np.testing.assert_allclose(Y[:, 1], -0.1 + s * math.sin(d), rtol=0, atol=1e-9)
    np.testing.assert_allclose(Y[:, 2], 0.25, rtol=0, atol=1e-9)  # the torque is held


FREE_BODY = """model thrown
import planar as mb
stone : mb.body(m = 2, j = 0.5, x0 = 1, y0 = -1, vx0 = 3, g = 9.81)
push : mb.force(fx = 1, fy = -4, tau = 0.25)
nothing : mb.force()
stone.a -> push.a; stone.b -> nothing.a
"""


def test_a_free_body_under_gravity_and_a_force():
    t, Y = simulate(FREE_BODY, ["stone.q[0]", "stone.q[1]", "stone.q[2]"])
    np.testing.assert_allclose(Y[:, 0], 1 + 3 * t + 0.5 * (1 / 2) * t ** 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Y[:, 1], -1 + 0.5 * (9.81 - 4 / 2) * t ** 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Y[:, 2], 0.5 * (0.25 / 0.5) * t ** 2, rtol=0, atol=1e-12)



# ------------------------------------------------------------------ switched parts
RECTIFIER = """model rectifier
import electrical as el
parameter V = 10; parameter w = 314.159; parameter R = 10; parameter L = 0.05
src : el.voltage_source(v = V*sin(w*t))
d : el.diode()
r : el.resistor(r = R)
l : el.inductor(l = L)
gnd : el.ground()
n1 : 0; n2 : 0; n3 : 0
src.p -> n1; n1 -> d.p; d.n -> n2; n2 -> r.p; r.n -> n3; n3 -> l.p; l.n -> gnd.p
"""


def test_a_diode_rectifies_as_the_closed_form():
    """Half-wave rectifier with an RL load: each period starts from zero current, conducts
    i = (V/Z)(sin(wt - phi) + sin(phi) exp(-t/tau)) until i falls to zero, then blocks."""
    from scipy.optimize import brentq
    t, Y = simulate(RECTIFIER, ["l.i.f", "d.d.e"], t_end=0.05, dt=0.0005)
    V, w, R, L = 10.0, 314.159, 10.0, 0.05
    Z, phi, tau, T = math.hypot(R, w * L), math.atan2(w * L, R), L / R, 2 * math.pi / w

    def on(s):
        return V / Z * (np.sin(w * s - phi) + math.sin(phi) * np.exp(-s / tau))
    t_off = brentq(on, T / 2, T)
    s = np.mod(t, T)
    ref = np.where(s < t_off, on(s), 0.0)
    assert np.max(np.abs(Y[:, 0] - ref)) < 1e-8 * V / R
    blocking = s > t_off + 1e-4
    assert np.all(Y[blocking, 0] == 0) and np.all(Y[blocking & (s < T / 2), 1] < 0)


SWITCHED_CAPACITORS = """model capacitors
import electrical as el
c1 : el.capacitor(c = 1, v0 = 3)
c2 : el.capacitor(c = 2)
r : el.resistor(r = 0.5)
s : el.ideal_switch(on = if t >= 1 then 1 else 0)
g1 : el.ground(); g2 : el.ground()
a : 0; b : 0; m : 0
a -> c1.p; c1.n -> g1.p; b -> c2.p; c2.n -> g2.p
a -> r.p; r.n -> m; m -> s.p; s.n -> b
"""


def test_a_switch_joins_two_capacitors_at_its_time():
    t, Y = simulate(SWITCHED_CAPACITORS, ["c1.store.q", "c2.store.q"], t_end=3.0, dt=0.01)
    tau = 0.5 * 1.0 * 2.0 / 3.0  # R C1 C2 / (C1 + C2)
    q2 = np.where(t < 1, 0.0, 2.0 * (1 - np.exp(-(t - 1) / tau)))
    np.testing.assert_allclose(Y[:, 1], q2, rtol=0, atol=1e-8)
    np.testing.assert_allclose(Y[:, 0] + Y[:, 1], 3.0, rtol=0, atol=1e-12)


SYNCHRONOUS_BUCK = """model sync_buck
import electrical as el
parameter f = 1e5
supply : el.voltage_source(v = 12)
high : el.switch_diode(on = square(1/f, 0.5))
low : el.switch_diode(on = 1 - square(1/f, 0.5))
coil : el.inductor(l = 1e-4)
cap : el.capacitor(c = 1e-5)
load : el.resistor(r = 50)
g1 : el.ground(); g2 : el.ground(); g3 : el.ground()
vin : 0; n : 0; out : 0; gn : 0
supply.p -> vin; vin -> high.p; high.n -> n; n -> low.p; low.n -> gn; gn -> g1.p
n -> coil.p; coil.n -> out; out -> cap.p; cap.n -> g2.p; out -> load.p; load.n -> g3.p
"""


SYNCHRONOUS_BUCK_LEG = """model sync_buck_leg
import electrical as el
parameter f = 1e5
supply : el.voltage_source(v = 12)
leg : el.half_bridge(high = square(1/f, 0.5), low = 1 - square(1/f, 0.5))
coil : el.inductor(l = 1e-4)
cap : el.capacitor(c = 1e-5)
load : el.resistor(r = 50)
g1 : el.ground(); g2 : el.ground(); g3 : el.ground()
vin : 0; out : 0; gn : 0
supply.p -> vin; vin -> leg.plus; leg.minus -> gn; gn -> g1.p
leg.out -> coil.p; coil.n -> out; out -> cap.p; cap.n -> g2.p; out -> load.p; load.n -> g3.p
"""


@pytest.mark.parametrize("text", [SYNCHRONOUS_BUCK, SYNCHRONOUS_BUCK_LEG], ids=["parts", "leg"])
def test_two_switches_with_their_diodes_make_a_synchronous_buck_converter(text):
    """A half-bridge of two switch_diodes driven in turn: the coil sees 12 V, then 0 V, and its
    current reverses through the low switch at light load (no discontinuous conduction): the
    exact solution is the matrix exponential of one linear circuit per half period."""
    from scipy.linalg import expm
    T, L, C, R = 1e-5, 1e-4, 1e-5, 50.0
    t, Y = simulate(text, ["coil.store.f", "cap.store.e"], t_end=20 * T, dt=T / 50)
    M = np.zeros((3, 3))
    M[:2, :2] = [[0, -1 / L], [1 / C, -1 / (R * C)]]

    def flow(x, v, h):
        M[0, 2] = v / L
        E = expm(M * h)
        return E[:2, :2] @ x + E[:2, 2]

    x, starts = np.zeros(2), []
    for k in range(20):
        starts += [(k * T, 12.0, x)]
        x = flow(x, 12.0, T / 2)
        starts += [((k + 0.5) * T, 0.0, x)]
        x = flow(x, 0.0, T / 2)
    at = np.array([s[0] for s in starts])
    exact = np.array([flow(starts[j][2], starts[j][1], tt - starts[j][0])
                      for tt, j in zip(t, np.searchsorted(at, t, side="right") - 1)])
    assert exact[:, 0].min() < -1  # the current does reverse
    for j in (0, 1):
        assert np.max(np.abs(Y[:, j] - exact[:, j])) < 1e-8 * np.max(np.abs(exact[:, j]))


FREEWHEEL = """model freewheel
import mechanics as mech
wheel : mech.inertia(j = 0.5)
pedals : mech.inertia(j = 0.2)
drag : mech.rotational_damper(d = 0.1)
push : mech.torque(tau = 1 - 2*step(1))
fw : mech.freewheel()
ground : mech.rotational_fixed()
w : 1; p : 1
w -> wheel.p; w -> drag.a; drag.b -> ground.p; w -> fw.a
push.p -> p; p -> pedals.p; fw.b -> p
"""


def test_a_freewheel_is_driven_then_overruns_as_the_closed_form():
    """The pedals push the wheel through the freewheel, locked: (Ja + Jb) w' = 1 - d w from
    rest; at t = 1 the push reverses, the freewheel cannot pull, and the two part: the wheel
    coasts against its drag, w = w1 exp(-d (t - 1)/Ja), the pedals decelerate at 1/Jb."""
    Ja, Jb, d = 0.5, 0.2, 0.1
    t, Y = simulate(FREEWHEEL, ["wheel.body.f", "pedals.body.f"], t_end=2.0, dt=0.01)
    w1 = (1 - math.exp(-d / (Ja + Jb))) / d
    together = (1 - np.exp(-d * t / (Ja + Jb))) / d
    wheel = np.where(t <= 1, together, w1 * np.exp(-d * (t - 1) / Ja))
    pedals = np.where(t <= 1, together, w1 - (t - 1) / Jb)
    np.testing.assert_allclose(Y[:, 0], wheel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(Y[:, 1], pedals, rtol=0, atol=1e-9)


AS_FLAT = [  # (the model of library parts, its plain counterpart in tests/models, t_end)
    ("hbridge_library.bg", "hbridge.bg", ".h_bridge(", 2e-4),
    ("one_way_clutch_library.bg", "one_way_clutch.bg", ".one_way_clutch(", 4.0),
]


@pytest.mark.parametrize("library, plain, used, t_end", AS_FLAT)
def test_bridges_and_clutches_of_library_parts_run_as_their_plain_models(library, plain, used,
                                                                         t_end):
    """Flattening is exact: the H-bridge drive of `el.h_bridge(` and the one-way clutch of
    `mech.one_way_clutch(` give the numbers of the same models written out flat (whose
    exact references tests/test_switching.py checks)."""
    models = ROOT / "tests" / "models"
    assert used in (models / library).read_text()
    runs = [simulated(models / name, "run", "python", t_end=t_end)[1]
            for name in (library, plain)]
    np.testing.assert_array_equal(runs[0], runs[1])


BRIDGE_PARTS = """model bridge_parts
import electrical as el
src : MSe(10*sin(314.159*t))
bridge : el.diode_bridge()
c : C(1e-3); r : R(100); p : 0
src -> bridge.ac; bridge.dc -> p; p -> c; p -> r
"""


def test_a_diode_bridge_rectifies_to_the_peak_while_it_charges():
    """From rest the capacitor follows |u| (two diodes conducting) while its current
    C d|u|/dt + |u|/R is positive: v = 10 |sin(w t)| up to the first peak."""
    t, Y = simulate(BRIDGE_PARTS, ["c.e"], t_end=4e-3, dt=1e-4)
    np.testing.assert_allclose(Y[:, 0], 10 * np.abs(np.sin(314.159 * t)), rtol=0, atol=1e-8)


KNEE = """model knee
import electrical as el
src : el.voltage_source(v = 5)
d : el.knee_diode(Ron = 1, Goff = 1e-3, Vknee = 0.7)
cap : el.capacitor(c = 1e-3)
gnd : el.ground()
top : 0; mid : 0; bot : 0
src.p -> top; top -> d.p; d.n -> mid; mid -> cap.p; cap.n -> bot; bot -> gnd.p
"""


def test_a_knee_diode_charges_a_capacitor_through_both_its_segments():
    """5 V through the diode into 1 mF from rest: above the knee, u = 5 - v - Vknee decays as
    u' = -(u/Ron + Goff Vknee)/C until it reaches 0 at t1 = Ron C ln((u0 + G V R)/(G V R));
    below, the leak charges on, 5 - v = Vknee exp(-Goff (t - t1)/C)."""
    Ron, Goff, Vk, C, V = 1.0, 1e-3, 0.7, 1e-3, 5.0
    t, Y = simulate(KNEE, ["cap.store.e"], t_end=0.5, dt=1e-3)
    gvr = Goff * Vk * Ron
    t1 = Ron * C * math.log((V - Vk + gvr) / gvr)
    above = (V - Vk + gvr) * np.exp(-t / (Ron * C)) - gvr
    v = np.where(t <= t1, V - Vk - above, V - Vk * np.exp(-Goff * (t - t1) / C))
    np.testing.assert_allclose(Y[:, 0], v, rtol=0, atol=1e-8)


B6 = """model b6
import electrical as el
parameter w = 314.1592653589793
star : 0
ua : Se(100*sin(w*t)); ub : Se(100*sin(w*t - 2.0943951023931953))
uc : Se(100*sin(w*t + 2.0943951023931953))
pa : 1; pb : 1; pc : 1
star -> pa; star -> pb; star -> pc; ua -> pa; ub -> pb; uc -> pc
pa -> bridge.a; pb -> bridge.b; pc -> bridge.c
bridge : el.b6_bridge(Ron = 0.01, Goff = 1e-5, Vknee = 0.7)
plus : 0
bridge.dc -> plus
load : R(20)
plus -> load
signal clock = integral(1, init = 0)
"""


def _b6_exact(t, Ron=0.01, Goff=1e-5, Vk=0.7, Rl=20.0):
    """The B6 bridge on a resistor, no storage: at each instant the star point's potential
    s and the plus rail's v from the two node laws (the phase currents add to zero; the
    upper diodes' currents feed the load), each diode on the segment of its law its voltage
    calls for, the 2^6 assignments tried in turn (the one consistent is the solution)."""
    def law(on):
        return (1 / Ron, (Goff - 1 / Ron) * Vk) if on else (Goff, 0.0)
    out = []
    for tk in t:
        V = 100 * np.sin(314.1592653589793 * tk + np.array([0, -1, 1]) * 2.0943951023931953)
        for bits in itertools.product((False, True), repeat=6):
            A, b = np.zeros((2, 2)), np.zeros(2)
            for n in range(3):  # upper: (V_n + s) - v; lower: 0 - (V_n + s)
                (Gu, cu), (Gl, cl) = law(bits[n]), law(bits[3 + n])
                A[0] += [Gu + Gl, -Gu]
                b[0] -= (Gu + Gl) * V[n] + cu - cl
                A[1] += [Gu, -Gu]
                b[1] -= Gu * V[n] + cu
            A[1, 1] -= 1 / Rl
            s, v = np.linalg.solve(A, b)
            volts = [V[n] + s - v for n in range(3)] + [-(V[n] + s) for n in range(3)]
            if all((u > Vk) == on for u, on in zip(volts, bits)):
                out.append(v)
                break
    return np.array(out)


def test_a_b6_bridge_on_a_resistor_follows_the_largest_line_voltage():
    """The rectified voltage over one mains period: the largest line-to-line voltage less
    two knees and the drops across Ron, against the network's solution at each instant."""
    t, Y = simulate(B6, ["load.e"], t_end=0.02, dt=2e-4)
    np.testing.assert_allclose(Y[:, 0], _b6_exact(t), rtol=0, atol=1e-8)
    assert np.ptp(Y[:, 0]) > 20  # (six pulses a period: the ripple of a B6)


STICK_SLIP = """model stick_slip
import mechanics as mech
parameter vb = 0.5
m : mech.mass(m = 1)
k : mech.spring(k = 10)
fr : mech.friction(fc = 2, fs = 3)
belt : mech.velocity(v = vb)
wall : mech.fixed()
v : 1; bj : 1
v -> m.p; v -> k.a; k.b -> wall.p; v -> fr.a; fr.b -> bj; belt.p -> bj
"""


def test_friction_sticks_to_a_belt_and_breaks_away_as_the_closed_form():
    """From rest the belt drags the mass, M x'' = -K x + Fc, until its speed reaches the
    belt's; stuck, it rides the belt until K x = Fs; then it slides back."""
    M, K, vb, Fc, Fs = 1.0, 10.0, 0.5, 2.0, 3.0
    w = math.sqrt(K / M)
    t_stick = math.asin(vb / (Fc / K * w)) / w
    x_stick = Fc / K * (1 - math.cos(w * t_stick))
    t_break = t_stick + (Fs / K - x_stick) / vb
    t, Y = simulate(STICK_SLIP, ["k.store.q", "fr.fr.f"], t_end=t_break + math.pi / w,
                    dt=0.01)
    after = t - t_break
    x = np.where(t < t_stick, Fc / K * (1 - np.cos(w * t)),
                 np.where(t < t_break, x_stick + vb * (t - t_stick),
                          Fc / K + (Fs - Fc) / K * np.cos(w * after) + vb / w * np.sin(w * after)))
    np.testing.assert_allclose(Y[:, 0], x, rtol=0, atol=1e-8)
    stuck = (t > t_stick) & (t < t_break)
    assert np.all(np.abs(Y[stuck, 1]) < 1e-12) and np.all(np.abs(Y[~stuck, 1][1:]) > 1e-3)


ROTATIONAL_SWITCHED = """model shafts
import mechanics as mech
# a flywheel spinning down against dry friction and a small torque, then held
wheel : mech.inertia(j = 0.5, w0 = 1.5)
fr : mech.rotational_friction(fc = 0.3, fs = 0.5)
brake : mech.torque(tau = -0.2)
wall : mech.rotational_fixed()
w : 1
brake.p -> w; w -> wheel.p; w -> fr.a; fr.b -> wall.p
# a shaft driven against a stop, resting on it, then pulled away
drive : mech.torque(tau = if t < 1.2 then 2 else -1)
rotor : mech.inertia(j = 0.25)
stop : mech.rotational_end_stop(gap0 = 0.5)
u : 1
drive.p -> u; u -> rotor.p; u -> stop.a
"""


def test_rotational_friction_and_a_plastic_end_stop_as_closed_forms():
    t, Y = simulate(ROTATIONAL_SWITCHED, ["w.f", "stop.gap", "stop.stop.lambda"], t_end=2.0,
                    dt=0.01)
    # the flywheel decelerates at (0.2 + 0.3)/0.5 until it stops at t = 1.5, then sticks
    np.testing.assert_allclose(Y[:, 0], np.maximum(1.5 - 1.0 * t, 0.0), rtol=0, atol=1e-9)
    # the rotor reaches the stop at sqrt(2 J gap0 / tau) = 0.25 s, rests on it (e = 0)
    # carrying the torque, and leaves it at t = 1.2 with the reversed torque
    t_hit = math.sqrt(2 * 0.25 * 0.5 / 2)
    gap = np.where(t < t_hit, 0.5 - 2 / 0.25 * t ** 2 / 2,
                   np.where(t < 1.2, 0.0, 1 / 0.25 * (t - 1.2) ** 2 / 2))
    np.testing.assert_allclose(Y[:, 1], gap, rtol=0, atol=1e-9)
    resting = (t > t_hit + 0.05) & (t < 1.2)
    np.testing.assert_allclose(np.abs(Y[resting, 2]), 2.0, rtol=1e-9)
    assert np.all(Y[t > 1.2, 2] == 0)


BOUNCE = """model bounce
import mechanics as mech
ball : mech.mass(m = 2)
weight : mech.force(f = 2*9.81)
floor : mech.end_stop(gap0 = 1, e = 0.8)
v : 1
weight.p -> v; v -> ball.p; v -> floor.a
"""


def test_an_end_stop_bounces_a_mass_as_the_closed_form():
    """Falling from a gap of 1 m: the first impact at sqrt(2/g), then flights of 2 e^k v1/g."""
    g, e = 9.81, 0.8
    t, Y = simulate(BOUNCE, ["floor.gap"], t_end=2.5, dt=0.01)
    t1 = math.sqrt(2 / g)
    ref, start, speed = np.where(t < t1, 1 - g * t ** 2 / 2, np.nan), t1, e * g * t1
    while start < t[-1]:
        flight = 2 * speed / g
        now = (t >= start) & (t < start + flight)
        ref[now] = speed * (t[now] - start) - g * (t[now] - start) ** 2 / 2
        start, speed = start + flight, e * speed
    np.testing.assert_allclose(Y[:, 0], ref, rtol=0, atol=1e-8)

# ------------------------------------------------------------------ the library's files
def test_every_library_component_is_documented_and_exercised():
    """Each component has a doc string, its ports a domain and a doc string, its parameters
    a unit (but a signal block's) and a doc string; each one is instantiated by a model of
    this file."""
    from bgc.front import ast
    from bgc.front.instantiate import LIBRARY
    from bgc.front.parser import parse
    here = Path(__file__).read_text()
    found = 0
    for path in sorted(LIBRARY.glob("*.bg")):
        decls = parse(path.read_text(), str(path)).decls
        assert isinstance(decls[0], ast.LibraryDecl) and decls[0].doc
        for comp in (d for d in decls if isinstance(d, ast.ComponentDecl)):
            found += 1
            name = f"{path.stem}.{comp.name.name}"
            assert comp.doc, name
            # (a signal block's inputs and outputs take the unit of what they are given)
            assert all((p.unit or path.stem == "blocks") and p.doc for p in comp.params), name
            ports = [d for d in comp.body if isinstance(d, ast.PortDecl)]
            assert all(p.domain is not None and p.doc for p in ports), name
            assert f".{comp.name.name}(" in here, f"{name} is not exercised"
    assert found >= 40


def test_a_component_parameter_cannot_be_named_t():
    with pytest.raises(bgc.BgcModelError, match=r"inline.bg:2:13: error: 't' is time and "
                                                "cannot be declared"):
        bgc.build(Source("inline.bg", "model m\ncomponent k(t = 1) { port p; s : Se(t); s -> p }"
                                      "\nx : k()\ny : C(1)\nx.p -> y\n"), program=False)


def test_docs_library_md_is_generated_from_the_library():
    """docs/library.md is tools/library_doc.py's output (run it after editing bgc/library)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("library_doc", ROOT / "tools" / "library_doc.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert (ROOT / "docs" / "library.md").read_text(encoding="utf-8") == module.page(), \
        "docs/library.md is out of date: run python tools/library_doc.py"
