"""The example models in models/ against references that owe nothing to bgc.

Each model's equations are derived here by hand, from the physics, and solved in two
independent ways:

* a closed form (exact solution of the hand-derived equations), and
* an ODE right-hand side written out as plain numpy, integrated with
  scipy's DOP853 at rtol 1e-12, atol 1e-14.

`bgc.simulate` is compared with the closed form, column by column, in both backends:
max|bgc - ref| <= 1e-6 * max(1, max|ref|). tests/test_reference_selfcheck.py checks
that the closed forms and the ODE references agree with each other (it needs no bgc).

Sign conventions follow docs/language.md: the half-arrow points the way power flows; at a
1-junction the efforts of the bonds pointing in sum to those of the bonds pointing out;
at a 0-junction likewise for flows; TF/MTF: e_in = n e_out, f_out = n f_in;
GY: e_in = r f_out, e_out = r f_in; a constraint 0-junction's flow balance (in minus out)
is the constraint and its effort is the multiplier lambda.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

MODELS = Path(__file__).resolve().parent.parent / "models"
REF_RTOL = 1e-12
REF_ATOL = 1e-14
TOLERANCE = 1e-6  # bgc against the reference, relative to max(1, max|ref|)

Params = dict[str, float]
Columns = dict[str, np.ndarray]


def integrate(rhs: Callable, y0, t: np.ndarray, P: Params) -> np.ndarray:
    """DOP853 at the reference tolerances, sampled at t; returns shape (len(t), len(y0))."""
    sol = solve_ivp(lambda tt, yy: rhs(tt, yy, P), (t[0], t[-1]), np.asarray(y0, float),
                    method="DOP853", rtol=REF_RTOL, atol=REF_ATOL, t_eval=t)
    assert sol.success, sol.message
    return sol.y.T


# ----------------------------------------------------------------------------- rlc
# Bond graph: supply(Se) -> mesh(1) -> ind(I), cap(C), res(R).
# One common current i = ind.f = ind.p/L. Efforts at the 1-junction (supply in; ind, cap,
# res out):  V0 = dp/dt + q/C + R i.  States p (flux linkage) and q (charge):
#     dq/dt = p/L
#     dp/dt = V0 - q/C - R p/L
# i.e. L q'' + R q' + q/C = V0: underdamped for R^2 < 4L/C.
RLC_DEFAULTS: Params = dict(V0=1.0, resistance=0.5, inductance=1.0, capacitance=0.25,
                            q0=0.1, i0=-0.2)


def rlc_rhs(t, s, P):
    q, p = s
    L, C, R = P["inductance"], P["capacitance"], P["resistance"]
    return [p / L, P["V0"] - q / C - R * p / L]


def rlc_columns(q, p, P) -> Columns:
    i = p / P["inductance"]
    return {"cap.q": q, "cap.e": q / P["capacitance"], "ind.p": p, "ind.f": i,
            "res.e": P["resistance"] * i}


def rlc_ode(t, P) -> Columns:
    s = integrate(rlc_rhs, [P["q0"], P["inductance"] * P["i0"]], t, P)
    return rlc_columns(s[:, 0], s[:, 1], P)


def rlc_closed(t, P) -> Columns:
    # q = C V0 + exp(-sigma t) (A cos(wd t) + B sin(wd t)), sigma = R/2L,
    # wd = sqrt(1/LC - sigma^2); q(0) = q0 gives A, q'(0) = i0 gives B.
    L, C, R, V = P["inductance"], P["capacitance"], P["resistance"], P["V0"]
    sigma = R / (2 * L)
    wd = math.sqrt(1 / (L * C) - sigma**2)
    A = P["q0"] - C * V
    B = (P["i0"] + sigma * A) / wd
    decay, c, s = np.exp(-sigma * t), np.cos(wd * t), np.sin(wd * t)
    q = C * V + decay * (A * c + B * s)
    i = decay * ((wd * B - sigma * A) * c - (wd * A + sigma * B) * s)
    return rlc_columns(q, L * i, P)


# ------------------------------------------------------------------------ dc_motor
# Bond graph: supply(Se) -> elec(1) -> res(R), ind(I), motor(GY) -> shaft(1) -> rotor(I),
# friction(R), load(Se, taking power in).
# elec (common current i = pL/La):  V = Ra i + dpL/dt + e_gy_in,  e_gy_in = kt w   (GY)
# shaft (common speed w = pJ/Jr):   e_gy_out = kt i = dpJ/dt + br w + tau_load
#     dpL/dt   = V - Ra pL/La - kt pJ/Jr
#     dpJ/dt   = kt pL/La - br pJ/Jr - tau_load
#     dangle/dt = pJ/Jr
# Linear with constant input: z' = A z + u, solved exactly with the matrix exponential of
# the augmented matrix [[A, u], [0, 0]].
DC_MOTOR_DEFAULTS: Params = dict(V=12.0, Ra=2.0, La=0.5, kt=0.8, Jr=0.05, br=0.1,
                                 tau_load=0.5, i0=0.0, w0=0.0)


def dc_motor_rhs(t, s, P):
    pL, pJ, _angle = s
    i, w = pL / P["La"], pJ / P["Jr"]
    return [P["V"] - P["Ra"] * i - P["kt"] * w,
            P["kt"] * i - P["br"] * w - P["tau_load"],
            w]


def dc_motor_columns(pL, pJ, angle, P) -> Columns:
    return {"ind.f": pL / P["La"], "rotor.f": pJ / P["Jr"], "ind.p": pL, "rotor.p": pJ,
            "angle": angle}


def dc_motor_init(P):
    return [P["La"] * P["i0"], P["Jr"] * P["w0"], 0.0]


def dc_motor_ode(t, P) -> Columns:
    s = integrate(dc_motor_rhs, dc_motor_init(P), t, P)
    return dc_motor_columns(s[:, 0], s[:, 1], s[:, 2], P)


def dc_motor_closed(t, P) -> Columns:
    Ra, La, kt, Jr, br = P["Ra"], P["La"], P["kt"], P["Jr"], P["br"]
    aug = np.array([[-Ra / La, -kt / Jr, 0.0, P["V"]],
                    [kt / La, -br / Jr, 0.0, -P["tau_load"]],
                    [0.0, 1.0 / Jr, 0.0, 0.0],
                    [0.0, 0.0, 0.0, 0.0]])
    z0 = np.array(dc_motor_init(P) + [1.0])
    return dc_motor_columns(*_linear_flow(aug, z0, np.asarray(t, float))[:3], P)


def _linear_flow(A, z0, t):
    """z(t) = expm(A t) z0 on the times t (rows of the result: the components).  On a
    uniform grid from 0 (to 1e-13 of its end) the exact step propagator, expm(A h) once and
    applied step after step (each step rounds at about 1e-16: the references agree to 1e-13,
    far inside the tolerances they are compared at); elsewhere one batched expm."""
    grid = np.linspace(0.0, t[-1], len(t)) if len(t) > 2 else None
    if grid is not None and np.all(np.abs(t - grid) <= 1e-13 * abs(t[-1])):
        h = t[-1] / (len(t) - 1)
        step = expm(A * h)
        z = np.empty((len(t), len(z0)))
        z[0] = z0
        for k in range(1, len(t)):
            z[k] = step @ z[k - 1]
        return z.T
    return (expm(A[None, :, :] * t[:, None, None]) @ z0).T  # one batched call


# ------------------------------------------------------------------- parallel_caps
# Bond graph: supply(Se) -> feed(1) -> r(R); feed -> node(0) -> c1(C), c2(C).
# node: one voltage e = q1/C1 = q2/C2, so c2 is in derivative causality (q2 = C2 q1/C1).
# feed (common current i): V0 = Rs i + e  ->  i = (V0 - e)/Rs.
# node (flows): i = dq1/dt + dq2/dt = (C1 + C2) de/dt.  State q1:
#     dq1/dt = C1/(C1 + C2) * (V0 - q1/C1)/Rs
# Closed form: e = V0 + (v0 - V0) exp(-t/tau), tau = Rs (C1 + C2).
PARALLEL_CAPS_DEFAULTS: Params = dict(V0=5.0, Rs=2.0, C1=0.5, C2=1.5, v0=1.0)


def parallel_caps_rhs(t, s, P):
    (q1,) = s
    e = q1 / P["C1"]
    return [P["C1"] / (P["C1"] + P["C2"]) * (P["V0"] - e) / P["Rs"]]


def parallel_caps_columns(e, P) -> Columns:
    i = (P["V0"] - e) / P["Rs"]
    return {"c1.q": P["C1"] * e, "c2.q": P["C2"] * e, "c1.e": e, "c2.e": e,
            "c2.f": P["C2"] / (P["C1"] + P["C2"]) * i, "r.f": i}


def parallel_caps_ode(t, P) -> Columns:
    s = integrate(parallel_caps_rhs, [P["C1"] * P["v0"]], t, P)
    return parallel_caps_columns(s[:, 0] / P["C1"], P)


def parallel_caps_closed(t, P) -> Columns:
    tau = P["Rs"] * (P["C1"] + P["C2"])
    e = P["V0"] + (P["v0"] - P["V0"]) * np.exp(-t / tau)
    return parallel_caps_columns(e, P)


# -------------------------------------------------------------------------- ladder
# Bond graph: supply(Se) -> s1(1) -> n2(0) -> s3(1) -> n4(0) -> s5(1) -> n6(0) -> cap(C),
# with r1 on s1, r2 on n2, r3 on s3, r4 on n4, r5 on s5 (series, shunt, series, shunt, series).
# Node voltages v2 (= r2.e), v4 (= r4.e), vC = q/Cc. Kirchhoff's current law at n2 and n4:
#     (V0 - v2)/R1 = v2/R2 + (v2 - v4)/R3
#     (v2 - v4)/R3 = v4/R4 + (v4 - vC)/R5
# a 2x2 linear system (the resistors' algebraic loop); then dq/dt = (v4 - vC)/R5.
# Closed form: Thevenin. Source + R1 | R2: Vt1 = V0 R2/(R1+R2), Rt1 = R1 R2/(R1+R2);
# + R3 in series, then | R4: Vt = Vt1 R4/(Rt1+R3+R4), Rt = (Rt1+R3) R4/(Rt1+R3+R4);
# + R5: vC = Vt + (v0 - Vt) exp(-t/tau), tau = (Rt + R5) Cc. The node voltages follow by
# walking back from the capacitor: i5 = (Vt - vC)/(Rt + R5), v4 = vC + R5 i5,
# i3 = i5 + v4/R4, v2 = v4 + R3 i3, i1 = i3 + v2/R2.
LADDER_DEFAULTS: Params = dict(V0=10.0, R1=1.0, R2=2.0, R3=1.5, R4=3.0, R5=0.5, Cc=0.2,
                               v0=0.0)


def ladder_nodes(vC, P):
    """v2, v4 from the nodal equations (the algebraic loop), for scalar vC."""
    R1, R2, R3, R4, R5 = (P[k] for k in ("R1", "R2", "R3", "R4", "R5"))
    G = np.array([[1 / R1 + 1 / R2 + 1 / R3, -1 / R3],
                  [-1 / R3, 1 / R3 + 1 / R4 + 1 / R5]])
    v2, v4 = np.linalg.solve(G, [P["V0"] / R1, vC / R5])
    return v2, v4


def ladder_rhs(t, s, P):
    vC = s[0] / P["Cc"]
    _v2, v4 = ladder_nodes(vC, P)
    return [(v4 - vC) / P["R5"]]


def ladder_ode(t, P) -> Columns:
    s = integrate(ladder_rhs, [P["Cc"] * P["v0"]], t, P)
    vC = s[:, 0] / P["Cc"]
    v2, v4 = np.array([ladder_nodes(v, P) for v in vC]).T
    return {"cap.e": vC, "cap.q": P["Cc"] * vC, "r1.f": (P["V0"] - v2) / P["R1"],
            "r2.e": v2, "r3.f": (v2 - v4) / P["R3"], "r4.e": v4}


def ladder_closed(t, P) -> Columns:
    R1, R2, R3, R4, R5 = (P[k] for k in ("R1", "R2", "R3", "R4", "R5"))
    Vt1, Rt1 = P["V0"] * R2 / (R1 + R2), R1 * R2 / (R1 + R2)
    Vt, Rt = Vt1 * R4 / (Rt1 + R3 + R4), (Rt1 + R3) * R4 / (Rt1 + R3 + R4)
    tau = (Rt + R5) * P["Cc"]
    vC = Vt + (P["v0"] - Vt) * np.exp(-t / tau)
    i5 = (Vt - vC) / (Rt + R5)
    v4 = vC + R5 * i5
    i3 = i5 + v4 / R4
    v2 = v4 + R3 * i3
    i1 = i3 + v2 / R2
    return {"cap.e": vC, "cap.q": P["Cc"] * vC, "r1.f": i1, "r2.e": v2, "r3.f": i3,
            "r4.e": v4}


# ---------------------------------------------------------------------- knife_edge
# Coordinates x (across the slope), y (down the slope), heading th from the x axis.
# Bond graph: vx(1) -> mx(I), vy(1) -> my(I), w(1) -> spin(I); weight(Se) -> vy;
# vx -> tx(MTF -sin th) -> blade(0, constraint), vy -> ty(MTF cos th) -> blade.
# Constraint (flow balance at blade, both bonds point in):
#     Phi = -sin(th) xd + cos(th) yd = 0
# MTF e_in = n e_out with e_out = lambda: the vx bond into tx carries -sin(th) lambda,
# the vy bond into ty carries cos(th) lambda. 1-junction effort balances:
#     vx: 0 = dpx/dt + (-sin th) lambda            ->  dpx/dt = sin(th) lambda
#     vy: m gs = dpy/dt + cos(th) lambda           ->  dpy/dt = m gs - cos(th) lambda
#     w:  0 = dpth/dt                              ->  th = th0 + omega0 t
# with gs = g sin(incline) and xd = px/m, yd = py/m, w = pth/Jz.
# dPhi/dt = -w (cos th xd + sin th yd) - sin th xdd + cos th ydd
#         = -w (cos th xd + sin th yd) + gs cos th - lambda/m.
# Baumgarte PD (corrector pd(gamma)): dPhi/dt + gamma Phi = 0 gives
#     lambda = m [gs cos th - w (cos th xd + sin th yd) + gamma Phi].
# Closed form (Phi = 0): v = cos th xd + sin th yd, the speed along the blade, obeys
# dv/dt = -w sin th xd + cos th xdd + w cos th yd + sin th ydd = gs sin th + w Phi = gs sin th,
# so v = A - B cos th, A = v0 + gs cos(th0)/omega0, B = gs/omega0, and xd = v cos th,
# yd = v sin th integrate to
#     x = x0 + A/w (sin th - sin th0) - B [t/2 + (sin 2th - sin 2th0)/(4 w)]
#     y = y0 - A/w (cos th - cos th0) - B (sin^2 th - sin^2 th0)/(2 w)
#     lambda = m (gs cos th - omega0 v).
# The sled drifts across the slope at mean speed -B/2 while its y motion stays bounded.
KNIFE_EDGE_DEFAULTS: Params = dict(m=1.0, Jz=0.2, g=9.81, incline=0.3, v0=0.5, omega0=2.0,
                                   th0=0.3, x0=0.0, y0=0.0, gamma=10.0)


def knife_edge_params(P: Params) -> Params:
    """Add the derived parameter g_slope = g sin(incline), as the model defines it."""
    return {**P, "g_slope": P["g"] * math.sin(P["incline"])}


def knife_edge_rhs(t, s, P):
    x, y, th, px, py, pth = s
    m = P["m"]
    xd, yd, w = px / m, py / m, pth / P["Jz"]
    c, sn = math.cos(th), math.sin(th)
    phi = -sn * xd + c * yd
    lam = m * (P["g_slope"] * c - w * (c * xd + sn * yd) + P["gamma"] * phi)
    return [xd, yd, w, sn * lam, m * P["g_slope"] - c * lam, 0.0]


def knife_edge_ode(t, P) -> Columns:
    m, th0, v0 = P["m"], P["th0"], P["v0"]
    s0 = [P["x0"], P["y0"], th0, m * v0 * math.cos(th0), m * v0 * math.sin(th0),
          P["Jz"] * P["omega0"]]
    s = integrate(knife_edge_rhs, s0, t, P)
    x, y, th = s[:, 0], s[:, 1], s[:, 2]
    xd, yd, w = s[:, 3] / m, s[:, 4] / m, s[:, 5] / P["Jz"]
    c, sn = np.cos(th), np.sin(th)
    phi = -sn * xd + c * yd
    lam = m * (P["g_slope"] * c - w * (c * xd + sn * yd) + P["gamma"] * phi)
    return {"x": x, "y": y, "th": th, "vx.f": xd, "vy.f": yd, "blade.lambda": lam,
            "blade.residual": phi}


def knife_edge_closed(t, P) -> Columns:
    gs, w, th0 = P["g_slope"], P["omega0"], P["th0"]
    th = th0 + w * t
    A = P["v0"] + gs * math.cos(th0) / w
    B = gs / w
    v = A - B * np.cos(th)
    x = (P["x0"] + A / w * (np.sin(th) - math.sin(th0))
         - B * (t / 2 + (np.sin(2 * th) - math.sin(2 * th0)) / (4 * w)))
    y = (P["y0"] - A / w * (np.cos(th) - math.cos(th0))
         - B * (np.sin(th) ** 2 - math.sin(th0) ** 2) / (2 * w))
    return {"x": x, "y": y, "th": th, "vx.f": v * np.cos(th), "vy.f": v * np.sin(th),
            "blade.lambda": P["m"] * (gs * np.cos(th) - w * v),
            "blade.residual": np.zeros_like(t)}


# --------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class Model:
    """A model file, its parameter defaults and its two independent references."""
    file: str
    defaults: Params
    closed: Callable[[np.ndarray, Params], Columns]
    ode: Callable[[np.ndarray, Params], Columns]
    derive: Callable[[Params], Params] = lambda P: P


MODEL_REFS = {
    "rlc": Model("rlc.bg", RLC_DEFAULTS, rlc_closed, rlc_ode),
    "dc_motor": Model("dc_motor.bg", DC_MOTOR_DEFAULTS, dc_motor_closed, dc_motor_ode),
    "parallel_caps": Model("parallel_caps.bg", PARALLEL_CAPS_DEFAULTS, parallel_caps_closed,
                           parallel_caps_ode),
    "ladder": Model("ladder.bg", LADDER_DEFAULTS, ladder_closed, ladder_ode),
    "knife_edge": Model("knife_edge.bg", KNIFE_EDGE_DEFAULTS, knife_edge_closed,
                        knife_edge_ode, knife_edge_params),
}

KNIFE_OUTPUTS = ("x", "y", "th", "vx.f", "vy.f", "blade.lambda", "blade.residual")


@dataclass(frozen=True)
class Case:
    """One simulation: model, scene, run-time overrides, and what the scene means for the
    reference (its `set` lines and the effects it leaves out, as parameter values)."""
    model: str
    scene: str
    outputs: tuple[str, ...]
    time: tuple[float, float, float]  # t0, t_end, every
    params: Params = field(default_factory=dict)
    scene_means: Params = field(default_factory=dict)

    @property
    def id(self) -> str:
        extra = ",".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.model}-{self.scene}" + (f"[{extra}]" if extra else "")

    def reference_params(self) -> Params:
        ref = MODEL_REFS[self.model]
        return ref.derive({**ref.defaults, **self.scene_means, **self.params})


CASES = [
    Case("rlc", "step", ("cap.q", "cap.e", "ind.p", "ind.f", "res.e"), (0, 10, 0.01)),
    Case("rlc", "step", ("cap.q", "cap.e", "ind.p", "ind.f", "res.e"), (0, 10, 0.01),
         params={"resistance": 1.5, "i0": 0.3}),
    Case("dc_motor", "run", ("ind.f", "rotor.f", "ind.p", "rotor.p", "angle"), (0, 5, 0.01)),
    Case("dc_motor", "noload", ("ind.f", "rotor.f", "angle"), (0, 5, 0.01),
         scene_means={"tau_load": 0.0}),
    Case("dc_motor", "high_voltage", ("ind.f", "rotor.f", "angle"), (0, 5, 0.01),
         scene_means={"V": 24.0}),
    Case("parallel_caps", "charge", ("c1.q", "c2.q", "c1.e", "c2.e", "c2.f", "r.f"),
         (0, 20, 0.05)),
    Case("parallel_caps", "charge", ("c1.q", "c2.q", "c1.e", "c2.e", "c2.f", "r.f"),
         (0, 20, 0.05), params={"C2": 0.25, "v0": 3.0}),
    Case("ladder", "charge", ("cap.e", "cap.q", "r1.f", "r2.e", "r3.f", "r4.e"), (0, 3, 0.01)),
    Case("ladder", "charge", ("cap.e", "cap.q", "r1.f", "r2.e", "r3.f", "r4.e"), (0, 3, 0.01),
         params={"R3": 0.2, "v0": 2.0}),
    Case("knife_edge", "slide", KNIFE_OUTPUTS, (0, 10, 0.01)),
    # g_slope is defined from incline: overriding incline must recompute it.
    Case("knife_edge", "slide", KNIFE_OUTPUTS, (0, 10, 0.01), params={"incline": 0.6}),
    # Without the corrector the exact solution is the same (Phi(0) = 0 and dPhi/dt = 0).
    Case("knife_edge", "unstabilised", KNIFE_OUTPUTS, (0, 10, 0.01),
         scene_means={"gamma": 0.0}),
    # Without gravity (the weight source left out) the sled runs round a circle.
    Case("knife_edge", "flat", KNIFE_OUTPUTS, (0, 10, 0.01), scene_means={"g": 0.0}),
]


def assert_columns_match(got: Columns, ref: Columns, t: np.ndarray, what: str,
                         tolerance: float = TOLERANCE) -> None:
    """max|got - ref| <= tolerance * max(1, max|ref|) for every column of ref."""
    failures = []
    for name, r in ref.items():
        g = np.asarray(got[name], float)
        err = np.abs(g - r)
        bound = tolerance * max(1.0, float(np.max(np.abs(r))))
        worst = int(np.argmax(err))
        if not err[worst] <= bound:  # also catches NaN
            failures.append(f"{name}: max|got-ref| = {err[worst]:.3e} > {bound:.3e} at "
                            f"t = {t[worst]:.6g} (got {g[worst]!r}, expected {r[worst]!r})")
    assert not failures, f"{what}:\n  " + "\n  ".join(failures)


# --------------------------------------------------------------------------- tests
@pytest.mark.parametrize("backend", ["c", "python"])
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_model_matches_reference(case: Case, backend: str) -> None:
    import bgc
    import bgc.base.toolchain

    if backend == "c":
        if not bgc.base.toolchain.have_c_compiler():
            pytest.skip("no C compiler")
    kwargs = {"scene": case.scene, "backend": backend}
    if case.params:
        kwargs["params"] = dict(case.params)
    t, Y, names = bgc.simulate(str(MODELS / MODEL_REFS[case.model].file), **kwargs)
    t, Y = np.asarray(t, float), np.asarray(Y, float)

    assert list(names) == list(case.outputs)
    t0, t_end, every = case.time
    n = int(round((t_end - t0) / every)) + 1
    assert t.shape == (n,) and Y.shape == (n, len(case.outputs))
    np.testing.assert_allclose(t, np.linspace(t0, t_end, n), rtol=0, atol=1e-9 * t_end)

    ref = MODEL_REFS[case.model].closed(t, case.reference_params())
    got = {name: Y[:, k] for k, name in enumerate(names)}
    assert_columns_match(got, {name: ref[name] for name in case.outputs}, t,
                         f"{case.id} ({backend} backend) vs closed form")


_NUMERIC_PARAMETER = re.compile(
    r"^parameter\s+([A-Za-z_]\w*)\s*=\s*(-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(?:\"|#|$)",
    re.MULTILINE)


@pytest.mark.parametrize("model", sorted(MODEL_REFS))
def test_reference_defaults_match_model_file(model: str) -> None:
    """The references use the same default parameter values as the .bg files."""
    ref = MODEL_REFS[model]
    text = (MODELS / ref.file).read_text(encoding="utf-8")
    in_file = {name: float(value) for name, value in _NUMERIC_PARAMETER.findall(text)}
    assert in_file == ref.defaults
