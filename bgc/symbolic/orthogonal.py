"""Dense least squares whose every bit is the same on every machine.

LAPACK's least-squares and rank routines (numpy.linalg.lstsq, matrix_rank, norm) pick their
kernels by the processor, so the last digits of an equilibrium printed by `bgc steady` moved
from one machine to another.  Here the same problem is solved by Householder reflections
with column pivoting, written with numpy's element-wise operations and sums taken strictly in
sequence (numpy.cumsum accumulates one element after another; numpy.sum and BLAS do not), so
the same inputs give the same bytes everywhere.  Meant for the analysis commands' matrices
(hundreds of rows), not for a solver's inner loop.
"""
from __future__ import annotations

import math

import numpy as np

EPS = np.finfo(float).eps


def total(x, axis=0):
    """The sum of x along axis, added in sequence (0 for an empty axis)."""
    x = np.asarray(x, dtype=float)
    if x.shape[axis] == 0:
        return np.zeros(np.delete(x.shape, axis)) if x.ndim > 1 else 0.0
    return np.take(np.cumsum(x, axis=axis), -1, axis=axis)


BIG, SMALL = 2.0 ** 500, 2.0 ** -500  # beyond these, squares over- or underflow


def _exponent(x) -> int:
    """k such that x * 2^-k has its largest magnitude in [0.5, 1), for an x whose squares
    would over- or underflow (entries beyond 2^±500); else 0.  A power of two scales
    exactly, so an x of ordinary size is computed as it is, to the bit."""
    m = float(np.max(np.abs(x), initial=0.0))
    if not math.isfinite(m) or m == 0.0 or SMALL <= m <= BIG:
        return 0
    return math.frexp(m)[1]


def norm(x) -> float:
    """The Euclidean norm of a vector, its squares added in sequence (scaled by a power of
    two where they would overflow: the norm of [1e200] is 1e200)."""
    x = np.asarray(x, dtype=float).ravel()
    k = _exponent(x)
    x = np.ldexp(x, -k)
    return math.ldexp(float(np.sqrt(total(x * x))), k)


def _reflect(a, k, pivot, perm):
    """One Householder step on column k of a (in place): the column of largest norm among
    k.. swapped in first when pivot; False where the columns left are all zero."""
    if pivot:
        p = k + int(np.argmax(total(a[k:, k:] ** 2)))
        if p != k:
            a[:, [k, p]] = a[:, [p, k]]
            perm[[k, p]] = perm[[p, k]]
    x = a[k:, k]
    alpha = np.sqrt(total(x * x))
    if alpha == 0.0:
        return None
    if x[0] > 0:
        alpha = -alpha
    v = x.copy()
    v[0] -= alpha
    scale = 2.0 / total(v * v)
    a[k:, k:] -= v[:, None] * (total(v[:, None] * a[k:, k:]) * scale)[None, :]
    a[k + 1:, k] = 0.0
    a[k, k] = alpha
    return v, scale


def _apply(v, scale, k, b):
    """b[k:] reflected by (v, scale), in place."""
    b[k:] -= v * (total(v * b[k:]) * scale)


def _qr(a, b, pivot):
    """Householder QR of a (m x n) with Q^T applied to b, both in place: (rank, the reflectors,
    the column permutation).  With pivot the rank is where the diagonal falls below
    max(m, n) * eps * |r_00| (numpy.linalg.matrix_rank's rule, on R's diagonal)."""
    m, n = a.shape
    perm = np.arange(n)
    reflectors = []
    for k in range(min(m, n)):
        step = _reflect(a, k, pivot, perm)
        if step is None:
            break
        reflectors.append(step)
        _apply(*step, k, b)
    diag = np.abs(np.diag(a))[:len(reflectors)]
    tol = max(m, n) * EPS * (diag[0] if len(diag) else 0.0)
    rank = int(np.count_nonzero(diag > tol)) if pivot else len(reflectors)
    return rank, reflectors, perm


def _back(r, c):
    """The solution of the upper triangular system r y = c, each row's sum in sequence."""
    n = len(c)
    y = np.zeros(n)
    for i in range(n - 1, -1, -1):
        y[i] = (c[i] - total(r[i, i + 1:n] * y[i + 1:n])) / r[i, i]
    return y


def _forward(l, c):
    """The solution of the lower triangular system l z = c."""
    n = len(c)
    z = np.zeros(n)
    for i in range(n):
        z[i] = (c[i] - total(l[i, :i] * z[:i])) / l[i, i]
    return z


def lstsq(a, b):
    """(x, rank): the least-squares solution of a x = b of least norm, and a's rank.

    a P = Q [R11 R12; 0 0] by pivoted QR; where the rank r is below the columns, the r rows
    [R11 R12] are factored again, [R11 R12]^T = Q2 R2, and x = P Q2 R2^-T (Q^T b)[:r] is the
    smallest of the solutions (LAPACK's complete orthogonal factorisation, in another order).
    a and b are scaled by powers of two where their squares would overflow (a Jacobian of
    1e200), which leaves x as it is."""
    a = np.array(a, dtype=float)
    c = np.array(b, dtype=float).ravel()
    ka, kb = _exponent(a), _exponent(c)
    if ka or kb:
        x, rank_ = lstsq(np.ldexp(a, -ka), np.ldexp(c, -kb))
        return np.ldexp(x, kb - ka), rank_
    m, n = a.shape
    rank, _, perm = _qr(a, c, pivot=True)
    x = np.zeros(n)
    if rank == 0:
        return x, 0
    if rank == n:
        x[perm] = _back(a[:n, :n], c[:n])
        return x, rank
    mt = a[:rank, :].T.copy()  # n x rank, of full column rank
    _, reflectors, _ = _qr(mt, np.zeros(n), pivot=False)
    y = np.zeros(n)
    y[:rank] = _forward(mt[:rank, :rank].T, c[:rank])
    for k in range(len(reflectors) - 1, -1, -1):
        _apply(*reflectors[k], k, y)
    x[perm] = y
    return x, rank


def rank(a) -> int:
    """a's rank by the pivoted QR of lstsq."""
    a = np.array(a, dtype=float)
    if a.size == 0:
        return 0
    a = np.ldexp(a, -_exponent(a))
    return _qr(a, np.zeros(a.shape[0]), pivot=True)[0]
