"""The runtimes' dense LU factorisations with partial pivoting (the stiff solvers' real and
complex iteration matrices, the algebraic blocks' dense fallback), against numpy's solve on
matrices that need row swaps after the first column; and a stiff model whose iteration matrix
needs them, in both backends, against its exact solution."""
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import bgc
from bgc import backends
from bgc.api import Source
from bgc.emit import emit_c, emit_python

ROOT = Path(__file__).resolve().parent.parent
needs_cc = pytest.mark.skipif(not backends.have_c_compiler(), reason="no C compiler")

# [[4,1,1],[2,1,3],[1,5,2]] pivots on row 2 at column 1; the others are random
MATRICES = [np.array([[4.0, 1.0, 1.0], [2.0, 1.0, 3.0], [1.0, 5.0, 2.0]])] + [
    np.random.default_rng(seed).normal(size=(n, n)) for seed, n in ((1, 4), (2, 6), (3, 9))]

HARNESS = r"""
#include "model.c"
int main(void)
{
    int n, i, j, piv[16];
    double a[256], b[16], scale[16];
    bgc_cplx za[256], zb[16];
    while (scanf("%d", &n) == 1) {
        for (i = 0; i < n * n; i++) scanf("%lf", &a[i]);
        for (i = 0; i < n; i++) scanf("%lf", &b[i]);
        for (i = 0; i < n * n; i++) za[i] = a[i] + (double)(i %% 3) * 0.25 * _Complex_I;
        for (i = 0; i < n; i++) zb[i] = b[i] - 0.5 * _Complex_I;
        {
            double c[256], d[16];
            for (i = 0; i < n * n; i++) c[i] = a[i];
            for (i = 0; i < n; i++) d[i] = b[i];
            if (bgc_stiff_lu(n, c, piv)) return 3;
            bgc_stiff_lu_solve(n, c, piv, d);
            for (i = 0; i < n; i++) printf("%.17g ", d[i]);
            printf("\n");
        }
        {
            double c[256], d[16];
            for (i = 0; i < n * n; i++) c[i] = a[i];
            for (i = 0; i < n; i++) { d[i] = b[i]; scale[i] = 1.0; }
            if (bgc_lu_dense(n, c, piv, scale)) return 4;
            bgc_lu_dense_solve(n, c, piv, d);
            for (i = 0; i < n; i++) printf("%.17g ", d[i]);
            printf("\n");
        }
        if (bgc_stiff_zlu(n, za, piv)) return 5;
        bgc_stiff_zlu_solve(n, za, piv, zb);
        for (j = 0; j < n; j++) printf("%.17g %.17g ", creal(zb[j]), cimag(zb[j]));
        printf("\n");
    }
    return 0;
}
""".replace("%%", "%")


def _complex_matrix(A):
    n = A.shape[0]
    return A + 1j * 0.25 * (np.arange(n * n) % 3).reshape(n, n)


@needs_cc
def test_c_factorisations_solve_with_row_swaps(tmp_path):
    (text,) = emit_c(bgc.build(ROOT / "models" / "pendulum.bg").program).values()
    (tmp_path / "model.c").write_text(text)
    (tmp_path / "harness.c").write_text(HARNESS)
    exe = tmp_path / "harness"
    subprocess.run(["cc", "-O2", "-std=c99", "-DBGC_NO_MAIN", "-w", str(tmp_path / "harness.c"),
                    "-o", str(exe), "-lm"], check=True, cwd=tmp_path)
    rng = np.random.default_rng(7)
    stdin, wants = [], []
    for A in MATRICES:
        b = rng.normal(size=A.shape[0])
        stdin.append(" ".join([str(A.shape[0])] + [f"{v:.17g}" for v in (*A.ravel(), *b)]))
        wants.append((np.linalg.solve(A, b), np.linalg.solve(_complex_matrix(A), b - 0.5j)))
    done = subprocess.run([str(exe)], input="\n".join(stdin) + "\n", capture_output=True,
                          text=True, check=True)
    lines = done.stdout.splitlines()
    for k, (real, cplx) in enumerate(wants):
        stiff, dense, z = (np.array(lines[3 * k + j].split(), dtype=float) for j in range(3))
        assert np.allclose(stiff, real, rtol=1e-12, atol=1e-12)
        assert np.allclose(dense, real, rtol=1e-12, atol=1e-12)
        assert np.allclose(z[0::2] + 1j * z[1::2], cplx, rtol=1e-12, atol=1e-12)


def test_python_dense_block_factorisation_solves_with_row_swaps():
    (text,) = emit_python(bgc.build(ROOT / "models" / "pendulum.bg").program).values()
    module = backends.load_python_module(text)
    rng = np.random.default_rng(8)
    for A in MATRICES:
        n = A.shape[0]
        a, piv, x = list(A.ravel()), [0] * n, list(rng.normal(size=n))
        want = np.linalg.solve(A, x)
        assert module._lu_dense(n, a, 0, piv, 0, [1.0] * n) is not False
        module._lu_dense_solve(n, a, 0, piv, 0, x, 0)
        assert np.allclose(x, want, rtol=1e-12, atol=1e-12)


SPRING = """model lu_pivot "two masses on a stiff spring: the iteration matrix pivots at column 1"
spring : C(1e-4)
m1 : I(1) init p = 1
m2 : I(1)
v1 : 1
v2 : 1
s : 0
v1 -> m1
v2 -> m2
v1 -> s
s -> spring
s -> v2
"""


@pytest.mark.parametrize("solver", ["rodas4", "radau5", "rodas5p"])
def test_stiff_solvers_on_a_pivoting_iteration_matrix(solver):
    """Fixed steps (no error control to hide a wrong linear solve): the C program equals the
    Python module (numpy's inverse); adaptive: both equal the exact solution (expm)."""
    fixed = [bgc.simulate(Source("lu_pivot.bg", SPRING), backend=b, solver=solver, t_end=0.1,
                          dt=0.05, step=0.01)[1] for b in BACKENDS]
    assert np.allclose(fixed[0], fixed[-1], rtol=1e-9, atol=1e-12)
    for backend in BACKENDS:
        _adaptive(backend, solver)


BACKENDS = ["python"] + (["c"] if backends.have_c_compiler() else [])


def _adaptive(backend, solver):
    """x = (spring.q, m1.p, m2.p): q' = p1 - p2, p1' = -q/c, p2' = q/c; exact by expm."""
    t, Y, names = bgc.simulate(Source("lu_pivot.bg", SPRING), backend=backend, solver=solver,
                               t_end=0.1, dt=0.05, rtol=1e-9, atol=1e-12)
    c, order = 1e-4, ["spring.q", "m1.p", "m2.p"]
    A = np.array([[0, 1, -1], [-1 / c, 0, 0], [1 / c, 0, 0]])
    perm = [order.index(n) for n in names]
    M = A[np.ix_(perm, perm)]
    x0 = np.array([{"spring.q": 0.0, "m1.p": 1.0, "m2.p": 0.0}[n] for n in names])
    want = expm(M * 0.1) @ x0
    assert np.allclose(Y[-1], want, rtol=0, atol=1e-6 * np.abs(x0).max())
