"""The stiff solvers' sparse LU (bgc/symbolic/sparse.py, iteration_plan; bgc_splu_* and bgc_smat_*
in bgc/runtime/stiff.c, _splu_* and _SparseMatrix in stiff.py): on random sparse patterns
against numpy's dense solve, the dense fallback when a pivot fails its test; the C and Python
factorisations and solves bit for bit on a model's plan; and the thermal grid, a model on the
sparse path, against its closed form (SciPy's expm), its C program's CSV byte for byte in
Python."""
import contextlib
import io
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import bgc
from bgc.base import processes, toolchain
from bgc.symbolic import sparse
from bgc.api import Source
from bgc.codegen.emit import emit_c, emit_python

from cbits import C_IO
from helpers import families, pyruntime

ROOT = Path(__file__).resolve().parent.parent
needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")
GRID = 6  # 36 states: above sparse.SPARSE_MIN_STATES
rt = pyruntime()  # the Python runtime, whose _splu_* and _SparseMatrix these tests call


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """The 6 x 6 grid's program (scene cool: every temperature an output), its C program with
    the harness below (one build: `--harness` runs the harness, anything else the program's
    main), and its Python module."""
    compiled = bgc.build(Source("grid.bg", families.thermal_grid(GRID)), scene="cool")
    program = compiled.program
    assert program.jacobian.lu is not None  # on the sparse path
    (c_text,) = emit_c(program).values()
    (py_text,) = emit_python(program).values()
    exe = None
    if toolchain.have_c_compiler():
        work = tmp_path_factory.mktemp("grid")
        (work / "model.c").write_text(c_text)
        (work / "harness.c").write_text(HARNESS)
        exe = work / "grid"
        subprocess.run(["cc", "-O0", "-std=c99", "-w", "harness.c", "-o", str(exe), "-lm"],
                       check=True, cwd=work)
    return program, exe, processes.load_python_module(py_text)


# ---------------------------------------------------------------- random patterns


def _random_pattern(rng, n):
    """J's columns: each a sorted set of rows near the diagonal (not always the diagonal), and
    now and then one anywhere."""
    columns = []
    for j in range(n):
        rows = {i for i in range(max(0, j - 4), min(n, j + 5)) if rng.random() < 0.5}
        if rng.random() < 0.15:
            rows.add(int(rng.integers(n)))
        columns.append(tuple(sorted(rows)))
    return columns


def _bind(monkeypatch, columns):
    plan = sparse.iteration_plan(columns)
    assert plan is not None
    monkeypatch.setattr(rt, "_N", len(columns))
    monkeypatch.setattr(rt, "_JAC_COLUMNS", columns)
    lu = rt._SparseLU(plan.perm, plan.rowptr, plan.cols, plan.diag, plan.jpos, plan.dpos)
    monkeypatch.setattr(rt, "_JAC_LU", lu)
    return plan


def _dense_J(columns, Jv):
    n = len(columns)
    J = np.zeros((n, n))
    q = 0
    for j, rows in enumerate(columns):
        for i in rows:
            J[i, j] = Jv[q]
            q += 1
    return J


@pytest.mark.parametrize("seed", [1, 2])
def test_sparse_lu_solves_random_patterns(monkeypatch, seed):
    """alpha I - J and (alpha + i beta) I - J: with a dominant diagonal the static order holds
    (no fallback); with alpha = 0 and no diagonal in J every pivot is zero, so the factors are
    the dense fallback's.  Either way the solution is numpy's."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(32, 70))
    columns = _random_pattern(rng, n)
    plan = _bind(monkeypatch, columns)
    assert plan.nnz >= sum(map(len, columns))  # the fill holds J
    Jv = rng.normal(size=sum(map(len, columns)))
    J = _dense_J(columns, Jv)
    b, c = rng.normal(size=n), rng.normal(size=n)
    alpha = 1.0 + np.abs(J).sum(axis=1).max()
    E = rt._SparseMatrix(Jv, alpha)
    assert E.piv is not None and not E.dense
    assert np.allclose(E.solve(b), np.linalg.solve(alpha * np.eye(n) - J, b), rtol=1e-11,
                       atol=1e-13)
    Z = rt._SparseMatrix(Jv, alpha, 0.75 * alpha)
    assert not Z.dense
    xr, xi = Z.zsolve(b, c)
    want = np.linalg.solve((alpha + 0.75j * alpha) * np.eye(n) - J, b + 1j * c)
    assert np.allclose(xr + 1j * xi, want, rtol=1e-11, atol=1e-13)
    # no diagonal at all: the pivots fail their test, the dense LU takes over
    hollow = [tuple(i for i in rows if i != j) for j, rows in enumerate(columns)]
    hollow = [rows or ((j + 1) % n,) for j, rows in enumerate(hollow)]
    _bind(monkeypatch, hollow)
    Hv = rng.normal(size=sum(map(len, hollow)))
    H = _dense_J(hollow, Hv)
    if abs(np.linalg.det(H)) > 1e-8:
        E = rt._SparseMatrix(Hv, 0.0)
        assert E.dense and E.piv is not None
        assert np.allclose(E.solve(b), np.linalg.solve(-H, b), rtol=1e-9, atol=1e-11)


def test_small_or_dense_patterns_stay_dense():
    n = sparse.SPARSE_MIN_STATES - 1
    assert sparse.iteration_plan([(j,) for j in range(n)]) is None
    full = tuple(range(40))
    assert sparse.iteration_plan([full] * 40) is None
    assert sparse.iteration_plan([(j,) for j in range(40)]) is not None


# ---------------------------------------------------------------- C and Python alike

HARNESS = r"""
#define main bgc_program_main
#include "model.c"
#undef main
""" + C_IO + r"""
static int harness(void);
int main(int argc, char **argv)
{
    return argc > 1 && strcmp(argv[1], "--harness") == 0 ? harness()
                                                          : bgc_program_main(argc, argv);
}
static int harness(void)
{
    enum { N = BGC_NUM_STATES };
    const int nj = bgc_jac_col_ptr[N];
    double Jv[4096], b[N], w[N];
    bgc_cplx zb[N], zw[N];
    int i, rc;
    while (scanf("%d", &i) == 1) {
        bgc_smat m;
        const double alpha = rd(), beta = rd();
        for (i = 0; i < nj; i++) Jv[i] = rd();
        for (i = 0; i < N; i++) b[i] = rd();
        if (bgc_smat_new(&m, 0)) return 7;
        rc = bgc_smat_factor(&m, Jv, alpha, w);
        printf("%d %d ", rc != 0, m.dense);
        if (!rc) {
            bgc_smat_solve(&m, b, w);
            for (i = 0; i < N; i++) wr(b[i]);
        }
        bgc_smat_free(&m);
        if (bgc_smat_new(&m, 1)) return 7;
        for (i = 0; i < N; i++) {
            const double re = rd(), im = rd();
            zb[i] = bgc_cmake(re, im);
        }
        rc = bgc_smat_zfactor(&m, Jv, bgc_cmake(alpha + beta * 0.0, beta), zw);
        printf("%d %d ", rc != 0, m.dense);
        if (!rc) {
            bgc_smat_zsolve(&m, zb, zw);
            for (i = 0; i < N; i++) { wr(creal(zb[i])); wr(cimag(zb[i])); }
        }
        bgc_smat_free(&m);
        printf("\n");
    }
    return 0;
}
"""


def _hex(v):
    return np.float64(v).view(np.uint64).item().__format__("x")


@needs_cc
def test_c_and_python_sparse_factorisations_are_the_same_bits(grid):
    program, exe, module = grid
    n = len(program.states)
    nj = sum(map(len, program.jacobian.columns))
    rng = np.random.default_rng(11)
    cases = []
    for alpha, beta, scale in ((10.0, 3.0, 1.0), (0.5, 0.25, 3.0), (0.0, 0.0, 1.0),
                               (1e-3, 2.0, 1e4)):
        cases.append((alpha, beta, rng.normal(size=nj) * scale, rng.normal(size=n),
                      rng.normal(size=n), rng.normal(size=n)))
    lines = []
    for alpha, beta, Jv, b, br, bi in cases:
        words = [_hex(alpha), _hex(beta)] + [_hex(v) for v in (*Jv, *b)]
        words += [w for re, im in zip(br, bi) for w in (_hex(re), _hex(im))]
        lines.append("0 " + " ".join(words))
    done = subprocess.run([str(exe), "--harness"], input="\n".join(lines) + "\n",
                          capture_output=True, text=True, check=True)
    fallbacks = 0
    for (alpha, beta, Jv, b, br, bi), line in zip(cases, done.stdout.splitlines()):
        want = []
        E = module._SparseMatrix(Jv, alpha)
        want += ["1" if E.piv is None else "0", "1" if E.dense else "0"]
        if E.piv is not None:
            want += [_hex(v) for v in E.solve(b)]
        Z = module._SparseMatrix(Jv, alpha + beta * 0.0, beta)
        want += ["1" if Z.piv is None else "0", "1" if Z.dense else "0"]
        if Z.piv is not None:
            xr, xi = Z.zsolve(br, bi)
            want += [w for re, im in zip(xr, xi) for w in (_hex(re), _hex(im))]
        fallbacks += E.dense + Z.dense
        assert line.split() == want
    assert fallbacks > 0  # the dense fallback was among the cases


# ---------------------------------------------------------------- the grid on the sparse path


def _grid_rhs(t, T, n=GRID, r=1.0, rb=2.0, c=1.0, q_in=1.0):
    """The grid's equations written out: cell k = i n + j, neighbours through r, the last
    column to the ambient (0) through rb, q_in into cell 0."""
    d = np.zeros_like(T)
    for i in range(n):
        for j in range(n):
            k = i * n + j
            for a, b in ((i, j - 1), (i, j + 1), (i - 1, j), (i + 1, j)):
                if 0 <= a < n and 0 <= b < n:
                    d[k] += (T[a * n + b] - T[k]) / r
            if j == n - 1:
                d[k] -= T[k] / rb
    d[0] += q_in
    return d / c


def _python_csv(module, argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = module.main(argv)
    return code, out.getvalue().encode()


@pytest.mark.parametrize("solver", ["rodas5p", "radau5"])
def test_grid_against_scipy_and_python_writes_the_c_bytes(grid, solver):
    program, exe, module = grid
    argv = ["--solver", solver, "--rtol", "1e-7", "--atol", "1e-10", "--t-end", "3", "--dt", "1"]
    code, out = _python_csv(module, argv)
    assert code == 0
    if exe is not None:
        done = subprocess.run([str(exe), *argv], capture_output=True, check=True)
        assert done.stdout == out
    rows = np.loadtxt(io.StringIO(out.decode()), delimiter=",", skiprows=1)
    names = out.decode().splitlines()[0].split(",")[1:]
    order = [int(name.split("[")[1].split("]")[0]) - 1 for name in names]  # cap[k].e
    # the equations are linear, dT/dt = A T + b: exactly T_ss + expm(A t) (T(0) - T_ss)
    N = GRID * GRID
    b = _grid_rhs(0.0, np.zeros(N))
    A = np.column_stack([_grid_rhs(0.0, e) - b for e in np.eye(N)])
    T0 = 1.0 + np.sin(np.arange(1, N + 1))
    steady = np.linalg.solve(A, -b)
    ref = np.array([steady + expm(A * t) @ (T0 - steady) for t in rows[:, 0]])
    assert np.max(np.abs(rows[:, 1:] - ref[:, order])) < 1e-6
