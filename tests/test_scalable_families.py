"""The Modelica ScalableTestSuite's families as bond graphs (benchmarks/families.py, written with
components and `for` loops, the form benchmarks/scalable.py measures as they grow), each at a
small size against its reference: the matrix exponential of its linear equations written from
the circuit (heat conduction, the transmission line), or its closed form (the cascade of lags,
the oscillators)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import bgc
from bgc.api import Source
from helpers import families

scipy_linalg = pytest.importorskip("scipy.linalg")


def _run(text: str, scene: str, name: str):
    t, Y, names = bgc.simulate(Source(f"{name}.bg", text), scene)
    return np.asarray(t), {n: Y[:, k] for k, n in enumerate(names)}


def _affine(A, b, x0, t):
    """x(t) of x' = A x + b, x(0) = x0, by one matrix exponential of the augmented system."""
    n = len(x0)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    return np.array([(scipy_linalg.expm(M * s) @ np.append(x0, 1.0))[:n] for s in t])


def test_heat_line_matches_its_matrix_exponential():
    n = 8
    t, y = _run(families.heat_line(n), "cool", "heatline")
    X = _affine(*families.heat_line_matrices(n), t)
    for k, name in ((0, "cell[1].cap.e"), (n - 1, f"cell[{n}].cap.e")):
        assert np.max(np.abs(y[name] - X[:, k])) < 1e-7 * np.max(np.abs(X)), name


def test_transmission_line_matches_its_matrix_exponential():
    n = 6
    t, y = _run(families.transmission_line(n, t_end=12.0), "step", "line")
    X = _affine(*families.transmission_line_matrices(n), t)
    assert np.max(np.abs(y[f"sec[{n}].cap.e"] - X[:, 2 * n - 1])) < 1e-9  # (cc = 1, l = 1)
    assert np.max(np.abs(y["sec[1].coil.f"] - X[:, 0])) < 1e-9
    assert np.max(np.abs(X[:, 2 * n - 1])) > 0.1  # (the step has reached the load)


def test_cascaded_first_order_matches_its_closed_form():
    n = 8
    t, y = _run(families.cascaded_first_order(n), "step", "cascade")
    exact = families.cascaded_first_order_exact(n, t)
    assert np.max(np.abs(y[f"lag[{n}].cap.e"] - exact)) < 1e-9
    assert exact[-1] > 0.9


def test_harmonic_oscillators_match_their_closed_form():
    n = 5
    t, y = _run(families.harmonic_oscillators(n), "swing", "oscillators")
    for i in (1, n):
        w = math.sqrt(100.0 * (1 + i / n))
        assert np.max(np.abs(y[f"osc[{i}].spring.q"] - 0.01 * np.cos(w * t))) < 1e-10, i
