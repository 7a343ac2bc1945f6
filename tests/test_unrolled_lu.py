"""Small algebraic blocks factor with straight-line code (bgc.codegen.emit._unrolled_lu) instead of
the runtime's loops over their plan.  The unrolled code must do the same floating-point
operations in the same order: for random sparse plans (general and symmetric, some planned
dense), on matrices whose pivots pass the static tests and on ones whose pivots fail them (the
runtime then factors densely), it must give the runtime's verdict and the runtime's factors
and solutions to the bit, in C and in Python; and the solutions must be numpy's."""
import subprocess

import numpy as np
import pytest

import bgc
from bgc.base import processes, toolchain
from bgc.symbolic import sparse
from bgc.codegen.emit import BlockArea, _unrolled_lu, emit_c, emit_python
from conftest import MODELS

PLAN_KEYS = ("diag", "lptr", "lpos", "lrow", "uptr", "upos", "ucol", "upd", "prow", "pcol")


def _plans():
    """(plan, entries) for random patterns with a full matching, m = 1..7, and full ones."""
    rng = np.random.default_rng(11)
    out = []
    for m in range(1, 8):
        for symmetric in (False, True):
            for _ in range(3):
                match = list(range(m)) if symmetric else list(rng.permutation(m))
                pattern = {(r, match[r]) for r in range(m)}
                for _ in range(rng.integers(0, m * m // 2 + 1)):
                    r, c = (int(v) for v in rng.integers(0, m, size=2))
                    pattern |= {(r, c), (c, r)} if symmetric else {(r, c)}
                entries = sorted(pattern)
                out.append((sparse.plan(m, entries, [int(c) for c in match], symmetric),
                            entries))
    for m in (4, 6):  # full: planned dense
        entries = [(r, c) for r in range(m) for c in range(m)]
        out.append((sparse.plan(m, entries, list(range(m))), entries))
    return out


PLANS = _plans()
# the workspace of the harness: save at 0, factors after it, right sides after those
AREAS = [BlockArea(0, p.nnz, 2 * p.nnz, 2 * p.nnz, 0, 0, 0, 0, 0, 0, 0) for p, _ in PLANS]


def _matrices(plan, entries, rng):
    """Values at `entries` (in the plan's given order): diagonally dominant (static pivots
    pass), random normal (some fail the threshold), and a first pivot of 1e-20 (fails)."""
    m = plan.m
    dominant = [(4.0 * m if r == c else 1.0) * rng.normal() + (4.0 * m if r == c else 0.0)
                for r, c in entries]
    random = list(rng.normal(size=len(entries)))
    tiny = list(random)
    first = plan.row_of[0], plan.col_of[0]
    tiny[entries.index(first)] = 1e-20
    if plan.symmetric:  # keep A = A^T
        random = _symmetrise(entries, random)
        dominant = _symmetrise(entries, dominant)
        tiny = _symmetrise(entries, tiny)
    return [dominant, random, tiny]


def _symmetrise(entries, values):
    at = dict(zip(entries, values))
    return [at[(min(r, c), max(r, c))] for r, c in entries]


def _python_functions(k, plan, area):
    code = _unrolled_lu(k, plan, area, c=False)
    if code is None:
        return None
    body = "\n".join(["import math", f"def factor(v):"]
                     + ["    " + line for line in code["factor_lines"]]
                     + ["def lsolve(v, xb):"] + ["    " + line for line in code["lsolve_lines"]])
    space: dict = {}
    exec(compile(body, f"<unrolled block {k}>", "exec"), space)  # noqa: S102 (bgc's own code)
    return space["factor"], space["lsolve"]


def test_plans_cover_static_symmetric_and_dense():
    unrolled = [p for (p, _), a in zip(PLANS, AREAS) if _unrolled_lu(0, p, a, True)]
    assert any(p.symmetric for p in unrolled) and any(not p.symmetric for p in unrolled)
    assert any(p.dense for p, _ in PLANS)  # those stay with the runtime's dense LU
    assert all(_unrolled_lu(0, p, a, True) is None for (p, _), a in zip(PLANS, AREAS) if p.dense)


def test_python_unrolled_lu_is_the_runtime_static_lu_to_the_bit():
    (text,) = emit_python(bgc.build(MODELS / "pendulum.bg").program).values()
    rt = processes.load_python_module(text)
    rng = np.random.default_rng(12)
    verdicts = set()
    for k, ((plan, entries), area) in enumerate(zip(PLANS, AREAS)):
        functions = _python_functions(k, plan, area)
        if functions is None:
            continue
        factor, lsolve = functions
        block = rt._Block([plan.m, plan.dense, plan.symmetric, plan.nnz]
                          + [getattr(plan, key) for key in PLAN_KEYS]
                          + [0] * 11 + [None, None])
        for values in _matrices(plan, entries, rng):
            rhs = list(rng.normal(size=plan.m))
            v = [0.0] * (2 * plan.nnz + plan.m)
            for pos, value in zip(plan.entries, values):
                v[pos] = value
            generic = v[:plan.nnz]
            passed = rt._lu_static(block, generic, 0, rt._row_scales(block, v, 0))
            ok = factor(v)
            assert ok == passed
            verdicts.add(ok)
            if not ok:
                continue
            assert v[plan.nnz:2 * plan.nnz] == generic  # the same factors, bit for bit
            b = [rhs[r] for r in plan.row_of]  # the right side in the plan's row order
            x = list(b)
            rt._lu_static_solve(block, generic, 0, x, 0)
            v[2 * plan.nnz:] = b
            lsolve(v, 2 * plan.nnz)
            assert v[2 * plan.nnz:] == x
            A = np.zeros((plan.m, plan.m))
            for (r, c), value in zip(entries, values):
                A[r, c] = value
            got = np.empty(plan.m)
            got[list(plan.col_of)] = x  # factored column k is unknown col_of[k]
            np.testing.assert_allclose(got, np.linalg.solve(A, rhs), rtol=1e-8, atol=1e-10)
    assert verdicts == {True, False}



needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")


def _c_harness(unrolled) -> str:
    """The pendulum's program as a library (for the runtime's static LU), each unrolled plan's
    functions and plan, and a main that factors and solves each input both ways and prints
    the verdicts and values in hexadecimal (exact)."""
    parts = ['#include "model.c"']
    table = []
    for k, plan, code in unrolled:
        for name, lines, head in (("factor", code["factor_lines"], "int {}(double *v)"),
                                  ("lsolve", code["lsolve_lines"],
                                   "void {}(const double *v, double *b)")):
            parts.append("static " + head.format(code[name]) + "\n{\n"
                         + "".join(f"    {line}\n" for line in lines) + "}")
        arrays = []
        for key in PLAN_KEYS:
            values = getattr(plan, key)
            parts.append(f"static const int plan{k}_{key}[] = {{ {', '.join(map(str, values or [0]))} }};")
            arrays.append(f"plan{k}_{key}")
        table.append(f"{{ {{ {plan.m}, 0, {int(plan.symmetric)}, {plan.nnz}, "
                     f"{', '.join(arrays)} }}, {code['factor']}, {code['lsolve']} }}")
    parts.append("static const struct { bgc_lu_plan pl; int (*factor)(double *);\n"
                 "    void (*lsolve)(const double *, double *); } plans[] = {\n    "
                 + ",\n    ".join(table) + "\n};")
    parts.append(r"""
int main(void)
{
    int k, q, n, ok, passed;
    double v[512], lu[256], scale[32], x[32];
    while (scanf("%d", &k) == 1) {
        const bgc_lu_plan *pl = &plans[k].pl;
        n = pl->nnz;
        for (q = 0; q < 512; q++) v[q] = 0.0;
        for (q = 0; q < n + pl->m; q++) scanf("%lf", &v[q]);  /* the matrix at save, then b */
        bgc_row_scales(pl, v, scale);
        memcpy(lu, v, (size_t)n * sizeof *lu);
        passed = bgc_lu_static(pl, lu, scale) == 0;
        for (q = 0; q < pl->m; q++) { x[q] = v[n + q]; v[2 * n + q] = v[n + q]; }
        ok = plans[k].factor(v) == 0;
        printf("%d %d", passed, ok);
        if (passed && ok) {
            bgc_lu_static_solve(pl, lu, x);
            plans[k].lsolve(v, v + 2 * n);
            for (q = 0; q < n; q++) printf(" %a %a", lu[q], v[n + q]);
            for (q = 0; q < pl->m; q++) printf(" %a %a", x[q], v[2 * n + q]);
        }
        printf("\n");
    }
    return 0;
}
""")
    return "\n".join(parts)


@needs_cc
def test_c_unrolled_lu_is_the_runtime_static_lu_to_the_bit(tmp_path):
    unrolled = [(k, plan, code) for k, ((plan, _), area) in enumerate(zip(PLANS, AREAS))
                if (code := _unrolled_lu(k, plan, area, c=True)) is not None]
    (text,) = emit_c(bgc.build(MODELS / "pendulum.bg").program).values()
    (tmp_path / "model.c").write_text(text)
    (tmp_path / "harness.c").write_text(_c_harness(unrolled))
    exe = tmp_path / "harness"
    subprocess.run(["cc", "-O2", "-std=c99", "-DBGC_NO_MAIN", "-Wall", "-Werror",
                    "-Wno-unused-function", str(tmp_path / "harness.c"), "-o", str(exe), "-lm"],
                   check=True, cwd=tmp_path)
    rng = np.random.default_rng(13)
    stdin, cases = [], []
    for k, plan, _ in unrolled:
        entries = PLANS[k][1]
        for values in _matrices(plan, entries, rng):
            save = [0.0] * plan.nnz
            for pos, value in zip(plan.entries, values):
                save[pos] = value
            b = list(rng.normal(size=plan.m))  # in the plan's row order; x in its column order
            stdin.append(" ".join([str(k)] + [f"{x:.17g}" for x in save + b]))
            A = np.zeros((plan.m, plan.m))
            for (r, c), value in zip(entries, values):
                A[r, c] = value
            cases.append((plan, np.linalg.solve(A[np.ix_(plan.row_of, plan.col_of)], b)))
    out = subprocess.run([str(exe)], input="\n".join(stdin) + "\n", capture_output=True,
                         text=True, check=True).stdout.splitlines()
    assert len(out) == len(cases)
    verdicts = set()
    for line, (plan, want) in zip(out, cases):
        fields = line.split()
        assert fields[0] == fields[1]  # the same verdict
        verdicts.add(fields[0])
        pairs = fields[2:]
        assert pairs[0::2] == pairs[1::2]  # factors and solution, bit for bit
        if pairs:
            x = [float.fromhex(h) for h in pairs[2 * plan.nnz::2]]
            np.testing.assert_allclose(x, want, rtol=1e-8, atol=1e-10)
    assert verdicts == {"0", "1"}
