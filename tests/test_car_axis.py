"""The car axis problem of the Test Set for IVP Solvers (F. Mazzia and C. Magherini, University
of Bari; problem "caraxis", an index-3 DAE of dimension 10), written as a bond graph in scalar
bonds (models/car_axis.bg) and in vector bonds (models/car_axis_vector.bg): two constraint
junctions with Baumgarte PID correctors, one of them time-dependent through a flow
source.  Both forms in both backends against the test set's published reference solution at
t = 3, against each other, and against the constraints evaluated here from the positions."""
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from bgc import api
from bgc.base import toolchain
from bgc.front.graph import TIME, var

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])
FORMS = ["car_axis", "car_axis_vector"]

# The problem's data: eps, M, L, L0, r, w, g; the wheels' mass k = eps^2 M / 2.
EPS, M, L, L0, R, W, G = 1e-2, 10.0, 1.0, 0.5, 0.1, 10.0, 1.0
K = EPS**2 * M / 2

# The reference solution at t = 3 that the test set publishes with the problem (its Fortran
# problem file caraxis.f, the reference-solution routine; the same digits in the R package
# deTestSet, src/Ex_car.f): y = (xl, yl, xr, yr, xl', yl', xr', yr', lambda1, lambda2).
REF_POSITIONS = np.array([0.4934557842755629e-01, 0.4969894602303324e+00,
                          0.1041742524885400e+01, 0.3739110272652214e+00])
REF_VELOCITIES = np.array([-0.7705836840321485e-01, 0.7446866596327776e-02,
                           0.1755681574942899e-01, 0.7703410437794031e+00])
REF_MULTIPLIERS = np.array([-0.4736886750784630e-02, -0.1104680411345730e-02])

COLUMNS = {
    "car_axis": ["xl", "yl", "xr", "yr", "mxl.p", "myl.p", "mxr.p", "myr.p", "wheel.lambda",
                 "axle.lambda", "wheel.residual", "axle.residual"],
    "car_axis_vector": ["q[0]", "q[1]", "q[2]", "q[3]", "mass.p[0]", "mass.p[1]", "mass.p[2]",
                        "mass.p[3]", "links.lambda[0]", "links.lambda[1]", "links.residual[0]",
                        "links.residual[1]"],
}


@lru_cache(maxsize=None)
def run(form, backend):
    """The scene 'bump': 0 .. 3 every 0.01, dop853 at rtol 1e-10, atol 1e-12."""
    t, Y, names = api.simulate(MODELS / f"{form}.bg", "bump", backend=backend)
    assert names == COLUMNS[form]
    return t, Y


def split(Y):
    """Positions, velocities (p / k), the test set's multipliers, and bgc's residuals.  The
    graph's multipliers act through J^T with the opposite sign of the test set's
    (k u' = F + weight - J^T lambda in the graph, + J^T lambda in the test set)."""
    return Y[:, :4], Y[:, 4:8] / K, -Y[:, 8:10], Y[:, 10:12]


def constraints(t, q, u):
    """Phi1 = xb xl + yb yl, Phi2 = (xl - xr)^2 + (yl - yr)^2 - L^2 and their rates, with
    (xb, yb) = (sqrt(L^2 - yb^2), r sin(w t)), from the positions and velocities."""
    yb = R * np.sin(W * t)
    xb = np.sqrt(L**2 - yb**2)
    dyb = R * W * np.cos(W * t)
    dxb = -yb * dyb / xb
    xl, yl, xr, yr = q.T
    ul, vl, ur, vr = u.T
    phi = np.column_stack([xb * xl + yb * yl, (xl - xr)**2 + (yl - yr)**2 - L**2])
    dphi = np.column_stack([xb * ul + yb * vl + dxb * xl + dyb * yl,
                            2 * (xl - xr) * (ul - ur) + 2 * (yl - yr) * (vl - vr)])
    return phi, dphi


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("form", FORMS)
def test_car_axis_reaches_the_test_set_reference_at_t3(form, backend):
    t, Y = run(form, backend)
    assert t[0] == 0.0 and t[-1] == 3.0 and len(t) == 301
    q, u, lam, _ = split(Y)
    assert np.abs(q[-1] / REF_POSITIONS - 1).max() < 1e-6  # the requirement
    assert np.abs(u[-1] / REF_VELOCITIES - 1).max() < 1e-6
    assert np.abs(lam[-1] / REF_MULTIPLIERS - 1).max() < 1e-6


@pytest.mark.parametrize("backend", BACKENDS)
def test_scalar_and_vector_forms_agree(backend):
    t, Ys = run("car_axis", backend)
    tv, Yv = run("car_axis_vector", backend)
    assert np.array_equal(t, tv)
    scale = np.abs(Ys[:, :10]).max(axis=0)  # positions, momenta, multipliers
    assert (np.abs(Ys[:, :10] - Yv[:, :10]).max(axis=0) / scale).max() < 1e-9
    assert np.abs(Ys[:, 10:] - Yv[:, 10:]).max() < 1e-12  # the residuals


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("form", FORMS)
def test_car_axis_keeps_its_constraints(form, backend):
    """Both constraints and their rates, evaluated here, stay near zero over the run; the
    residuals bgc reports are the same Phi."""
    t, Y = run(form, backend)
    q, u, _, residual = split(Y)
    phi, dphi = constraints(t, q, u)
    assert np.abs(phi).max() < 1e-9
    assert np.abs(dphi).max() < 1e-8
    assert np.abs(residual - phi).max() < 1e-13


@pytest.mark.parametrize("form, rows", [("car_axis", ("wheel", "axle")),
                                        ("car_axis_vector", ("links[0]", "links[1]"))])
def test_time_dependent_row_is_holonomic_with_the_published_phi(form, rows):
    """The flow source's partial in t makes the first row's balance a closed form in (q, t):
    holonomic, Phi1 = sqrt(L^2 - r^2 sin^2(w t)) xl + r sin(w t) yl (with init = 0)."""
    reduced = api.build(MODELS / f"{form}.bg", "bump", program=False).reduced
    by_name = {c.junction: c for c in reduced.constraints}
    names = ("xl", "yl", "xr", "yr") if form == "car_axis" else ("q[0]", "q[1]", "q[2]", "q[3]")
    xl, yl, xr, yr = (var(n) for n in names)
    Ls, rs, ws = var("L"), var("r"), var("w")
    yb = rs * sp.sin(ws * TIME)
    expected = [sp.sqrt(Ls**2 - yb**2) * xl + yb * yl, (xl - xr)**2 + (yl - yr)**2 - Ls**2]
    for row, phi in zip(rows, expected):
        c = by_name[row]
        assert c.kind == "holonomic"
        assert sp.simplify(c.phi - phi) == 0
