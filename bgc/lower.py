"""Stage 7, lower: Reduced -> Program, the IR the emitters print (bgc.ir).

1. Each function takes from the sorted steps only what its results need (dead-code
   elimination from the results backwards): `rhs` the state derivatives, `outputs` the scene's
   outputs.
2. `jvp`, the Jacobian of the right side times a direction v, is derived from `rhs` by forward
   differentiation, statement by statement: an assignment's tangent is the directional
   derivative of its expression; through a linear block A z = b the tangent solves
   A dz = db - dA z with A's factors; through a Newton block dz = -J^-1 (dr/du du), J at the
   solution.  `jacobian()` of the generated code evaluates jvp once per colour of the columns.
3. Model symbols become IR symbols (states x[i], parameters p[j], the rest w<k>); an assignment
   that only renames or negates is propagated, not emitted.
4. Subexpressions of the parameters alone become constants c[k]; repeated subexpressions
   within a function become temporaries (value numbering, linear in the code's size).
5. Every block gets its factorization plan (bgc.sparse).
"""
from __future__ import annotations

import sympy as sp

from . import ir
from .blt import perfect_matching
from .differentiate import directional, partial
from .ir import (C, P, T, V, X, Assign, BlockPlan, ConstraintRow, Function, JacobianPattern,
                 Newton, Param, Program, Resolve, SceneSettings, Solve, Store, as_expr)
from .reduce import Assign as RAssign
from .reduce import Block, Reduced
from .sparse import plan as lu_plan
from .graph import TIME, var


# ---------------------------------------------------------------- model-level statements
# Before symbols are mapped, a function is a list of these, over model symbols:
#   RAssign(target, expr)              (from bgc.reduce)
#   ("solve", Block)                   the unknowns of a linear block
#   ("newton", Block, final_factor)    the unknowns and body of a nonlinear block
#   ("resolve", Block, targets, rhs)   a tangent solve with the block's factors
#   ("store", index, expr)


def _flatten(steps):
    out = []
    for s in steps:
        if isinstance(s, Block) and s.method == "lu":
            out.extend(s.prelude)
            out.append(("solve", s))
            out.extend(s.body)
        elif isinstance(s, Block):
            out.append(("newton", s, False))
        else:
            out.append(s)
    return out


def _defined(s):
    if isinstance(s, RAssign):
        return (s.target,)
    if s[0] == "solve":
        return s[1].unknowns
    if s[0] == "newton":
        return s[1].unknowns + tuple(a.target for a in s[1].body)
    if s[0] == "resolve":
        return s[2]
    return ()


def _read(s) -> set:
    if isinstance(s, RAssign):
        return s.expr.free_symbols
    if s[0] == "store":
        return s[2].free_symbols
    if s[0] == "solve":
        b = s[1]
        out = set()
        for e in [e for _, _, e in b.matrix] + list(b.rhs):
            out |= e.free_symbols
        return out
    if s[0] == "resolve":
        out = set()
        for e in s[3]:
            out |= e.free_symbols
        return out
    b = s[1]
    inner = set(b.unknowns) | {a.target for a in b.body} | {a.target for a in b.tangents}
    out = set()
    for e in [a.expr for a in b.body] + list(b.residuals) + [a.expr for a in b.tangents] + \
            [e for _, _, e in b.jacobian]:
        out |= e.free_symbols
    return out - inner


def _select(statements, needed: set) -> list:
    """The statements that the needed symbols depend on, in order (stores always kept)."""
    keep = []
    needed = set(needed)
    for s in reversed(statements):
        if not isinstance(s, RAssign) and s[0] == "store":
            keep.append(s)
            needed |= _read(s)
        elif any(d in needed for d in _defined(s)):
            keep.append(s)
            needed |= _read(s)
    keep.reverse()
    return keep


# ---------------------------------------------------------------- forward differentiation


class _Tangents:
    """The jvp statements of a function: each primal statement followed by its tangent."""

    def __init__(self, seeds: dict):
        self.tan = dict(seeds)  # symbol -> its tangent (a symbol or an expression)
        self.fresh = 0

    def symbol(self, s, prefix="d"):
        self.fresh += 1
        return sp.Symbol(f"{prefix}[{s.name}]#{self.fresh}", real=True)

    def of(self, expr):
        return directional(expr, {u: self.tan[u] for u in expr.free_symbols if u in self.tan})

    def bind(self, target, value, out, prefix="d"):
        """target's tangent is value: a new assignment unless it is zero or a symbol."""
        if value == 0:
            return
        if value.is_Symbol or value.is_Indexed:
            self.tan[target] = value
            return
        d = self.symbol(target, prefix)
        out.append(RAssign(d, value))
        self.tan[target] = d

    def program(self, statements) -> list:
        out = []
        for s in statements:
            if isinstance(s, RAssign):
                out.append(s)
                self.bind(s.target, self.of(s.expr), out)
            elif s[0] == "store":
                out.append(("store", s[1], self.of(s[2])))
            elif s[0] == "solve":
                out.append(s)
                self._solve(s[1], out)
            elif s[0] == "newton":
                out.append(("newton", s[1], True))
                self._newton(s[1], out)
        return out

    def _solve(self, b: Block, out):
        dA = {(i, k): self.of(e) for i, k, e in b.matrix}
        rows = []
        for i, rhs in enumerate(b.rhs):
            row = self.of(rhs) - sp.Add(*[dA[(ii, k)] * b.unknowns[k]
                                          for (ii, k) in dA if ii == i and dA[(ii, k)] != 0])
            rows.append(row)
        self._resolve(b, rows, out)

    def _newton(self, b: Block, out):
        # partial tangents of the body with z held, then dz = -J^-1 dr, then full tangents
        held = _Tangents({})
        held.tan = dict(self.tan)
        held.fresh = self.fresh
        for a in b.body:
            held.bind(a.target, held.of(a.expr), out, prefix="h")
        self.fresh = held.fresh
        rows = [-held.of(r) for r in b.residuals]
        self._resolve(b, rows, out)
        for a in b.body:
            self.bind(a.target, self.of(a.expr), out)

    def _resolve(self, b: Block, rows, out):
        if all(r == 0 for r in rows):
            return
        targets = tuple(self.symbol(z) for z in b.unknowns)
        out.append(("resolve", b, targets, tuple(rows)))
        for z, d in zip(b.unknowns, targets):
            self.tan[z] = d


# ---------------------------------------------------------------- mapping to the IR


class _Mapper:
    """Model symbols to IR symbols, with copy propagation; blocks to plans."""

    def __init__(self, base: dict):
        self.sub = dict(base)  # model symbol -> what it is in the IR (a symbol or expression)
        self.names: dict = {}  # model symbol -> its program variable, the same in every function
        self.count = 0
        self.blocks: dict = {}  # reduce Block.index -> position in plans
        self.plans: list[BlockPlan] = []
        self.mapped: dict = {}  # model expression -> IR expression

    def target(self, s):
        """The program variable of s (from now on, s means it)."""
        w = self.names.get(s)
        if w is None:
            w = self.names[s] = ir.W(self.count)
            self.count += 1
        self.sub[s] = w
        return w

    def expr(self, e):
        """e in the IR's symbols.  A model symbol means the same in every function, so an
        expression that rhs, outputs and jvp share is mapped once."""
        done = self.mapped.get(e)
        if done is None:
            done = self.mapped[e] = _integral_floats(ir.substitute(e, self.sub))
        return done

    def assign(self, a: RAssign, out, propagate=True):
        e = self.expr(a.expr)
        if propagate and _trivial(e):
            self.sub[a.target] = e
            return
        out.append(Assign(self.target(a.target), e))

    def plan(self, b: Block):
        if b.index not in self.blocks:
            entries = b.matrix if b.method == "lu" else b.jacobian
            pattern = [(i, k) for i, k, _ in entries]
            cols = [[k for (i, k) in pattern if i == r] for r in range(len(b.unknowns))]
            matching = perfect_matching(len(b.unknowns), cols)
            if matching is None:  # pragma: no cover - reduce checked the structure
                raise AssertionError("bgc bug: a block without a matching reached lower")
            self.blocks[b.index] = len(self.plans)
            self.plans.append(BlockPlan(b.index, tuple(z.name for z in b.unknowns), b.method,
                                        lu_plan(len(b.unknowns), pattern, matching,
                                                b.symmetric)))
        return self.blocks[b.index]

    def function(self, name, args, statements, size) -> Function:
        body = []
        for s in statements:
            if isinstance(s, RAssign):
                self.assign(s, body)
            elif s[0] == "store":
                body.append(Store(s[1], self.expr(s[2])))
            elif s[0] == "solve":
                self._solve(s[1], body)
            elif s[0] == "newton":
                self._newton(s[1], s[2], body)
            elif s[0] == "resolve":
                k = self.plan(s[1])
                lu = self.plans[k].lu
                rhs = tuple(self.expr(s[3][lu.row_of[r]]) for r in range(lu.m))
                targets = tuple(self.target(t) for t in s[2])
                body.append(Resolve(k, tuple(targets[lu.col_of[c]] for c in range(lu.m)), rhs))
        return Function(name, args, size, tuple(body))

    def _solve(self, b: Block, body):
        k = self.plan(b)
        lu = self.plans[k].lu
        matrix = tuple(self.expr(e) for _, _, e in b.matrix)
        rhs = tuple(self.expr(b.rhs[lu.row_of[r]]) for r in range(lu.m))
        z = tuple(self.target(u) for u in b.unknowns)
        body.append(Solve(k, tuple(z[lu.col_of[c]] for c in range(lu.m)), matrix, rhs))

    def _newton(self, b: Block, final, body):
        k = self.plan(b)
        lu = self.plans[k].lu
        z = tuple(self.target(u) for u in b.unknowns)
        inner: list = []
        for a in b.body:
            self.assign(a, inner, propagate=False)
        tangents: list = []
        for a in b.tangents:
            self.assign(a, tangents)
        residuals = tuple(self.expr(r) for r in b.residuals)
        jacobian = tuple(self.expr(e) for _, _, e in b.jacobian)
        body.append(Newton(k, tuple(z[lu.col_of[c]] for c in range(lu.m)), tuple(inner),
                           tuple(residuals[lu.row_of[r]] for r in range(lu.m)), tuple(tangents),
                           jacobian, final))


def _trivial(e) -> bool:
    """A number, a symbol, or a negated symbol: propagated instead of assigned."""
    if e.is_Number or e.is_Symbol or e.is_Indexed:
        return True
    return e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and (e.args[1].is_Symbol
                                                                   or e.args[1].is_Indexed)


def _integral_floats(e):
    """Floats with an integral value as integers (1.0*x is x), exact either way."""
    floats = [f for f in e.atoms(sp.Float) if float(f).is_integer() and abs(float(f)) < 2 ** 53]
    if not floats:
        return e
    return e.xreplace({f: sp.Integer(int(f)) for f in floats})


# ---------------------------------------------------------------- passes on IR functions


def _dead_code(f: Function) -> Function:
    """The statements the stores need, backwards; a Resolve needs the factors of its block's
    solve as well as its own inputs."""
    needed = set()
    factored = set()  # blocks whose factors a kept Resolve uses
    keep = []
    for s in reversed(f.body):
        if isinstance(s, Store) or any(d in needed for d in ir.defines(s)) or (
                isinstance(s, (Solve, Newton)) and s.block in factored):
            keep.append(s)
            needed |= ir.uses(s)
            if isinstance(s, Resolve):
                factored.add(s.block)
            elif isinstance(s, (Solve, Newton)):
                factored.discard(s.block)
    keep.reverse()
    return Function(f.name, f.args, f.size, tuple(keep))


def _map_statement(s, fn):
    if isinstance(s, Assign):
        return Assign(s.target, fn(s.expr))
    if isinstance(s, Store):
        return Store(s.index, fn(s.expr))
    if isinstance(s, Solve):
        return Solve(s.block, s.unknowns, tuple(fn(e) for e in s.matrix),
                     tuple(fn(e) for e in s.rhs))
    if isinstance(s, Resolve):
        return Resolve(s.block, s.targets, tuple(fn(e) for e in s.rhs))
    return Newton(s.block, s.unknowns, tuple(Assign(a.target, fn(a.expr)) for a in s.body),
                  tuple(fn(e) for e in s.residuals),
                  tuple(Assign(a.target, fn(a.expr)) for a in s.tangents),
                  tuple(fn(e) for e in s.jacobian), s.final_factor)


def hoist_constants(functions: list[Function]) -> tuple[tuple[sp.Expr, ...], list[Function]]:
    """The parameter-only subexpressions of the functions, replaced by constants c[k]: every
    largest subexpression that uses parameters and no t, x, v or program variable and is more
    than a single parameter; and within a sum or product that also uses those, its
    parameter-only terms or factors taken together (2*m*g*y becomes c[k]*y).  A constant that
    occurs more than once is one c[k]; they are numbered in order of first occurrence (walking
    the statements and the expression trees left to right in their canonical order), so that
    no set or hash order reaches the result.  Sums and products may group their terms
    differently, so values can differ in the last bits.  One bottom-up pass per expression."""
    pool: dict = {}
    info: dict = {}  # node -> (rewritten, parameter-only, uses a parameter)

    def constant(e, uses_p):
        if e.is_Atom or e.is_Indexed or not uses_p:
            return e
        if e not in pool:
            pool[e] = C[len(pool)]
        return pool[e]

    def analyse(root):
        stack = [(root, False)]
        while stack:
            e, ready = stack.pop()
            if e in info:
                continue
            if e.is_Indexed:
                info[e] = (e, e.base == P, e.base == P)
                continue
            if e.is_Symbol:
                info[e] = (e, False, False)  # t, a program variable
                continue
            if e.is_Atom or not e.args:
                info[e] = (e, True, False)  # a number
                continue
            if not ready:
                stack.append((e, True))
                stack.extend((a, False) for a in reversed(e.args) if a not in info)
                continue
            kids = [info[a] for a in e.args]
            uses_p = any(k[2] for k in kids)
            if all(k[1] for k in kids):
                info[e] = (e, True, uses_p)
                continue
            if (e.is_Add or e.is_Mul) and sum(1 for k in kids if k[1]) > 1:
                fixed = [a for a, k in zip(e.args, kids) if k[1]]
                group = e.func(*fixed)
                varying = [k[0] for k in kids if not k[1]]
                new = e.func(constant(group, any(k[2] for k in kids if k[1])), *varying)
            else:
                new = ir.rebuild(e, [constant(a, k[2]) if k[1] else k[0]
                                     for a, k in zip(e.args, kids)])
            info[e] = (new, False, uses_p)

    def visit(e):
        analyse(e)
        new, fixed, uses_p = info[e]
        return constant(e, uses_p) if fixed else new

    out = [Function(f.name, f.args, f.size, tuple(_map_statement(s, visit) for s in f.body))
           for f in functions]
    return tuple(pool), out


def _worth_a_temporary(e) -> bool:
    if e.is_Atom or e.is_Indexed:
        return False
    if e.is_Mul and len(e.args) == 2 and e.args[0].is_Number and (e.args[1].is_Atom
                                                                   or e.args[1].is_Indexed):
        return False  # -x, 2*x: free in the printed sum or product
    if e.is_Pow and e.exp == -1:
        return False  # a division stays a division (same rounding as without the temporary)
    return True


def common_subexpressions(f: Function, start: int) -> tuple[Function, int]:
    """Repeated subexpressions of f's top-level statements as temporaries, each assigned just
    before the first statement that uses it (value numbering: one pass to count, one to
    rewrite, linear in the code's size).  Temporaries are numbered from `start`."""
    counts: dict = {}
    for s in f.body:
        for e in ir.expressions(s):
            stack = [e]
            while stack:
                n = stack.pop()
                if n.is_Atom or n.is_Indexed:
                    continue
                c = counts.get(n, 0)
                counts[n] = c + 1
                if c == 0:
                    stack.extend(n.args)
    repeated = {n for n, c in counts.items() if c > 1 and _worth_a_temporary(n)}
    if not repeated:
        return f, start
    names: dict = {}
    count = start
    body = []
    for s in f.body:
        pending = []

        def rewrite(e):
            nonlocal count
            if e.is_Atom or e.is_Indexed:
                return e
            done: dict = {}
            stack = [(e, False)]
            while stack:
                n, ready = stack.pop()
                if n in done or n.is_Atom or n.is_Indexed:
                    continue
                if n in names:
                    done[n] = names[n]
                    continue
                if not ready:
                    stack.append((n, True))
                    stack.extend((a, False) for a in n.args)
                    continue
                value = ir.rebuild(n, [done.get(a, names.get(a, a)) for a in n.args])
                if n in repeated:
                    w = ir.W(count)
                    count += 1
                    names[n] = w
                    pending.append(Assign(w, value))
                    done[n] = w
                else:
                    done[n] = value
            return done.get(e, names.get(e, e))

        new = _map_statement(s, rewrite) if not isinstance(s, Newton) else s
        body.extend(pending)
        body.append(new)
    return Function(f.name, f.args, f.size, tuple(body)), count


def _propagate_copies(f: Function) -> Function:
    """Assignments that only rename, negate or name a constant, substituted into their uses
    (hoisting and temporaries leave some: w6 = c[2], w16 = w26)."""
    sub: dict = {}
    body = []
    for s in f.body:
        if sub:
            s = _map_statement(s, lambda e: ir.substitute(e, sub) if e.free_symbols & sub.keys()
                               else e)
        if isinstance(s, Assign) and _trivial(s.expr):
            sub[s.target] = s.expr
            continue
        body.append(s)
    return Function(f.name, f.args, f.size, tuple(body))


# ---------------------------------------------------------------- the Jacobian's pattern


def jacobian_pattern(rhs: Function, n: int, blocks) -> JacobianPattern:
    """Structural dependence of each derivative on each state (through solves: every unknown
    of a block depends on everything the block reads), and a greedy colouring of the columns
    in order (no two columns of a colour share a row)."""
    rows = ir.state_masks(rhs, n)
    columns = [[] for _ in range(n)]
    for i, m in enumerate(rows):
        j = 0
        while m:
            if m & 1:
                columns[j].append(i)
            m >>= 1
            j += 1
    colors: list[list[int]] = []
    covered: list[int] = []
    for j in range(n):
        rowmask = 0
        for i in columns[j]:
            rowmask |= 1 << i
        for c, cov in enumerate(covered):
            if not cov & rowmask:
                colors[c].append(j)
                covered[c] |= rowmask
                break
        else:
            colors.append([j])
            covered.append(rowmask)
    return JacobianPattern(tuple(tuple(c) for c in columns), tuple(tuple(c) for c in colors))


# ---------------------------------------------------------------- the stage


def lower(reduced: Reduced) -> Program:
    """The program of a reduced system."""
    states = [st.symbol for st in reduced.states]
    base = {TIME: T}
    for i, s in enumerate(states):
        base[s] = X[i]
    for j, prm in enumerate(reduced.parameters):
        base[var(prm.name)] = P[j]
    steps = _flatten(reduced.steps)
    n = len(states)
    rhs = _select(steps, set(reduced.rates)) + [("store", i, r)
                                                for i, r in enumerate(reduced.rates)]
    outs = _select(steps, set().union(*[o.expr.free_symbols for o in reduced.outputs])
                   if reduced.outputs else set()) + \
        [("store", j, o.expr) for j, o in enumerate(reduced.outputs)]
    directions = {s: sp.Symbol(f"v[{s.name}]", real=True) for s in states}
    jvp = _Tangents(directions).program(rhs)
    mapper = _Mapper(base)
    for i, s in enumerate(states):
        mapper.sub[directions[s]] = V[i]
    t0 = sp.Float(reduced.run.t0)
    init = [("store", i, st.init.xreplace({TIME: t0})) for i, st in enumerate(reduced.states)]
    rows = reduced.rows
    position = [r.expr for r in rows if r.level == "position"]
    velocity = [r.expr for r in rows if r.level == "velocity"]
    functions = {
        "init": mapper.function("init", ("p",), init, n),
        "rhs": mapper.function("rhs", ("t", "x", "p"), rhs, n),
        "outputs": mapper.function("outputs", ("t", "x", "p"), outs, len(reduced.outputs)),
        "jvp": mapper.function("jvp", ("t", "x", "p", "v"), jvp, n),
        "residual": mapper.function("residual", ("t", "x", "p"),
                                    [("store", k, r.expr) for k, r in enumerate(rows)],
                                    len(rows)),
        "scale": mapper.function("scale", ("t", "x", "p"),
                                 [("store", k, r.scale) for k, r in enumerate(rows)], len(rows)),
        "position_jac": mapper.function("position_jac", ("t", "x", "p"),
                                        _row_jacobian(position, states), len(position) * n),
        "velocity_jac": mapper.function("velocity_jac", ("t", "x", "p"),
                                        _row_jacobian(velocity, states), len(velocity) * n),
    }
    params = tuple(Param(p.name, mapper.expr(p.expr)) for p in reduced.parameters)
    in_position = set().union(*[e.free_symbols for e in position]) if position else set()
    movable = tuple(s not in in_position for s in states)
    run = reduced.run
    scene = SceneSettings(run.t0, run.t_end, run.dt, run.solver, run.rtol, run.atol, run.step)
    return finish(reduced.name, tuple(st.name for st in reduced.states), params,
                  tuple(o.name for o in reduced.outputs),
                  tuple(ConstraintRow(r.junction, r.level) for r in rows), movable, scene,
                  functions, tuple(mapper.plans), mapper.count)


def _row_jacobian(rows, states):
    """The nonzero entries of d row / d x, row-major (the caller zeroes the rest): only the
    states that occur in a row are differentiated, so the work is the rows' size, not
    rows x states."""
    index = {s: i for i, s in enumerate(states)}
    out = []
    for k, r in enumerate(rows):
        for s in sorted((s for s in r.free_symbols if s in index), key=index.get):
            d = partial(r, s)
            if d != 0:
                out.append(("store", k * len(states) + index[s], d))
    return out


HOISTED = ("rhs", "outputs", "jvp", "residual", "scale", "position_jac", "velocity_jac")


def finish(name, states, params, outputs, constraints, movable, scene, functions, plans,
           count) -> Program:
    """The passes every program goes through: dead code, constants, temporaries, the
    Jacobian's pattern."""
    functions = {k: _dead_code(f) for k, f in functions.items()}
    consts, hoisted = hoist_constants([functions[k] for k in HOISTED])
    functions.update(zip(HOISTED, hoisted))
    functions["consts"] = Function("consts", ("p",), len(consts),
                                   tuple(Store(k, c) for k, c in enumerate(consts)))
    for k in list(functions):
        functions[k], count = common_subexpressions(functions[k], count)
        functions[k] = _propagate_copies(functions[k])
    functions = {k: functions[k] for k in ir.FUNCTION_NAMES}
    pattern = jacobian_pattern(functions["rhs"], len(states), plans)
    return Program(name, states, params, outputs, constraints, movable, scene, functions,
                   tuple(plans), pattern)


def explicit_program(name, states, params, outputs, init, rhs, out, scene,
                     constraints=(), residual=(), scale=(), position_jac=(), velocity_jac=(),
                     velocity_movable=None) -> Program:
    """A program from explicit expressions over the IR's own symbols (x[i], p[j], t): for
    tests and for code that builds models without the front end.  jvp is derived as for
    compiled models."""
    n = len(states)
    mapper = _Mapper({})
    for i in range(n):
        mapper.sub[V[i]] = V[i]
    rhs_s = [("store", i, as_expr(e)) for i, e in enumerate(rhs)]
    jvp = _Tangents({X[i]: V[i] for i in range(n)}).program(rhs_s)
    functions = {
        "init": mapper.function("init", ("p",), [("store", i, as_expr(e))
                                                 for i, e in enumerate(init)], n),
        "rhs": mapper.function("rhs", ("t", "x", "p"), rhs_s, n),
        "outputs": mapper.function("outputs", ("t", "x", "p"),
                                   [("store", j, as_expr(e)) for j, e in enumerate(out)],
                                   len(out)),
        "jvp": mapper.function("jvp", ("t", "x", "p", "v"), jvp, n),
    }
    for key, exprs in (("residual", residual), ("scale", scale), ("position_jac", position_jac),
                       ("velocity_jac", velocity_jac)):
        functions[key] = mapper.function(key, ("t", "x", "p"),
                                         [("store", k, as_expr(e)) for k, e in enumerate(exprs)],
                                         len(exprs))
    movable = tuple(velocity_movable) if velocity_movable is not None else (True,) * n
    return finish(name, tuple(states), tuple(params), tuple(outputs), tuple(constraints),
                  movable, scene, functions, (), mapper.count)
