"""The runtimes' dense LU factorisations with partial pivoting (the stiff solvers' real and
complex iteration matrices, the algebraic blocks' dense fallback), against numpy's solve on
matrices that need row swaps after the first column; a stiff model whose iteration matrix
needs them, in both backends, against its exact solution; and the Python runtime's real and
complex factorisations and solves bit for bit against the C runtime's."""
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import bgc
from bgc.base import processes, toolchain
from bgc.api import Source
from bgc.codegen.emit import emit_c, emit_python

from cbits import C_IO

ROOT = Path(__file__).resolve().parent.parent
needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")

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
    module = processes.load_python_module(text)
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
    Python module to the bit (its transcription of the C runtime's LU); adaptive: both equal
    the exact solution (expm)."""
    fixed = [bgc.simulate(Source("lu_pivot.bg", SPRING), backend=b, solver=solver, t_end=0.1,
                          dt=0.05, step=0.01)[1] for b in BACKENDS]
    assert np.array_equal(fixed[0], fixed[-1])
    for backend in BACKENDS:
        _adaptive(backend, solver)


BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])


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


# ---------------------------------------------------------------- byte parity
# The Python runtime's factorisations and solves (and its complex products and quotients) are
# the C runtime's operations in C's order: the same bits, on random, singular, near-singular,
# non-finite and badly scaled matrices.  The C side is the generated program's own functions,
# compiled by the C compiler; numbers cross as bit patterns.

BITS_HARNESS = r"""
#include "model.c"
""" + C_IO + r"""
static bgc_cplx rdz(void)
{
    bgc_cplx z;
    double *p = (double *)&z;
    p[0] = rd();
    p[1] = rd();
    return z;
}
static void wrz(bgc_cplx z) { wr(creal(z)); wr(cimag(z)); }
static double a[4096], b[64];
static bgc_cplx za[4096], zb[64];
int main(void)
{
    int kind, n, i, rc, piv[64];
    while (scanf("%d %d", &kind, &n) == 2) {
        if (kind == 0) {
            for (i = 0; i < n * n; i++) a[i] = rd();
            for (i = 0; i < n; i++) b[i] = rd();
            rc = bgc_stiff_lu(n, a, piv);
            printf("%d ", rc != 0);
            if (!rc) {
                bgc_stiff_lu_solve(n, a, piv, b);
                for (i = 0; i < n * n; i++) wr(a[i]);
                for (i = 0; i < n; i++) wr(b[i]);
            }
        } else if (kind == 1) {
            for (i = 0; i < n * n; i++) za[i] = rdz();
            for (i = 0; i < n; i++) zb[i] = rdz();
            rc = bgc_stiff_zlu(n, za, piv);
            printf("%d ", rc != 0);
            if (!rc) {
                bgc_stiff_zlu_solve(n, za, piv, zb);
                for (i = 0; i < n * n; i++) wrz(za[i]);
                for (i = 0; i < n; i++) wrz(zb[i]);
            }
        } else { /* n products and quotients */
            for (i = 0; i < n; i++) {
                const bgc_cplx x = rdz(), y = rdz();
                wrz(x * y); /* the compiler's own */
                wrz(x / y);
                wrz(bgc_cmul(x, y)); /* the runtime's, written out */
                wrz(bgc_cdiv(x, y));
            }
        }
        printf("\n");
    }
    return 0;
}
"""


def _bits(values):
    """The bit patterns, every NaN as one: which NaN an operation on two NaNs returns (their
    sign, the payload) is the compiler's choice of operand order, and a NaN is written 'nan'."""
    v = np.array(values, dtype=float).ravel()
    v[np.isnan(v)] = np.nan
    return " ".join("%x" % u for u in v.view(np.uint64))


def _floats(words):
    return np.array([int(w, 16) for w in words], dtype=np.uint64).view(float)


SPECIAL = [0.0, -0.0, 1.0, -2.5, 3e-320, -1e-310, 1e-300, 2.2e-308, 1e300, -1.7e308,
           float("inf"), float("-inf"), float("nan")]


def _real_cases(rng):
    cases = []
    for n in (1, 2, 3, 5, 8, 13, 20):
        cases.append(rng.normal(size=(n, n)))
    A = rng.normal(size=(6, 6))
    A[:, 2] = 0.0  # a zero column: singular at column 2
    cases.append(A)
    A = rng.normal(size=(5, 5))
    A[3] = A[1]  # equal rows: an exactly zero pivot after elimination
    cases.append(A)
    A = rng.normal(size=(7, 7))
    A[4] = A[2] * (1 + 2 ** -50)  # near-singular
    cases.append(A)
    A = rng.normal(size=(6, 6)) * np.logspace(-150, 150, 6)[:, None]  # badly scaled rows
    cases.append(A)
    A = rng.normal(size=(6, 6))
    A[rng.random(size=(6, 6)) < 0.4] = 0.0  # sparse: skipped multipliers and right sides
    cases.append(A)
    for value in (float("nan"), float("inf")):
        A = rng.normal(size=(5, 5))
        A[2, 3] = value
        cases.append(A)
    A = rng.normal(size=(4, 4))
    A[0, 0] = float("nan")  # a NaN first pivot stays
    cases.append(A)
    return cases


def _complex_cases(rng):
    cases = [rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n)) for n in (1, 2, 4, 7, 12, 16)]
    n = 6  # the Radau matrices: (alpha + i beta)/h on the diagonal, -J real elsewhere
    cases.append(np.diag(np.full(n, 3.5 + 2.1j)) - rng.normal(size=(n, n)))
    A = rng.normal(size=(5, 5)) + 1j * rng.normal(size=(5, 5))
    A[:, 1] = 0.0
    cases.append(A)
    A = rng.normal(size=(5, 5)) + 1j * rng.normal(size=(5, 5))
    A[4] = A[0]
    cases.append(A)
    A = (rng.normal(size=(6, 6)) + 1j * rng.normal(size=(6, 6))) * np.logspace(-300, 300, 6)
    cases.append(A)  # the quotients' scaling branches
    A = rng.normal(size=(4, 4)) + 1j * rng.normal(size=(4, 4)) * 1e-310
    cases.append(A)  # subnormal imaginary parts: ratios below the least normal
    for value in (complex("nan"), complex(float("inf"), 1.0), complex(0.0, float("-inf"))):
        A = rng.normal(size=(4, 4)) + 1j * rng.normal(size=(4, 4))
        A[1, 2] = value
        cases.append(A)
    A = rng.normal(size=(6, 6)) + 0j
    A[rng.random(size=(6, 6)) < 0.4] = 0.0
    cases.append(A)
    return cases


@pytest.fixture(scope="module")
def bits_harness(tmp_path_factory):
    if not toolchain.have_c_compiler():
        pytest.skip("no C compiler")
    tmp = tmp_path_factory.mktemp("lu_bits")
    (text,) = emit_c(bgc.build(ROOT / "models" / "pendulum.bg").program).values()
    (tmp / "model.c").write_text(text)
    (tmp / "harness.c").write_text(BITS_HARNESS)
    subprocess.run(["cc", "-O2", "-std=c99", "-DBGC_NO_MAIN", "-w", str(tmp / "harness.c"),
                    "-o", str(tmp / "harness"), "-lm"], check=True, cwd=tmp)
    (py,) = emit_python(bgc.build(ROOT / "models" / "pendulum.bg").program).values()
    return tmp / "harness", processes.load_python_module(py)


def _run_harness(exe, lines):
    done = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True,
                          text=True, check=True)
    return [line.split() for line in done.stdout.splitlines()]


def test_python_lu_is_c_lu_bit_for_bit(bits_harness):
    exe, m = bits_harness
    rng = np.random.default_rng(11)
    cases = [(A, rng.normal(size=len(A))) for A in _real_cases(rng)]
    cases[3][1][1:3] = 0.0  # zeros in a right side: C skips their columns
    lines = [f"0 {len(A)} {_bits(A)} {_bits(b)}" for A, b in cases]
    singular = 0
    for (A, b), words in zip(cases, _run_harness(exe, lines)):
        a = A.copy()
        piv = m._lu(a)
        assert (piv is None) == (words[0] == "1"), A
        if piv is None:
            singular += 1
            continue
        x = m._lu_solve(a, piv, b)
        c = _floats(words[1:])
        n = len(A)
        assert _bits(a) == _bits(c[:n * n])
        assert _bits(x) == _bits(c[n * n:])
    assert singular == 2


def test_python_complex_lu_is_c_zlu_bit_for_bit(bits_harness):
    exe, m = bits_harness
    rng = np.random.default_rng(12)
    cases = [(A, rng.normal(size=len(A)) - 0.5j * rng.normal(size=len(A)))
             for A in _complex_cases(rng)]
    cases[0][1][0] = 0.0
    lines = [f"1 {len(A)} {_bits(A.view(float))} {_bits(b.view(float))}" for A, b in cases]
    singular = 0
    for (A, b), words in zip(cases, _run_harness(exe, lines)):
        ar, ai = A.real.copy(), A.imag.copy()
        piv = m._zlu(ar, ai)
        assert (piv is None) == (words[0] == "1"), A
        if piv is None:
            singular += 1
            continue
        xr, xi = m._zlu_solve(ar, ai, piv, b.real, b.imag)
        c = _floats(words[1:])
        n = len(A)
        assert _bits(np.stack([ar, ai], axis=-1)) == _bits(c[:2 * n * n])
        assert _bits(np.stack([xr, xi], axis=-1)) == _bits(c[2 * n * n:])
    assert singular == 2


def test_complex_products_and_quotients_are_gccs(bits_harness):
    """Every pair of special values (zeros, subnormals, huge, inf, nan) and random ones: the
    scalar __muldc3/__divdc3 transcriptions and the vectorised paths against gcc's."""
    exe, m = bits_harness
    rng = np.random.default_rng(13)
    parts = np.array(SPECIAL + list(rng.normal(size=4) * 10.0 ** rng.integers(-5, 5, 4)))
    grid = np.array(np.meshgrid(parts, parts, indexing="ij")).reshape(2, -1).T
    x = grid[rng.permutation(len(grid))]
    y = grid[rng.permutation(len(grid))]
    quads = np.concatenate([np.hstack([x, y]), rng.normal(size=(200, 4))
                            * 10.0 ** rng.integers(-310, 300, (200, 4))])
    (words,) = _run_harness(exe, [f"2 {len(quads)} {_bits(quads)}"])
    c = _floats(words).reshape(-1, 8)
    # the C runtime's written-out product and quotient are gcc's own, to the bit (so the C
    # program's numbers do not depend on which compiler's runtime library divides)
    assert _bits(c[:, 4:]) == _bits(c[:, :4])
    with np.errstate(all="ignore"):
        mul = np.array([m._muldc3(*map(float, q)) for q in quads])
        div = np.array([m._divdc3(*map(float, q)) for q in quads])
        vmul = np.array(m._cmul(*quads.T)).T
    assert _bits(mul) == _bits(c[:, :2])
    assert _bits(div) == _bits(c[:, 2:4])
    assert _bits(vmul) == _bits(c[:, :2])
    for k, (cr, ci) in enumerate(quads[:60, 2:].tolist()):  # one divisor, many numerators
        with np.errstate(all="ignore"):
            vdiv = np.array(m._cdiv(quads[:, 0], quads[:, 1], cr, ci)).T
        want = np.array([m._divdc3(a, b, cr, ci) for a, b in quads[:, :2].tolist()])
        assert _bits(vdiv) == _bits(want), k
