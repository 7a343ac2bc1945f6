"""Plans for the linear solves in the generated code: an LU factorization fixed at compile time.

A block's matrix has a sparsity pattern known when the model is compiled (the residuals of a
chain of constraints form a band, a resistor ladder a tridiagonal matrix).  `plan` chooses,
once, a row permutation that puts a structurally nonzero entry on every diagonal position (the
block's matching), a symmetric fill-reducing order (minimum degree, ties by index), and the
positions of every entry of L and U with their update lists.  The generated code then factors
in that order with no search: O(fill) work and memory instead of O(m^3).

Because no pivot is chosen at run time, the runtime tests every pivot: for a symmetric matrix,
that all have one sign (the matrix is then definite, as J M^-1 J^T of a constraint block is,
and elimination without pivoting is LDL^T, stable); otherwise threshold partial pivoting,
|pivot| >= 0.1 * the largest entry below it in its column.  Every pivot must also be clearly
nonzero relative to its row.  If a test fails, the runtime factors the same matrix again
densely with partial pivoting, so that the result is always that of a stable elimination.  Blocks
whose static factorization would save less than half of a dense one's m^3/3 multiply-adds, or whose
update list would be too long to carry as data, are planned dense from the start.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

MAX_UPDATES = 250_000  # a static plan's update list beyond this (in ints) is planned dense


@dataclass(frozen=True)
class LUPlan:
    m: int
    dense: bool  # factor densely with partial pivoting (the static lists below are empty)
    symmetric: bool  # A = A^T: pivots of one sign prove it definite (LDL^T, no threshold)
    row_of: tuple[int, ...]  # factored row k is residual row_of[k]
    col_of: tuple[int, ...]  # factored column k is unknown col_of[k]
    entries: tuple[int, ...]  # storage position of each given entry, in the order given
    nnz: int  # storage size: entries of L + U (m*m when dense)
    diag: tuple[int, ...] = ()  # position of (k, k)
    lptr: tuple[int, ...] = ()  # column k of L below the diagonal: lpos[lptr[k]:lptr[k+1]]
    lpos: tuple[int, ...] = ()
    lrow: tuple[int, ...] = ()
    uptr: tuple[int, ...] = ()  # row k of U right of the diagonal: upos[uptr[k]:uptr[k+1]]
    upos: tuple[int, ...] = ()
    ucol: tuple[int, ...] = ()
    upd: tuple[int, ...] = ()  # per k, per L entry, per U entry: position of (row, col)
    prow: tuple[int, ...] = ()  # row and column of every position (for the dense fallback)
    pcol: tuple[int, ...] = ()

    @property
    def flops(self) -> int:
        """Multiply-adds of one factorization."""
        return len(self.upd) + len(self.lpos) if not self.dense else self.m ** 3 // 3


def plan(m: int, entries: list[tuple[int, int]], matching: list[int],
         symmetric: bool = False) -> LUPlan:
    """The plan for an m x m matrix with the given (row, column) entries; matching[r] is a
    column with entry (r, matching[r]) for each row r, all distinct.  A symmetric matrix
    (with a full diagonal) keeps its rows: the order is then symmetric, and the elimination
    that of LDL^T."""
    if m == 0:
        return LUPlan(0, False, False, (), (), (), 0)
    if symmetric:
        matching = list(range(m))
    perm_row = {r: matching[r] for r in range(m)}  # B = rows moved so that B[c, c] != 0
    pattern = [set() for _ in range(m)]  # B's rows: column sets
    for r, c in entries:
        pattern[perm_row[r]].add(c)
    order = _minimum_degree(m, pattern)
    rank = {v: k for k, v in enumerate(order)}
    row_inv = {c: r for r, c in perm_row.items()}
    row_of = tuple(row_inv[order[k]] for k in range(m))
    col_of = tuple(order)
    rows = [set() for _ in range(m)]  # final numbering
    for r, c in entries:
        rows[rank[perm_row[r]]].add(rank[c])
    for k in range(m):
        rows[k].add(k)
    filled, flops = _symbolic(m, rows)
    if (m > 2 and flops > m ** 3 // 6) or flops > MAX_UPDATES:
        return _dense(m, entries)  # static order saves less than half of dense LU's work
    positions = {}
    prow, pcol = [], []
    for i in range(m):
        for j in sorted(filled[i]):
            positions[(i, j)] = len(prow)
            prow.append(i)
            pcol.append(j)
    cols = [[] for _ in range(m)]
    for i in range(m):
        for j in filled[i]:
            if i > j:
                cols[j].append(i)
    diag, lptr, lpos, lrow, uptr, upos, ucol, upd = [], [0], [], [], [0], [], [], []
    for k in range(m):
        diag.append(positions[(k, k)])
        below = sorted(cols[k])
        right = sorted(j for j in filled[k] if j > k)
        lpos += [positions[(i, k)] for i in below]
        lrow += below
        lptr.append(len(lpos))
        upos += [positions[(k, j)] for j in right]
        ucol += right
        uptr.append(len(upos))
        for i in below:
            upd += [positions[(i, j)] for j in right]
    given = tuple(positions[(rank[perm_row[r]], rank[c])] for r, c in entries)
    return LUPlan(m, False, symmetric, row_of, col_of, given, len(prow), tuple(diag), tuple(lptr),
                  tuple(lpos), tuple(lrow), tuple(uptr), tuple(upos), tuple(ucol), tuple(upd),
                  tuple(prow), tuple(pcol))


def _dense(m, entries) -> LUPlan:
    ident = tuple(range(m))
    return LUPlan(m, True, False, ident, ident, tuple(r * m + c for r, c in entries), m * m)


def _minimum_degree(m: int, pattern: list[set]) -> list[int]:
    """A symmetric minimum-degree order of the pattern (with its transpose): eliminate the
    vertex of least degree (ties: the lowest), joining its neighbours; a heap with stale
    entries skipped keeps it near-linear for the band structures of models."""
    adj = [set() for _ in range(m)]
    for i in range(m):
        for j in pattern[i]:
            if i != j:
                adj[i].add(j)
                adj[j].add(i)
    heap = [(len(adj[v]), v) for v in range(m)]
    heapq.heapify(heap)
    alive = [True] * m
    order = []
    while heap:
        degree, v = heapq.heappop(heap)
        if not alive[v] or degree != len(adj[v]):
            continue
        alive[v] = False
        order.append(v)
        nbrs = adj[v]
        for a in nbrs:
            adj[a].discard(v)
            adj[a] |= nbrs - {a}
            heapq.heappush(heap, (len(adj[a]), a))
        adj[v] = set()
    return order


def _symbolic(m: int, rows: list[set]) -> tuple[list[set], int]:
    """The pattern of L + U for elimination in the natural order, and its multiply-adds."""
    filled = [set(r) for r in rows]
    cols = [set() for _ in range(m)]
    for i in range(m):
        for j in filled[i]:
            cols[j].add(i)
    flops = 0
    for k in range(m):
        right = [j for j in filled[k] if j > k]
        below = [i for i in cols[k] if i > k]
        flops += len(right) * len(below)
        for i in below:
            new = [j for j in right if j not in filled[i]]
            filled[i].update(new)
            for j in new:
                cols[j].add(i)
    return filled, flops


# ---------------------------------------------------------------- the stiff solvers' matrices

SPARSE_MIN_STATES = 32  # below this, the iteration matrices are factored densely
SPARSE_MAX_FILL = 0.25  # ... and at or above it, when L + U fills more than this of n x n


@dataclass(frozen=True)
class IterationPlan:
    """A static sparse LU of the stiff solvers' iteration matrices, c I - J (c real, or complex
    for Radau's pairs), whose pattern is the Jacobian's with the diagonal.  Row and column
    k of the factored matrix are state perm[k] (a symmetric minimum-degree order; the diagonal
    is always structurally there, so no matching is needed).  L + U is stored by rows: row k
    holds the positions rowptr[k] .. rowptr[k + 1] - 1, its columns cols[...] ascending, the
    diagonal at diag[k]; jpos[q] is the position of the Jacobian's q-th structural entry (in the
    order of its columns, JacobianPattern.columns) and dpos[i] that of state i's diagonal."""

    n: int
    perm: tuple[int, ...]
    rowptr: tuple[int, ...]
    cols: tuple[int, ...]
    diag: tuple[int, ...]
    jpos: tuple[int, ...]
    dpos: tuple[int, ...]
    flops: int  # multiply-adds of one factorisation

    @property
    def nnz(self) -> int:
        return len(self.cols)


def iteration_plan(columns) -> IterationPlan | None:
    """The plan for c I - J given J's structure (columns[j]: the rows of column j), or None
    when the dense factorisation is the better one: fewer than SPARSE_MIN_STATES states, or
    L + U filling SPARSE_MAX_FILL of the matrix or more.  Linear in the fill: the elimination's
    updates are not listed (the runtime reads them off the rows of L + U)."""
    n = len(columns)
    if n < SPARSE_MIN_STATES:
        return None
    pattern = [set() for _ in range(n)]
    for j, rows in enumerate(columns):
        for i in rows:
            pattern[i].add(j)
    if sum(len(r) for r in pattern) + n > SPARSE_MAX_FILL * n * n:
        return None
    order = _minimum_degree(n, pattern)
    rank = [0] * n
    for k, v in enumerate(order):
        rank[v] = k
    rows = [set() for _ in range(n)]
    for i in range(n):
        rows[rank[i]] = {rank[j] for j in pattern[i]}
        rows[rank[i]].add(rank[i])
    filled, flops = _symbolic(n, rows)
    if sum(len(r) for r in filled) > SPARSE_MAX_FILL * n * n:
        return None
    rowptr, cols, diag = [0], [], []
    where = []  # per factored row: column -> position
    for k in range(n):
        row = sorted(filled[k])
        at = {}
        for j in row:
            if j == k:
                diag.append(len(cols))
            at[j] = len(cols)
            cols.append(j)
        where.append(at)
        rowptr.append(len(cols))
    jpos = tuple(where[rank[i]][rank[j]] for j, rows_j in enumerate(columns) for i in rows_j)
    dpos = tuple(diag[rank[i]] for i in range(n))
    return IterationPlan(n, tuple(order), tuple(rowptr), tuple(cols), tuple(diag), jpos, dpos,
                         flops)
