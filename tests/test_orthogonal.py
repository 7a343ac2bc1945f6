"""bgc.symbolic.orthogonal: the analysis commands' least squares, every sum in sequence."""
import math
import random

import numpy as np
import pytest

from bgc.symbolic import orthogonal


def test_total_adds_in_sequence_as_python_does():
    """numpy.sum adds pairwise; total must add left to right, as Python's sum of floats does
    (values of many magnitudes, so that any other order rounds differently)."""
    rng = random.Random(3)
    x = [rng.uniform(-1, 1) * 10.0 ** rng.randint(-8, 8) for _ in range(1000)]
    seq = 0.0
    for v in x:
        seq += v
    assert orthogonal.total(np.array(x)) == seq
    assert np.sum(np.array(x)) != seq  # the data tells the orders apart
    cols = np.array(x).reshape(250, 4)
    for j in range(4):
        s = 0.0
        for v in cols[:, j]:
            s += v
        assert orthogonal.total(cols)[j] == s
    assert orthogonal.norm([3.0, 4.0]) == 5.0
    assert orthogonal.total(np.zeros(0)) == 0.0


@pytest.mark.parametrize("m,n,r", [(5, 5, 5), (9, 5, 5), (5, 9, 5), (9, 6, 3), (6, 6, 0),
                                   (12, 4, 2), (3, 8, 2), (1, 1, 1), (40, 30, 30)])
def test_least_norm_solution_and_rank_are_lapacks(m, n, r):
    rng = np.random.default_rng(m * 100 + n * 10 + r)
    A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n)) if r else np.zeros((m, n))
    b = rng.standard_normal(m)
    x, rank = orthogonal.lstsq(A, b)
    assert rank == np.linalg.matrix_rank(A) == orthogonal.rank(A)
    ref = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.abs(x - ref).max() <= 1e-11 * max(1.0, np.abs(ref).max())


def test_a_free_direction_gets_the_least_norm_step():
    """x + y = 2 has a line of solutions; the least-norm one is (1, 1)."""
    x, rank = orthogonal.lstsq([[1.0, 1.0]], [2.0])
    assert rank == 1 and np.allclose(x, [1.0, 1.0], atol=1e-15)
    assert math.isclose(orthogonal.norm(x), math.sqrt(2.0), rel_tol=1e-15)


@pytest.mark.parametrize("k", [600, -600, 1000])
def test_entries_whose_squares_overflow_scale_exactly(k):
    """A Jacobian of 1e200 (`bgc steady -p a=1e200`): the squares of the reflections
    overflowed to inf, the rank came out 0 and the step NaN.  Scaled by 2^k, a least-squares
    problem has the same solution to the bit (a power of two scales exactly), and the norm
    of [3, 4] 2^k is 5 2^k."""
    rng = np.random.default_rng(7)
    A, b = rng.standard_normal((6, 4)), rng.standard_normal(6)
    x, rank = orthogonal.lstsq(A, b)
    big = np.ldexp(A, k)
    scaled, rank_scaled = orthogonal.lstsq(big, np.ldexp(b, k))
    assert np.array_equal(scaled, x) and rank_scaled == rank == 4
    assert np.array_equal(orthogonal.lstsq(big, b)[0], np.ldexp(x, -k))
    assert orthogonal.rank(big) == 4
    assert orthogonal.norm(np.ldexp([3.0, 4.0], k)) == math.ldexp(5.0, k)
    x, rank = orthogonal.lstsq([[-1e308]], [1e308])
    assert x.tolist() == [-1.0] and rank == 1
