"""The program IR: what the emitters print, nothing they must derive.

A Program is a few functions, each a list of statements over these symbols:
  t            Symbol("t")            time
  x[i]         IndexedBase("x")[i]    state i, ordered as `states`
  p[j]         IndexedBase("p")[j]    parameter j, ordered as `params`
  c[k]         IndexedBase("c")[k]    constant k: result k of the `consts` function (parameters
                                      only), computed once whenever they are set
  v[i]         IndexedBase("v")[i]    component i of the direction of `jvp`
  d[k]         IndexedBase("d")[k]    discrete value k (bgc.front.events): a relation's frozen value
                                      (0 or 1), a square wave's, a discrete variable's; set
                                      only at events, read by every function
  atol         Symbol("atol")         the run's absolute tolerance (the workspace's)
  r[k]         IndexedBase("r")[k]    `update`'s input: the new value of state relation k
                                      (from the located crossing), r[n] 1 at the run's start
  w0, w1, ...  Symbol("w<k>")         program variables, each assigned once
and the functions sin cos tan asin acos atan atan2 sinh cosh tanh asinh atanh exp log sqrt
Abs sign Min Max (bgc.symbolic.algebra's) Heaviside, Pow, Rational, Float, Integer, pi, E; the
conditional Piecewise over relations (< <= > >= == !=) and And, Or, Not (booleans are never
stored: a condition chooses a value); and SquareWave, SquareNext (a square wave's value at t
and its next edge after t, computed by the runtimes), PeriodicNext (the next of a family
of times C + P n: a relation of t's crossings), Table, TableNext, TablePiece (a lookup
table's value, its next breakpoint after t, the piece holding t: bgc.front.tables), InputPart,
InputNext (an input's segment and next breakpoint, from the run's data).  Model names
never occur in expressions, so nothing a model author writes reaches generated code except
through the name strings (states, outputs, params, block unknowns), which the emitters escape
as literals.

Statements, the one vocabulary from bgc.middle.reduce to the emitters (reduce writes them over model
symbols, bgc.codegen.lower maps them to the symbols above; pruning, mapping, differentiation and the
emitters all walk the same kinds):
  Assign(w, expr)            w = expr
  Store(k, expr)             result[k] = expr (a state derivative, an output, x0[k], ...)
  Solve(block, z, A, b)      A z = b for the unknowns z: A's entries in the order of the
                             block's plan (bgc.symbolic.sparse), factored and kept for a Resolve
  Newton(block, z, ...)      residuals(z) = 0 by Newton's method from z's previous value: body
                             (assignments given z), residuals, tangents and Jacobian entries
  Resolve(block, dz, rhs)    J dz = rhs with the factors the block's last solve left (the
                             tangent of a block in `jvp`)
A block is an index into the blocks' plans (BlockPlan: its LU plan and the (row, unknown) of
each matrix entry); Solve's and Newton's unknowns are in the plan's column order, their right
sides and residuals in its row order.  `defines` and `uses` are the one def/use analysis,
`prune` the one dead-code pass, `map_statement` the one rewrite of a statement's expressions.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import sympy as sp

from ..symbolic.algebra import Max, Min
from ..symbolic.canonical import free_symbols, new
from ..symbolic.walk import DESCEND, fold
from ..base.resources import compile_memo
from ..base.run_settings import RunSettings
from ..symbolic.sparse import IterationPlan, LUPlan

T = sp.Symbol("t")
X = sp.IndexedBase("x")
P = sp.IndexedBase("p")
C = sp.IndexedBase("c")
V = sp.IndexedBase("v")
D = sp.IndexedBase("d")
R = sp.IndexedBase("r")
ATOL = sp.Symbol("atol")  # the run's absolute tolerance (a switched element's dead band)


class SquareWave(sp.Function):
    """SquareWave(t, period, duty, t0): 1 on [t0 + k period, t0 + (k + duty) period) for
    integers k >= 0, else 0; at an edge, the value after it (the runtimes' bgc_square)."""

    nargs = 4


class SquareNext(sp.Function):
    """SquareNext(t, period, duty, t0): the first edge of the square wave after t."""

    nargs = 4


class Table(sp.Function):
    """Table(k, X, piece, order): table k (Program.tables, bgc.front.tables) at X, or its
    derivative of that order (0 to 3); piece -1: the runtime finds X's piece, else the piece
    (a time table's discrete value, set at events)."""

    nargs = 4

    def fdiff(self, argindex=1):
        k, X, piece, order = self.args
        if argindex == 2:
            return Table(k, X, piece, order + 1) if int(order) < 3 else sp.S.Zero
        return sp.S.Zero

    def _sympystr(self, printer):
        k, X, _, order = self.args
        return f"table{int(k)}{chr(39) * int(order)}({printer._print(X)})"


class TableGuard(sp.Function):
    """TableGuard(k, X): how far X is within table k's rows (negative outside): the indicator
    of a table with extrapolate = error, whose crossing is located and stops the run."""

    nargs = 2

    def fdiff(self, argindex=1):
        return sp.S.Zero


class TableNext(sp.Function):
    """TableNext(k, t): table k's first breakpoint after t (inf: none)."""

    nargs = 2


class TablePiece(sp.Function):
    """TablePiece(k, t): the piece of table k that holds t (bgc.front.tables.piece)."""

    nargs = 2


class InputPart(sp.Function):
    """InputPart(j, t, part, default): input j's segment at t, as the run's data give it
    (bgc.front.events.InputSlot): its start (part 0), the value there (1), its slope (2); without
    data 0, default, 0."""

    nargs = 4


class InputNext(sp.Function):
    """InputNext(j, t): the first time of input j's data after t (inf: none)."""

    nargs = 2


class PeriodicNext(sp.Function):
    """PeriodicNext(t, P, C): the first of the times C + P n (n any integer) after t; NaN
    where P is zero or not finite (the runtimes' bgc_periodic_next)."""

    nargs = 3


RUNTIME_FUNCTIONS = (SquareWave, SquareNext, Table, TableNext, TablePiece, TableGuard, InputPart,
                     InputNext, PeriodicNext)
FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh",
             "asinh", "atanh", "exp", "log", "sqrt", "Abs", "sign", "Min", "Max", "Heaviside")


CLASSES = {name: {"Min": Min, "Max": Max}.get(name) or getattr(sp, name)
           for name in FUNCTIONS if name != "sqrt"}  # sqrt is a Pow


def is_number_node(e) -> bool:
    """Whether e is a number-valued node (not a condition, nor a Piecewise's (value,
    condition) pair): only those become constants or temporaries."""
    return isinstance(e, sp.Expr) and not isinstance(e, sp.core.relational.Relational)


def W(k: int) -> sp.Symbol:
    return sp.Symbol(f"w{k}")


def as_expr(value) -> sp.Basic:
    """A SymPy object from a SymPy object or a Python number; never parses text."""
    if isinstance(value, sp.Basic):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"expected a SymPy expression or a number, got {type(value).__name__}")
    return sp.Integer(value) if isinstance(value, int) else sp.Float(value)


# ---------------------------------------------------------------- rebuilding expressions

_UNEVALUATED = (sp.Abs, sp.sign)  # rebuilt as they are: evaluating them queries SymPy's
#                                   assumptions about every factor, the costliest step here


def rebuild(e, args):
    """e with new arguments (e itself when none changed)."""
    if all(a is b for a, b in zip(args, e.args)):
        return e
    if isinstance(e, _UNEVALUATED):
        return e.func(*args, evaluate=False)
    cls = type(e)
    if cls is sp.Add or cls is sp.Mul:
        return new(cls, args)
    return e.func(*args)


def substitute(expr, mapping: dict, memo: dict | None = None):
    """expr with the symbols (or subexpressions) of mapping replaced, bottom-up (one walk,
    bgc.symbolic.walk); only changed nodes are rebuilt; memo (shared between calls) remembers
    results."""
    def leaf(e):
        if e in mapping:
            return mapping[e]
        if e.is_Atom or e.is_Indexed or not e.args:
            return e
        return DESCEND

    return fold(expr, {} if memo is None else memo, leaf, rebuild)


def trivial(e) -> bool:
    """A number, a symbol, or a negated symbol: substituted where it is used, never assigned."""
    if e.is_Number or e.is_Symbol or e.is_Indexed:
        return True
    return e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and (e.args[1].is_Symbol
                                                                   or e.args[1].is_Indexed)


def _union(e, values):
    return frozenset().union(*values)


_FLOATS = compile_memo()  # expression -> frozenset of its Floats with an integral value


def _integral(f) -> bool:
    return float(f).is_integer() and abs(float(f)) < 2 ** 53


def _float_leaf(n):
    if not n.args:
        return frozenset((n,)) if isinstance(n, sp.Float) and _integral(n) else frozenset()
    return DESCEND


def integral_floats(e):
    """Floats with an integral value as integers (1.0*x is x), exact either way.  Which
    subexpressions hold such floats is remembered (explicit stack), like free_symbols."""
    found = _FLOATS.get(e)
    if found is None:
        found = fold(e, _FLOATS, _float_leaf, _union)
    if not found:
        return e
    return e.xreplace({f: sp.Integer(int(f)) for f in found})


# ---------------------------------------------------------------- statements


@dataclass(frozen=True)
class Assign:
    target: sp.Symbol
    expr: sp.Expr


@dataclass(frozen=True)
class Store:
    index: int
    expr: sp.Expr


@dataclass(frozen=True)
class Solve:
    block: int  # index into Program.blocks
    unknowns: tuple[sp.Symbol, ...]
    matrix: tuple[sp.Expr, ...]  # one per entry of the block's plan, in the plan's order
    rhs: tuple[sp.Expr, ...]  # one per residual row, in the block's row order


@dataclass(frozen=True)
class Newton:
    block: int
    unknowns: tuple[sp.Symbol, ...]
    body: tuple[Assign, ...]
    residuals: tuple[sp.Expr, ...]
    tangents: tuple[Assign, ...]
    jacobian: tuple[sp.Expr, ...]  # one per entry of the block's plan
    final_factor: bool = False  # factor the Jacobian at the solution (for a Resolve)


@dataclass(frozen=True)
class Resolve:
    block: int
    targets: tuple[sp.Symbol, ...]
    rhs: tuple[sp.Expr, ...]


Statement = Assign | Store | Solve | Newton | Resolve


def expressions(s) -> list[sp.Expr]:
    """The expressions a statement reads at its own level (a Newton's inner ones excluded)."""
    if isinstance(s, (Assign, Store)):
        return [s.expr]
    if isinstance(s, Solve):
        return list(s.matrix) + list(s.rhs)
    if isinstance(s, Resolve):
        return list(s.rhs)
    return []


def inner_expressions(s: Newton) -> list[sp.Expr]:
    return [a.expr for a in s.body] + list(s.residuals) + [a.expr for a in s.tangents] + \
        list(s.jacobian)


def defines(s) -> tuple[sp.Symbol, ...]:
    """The program variables a statement defines (visible after it)."""
    if isinstance(s, Assign):
        return (s.target,)
    if isinstance(s, Solve):
        return s.unknowns
    if isinstance(s, Resolve):
        return s.targets
    if isinstance(s, Newton):
        return s.unknowns + tuple(a.target for a in s.body)
    return ()


def state_dependencies(f: Function, size: int) -> list[frozenset]:
    """For each result f stores (Store index 0..size-1), the states it may depend on:
    structurally, through assignments, and through solves (every unknown of a block depends
    on everything the block reads).  One pass over the body; sets, not bit masks over the
    states (a mask's operations cost the highest state's index: quadratic in a long chain)."""
    deps: dict = {}

    def reads(e) -> frozenset:
        own = [int(a.indices[0]) for a in e.atoms(sp.Indexed) if a.base == X]
        return _joined(own, [deps[s] for s in free_symbols(e) if s in deps])

    rows = [frozenset()] * size
    for s in f.body:
        if isinstance(s, Assign):
            deps[s.target] = reads(s.expr)
        elif isinstance(s, Store):
            rows[s.index] = reads(s.expr)
        else:
            exprs = expressions(s) + (inner_expressions(s) if isinstance(s, Newton) else [])
            block = _joined([], [reads(e) for e in exprs])
            for d in defines(s):
                deps[d] = block
    return rows


def _joined(items, sets) -> frozenset:
    """items and the sets together; one of the sets itself when it holds all (no copy)."""
    if not items and len(sets) == 1:
        return sets[0]
    return frozenset(items).union(*sets)


def uses(s) -> set:
    """The symbols a statement reads from before it."""
    if isinstance(s, Newton):
        inner = set(s.unknowns) | {a.target for a in s.body} | {a.target for a in s.tangents}
        out = set()
        for e in inner_expressions(s):
            out |= free_symbols(e)
        return out - inner
    out = set()
    for e in expressions(s):
        out |= free_symbols(e)
    return out


def prune(body) -> tuple:
    """The statements the stores need, in order: the one pruning pass (backwards, from the
    results), for every function at every level (model symbols in bgc.codegen.lower, IR symbols
    after
    it).  A Resolve needs its block's last Solve or Newton (whose factors it reuses) besides
    its own inputs."""
    needed = set()
    factored = set()  # blocks whose factors a kept Resolve uses
    keep = []
    for s in reversed(body):
        if isinstance(s, Store) or any(d in needed for d in defines(s)) or (
                isinstance(s, (Solve, Newton)) and s.block in factored):
            keep.append(s)
            needed |= uses(s)
            if isinstance(s, Resolve):
                factored.add(s.block)
            elif isinstance(s, (Solve, Newton)):
                factored.discard(s.block)
    keep.reverse()
    return tuple(keep)


def prune_each(steps, results) -> list[tuple]:
    """prune(steps + r) for each list of Stores r in results, in one backward pass over steps
    (each symbol remembers, as a bit mask, the results that need it), so that the functions
    built from one program cost one walk, not one each.  Steps holding a Store or a Resolve
    are pruned one function at a time."""
    steps = list(steps)
    if any(isinstance(s, (Store, Resolve)) for s in steps) or \
            not all(isinstance(s, Store) for r in results for s in r):
        return [prune(steps + list(r)) for r in results]
    need: dict = {}  # symbol -> the results that need it (bit k: results[k])
    for k, r in enumerate(results):
        bit = 1 << k
        for s in r:
            for sym in uses(s):
                need[sym] = need.get(sym, 0) | bit
    masks = []
    for s in reversed(steps):
        m = 0
        for d in defines(s):
            m |= need.get(d, 0)
        masks.append(m)
        if m:
            for sym in uses(s):
                need[sym] = need.get(sym, 0) | m
    masks.reverse()
    return [tuple(s for s, m in zip(steps, masks) if m >> k & 1) + tuple(r)
            for k, r in enumerate(results)]


def positions(order) -> list[int]:
    """The inverse permutation: positions(order)[k] is where k is in order (a plan's row_of
    and col_of give, for each position, the residual or unknown reduce numbered)."""
    at = [0] * len(order)
    for pos, k in enumerate(order):
        at[k] = pos
    return at


def map_statement(s, fn):
    """s with fn applied to every expression it holds (its targets unchanged)."""
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


# ---------------------------------------------------------------- the program


@dataclass(frozen=True)
class Function:
    name: str  # consts init rhs outputs jvp residual scale position_jac velocity_jac
    #            velocity_metric, ...
    args: tuple[str, ...]  # of t, x, p, v
    size: int  # of its result array
    body: tuple


@dataclass(frozen=True)
class Param:
    name: str
    default: sp.Expr  # uses only p[k] for k < own index; recomputed when not overridden


@dataclass(frozen=True)
class ConstraintRow:
    """One scalar constraint residual, checked (and optionally projected) at the initial time."""

    junction: str
    level: str  # "position" (holonomic Phi) or "velocity" (dPhi/dt, or nonholonomic Phi)


SceneSettings = RunSettings  # the scene's settings: bgc.base.run_settings's one type of them


@dataclass(frozen=True)
class BlockPlan:
    index: int  # 1-based, as messages and reports name it
    unknowns: tuple[str, ...]  # display names
    method: str  # "lu" | "newton"
    lu: LUPlan
    pattern: tuple[tuple[int, int], ...] = ()  # (residual, unknown) of each matrix entry, in
    #                                            the order of Solve.matrix, Newton.jacobian


@dataclass(frozen=True)
class JacobianPattern:
    """Where d rhs / d x may be nonzero, and the columns that one directional derivative can
    evaluate together (no two share a row): J costs len(colors) calls of jvp."""

    columns: tuple[tuple[int, ...], ...]  # per state j: the rows i with J[i, j] possibly nonzero
    colors: tuple[tuple[int, ...], ...]
    lu: IterationPlan | None = None  # a large sparse model: the stiff solvers' sparse LU


LOG_PLAIN, LOG_INPUT, LOG_TABLE = 0, 1, 2  # Events.log: what a discrete value's change shows
FUNCTION_NAMES = ("consts", "init", "rhs", "outputs", "jvp", "residual", "scale",
                  "position_jac", "velocity_jac", "velocity_metric")
EVENT_FUNCTIONS = ("events", "next_time", "update")  # a program with events has them too


@dataclass(frozen=True)
class Events:
    """What the runtimes need to know of a program's events (bgc.front.events): the discrete values
    d are the state relations' (their indicators g = events(), in the same order), then the
    time relations', the discrete relations', the square waves' and the discrete variables'.
    A state relation holds when g > 0 (strict) or g >= 0."""

    strict: tuple[bool, ...]  # per state relation (indicator)
    timers: int  # results of next_time: the time relations' times, the square waves' edges
    names: tuple[str, ...]  # per discrete value: what the event log calls it
    kinds: tuple[str, ...]  # per discrete value: "relation" | "square" | "table" | "input" |
    #                         "discrete"
    log: tuple[int, ...] = ()  # per discrete value two ints, how the event log writes its
    #   change (LOG_*): (LOG_PLAIN, 0) its own values; (LOG_TABLE, k) table k's values (a
    #   table of t: the value is its piece); (LOG_INPUT, j) input j's values, one row by the
    #   input's name for its three (segment start, value, slope).  () : every one plain
    jumps: int = 0  # the parameters of the sensitivities the update carries through its
    #   jumps (bgc.codegen.sensitivity's _jumping): r and its results have `jumps` more

    @property
    def indicators(self) -> int:
        return len(self.strict)

    @property
    def discrete(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class InputInfo:
    """An input of the model: its name, its default (an expression of p) and its doc."""

    name: str
    default: sp.Expr
    doc: str | None = None


@dataclass(frozen=True)
class Program:
    name: str
    states: tuple[str, ...]
    params: tuple[Param, ...]
    outputs: tuple[str, ...]
    constraints: tuple[ConstraintRow, ...]
    velocity_movable: tuple[bool, ...]
    scene: SceneSettings
    functions: dict  # name -> Function: every name of FUNCTION_NAMES (but jvp in a program
    #                  built for explicit solvers only: has_jacobian), then any others (an
    #                  FMU's outputs_jvp; the C emitter renders them as it renders jvp)
    blocks: tuple[BlockPlan, ...] = ()
    jacobian: JacobianPattern = JacobianPattern((), ())
    events: Events | None = None  # None: the program has no events (and none of their code)
    tables: tuple = ()  # bgc.front.tables.TableData, numbered as Table(k, ...) numbers them
    inputs: tuple = ()  # InputInfo, numbered as InputPart(j, ...) numbers them

    def function(self, name: str) -> Function:
        return self.functions[name]

    @property
    def n_consts(self) -> int:
        return self.functions["consts"].size

    @property
    def has_jacobian(self) -> bool:
        """Whether the program has jvp, and so the Jacobian that the implicit solvers need
        (bgc.codegen.lower builds it unless told the run's solver does without)."""
        return "jvp" in self.functions

    @property
    def position_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "position")

    @property
    def velocity_rows(self) -> tuple[int, ...]:
        return tuple(k for k, c in enumerate(self.constraints) if c.level == "velocity")


# ---------------------------------------------------------------- operation counts


def count_ops(program: Program, names=("rhs", "outputs")) -> Counter:
    """Operations by kind (add, mul, div, call, pow, solve) of the named functions, counted as
    the printers write them: a - b is one add, x**2 one mul, a/b one div."""
    total = Counter()
    for name in names:
        for s in program.function(name).body:
            for e in expressions(s):
                total.update(expression_ops(e))
            if isinstance(s, Newton):
                for e in inner_expressions(s):
                    total.update(expression_ops(e))
            if isinstance(s, (Solve, Newton, Resolve)):
                total["solve"] += 1
                total["solve_flops"] += program.blocks[s.block].lu.flops
    return total


def expression_ops(expr: sp.Expr) -> Counter:
    ops = Counter()
    stack = [(expr, False)]
    while stack:
        e, in_sum = stack.pop()
        if e.is_Atom or e.is_Indexed:
            continue
        if e.is_Add:
            ops["add"] += len(e.args) - 1
            stack.extend((a, True) for a in e.args)
            continue
        elif e.is_Mul:
            coeff, rest = e.as_coeff_Mul()
            factors = sp.Mul.make_args(rest)
            inverse = sum(1 for f in factors if f.is_Pow and f.exp.is_Rational and f.exp < 0)
            direct = len(factors) - inverse + (0 if abs(coeff) == 1 else 1)
            ops["mul"] += max(direct - 1, 0)
            ops["div"] += 1 if inverse else 0
            ops["mul"] += max(inverse - 1, 0)
            if coeff == -1 and direct <= 1 and not inverse and not in_sum:
                ops["neg"] += 1  # a negated term of a sum is a subtraction, counted there
        elif e.is_Pow:
            if e.exp == sp.S.Half:
                ops["call"] += 1
            elif e.exp.is_Integer and 2 <= abs(int(e.exp)) <= 4:
                ops["mul"] += abs(int(e.exp)) - 1
                ops["div"] += 1 if e.exp < 0 else 0
            elif e.exp == -1:
                ops["div"] += 1
            else:
                ops["call"] += 1
        else:
            ops["call"] += 1
        stack.extend((a, False) for a in e.args)
    return ops


# ---------------------------------------------------------------- layout for emitters


@dataclass(frozen=True)
class Layout:
    """How an emitter lays a function out: chunks of statements (each its own C or Python
    function, so that long straight-line code stays digestible), and which program variables
    live in the workspace (read across chunks, or by a Newton block's own function) rather than
    as locals: slot[w] = index into the workspace's variable area."""

    chunks: tuple[tuple, ...]
    slot: dict = field(default_factory=dict)


CHUNK_OPS = 1500  # operations per chunk (gcc -O2 time grows faster than linearly in this)


def layout(body: tuple, base: int = 0, chunk_ops: int = CHUNK_OPS) -> Layout:
    """Split body into chunks of at most about chunk_ops operations; variables read outside the
    chunk that defines them, and everything a Newton block reads or defines, get slots from
    `base` on, in order of definition."""
    chunks: list[list] = [[]]
    ops = 0
    for s in body:
        cost = sum(sum(expression_ops(e).values()) + 1 for e in expressions(s))
        if isinstance(s, Newton):
            cost += sum(sum(expression_ops(e).values()) + 1 for e in inner_expressions(s))
        if chunks[-1] and ops + cost > chunk_ops:
            chunks.append([])
            ops = 0
        chunks[-1].append(s)
        ops += cost
    home = {}
    for k, chunk in enumerate(chunks):
        for s in chunk:
            for w in defines(s):
                home[w] = k
    shared = set()
    for k, chunk in enumerate(chunks):
        for s in chunk:
            read = uses(s)
            if isinstance(s, Newton):
                shared |= {u for u in read if u in home}
                shared |= set(defines(s))
            else:
                shared |= {u for u in read if u in home and home[u] != k}
    slot = {}
    for chunk in chunks:
        for s in chunk:
            for w in defines(s):
                if w in shared and w not in slot:
                    slot[w] = base + len(slot)
    return Layout(tuple(tuple(c) for c in chunks), slot)
