"""The Radau IIA stage sets in the registry (3, 5 and 7 stages), derived again here from the
method's definition in 50-digit arithmetic (mpmath, which SymPy brings): the nodes as the zeros
of d^(s-1)/dx^(s-1) x^(s-1) (x - 1)^s, the Butcher matrix from the collocation conditions, the
eigenvalues of its inverse, the transformation T to the real block form, and the error
estimate's weights from the embedded formula of order s on the nodes 0, c with the weight
1/gamma on f(t, y) (Hairer & Wanner II, IV.8).  Also: the variable-order solver against SciPy
on Van der Pol, and its order changes seen in its steps."""
from math import comb

import mpmath
import pytest

from bgc.base import solvers

DIGITS = 50


def _definition(s: int):
    """(c, A) of Radau IIA with s stages, at DIGITS digits."""
    with mpmath.workdps(DIGITS):
        # x^(s-1) (x - 1)^s by powers, then differentiated s - 1 times
        p = [mpmath.mpf(0)] * (2 * s)
        for k in range(s + 1):
            p[s - 1 + k] += comb(s, k) * (-1) ** (s - k)
        for _ in range(s - 1):
            p = [p[i + 1] * (i + 1) for i in range(len(p) - 1)]
        roots = mpmath.polyroots(p[::-1], maxsteps=500, extraprec=4 * DIGITS)
        c = sorted(mpmath.re(r) for r in roots)
        A = mpmath.matrix(s, s)
        for j in range(s):  # a_ij = integral from 0 to c_i of the Lagrange polynomial l_j
            coeffs, den = [mpmath.mpf(1)], mpmath.mpf(1)
            for m in range(s):
                if m != j:
                    coeffs = [(coeffs[i - 1] if i else 0) - c[m] * (coeffs[i] if i < len(coeffs)
                                                                   else 0)
                              for i in range(len(coeffs) + 1)]
                    den *= c[j] - c[m]
            for i in range(s):
                A[i, j] = sum(a * c[i] ** (k + 1) / (k + 1) for k, a in enumerate(coeffs)) / den
        return c, A


def _mp(values):
    return [mpmath.mpf(v.numerator) / v.denominator for v in values]


@pytest.mark.parametrize("stages", [3, 5, 7])
def test_stage_set_matches_the_definition(stages):
    (tab,) = [t for s in solvers.SOLVER_LIST if s.family == "radau" for t in s.tableau
              if t.stages == stages][:1]
    with mpmath.workdps(DIGITS):
        c, A = _definition(stages)
        tol = mpmath.mpf(10) ** -27  # the registry's 30 digits
        assert abs(c[-1] - 1) < mpmath.mpf(10) ** -40
        assert max(abs(x - y) for x, y in zip(_mp(tab.c), c)) < tol
        # the collocation conditions: sum_j a_ij c_j^(k-1) = c_i^k / k
        for k in range(1, stages + 1):
            for i in range(stages):
                assert abs(sum(A[i, j] * c[j] ** (k - 1) for j in range(stages))
                           - c[i] ** k / k) < mpmath.mpf(10) ** -40
        T = mpmath.matrix([_mp(row) for row in tab.T])
        Ti = mpmath.matrix([_mp(row) for row in tab.Ti])
        assert mpmath.mnorm(T * Ti - mpmath.eye(stages), 1) < tol
        pairs = (stages - 1) // 2
        block = mpmath.zeros(stages, stages)
        block[0, 0] = _mp([tab.gamma])[0]
        for k, (a, b) in enumerate(zip(_mp(tab.alpha), _mp(tab.beta))):
            i = 2 * k + 1
            block[i, i] = block[i + 1, i + 1] = a
            block[i, i + 1], block[i + 1, i] = -b, b
        assert mpmath.mnorm(Ti * A ** -1 * T - block, 1) < 1e-24
        # the eigenvalues of A^-1: gamma and alpha_k +- i beta_k, nothing else
        eig = list(mpmath.eig(A ** -1, left=False, right=False))
        want = [mpmath.mpc(block[0, 0])] + [
            mpmath.mpc(block[2 * k + 1, 2 * k + 1], sg * block[2 * k + 2, 2 * k + 1])
            for k in range(pairs) for sg in (1, -1)]
        assert len(eig) == len(want)
        assert max(min(abs(x - y) for x in eig) for y in want) < 1e-24
        # the error estimate: (gamma/h) (yhat - y1) = f0 + sum_j e_j Z_j / h for the embedded
        # formula yhat = y0 + h (f0 / gamma + sum_j bhat_j F_j) of order s on the nodes 0, c:
        # with Z = h A F, the weights (1, A^T e / gamma) on (f0, F) are (1/gamma, bhat - b)
        # scaled by gamma, so they integrate 1, x, ..., x^(s-1) to zero and x^s not
        e = mpmath.matrix(_mp(tab.e))
        w = A.T * e
        moments = [(1 if k == 0 else 0) + sum(w[j] * c[j] ** k for j in range(stages))
                   for k in range(stages + 1)]
        assert max(abs(m) for m in moments[:stages]) < tol * 100
        assert abs(moments[stages]) > 1e-4


def test_variable_order_is_one_solver_of_the_three_stage_sets():
    radau = solvers.get("radau")
    assert [t.stages for t in radau.tableau] == [3, 5, 7]
    assert radau.tableau == (solvers.get("radau5").tableau + solvers.get("radau9").tableau
                             + solvers.get("radau13").tableau)
    assert [solvers.get(n).order for n in ("radau5", "radau9", "radau13")] == [5, 9, 13]


def test_radau_takes_fewer_steps_than_scipy_radau_at_equal_error():
    """Van der Pol at mu = 1e5 over one period (tests/test_stiff.py's model and its reference,
    SciPy's Radau at rtol 1e-10): SciPy's Radau at rtol 1e-6 (atol 1e-9), run here, against
    bgc's Radau solvers at a tolerance that reaches at least SciPy's accuracy.  The variable
    order and the fixed orders 9 and 13 reach it in well under half of SciPy's steps (measured:
    SciPy 1338 steps at 1.5e-7; radau 468 steps at 3.3e-8, radau9 402 at 8.1e-8, radau13 194 at
    6.8e-8)."""
    from scipy.integrate import solve_ivp

    import test_stiff as ts

    t_ref, ref = ts.van_der_pol_reference()
    eps = ts.EPS_VDP

    def f(t, y):
        return [y[1], ((1 - y[0] ** 2) * y[1] - y[0]) / eps]

    def jac(t, y):
        return [[0.0, 1.0], [(-2 * y[0] * y[1] - 1) / eps, (1 - y[0] ** 2) / eps]]

    scipy = solve_ivp(f, (0.0, 2.0), [2.0, -2 / 3 + 10 / 81 * eps], method="Radau", jac=jac,
                      rtol=1e-6, atol=1e-9, dense_output=True)
    assert scipy.status == 0
    scipy_error = ts._scaled_error(scipy.sol(t_ref).T, ref).max()
    scipy_steps = len(scipy.t) - 1
    backend = ts.BACKENDS[-1]  # C if there is a compiler
    for solver in ("radau", "radau9", "radau13"):
        t, Y, st = ts._run(ts.van_der_pol, backend, solver=solver, t_end=2.0, dt=0.02,
                           rtol=1e-9, atol=1e-12)
        error = ts._scaled_error(Y, ref).max()
        assert error <= scipy_error, (solver, error, scipy_error)
        assert 2 * st["steps"] <= scipy_steps, (solver, st["steps"], scipy_steps)
