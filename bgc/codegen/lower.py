"""Stage 7, lower: Reduced -> Program, the IR the emitters print (bgc.ir).

reduce hands on its sorted steps already as IR statements (Assign, Solve, Newton) over model
symbols; every function of the program is built from them by the same passes:

1. `functions` lists each function by its results (Store statements); `TANGENTS` the ones
   derived by forward differentiation (`jvp` from `rhs`; bgc.ir.tangent.tangent).  A new
   function (an event's indicators, a reset) is a new entry there, nothing else.
2. Each takes from the steps only what its results need (bgc.ir.prune, backwards).
3. Model symbols become IR symbols (states x[i], parameters p[j], the rest w<k>, numbered as
   first met); an assignment that only renames or negates is propagated, not emitted; blocks
   are numbered in the order the functions first use them.
4. The tangents are derived on the IR functions; `jacobian()` of the generated code evaluates
   jvp once per colour of the columns.  `with_tangent` derives one more on a finished program
   (the FMU's outputs_jvp).
5. Subexpressions of the parameters alone become constants c[k]; repeated subexpressions
   within a function become temporaries (value numbering, linear in the code's size).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp

from ..front import events
from .. import ir
from ..symbolic import sparse
from ..symbolic.differentiate import partial
from ..ir.tangent import jacobian, tangent
from ..front.graph import TIME, var
from ..ir import (C, D, P, R, T, V, X, Assign, BlockPlan, ConstraintRow, Function, JacobianPattern,
                  Newton, Param, Program, SceneSettings, Solve, Store, as_expr)
from ..middle.reduce import Reduced


# ---------------------------------------------------------------- mapping to the IR


class _Mapper:
    """Model symbols to IR symbols, with copy propagation; the blocks numbered in the order the
    functions first use them."""

    def __init__(self, base: dict, plans=()):
        self.sub = dict(base)  # model symbol -> what it is in the IR (a symbol or expression)
        self.names: dict = {}  # model symbol -> its program variable, the same in every function
        self.count = 0
        self.reduced_plans = plans
        self.blocks: dict = {}  # reduce's plan index -> the program's
        self.plans: list[BlockPlan] = []
        self.mapped: dict = {}  # model expression -> IR expression
        self.memo: dict = {}  # model subexpression -> IR expression (ir.substitute's memo)

    def target(self, s):
        """The program variable of s (from now on, s means it)."""
        w = self.names.get(s)
        if w is None:
            w = self.names[s] = ir.W(self.count)
            self.count += 1
        self.sub[s] = w
        return w

    def expr(self, e):
        """e in the IR's symbols.  A model symbol means the same in every function (and is
        mapped before the first expression that reads it), so an expression, and any
        subexpression, that several expressions share is mapped once."""
        done = self.mapped.get(e)
        if done is None:
            done = self.mapped[e] = ir.integral_floats(ir.substitute(e, self.sub, self.memo))
        return done

    def assign(self, a: Assign, out, propagate=True):
        e = self.expr(a.expr)
        if propagate and ir.trivial(e):
            self.sub[a.target] = e
            return
        out.append(Assign(self.target(a.target), e))

    def block(self, k: int) -> int:
        if k not in self.blocks:
            self.blocks[k] = len(self.plans)
            self.plans.append(self.reduced_plans[k])
        return self.blocks[k]

    def unknowns(self, s):
        """The unknowns' program variables, numbered in the block's own order (as reduce found
        them), listed in the plan's."""
        for pos in ir.positions(self.reduced_plans[s.block].lu.col_of):
            self.target(s.unknowns[pos])
        return tuple(self.sub[u] for u in s.unknowns)

    def function(self, name, args, statements, size) -> Function:
        body = []
        for s in statements:
            if isinstance(s, Assign):
                self.assign(s, body)
            elif isinstance(s, Store):
                body.append(Store(s.index, self.expr(s.expr)))
            elif isinstance(s, Solve):
                k = self.block(s.block)
                matrix = tuple(self.expr(e) for e in s.matrix)
                rhs = tuple(self.expr(e) for e in s.rhs)
                body.append(Solve(k, self.unknowns(s), matrix, rhs))
            else:
                body.append(self._newton(s))
        return Function(name, args, size, tuple(body))

    def _newton(self, s: Newton) -> Newton:
        k = self.block(s.block)
        z = self.unknowns(s)
        inner: list = []
        for a in s.body:
            self.assign(a, inner, propagate=False)
        tangents: list = []
        for a in s.tangents:
            self.assign(a, tangents)
        return Newton(k, z, tuple(inner), tuple(self.expr(r) for r in s.residuals),
                      tuple(tangents), tuple(self.expr(e) for e in s.jacobian))


# ---------------------------------------------------------------- passes on IR functions


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
        if e.is_Atom or e.is_Indexed or not uses_p or not ir.is_number_node(e):
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
                group = ir.new(e.func, fixed)
                varying = [k[0] for k in kids if not k[1]]
                new = ir.new(e.func, [constant(group, any(k[2] for k in kids if k[1]))]
                             + varying)
            else:
                new = ir.rebuild(e, [constant(a, k[2]) if k[1] else k[0]
                                     for a, k in zip(e.args, kids)])
            info[e] = (new, False, uses_p)

    def visit(e):
        analyse(e)
        new, fixed, uses_p = info[e]
        return constant(e, uses_p) if fixed else new

    out = [Function(f.name, f.args, f.size, tuple(ir.map_statement(s, visit) for s in f.body))
           for f in functions]
    return tuple(pool), out


def _worth_a_temporary(e) -> bool:
    if e.is_Atom or e.is_Indexed or not ir.is_number_node(e):
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

        new = ir.map_statement(s, rewrite) if not isinstance(s, Newton) else s
        body.extend(pending)
        body.append(new)
    return Function(f.name, f.args, f.size, tuple(body)), count


def _propagate_copies(f: Function) -> Function:
    """Assignments that only rename, negate or name a constant, substituted into their uses
    (hoisting and temporaries leave some: w6 = c[2], w16 = w26)."""
    sub: dict = {}
    memo: dict = {}  # (a variable is in sub before any statement that reads it: one memo)
    body = []
    for s in f.body:
        if sub:
            s = ir.map_statement(s, lambda e: ir.substitute(e, sub, memo)
                                 if ir.free_symbols(e) & sub.keys() else e)
        if isinstance(s, Assign) and ir.trivial(s.expr):
            sub[s.target] = s.expr
            continue
        body.append(s)
    return Function(f.name, f.args, f.size, tuple(body))


# ---------------------------------------------------------------- the Jacobian's pattern


def jacobian_pattern(rhs: Function, n: int, blocks) -> JacobianPattern:
    """Structural dependence of each derivative on each state (through solves: every unknown
    of a block depends on everything the block reads), a greedy colouring of the columns
    in order (no two columns of a colour share a row), and for a large sparse pattern the
    stiff solvers' sparse LU (bgc/symbolic/sparse.py, iteration_plan)."""
    columns = [[] for _ in range(n)]
    for i, row in enumerate(ir.state_dependencies(rhs, n)):
        for j in row:
            columns[j].append(i)
    return JacobianPattern(tuple(map(tuple, columns)), _colours(columns),
                           sparse.iteration_plan(columns))


def _colours(columns) -> tuple[tuple[int, ...], ...]:
    """A greedy colouring of the columns in order: each joins the first colour none of whose
    columns shares a row with it (the rows of a colour kept as a set: the work is the
    nonzeros', not the rows')."""
    colours: list[list[int]] = []
    covered: list[set] = []
    for j, rows in enumerate(columns):
        for colour, cov in zip(colours, covered):
            if cov.isdisjoint(rows):
                colour.append(j)
                cov.update(rows)
                break
        else:
            colours.append([j])
            covered.append(set(rows))
    return tuple(map(tuple, colours))


# ---------------------------------------------------------------- the stage


def functions(reduced: Reduced, jumps: bool = False) -> dict:
    """The program's functions as their results: name -> (arguments, size, stores over model
    symbols).  Each is built from the sorted steps by the same passes (pruning from its
    results, mapping, constants, temporaries), so a new function is a new entry here.
    jumps: update's results are followed by what the sensitivities' jumps read (the right
    side, the state relations' indicators, the time relations' times:
    bgc.codegen.sensitivity's _jumping)."""
    states = [st.symbol for st in reduced.states]
    rows, t0 = reduced.rows, sp.Float(reduced.run.t0)
    position = [r.expr for r in rows if r.level == "position"]
    velocity = [r.expr for r in rows if r.level == "velocity"]
    leaves = {TIME} | set(states) | {var(p.name) for p in reduced.parameters}

    def jacobian(exprs):
        size = len(exprs) * len(states)
        if all(e.free_symbols <= leaves for e in exprs):
            return size, _row_jacobian(exprs, states)
        return size, _Through(tuple(exprs))  # rows that read a block's unknowns

    index = {s: i for i, s in enumerate(states)}
    metric = [Store(k * len(states) + index[p], d)
              for k, r in enumerate(r for r in rows if r.level == "velocity")
              for p, d in r.weights if d != 0]
    specs = _specs([st.init.xreplace({TIME: t0}) for st in reduced.states], reduced.rates,
                   [o.expr for o in reduced.outputs], [r.expr for r in rows],
                   [r.scale for r in rows], jacobian(position), jacobian(velocity))
    specs["velocity_metric"] = (("t", "x", "p"), len(velocity) * len(states), metric)
    sel = reduced.events
    if sel is not None:
        txp = ("t", "x", "p")
        specs["events"] = (txp, len(sel.state), _stores([r.indicator for r in sel.state]))
        times = events.next_times(sel)
        specs["next_time"] = (txp, len(times), _stores(times))
        update = events.update_stores(sel, reduced.states)
        if jumps:
            update += list(reduced.rates) + [r.indicator for r in sel.state]
            update += [sp.Integer(0) if events.never(at) else at for _, at, _ in sel.time]
        specs["update"] = (("t", "x", "p", "r"), len(update), _stores(update))
    return specs


def _event_symbols(sel) -> dict:
    """The events' model symbols in the IR: a relation's frozen value is d[k] != 0, a square
    wave's or a discrete variable's d[k]; update's inputs r[k], r[n] != 0 at the start."""
    out = {}
    for k, sym in enumerate(sel.slots()):
        out[sym] = sp.Ne(D[k], 0) if sym.name.startswith("event#") else D[k]
    for k in range(len(sel.state)):
        out[events.new_value(k)] = R[k]
    out[events.FIRST] = sp.Ne(R[len(sel.state)], 0)
    out[events.TOLERANCE] = ir.ATOL
    return out


def _events_info(sel) -> ir.Events | None:
    if sel is None:
        return None
    names, kinds = events.log_names(sel)
    return ir.Events(tuple(events.strict(r) for r in sel.state),
                     len(events.next_times(sel)), names, kinds, _log(sel, kinds))


def _log(sel, kinds) -> tuple[int, ...]:
    """ir.Events.log: a table of t's and an input's changes shown as their values, from the
    data (the discrete values of the squares: TimeTable and InputSlot carry their number)."""
    first = len(kinds) - len(sel.squares) - len(sel.discretes)
    out = [ir.LOG_PLAIN, 0] * len(kinds)
    for k, s in enumerate(sel.squares, first):
        if kinds[k] in ("table", "input"):
            out[2 * k: 2 * k + 2] = [ir.LOG_TABLE if kinds[k] == "table" else ir.LOG_INPUT,
                                     s.index]
    return tuple(out)


@dataclass(frozen=True)
class _Through:
    """The rows of a Jacobian that is derived through the steps (bgc.ir.tangent.jacobian): the
    rows read the unknowns of a block (the flows of a coupled field), not the states alone."""

    rows: tuple


def velocity_movable(rows, states) -> tuple[bool, ...]:
    """The states that the projection onto the velocity rows moves: the momenta those rows
    read (by the kinetic metric, see bgc.middle.reduce's _Weights), the positions held; when they
    read no momentum (a constraint on other stores), every state the position rows leave."""
    position = [r.expr for r in rows if r.level == "position"]
    in_position = set().union(*[e.free_symbols for e in position]) if position else set()
    weighed = {p for r in rows for p, d in r.weights if d != 0}
    if weighed:
        return tuple(s in weighed and s not in in_position for s in states)
    return tuple(s not in in_position for s in states)


def _specs(init, rhs, outputs, residual, scale, position_jac, velocity_jac) -> dict:
    """The functions every program has; the constraint rows' Jacobians as (size, stores)."""
    txp = ("t", "x", "p")
    return {"init": (("p",), len(init), _stores(init)), "rhs": (txp, len(rhs), _stores(rhs)),
            "outputs": (txp, len(outputs), _stores(outputs)),
            "residual": (txp, len(residual), _stores(residual)),
            "scale": (txp, len(scale), _stores(scale)),
            "position_jac": (txp, *position_jac), "velocity_jac": (txp, *velocity_jac)}


TANGENTS = {"jvp": "rhs"}  # derived functions: name -> the function differentiated along v


def _stores(exprs) -> list[Store]:
    return [Store(k, as_expr(e)) for k, e in enumerate(exprs)]


def lower(reduced: Reduced, sensitivities: tuple[str, ...] = (), given=(),
          state_outputs: bool = False, jacobian: bool = True) -> Program:
    """The program of a reduced system.  sensitivities: parameter names, for the program
    augmented with the states' sensitivities to them (bgc.codegen.sensitivity, which says what given
    and state_outputs mean).  jacobian=False: without jvp, the tangent the implicit solvers
    need (a program for an explicit solver's run; without_jacobian)."""
    states = [st.symbol for st in reduced.states]
    base = {TIME: T}
    base.update((s, X[i]) for i, s in enumerate(states))
    base.update((var(prm.name), P[j]) for j, prm in enumerate(reduced.parameters))
    if reduced.events is not None:
        base.update(_event_symbols(reduced.events))
    mapper = _Mapper(base, reduced.plans)
    rows = reduced.rows
    jumps = False
    if sensitivities:
        from . import sensitivity
        defaults = {p.name: p.expr for p in reduced.parameters}
        sensitivity.check(sensitivities, [p.name for p in reduced.parameters],
                          reduced.events, states, defaults, reduced.steps,
                          list(reduced.rates) + [o.expr for o in reduced.outputs])
        jumps = sensitivity.needs_jumps(reduced.events, sensitivities, states, defaults,
                                        reduced.steps)
    fns = _build(mapper, reduced.steps, functions(reduced, jumps), len(states))
    params = tuple(Param(p.name, mapper.expr(p.expr)) for p in reduced.parameters)
    movable = velocity_movable(rows, states)
    run = reduced.run
    scene = SceneSettings(run.t0, run.t_end, run.dt, run.solver, run.rtol, run.atol, run.step,
                          max_step=run.max_step)
    names = tuple(st.name for st in reduced.states)
    outputs = tuple(o.name for o in reduced.outputs)
    if sensitivities:
        aug = sensitivity.augment(fns, params, names, outputs, movable, tuple(sensitivities),
                                  given, mapper.plans, mapper.count, state_outputs,
                                  jacobian_pattern, reduced.events if jumps else None)
        names, outputs, fns, movable, mapper.count = aug.states, aug.outputs, aug.functions, \
            aug.movable, aug.count
    program = finish(reduced.name, names, params, outputs,
                     tuple(ConstraintRow(r.junction, r.level) for r in rows), movable, scene,
                     fns, tuple(mapper.plans), mapper.count,
                     _with_jumps(_events_info(reduced.events), len(sensitivities) if jumps else 0),
                     reduced.tables, tuple(ir.InputInfo(u.name, mapper.expr(u.default), u.doc)
                                           for u in reduced.inputs))
    program = aug.pattern(program) if sensitivities else program
    return program if jacobian else without_jacobian(program)


def without_jacobian(program: Program) -> Program:
    """program without jvp, nor the Jacobian's pattern and the stiff solvers' sparse LU plan
    (empty: a dense chain's pattern is most of its part's text): for a run whose solver is
    explicit, which never calls them.  The tangent is still derived, and then dropped: the
    variables and constants of the other functions are numbered after its own, and the
    printers order a product's factors by their names, so that building without it would
    change the other functions' rounding (their bytes must be the full program's)."""
    functions = {k: f for k, f in program.functions.items() if k != "jvp"}
    pattern = JacobianPattern(((),) * len(program.states), ())
    return replace(program, functions=functions, jacobian=pattern)


def _build(mapper: _Mapper, steps, specs: dict, n: int) -> dict:
    """Each function from what its results need of the steps, in the IR's symbols; then the
    tangents (after the primal functions, so that their variables are numbered after)."""
    steps = list(steps)
    out = {}
    results = [_stores(stores.rows) if isinstance(stores, _Through) else list(stores)
               for _, _, stores in specs.values()]
    for (name, (args, size, stores)), body in zip(specs.items(), ir.prune_each(steps, results)):
        if isinstance(stores, _Through):
            rows = mapper.function(name, args, body, len(stores.rows))
            out[name], mapper.count = jacobian(rows, name, n, mapper.plans, mapper.count)
        else:
            out[name] = mapper.function(name, args, body, size)
    for name, of in TANGENTS.items():
        out[name], mapper.count = tangent(out[of], name, {X[i]: V[i] for i in range(n)},
                                          mapper.plans, mapper.count)
    return _ordered(out)


def _ordered(functions: dict) -> dict:
    """The functions in the IR's order, then any others: the order numbers the constants and
    the temporaries."""
    rank = {k: i for i, k in enumerate(ir.FUNCTION_NAMES)}
    return {k: functions[k] for k in sorted(functions, key=lambda k: rank.get(k, len(rank)))}


def with_tangent(program: Program, of: str, name: str, seeds: dict | None = None) -> Program:
    """program with one more function, `name`: the derivative of function `of` along v (the
    FMU's outputs_jvp), derived, pruned and simplified by the passes of every function.
    seeds: the tangents of the symbols (default: x along v; bgc.analysis.operating seeds a parameter
    and the constants computed from it)."""
    f = program.function(of)
    fresh = 1 + max((int(w.name[1:]) for s in f.body for w in _defined_all(s)), default=-1)
    if seeds is None:
        seeds = {X[i]: V[i] for i in range(len(program.states))}
    g, count = tangent(f, name, seeds, program.blocks, fresh)
    g, _ = common_subexpressions(Function(name, g.args, g.size, ir.prune(g.body)), count)
    return replace(program, functions={**program.functions, name: _propagate_copies(g)})


def _defined_all(s):
    """Every program variable a statement defines, a Newton block's inner ones included."""
    if isinstance(s, Newton):
        return ir.defines(s) + tuple(a.target for a in s.tangents)
    return ir.defines(s)


def _row_jacobian(rows, states) -> list[Store]:
    """The nonzero entries of d row / d x, row-major (the caller zeroes the rest): only the
    states that occur in a row are differentiated, so the work is the rows' size, not
    rows x states."""
    index = {s: i for i, s in enumerate(states)}
    out = []
    for k, r in enumerate(rows):
        for s in sorted((s for s in r.free_symbols if s in index), key=index.get):
            d = partial(r, s)
            if d != 0:
                out.append(Store(k * len(states) + index[s], d))
    return out


def finish(name, states, params, outputs, constraints, movable, scene, functions, plans,
           count, events_info=None, tables=(), inputs=()) -> Program:
    """The passes every program goes through: pruning, constants (of every function but
    init, which runs once per parameter set anyway), temporaries, the Jacobian's pattern."""
    functions = {k: Function(f.name, f.args, f.size, ir.prune(f.body))
                 for k, f in functions.items()}
    hoisted = [k for k in functions if k != "init"]
    consts, done = hoist_constants([functions[k] for k in hoisted])
    functions.update(zip(hoisted, done))
    functions["consts"] = Function("consts", ("p",), len(consts),
                                   tuple(Store(k, c) for k, c in enumerate(consts)))
    for k in list(functions):
        functions[k], count = common_subexpressions(functions[k], count)
        functions[k] = _propagate_copies(functions[k])
    functions = _ordered(functions)
    _refuse_non_finite(functions, params)
    pattern = jacobian_pattern(functions["rhs"], len(states), plans)
    return Program(name, states, params, outputs, constraints, movable, scene, functions,
                   tuple(plans), pattern, events_info, tuple(tables), tuple(inputs))


def _with_jumps(info, m: int):
    """The program's ir.Events with the number of parameters its update's jumps carry."""
    return replace(info, jumps=m) if info is not None and m else info


_NON_FINITE = (sp.zoo, sp.nan, sp.oo, -sp.oo)


def _non_finite(expr, seen: set | None = None) -> sp.Basic | None:
    """The first constant of expr that is not a finite number (zoo, nan, oo, a Float beyond a
    double), or None; an explicit stack, however deep the expression.  seen (shared between
    calls) holds the subexpressions already found finite: each is walked once."""
    seen = set() if seen is None else seen
    stack = [expr]
    while stack:
        e = stack.pop()
        if e in seen:
            continue
        seen.add(e)
        args = e.args
        if args:  # (only atoms are constants)
            stack.extend(args)
            continue
        if e.is_Symbol:
            continue
        if e in _NON_FINITE or (isinstance(e, sp.Float) and not e.is_finite) or \
                (isinstance(e, sp.Number) and not e.is_finite):
            return e
        if isinstance(e, (sp.Float, sp.Rational)):  # (an exact integer beyond a double too)
            try:
                if float(e) in (float("inf"), float("-inf")):
                    return e
            except (OverflowError, ValueError):
                return e
    return None


def _exprs(statement):
    for name in ("expr", "matrix", "rhs", "residuals", "jacobian"):
        value = getattr(statement, name, None)
        if isinstance(value, tuple):
            yield from value
        elif value is not None:
            yield value
    for name in ("body", "tangents"):
        for inner in getattr(statement, name, ()) or ():
            yield from _exprs(inner)


def _refuse_non_finite(functions: dict, params) -> None:
    """A model error when the generated functions hold a constant that is not a finite double:
    the model's numbers are finite, but their derivatives or products need not be (2^1000
    squared in a constraint's second derivative, a division by zero once a Jacobian is
    simplified); the program would compute inf or NaN, or could not be written at all."""
    from ..base.diagnostics import Diagnostic, ModelError
    what = {"rhs": "the derivatives of the states", "outputs": "the outputs",
            "init": "the initial values", "jvp": "the Jacobian",
            "position_jac": "the constraints' Jacobian", "velocity_jac": "the constraints' "
            "Jacobian", "residual": "the constraints' residuals", "consts": "the constants"}
    seen: set = set()
    for prm in params:
        bad = _non_finite(prm.default, seen)
        if bad is not None:
            raise ModelError([Diagnostic("error", None, f"parameter '{prm.name}' is not finite "
                                                          f"({bad}): a number beyond a double")])
    for name, fn in functions.items():
        for statement in fn.body:
            for expr in _exprs(statement):
                bad = _non_finite(expr, seen)
                if bad is None:
                    continue
                if bad == sp.zoo:
                    kind = "a division by zero"
                elif bad == sp.nan:
                    kind = "an undefined value"
                else:
                    kind = "a number beyond a double"
                    bad = sp.N(bad, 6)
                raise ModelError([Diagnostic(
                    "error", None, f"the generated equations are not finite: "
                    f"{what.get(name, name)} hold {kind} ({bad}) once the model's laws and "
                    f"constraints are differentiated and simplified")])


def explicit_program(name, states, params, outputs, init, rhs, out, scene,
                     constraints=(), residual=(), scale=(), position_jac=(), velocity_jac=(),
                     velocity_movable=None, velocity_metric=None) -> Program:
    """A program from explicit expressions over the IR's own symbols (x[i], p[j], t): for
    tests and for code that builds models without the front end.  jvp is derived as for
    compiled models; the velocity projection's metric is the identity unless given (as the
    rows of velocity_jac times M)."""
    n = len(states)
    specs = _specs(init, rhs, out, residual, scale, (len(position_jac), _stores(position_jac)),
                   (len(velocity_jac), _stores(velocity_jac)))
    metric = velocity_jac if velocity_metric is None else velocity_metric
    specs["velocity_metric"] = (("t", "x", "p"), len(metric), _stores(metric))
    mapper = _Mapper({})
    fns = _build(mapper, (), specs, n)
    movable = tuple(velocity_movable) if velocity_movable is not None else (True,) * n
    return finish(name, tuple(states), tuple(params), tuple(outputs), tuple(constraints),
                  movable, scene, fns, (), mapper.count)
