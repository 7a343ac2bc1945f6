"""The graph algorithms of the block sort (bgc/symbolic/blt.py) and the LU plans
(bgc/symbolic/sparse.py), on small graphs and random matrices whose answers are known or computed
by numpy."""
import random

import numpy as np
import pytest

from bgc.symbolic import blt
from bgc.symbolic.sparse import plan


def test_components_in_dependency_order():
    # 0 -> 1 -> 2 -> 1 (a cycle), 3 -> 0, 4 alone
    succ = [[1], [2], [1], [0], []]
    comps = blt.components(5, succ)
    assert sorted(map(tuple, comps)) == [(0,), (1, 2), (3,), (4,)]
    where = {v: k for k, comp in enumerate(comps) for v in comp}
    for v, ws in enumerate(succ):  # every edge points to an earlier (or the same) component
        assert all(where[w] <= where[v] for w in ws)


def test_components_of_a_long_chain_do_not_recurse():
    n = 200_000
    succ = [[v + 1] if v + 1 < n else [0] for v in range(n)]  # one cycle through everything
    (comp,) = blt.components(n, succ)
    assert len(comp) == n


def test_tear_breaks_every_cycle():
    # two cycles sharing vertex 2: 0 -> 1 -> 2 -> 0 and 2 -> 3 -> 2
    succ = {0: [1], 1: [2], 2: [0, 3], 3: [2]}
    tears, order = blt.tear([0, 1, 2, 3], succ, [])
    assert tears == [2]  # the vertex with the most edges into it
    assert sorted(order) == [0, 1, 3]
    done = set(tears)
    for v in order:  # evaluation order: everything a vertex reads is known before it
        assert all(w in done for w in succ[v])
        done.add(v)


def test_tear_prefers_the_inputs_of_nonlinearities():
    succ = {0: [1], 1: [2], 2: [0]}  # one cycle, all vertices alike
    assert blt.tear([0, 1, 2], succ, [])[0] == [0]
    assert blt.tear([0, 1, 2], succ, [], frozenset({2}))[0] == [2]


def test_perfect_matching():
    assert blt.perfect_matching(3, [[0, 1], [0], [1, 2]]) == [1, 0, 2]
    assert blt.perfect_matching(2, [[0], [0]]) is None


def _factor_with_plan(p, values):
    """The runtime's static elimination, in numpy, following the plan's lists."""
    lu = np.zeros(p.nnz)
    for pos, v in zip(p.entries, values):
        lu[pos] = v
    q = 0
    for k in range(p.m):
        pivot = lu[p.diag[k]]
        for l in range(p.lptr[k], p.lptr[k + 1]):
            f = lu[p.lpos[l]] / pivot
            lu[p.lpos[l]] = f
            for u in range(p.uptr[k], p.uptr[k + 1]):
                lu[p.upd[q]] -= f * lu[p.upos[u]]
                q += 1
    return lu


def _solve_with_plan(p, lu, b):
    x = np.array(b, float)
    for k in range(p.m):
        for l in range(p.lptr[k], p.lptr[k + 1]):
            x[p.lrow[l]] -= lu[p.lpos[l]] * x[k]
    for k in range(p.m - 1, -1, -1):
        s = x[k]
        for u in range(p.uptr[k], p.uptr[k + 1]):
            s -= lu[p.upos[u]] * x[p.ucol[u]]
        x[k] = s / lu[p.diag[k]]
    return x


@pytest.mark.parametrize("shape", ["tridiagonal", "arrow", "random", "permuted"])
def test_static_plan_solves_like_numpy(shape):
    rng = random.Random(5)
    m = 12
    entries = set()
    for i in range(m):
        entries.add((i, i))
        if shape == "tridiagonal" and i + 1 < m:
            entries |= {(i, i + 1), (i + 1, i)}
        if shape == "arrow":
            entries |= {(0, i), (i, 0)}
        if shape == "random":
            entries |= {(i, rng.randrange(m)) for _ in range(2)}
    if shape == "permuted":  # a zero diagonal: the plan must permute rows onto it
        entries = {(i, (i + 3) % m) for i in range(m)} | {(i, (i + 4) % m) for i in range(m)}
    entries = sorted(entries)
    cols = [[c for r, c in entries if r == i] for i in range(m)]
    matching = blt.perfect_matching(m, cols)
    p = plan(m, entries, matching)
    assert not p.dense
    values = [rng.uniform(1, 2) * (5 if r == c else 1) for r, c in entries]
    A = np.zeros((m, m))
    for (r, c), v in zip(entries, values):
        A[r, c] = v
    b = np.array([rng.uniform(-1, 1) for _ in range(m)])
    lu = _factor_with_plan(p, values)
    z = _solve_with_plan(p, lu, [b[p.row_of[k]] for k in range(m)])
    x = np.zeros(m)
    for k in range(m):
        x[p.col_of[k]] = z[k]
    assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-12, atol=1e-12)


def test_band_matrix_plan_has_no_fill_and_linear_work():
    m = 200
    entries = sorted({(i, j) for i in range(m) for j in (i - 1, i, i + 1) if 0 <= j < m})
    p = plan(m, entries, list(range(m)))
    assert p.nnz == len(entries) and p.flops <= 2 * m


def test_dense_matrix_is_planned_dense():
    m = 30
    entries = [(i, j) for i in range(m) for j in range(m)]
    p = plan(m, entries, list(range(m)))
    assert p.dense and p.nnz == m * m


def test_symmetric_definite_matrix_needs_no_pivoting_however_scaled():
    """A symmetric positive definite band matrix whose pivots are tiny next to the entries below
    them: the threshold test of a general matrix rejects its static elimination (the runtime
    would refactor it densely), the one-sign test of a symmetric one accepts it, and the
    solution is right."""
    import bgc
    from bgc.base import processes
    from bgc.codegen.emit import emit_python

    (text,) = emit_python(bgc.build(bgc.api.Source("c.bg", "model c\n")).program).values()
    runtime = processes.load_python_module(text)  # the runtime's routines, as generated
    m = 6
    entries = sorted({(i, j) for i in range(m) for j in (i - 1, i, i + 1) if 0 <= j < m})
    scales = [1e-6 if i % 2 == 0 else 1e3 for i in range(m)]  # D B D: SPD, badly scaled
    B = np.zeros((m, m))
    for i, j in entries:
        B[i, j] = 2.0 if i == j else -0.9
    A = np.diag(scales) @ B @ np.diag(scales)
    assert np.all(np.linalg.eigvalsh(A) > 0)
    accepted = {}
    for symmetric in (False, True):
        p = plan(m, entries, list(range(m)), symmetric=symmetric)
        lu = [0.0] * p.nnz
        for (i, j), pos in zip(entries, p.entries):
            lu[pos] = A[i, j]
        block = runtime._Block((p.m, p.dense, p.symmetric, p.nnz, p.diag, p.lptr, p.lpos,
                                p.lrow, p.uptr, p.upos, p.ucol, p.upd, p.prow, p.pcol))
        scale = [max(abs(A[p.row_of[k], j]) for j in range(m)) for k in range(m)]
        accepted[symmetric] = runtime._lu_static(block, lu, 0, scale)
        if accepted[symmetric]:
            rhs = np.arange(1.0, m + 1)
            z = [rhs[p.row_of[k]] for k in range(m)]
            runtime._lu_static_solve(block, lu, 0, z, 0)
            x = np.zeros(m)
            for k in range(m):
                x[p.col_of[k]] = z[k]
            assert np.allclose(x, np.linalg.solve(A, rhs), rtol=1e-9, atol=0)
    assert accepted == {False: False, True: True}


def test_bound_adds_tears_where_a_vertex_reads_many_and_leaves_small_blocks_alone():
    # a running sum: v_k reads v_{k+1} and tear t_k, as a ladder's series currents read every
    # later branch's; tears 0..n-1, sums n..2n-1 evaluated from the far end
    n = 30
    succ = {n + k: [k] + ([n + k + 1] if k + 1 < n else []) for k in range(n)}
    order = [n + k for k in reversed(range(n))]
    tears, rest = blt.bound(list(range(n)), order, succ, 8)
    assert tears[:n] == list(range(n)) and len(tears) > n
    reach = {t: {t} for t in tears}
    done = set(tears)
    for v in rest:  # each vertex left to evaluate reads at most 8 tears, in order
        assert all(w in done for w in succ[v])
        reach[v] = set().union(*(reach[w] for w in succ[v]))
        assert len(reach[v]) <= 8
        done.add(v)
    assert sorted(tears[n:] + rest) == sorted(order)  # every sum torn or evaluated, once
    small = blt.bound(list(range(8)), [8, 9], {8: list(range(8)), 9: [8]}, 8)
    assert small == (list(range(8)), [8, 9])


def _resistor_ladder(n: int) -> str:
    lines = ["model ladder", "parameter V0 = 10.0", "parameter Cc = 0.2"]
    for i in range(1, n + 1):
        lines += [f"parameter Rs{i} = {0.1 + 0.01 * i!r}", f"parameter Rp{i} = {50.0 + i!r}"]
    lines += ["src : Se(V0)", "cap : C(Cc)"]
    for i in range(1, n + 1):
        left = "src" if i == 1 else f"n{i - 1}"
        lines += [f"s{i} : 1", f"rs{i} : R(Rs{i})", f"n{i} : 0", f"rp{i} : R(Rp{i})",
                  f"{left} -> s{i} -> n{i}", f"s{i} -> rs{i}", f"n{i} -> rp{i}"]
    lines += ["last : 1", "rl : R(Rs1)", f"n{n} -> last -> cap", "last -> rl"]
    return "\n".join(lines) + "\n"


def test_a_ladder_of_symbolic_resistors_is_a_banded_block_with_its_thevenin_answer():
    """The 64 node voltages alone are a dense system (each series current sums every later
    branch's); with a series current torn every few sections the block's entries grow with
    the ladder, and the capacitor still charges as the ladder's Thevenin equivalent says."""
    import bgc
    from bgc.api import Source

    n = 64
    source = Source("ladder.bg", _resistor_ladder(n))
    (block,) = bgc.build(source).program.blocks
    assert len(block.pattern) <= 8 * n  # dense Hessenberg: n(n+1)/2 + n - 1 = 2 143
    assert block.lu.nnz <= 12 * n
    V, R = 10.0, 0.0  # the source, then each section: Rs in series, Rp across
    for i in range(1, n + 1):
        R += 0.1 + 0.01 * i
        rp = 50.0 + i
        V, R = V * rp / (R + rp), R * rp / (R + rp)
    tau = (R + 0.11) * 0.2  # about 1.7
    t, Y, names = bgc.simulate(source, backend="python", t_end=5.0, dt=0.5,
                               solver="dopri5", rtol=1e-11, atol=1e-13, outputs=["cap.q"])
    expected = 0.2 * V * (1.0 - np.exp(-np.asarray(t) / tau))
    assert np.abs(np.asarray(Y)[:, 0] - expected).max() <= 1e-9 * 0.2 * V
