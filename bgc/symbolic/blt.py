"""Graph algorithms of the block-lower-triangular sort, on integer vertices.

- `components`: Tarjan's strongly connected components, iterative, dependencies first;
- `tear`: choose tear vertices that break every cycle of a component, so that the rest can be
  evaluated in order once the tears are known;
- `bound`: more tears where an evaluated vertex would read many tears through the others, so
  that the torn system stays as sparse as the graph (a ladder's block banded, not dense);
- `perfect_matching`: whether each residual can be paired with its own unknown (else the block is
  structurally singular).

Everything is deterministic: vertices and their successors are taken in increasing order, and
no set order reaches a result.  Nothing recurses.
"""
from __future__ import annotations


def components(n: int, succ: list[list[int]], roots=None) -> list[list[int]]:
    """Strongly connected components of the graph v -> succ[v] (v < n), each sorted, in an
    order where every component comes after the components it has edges into."""
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    stack: list[int] = []
    out: list[list[int]] = []
    counter = 0
    for root in (range(n) if roots is None else roots):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        while work:
            v, k = work[-1]
            edges = succ[v]
            if k < len(edges):
                work[-1] = (v, k + 1)
                w = edges[k]
                if index[w] < 0:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack[w] = True
                    work.append((w, 0))
                elif on_stack[w] and index[w] < low[v]:
                    low[v] = index[w]
                continue
            work.pop()
            if work:
                u = work[-1][0]
                if low[v] < low[u]:
                    low[u] = low[v]
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == v:
                        break
                comp.sort()
                out.append(comp)
    return out


def tear(vertices: list[int], succ: dict[int, list[int]], fixed: list[int],
         preferred: frozenset = frozenset()) -> tuple[list[int], list[int]]:
    """Tears for the subgraph on `vertices` (succ restricted to them): `fixed` are tears
    already (their edges are cut), more are chosen until no cycle is left, each from a
    remaining cycle: a `preferred` vertex first, then the one with the most edges into it
    from that cycle, then the lowest.  Returns (tears, the others in evaluation order,
    dependencies first)."""
    tears = list(fixed)
    cut = set(fixed)
    while True:
        rest = [v for v in vertices if v not in cut]
        local = {v: i for i, v in enumerate(rest)}
        graph = [[local[w] for w in succ.get(v, ()) if w in local] for v in rest]
        comps = components(len(rest), graph)
        cyclic = [c for c in comps if len(c) > 1 or c[0] in graph[c[0]]]
        if not cyclic:
            return tears, [rest[c[0]] for c in comps]
        for comp in cyclic:
            members = set(comp)
            indegree = {v: 0 for v in comp}
            for v in comp:
                for w in graph[v]:
                    if w in members:
                        indegree[w] += 1
            best = max(comp, key=lambda v: (rest[v] in preferred, indegree[v], -v))
            tears.append(rest[best])
            cut.add(rest[best])


def bound(tears: list[int], order: list[int], succ: dict[int, list[int]],
          limit: int) -> tuple[list[int], list[int]]:
    """(tears, order) with more tears: taking `order` (dependencies first), a vertex whose
    inputs reach more than `limit` tears through the vertices evaluated before it becomes a
    tear itself.  Each row of the torn system (a tear's residual) then reads at most `limit`
    tears through each of its inputs, where the tears of `tear` alone can leave a residual
    reading all of them: in a ladder of resistors the series currents are sums of every later
    branch's, and its n node voltages a dense n x n system where the 2n voltages and currents
    are a banded one.  A block whose tears number `limit` or fewer is left as it is.  The work
    is linear in the edges: no set grows past limit + 1 before it is cut."""
    if len(tears) <= limit:
        return tears, order
    tears = list(tears)
    reach: dict[int, frozenset] = {v: frozenset((v,)) for v in tears}
    rest = []
    for v in order:
        seen: set = set()
        for w in succ.get(v, ()):
            seen.update(reach.get(w, ()))
            if len(seen) > limit:
                break
        if len(seen) > limit:
            tears.append(v)
            reach[v] = frozenset((v,))
        else:
            reach[v] = frozenset(seen)
            rest.append(v)
    return tears, rest


def perfect_matching(rows: int, cols: list[list[int]]) -> list[int] | None:
    """A matching of every row r to a distinct column in cols[r] (augmenting paths, iterative),
    as the column of each row; None if there is none."""
    match_col: dict[int, int] = {}  # column -> row
    result = [-1] * rows
    for r in range(rows):
        # depth-first search for an augmenting path from row r
        parent: dict[int, tuple[int, int]] = {}  # column -> (row it was reached from, prev col)
        stack = [(r, -1)]
        seen_rows = {r}
        found = -1
        while stack and found < 0:
            row, via = stack.pop()
            for c in cols[row]:
                if c in parent:
                    continue
                parent[c] = (row, via)
                if c not in match_col:
                    found = c
                    break
                nxt = match_col[c]
                if nxt not in seen_rows:
                    seen_rows.add(nxt)
                    stack.append((nxt, c))
        if found < 0:
            return None
        c = found
        while c >= 0:
            row, prev = parent[c]
            match_col[c] = row
            result[row] = c
            c = prev
    return result
