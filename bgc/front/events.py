"""Events: the relations that switch a model, its time sources, discrete variables and
when-blocks (docs/hybrid.md), from the resolve stage to the program's event functions.

The resolve stage meets a relation of varying quantities (`x > 0`, `step(t0)`'s `t >= t0`)
and registers it here: the expression gets a boolean symbol in its place, the relation's
value *frozen* between events, so that the right side is smooth within a step and the
solver never integrates across a switch.  What changes the frozen values:

  state relation    reads the states: its indicator g = lhs - rhs is evaluated at the end of
                    every step; a change of the relation's value there is located on the
                    step's dense output and the step ends at the crossing;
  time relation     a relation linear in t with parameters alone (t >= t0): its time is known
                    in advance, t* = -b/a, and the solver steps onto it exactly;
                    another relation of t and parameters alone (sin(w*t) > 0.5) is a state
                    relation whose crossings are also times the solver steps onto, where
                    the indicator can be inverted (time_roots: t in one place, under
                    functions whose inverses are known); so no window of it falls inside a
                    step, however long the solver's steps grow;
  discrete relation reads discrete variables and parameters alone: it changes only at events;
  square wave       `square(period, duty, t0)`: a value 0 or 1 whose edges are time events;
  time table        `table(..., t)` (bgc.front.tables): the piece that holds t, its breakpoints
                    time events.

At an event the program's `update` function gives the state and the discrete values after
it: every relation's new value (a state relation's from the located crossing), the when-
blocks that fire (their condition became true: a rising edge), their reinits and
assignments, all computed from the values just before (the left limit).  The driver calls it
again until nothing changes (an event iteration: at most MAX_ITERATIONS passes that change
something, the chain of events at one instant docs/hybrid.md allows; the runtimes' limit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import sympy as sp
from sympy.core.relational import Relational
from sympy.logic.boolalg import BooleanAtom, BooleanFunction

from ..base.diagnostics import Span
from ..symbolic.canonical import free_symbols, xreplace
from ..symbolic.differentiate import partial
from .graph import TIME, written
from .kinds import TIME_SOURCES
from ..ir import InputNext, InputPart, PeriodicNext, SquareNext, SquareWave, TableNext, TablePiece

RELATIONS = {"<": sp.StrictLessThan, "<=": sp.LessThan, ">": sp.StrictGreaterThan,
             ">=": sp.GreaterThan, "==": sp.Eq, "!=": sp.Ne}
SOURCES = {"step": (1, 1), "ramp": (1, 1), "pulse": (2, 2), "square": (2, 3),
           "initial": (0, 0)}  # name -> (fewest, most) arguments
assert tuple(SOURCES) == TIME_SOURCES
INITIAL = sp.Symbol("initial#")  # initial(): true in the event iteration at the start only
MAX_ITERATIONS = 100  # events at one instant a run allows, then stops as chattering (Zeno)


def is_condition(v) -> bool:
    """Whether a built value is a condition (a boolean), not a number."""
    if isinstance(v, (Relational, BooleanFunction, BooleanAtom)):
        return True
    return isinstance(v, sp.Symbol) and (v is INITIAL or v.name.startswith("event#"))


@dataclass(frozen=True)
class Relation:
    symbol: sp.Symbol  # the relation's frozen value (a boolean symbol)
    relation: sp.Basic  # over model symbols
    text: str  # as the event log names it
    span: Span
    owner: str | None  # the element whose law holds it (its own e, f read through the bond)
    needs: frozenset = frozenset()  # a guard (a table's range): kept when these are used

    @property
    def indicator(self) -> sp.Expr:
        """g: the relation holds when g > 0 (> and >=) or g < 0 (< and <=)."""
        return self.relation.lhs - self.relation.rhs


@dataclass(frozen=True)
class Square:
    symbol: sp.Symbol  # its value, 0 or 1
    period: sp.Expr
    duty: sp.Expr
    t0: sp.Expr
    text: str
    span: Span
    kind = "square"

    def value(self):
        return SquareWave(TIME, self.period, self.duty, self.t0)

    def next(self):
        return SquareNext(TIME, self.period, self.duty, self.t0)


@dataclass(frozen=True)
class TimeTable:
    """A table of t: its discrete value is the piece that holds t (listed with the square
    waves: both are time sources, their values set at their time events)."""

    symbol: sp.Symbol
    index: int  # the table's number (Table(k, ...))
    text: str
    span: Span
    kind = "table"

    def value(self):
        return TablePiece(sp.Integer(self.index), TIME)

    def next(self):
        return TableNext(sp.Integer(self.index), TIME)


@dataclass(frozen=True)
class InputSlot:
    """One of an input's three discrete values: its data's segment at t is the line through
    (start, value) with a slope, set at the data's breakpoints (time events), so that the
    input's value u = value + slope (t - start) is a polynomial of t between events."""

    symbol: sp.Symbol
    index: int  # the input's number
    part: int  # 0 start, 1 value, 2 slope
    default: sp.Expr
    text: str
    span: Span
    kind = "input"

    def value(self):
        return InputPart(sp.Integer(self.index), TIME, sp.Integer(self.part), self.default)

    def next(self):
        return InputNext(sp.Integer(self.index), TIME) if self.part == 1 else None


@dataclass(frozen=True)
class Discrete:
    name: str
    symbol: sp.Symbol
    init: sp.Expr  # parameters only (a mode's: the states too)
    doc: str | None
    span: Span
    next: sp.Expr | None = None  # a mode (bgc.middle.contact): its value after each pass of the
    #                              event iteration, from the relations' values then


@dataclass(frozen=True)
class Action:
    kind: str  # "reinit" | "assign"
    name: str  # the state or the discrete variable, as written
    symbol: sp.Symbol
    expr: sp.Expr
    span: Span


@dataclass(frozen=True)
class When:
    condition: sp.Basic  # over relation symbols, INITIAL and parameters
    text: str
    actions: tuple[Action, ...]
    span: Span


@dataclass
class EventTable:
    """The relations and square waves of a model, numbered in the order they are met."""

    relations: list = field(default_factory=list)
    squares: list = field(default_factory=list)
    _index: dict = field(default_factory=dict)

    def relation(self, rel, node, owner, text: str | None = None) -> sp.Symbol:
        """The symbol of relation rel (of element owner's law, or None); text: its name as
        written (bgc.front.spelling), else SymPy's; the first text of a relation met names it."""
        key = (rel, owner)
        if key not in self._index:
            sym = sp.Symbol(f"event#{len(self.relations)}")
            self.relations.append(Relation(sym, rel, text or written(rel), node.span, owner))
            self._index[key] = sym
        return self._index[key]

    def guard(self, rel, text: str, span, needs) -> sp.Symbol:
        """A relation that holds while the model is defined (a table's range, extrapolate =
        error): its indicator is not a number where it is not, which stops the run."""
        sym = sp.Symbol(f"event#{len(self.relations)}")
        self.relations.append(Relation(sym, rel, text, span, None, frozenset(needs)))
        return sym

    def square(self, period, duty, t0, node, text: str | None = None) -> sp.Symbol:
        key = ("square", period, duty, t0)
        if key not in self._index:
            sym = sp.Symbol(f"square#{len(self.squares)}", real=True)
            text = text or f"square({written(period)}, {written(duty)}, {written(t0)})"
            self.squares.append(Square(sym, period, duty, t0, text, node.span))
            self._index[key] = sym
        return self._index[key]

    def input(self, j: int, name: str, default, span) -> tuple:
        """The three discrete values of input j (InputSlot): start, value, slope."""
        out = []
        for part, what in enumerate((f"{name} (segment start)", name, f"{name} (slope)")):
            sym = sp.Symbol(f"input#{j}.{part}", real=True)
            self.squares.append(InputSlot(sym, j, part, default, what, span))
            out.append(sym)
        return tuple(out)

    def time_table(self, k: int, text: str, span) -> sp.Symbol:
        sym = sp.Symbol(f"table#{k}", real=True)
        self.squares.append(TimeTable(sym, k, text, span))
        return sym


# ---------------------------------------------------------------- the scene's events


FIRST = sp.Symbol("first#")
TOLERANCE = sp.Symbol("atol#")  # the run's absolute tolerance: a switch's dead band  # update's r[n]: 1 in the event iteration at the start of a run


def new_value(k: int) -> sp.Symbol:
    """update's r[k]: state relation k's value at the event (from the located crossing)."""
    return sp.Symbol(f"new#{k}")


@dataclass(frozen=True)
class Selected:
    """The events a scene needs, in the order of their discrete values (ir.Events)."""

    state: tuple[Relation, ...]  # read the states: indicators, located crossings
    time: tuple[tuple[Relation, sp.Expr, sp.Basic], ...]  # (relation, its time, its value
    #                                                        after that time: a condition)
    discrete: tuple[Relation, ...]  # of discrete variables and parameters
    squares: tuple[Square, ...]
    discretes: tuple[Discrete, ...]
    whens: tuple[When, ...]
    crossings: tuple[tuple[sp.Symbol, tuple], ...] = ()  # per state relation of t and
    #   parameters alone: its crossings' times as families (C, P), t = C + P n (time_roots),
    #   or None where they cannot be found in advance
    starts: tuple[tuple[sp.Symbol, sp.Basic], ...] = ()  # (symbol, the state relation with
    #   the signals it reads written out): what the start's first pass evaluates (_at_start)

    @property
    def empty(self) -> bool:
        return not (self.state or self.time or self.discrete or self.squares or self.discretes
                    or self.whens)

    def roots(self) -> list:
        """(expression, span) the steps must compute for the events: the indicators, the
        discrete relations' sides, the when-blocks' right sides."""
        out = [(r.indicator, r.span) for r in self.state + self.discrete]
        out += [(a.expr, a.span) for w in self.whens for a in w.actions]
        out += [(d.init, d.span) for d in self.discretes if d.next is not None]
        return out

    def slots(self) -> list:
        """Every discrete value's symbol, in the order of d."""
        return [r.symbol for r in self.state] + [r.symbol for r, _, _ in self.time] + \
            [r.symbol for r in self.discrete] + [s.symbol for s in self.squares] + \
            [d.symbol for d in self.discretes]


def select(graph_events, used: set, states: dict, params: set) -> Selected:
    """The relations, square waves, discrete variables and when-blocks that what the scene
    computes (`used`: the symbols its steps and outputs read) needs; states: the kept states'
    symbols -> StateVar.  The when-blocks kept are those that set a kept state or a discrete
    variable something reads; what they read is then used too."""
    relations, squares, discretes, whens = graph_events
    used = set(used)
    kept: list = []
    while True:
        size = len(used) + 1
        while len(used) != size:  # until nothing more is read (a mode reads a relation that
            size = len(used)      # reads a discrete variable: a switch's Sw(d < 16))
            for r in relations:  # what a relation reads is read too (a discrete variable)
                if r.symbol in used:
                    used |= free_symbols(r.relation)
            for d in discretes:  # and what a mode's next value reads
                if d.symbol in used and d.next is not None:
                    used |= free_symbols(d.next) | free_symbols(d.init)
        more = [w for w in whens if w not in kept and any(
            a.symbol in states if a.kind == "reinit" else a.symbol in used for a in w.actions)]
        if not more:
            break
        kept += more
        for w in more:
            used |= free_symbols(w.condition)
            for a in w.actions:
                used |= free_symbols(a.expr)
    kept = [w for w in whens if w in kept]
    discrete_symbols = {d.symbol for d in discretes}
    state, time, discrete, crossings = [], [], [], []
    for r in relations:
        if r.symbol not in used and not (r.needs and r.needs <= used | {TIME}):
            continue
        free = free_symbols(r.relation)
        if free <= params | discrete_symbols:
            discrete.append(r)
            continue
        timed = _time_event(r, params) if free <= params | {TIME} else None
        if timed is not None:
            time.append((r, *timed))
            continue
        state.append(_oriented(r))
        if free <= params | {TIME} and not r.needs:
            crossings.append((r.symbol, time_roots(r.indicator)))
    return Selected(tuple(state), tuple(time), tuple(discrete),
                    tuple(s for s in squares if s.symbol in used),
                    tuple(d for d in discretes if d.symbol in used), tuple(kept),
                    tuple(crossings))


def _oriented(r: Relation) -> Relation:
    """r with its indicator oriented to hold when g > 0 (or >= 0): x < y becomes y > x."""
    rel = r.relation
    if isinstance(rel, (sp.StrictLessThan, sp.LessThan)):
        flipped = (sp.StrictGreaterThan if isinstance(rel, sp.StrictLessThan) else
                   sp.GreaterThan)(rel.rhs, rel.lhs, evaluate=False)
        return Relation(r.symbol, flipped, r.text, r.span, r.owner, r.needs)
    return r


def strict(r: Relation) -> bool:
    return isinstance(r.relation, sp.StrictGreaterThan)


def _time_event(r: Relation, params: set):
    """(t*, value after t*) of a relation a t + b > 0 (a, b of parameters, a != 0), else
    None (a relation of t that is not linear: located as a state relation)."""
    rel = r.relation
    g = rel.lhs - rel.rhs
    a = partial(g, TIME)
    if TIME in a.free_symbols or a == 0:
        return None
    b = sp.expand(g - a * TIME)
    if TIME in b.free_symbols:
        return None
    at = _time(-b / a)
    rising = sp.StrictGreaterThan(a, 0)
    if isinstance(rel, (sp.StrictLessThan, sp.LessThan)):
        rising = sp.Not(rising)
    after = sp.Or(sp.And(rising, sp.GreaterThan(TIME, at)),
                  sp.And(sp.Not(rising), sp.StrictLessThan(TIME, at)))
    return at, after


def _time(at):
    """A time event's time; a number beyond a double (t0 + width = 2e308) as oo or -oo: no
    run reaches it, so the event never comes (it is no event) and the relation keeps its
    value for ever (a pulse that starts at 1e308 never ends).  Every runtime computes such a
    time from parameters as inf too, and steps onto no time that is not finite."""
    if at.is_number and at.is_extended_real:
        try:
            value = float(at)
        except (TypeError, ValueError, OverflowError):
            return at
        if math.isinf(value):
            return sp.oo if value > 0 else -sp.oo
    return at


def never(at) -> bool:
    """Whether a time event's time (_time's) is one no run reaches."""
    return at in (sp.oo, -sp.oo)


MAX_FAMILIES = 8  # of one relation's crossing times


def _one_place(e, x) -> bool:
    """Whether symbol x occurs exactly once in e's tree."""
    count, stack = 0, [e]
    while stack:
        a = stack.pop()
        if a == x:
            count += 1
            if count > 1:
                return False
        else:
            stack.extend(a.args)
    return count == 1


def _invert(e, c):
    """(the argument u of e, the values of u where e(u) = c as families (C, P)) for a
    function e of one argument whose inverse is known; None for any other."""
    two_pi = 2 * sp.pi
    if isinstance(e, sp.sin):
        return e.args[0], [(sp.asin(c), two_pi), (sp.pi - sp.asin(c), two_pi)]
    if isinstance(e, sp.cos):
        return e.args[0], [(sp.acos(c), two_pi), (-sp.acos(c), two_pi)]
    if isinstance(e, sp.tan):
        return e.args[0], [(sp.atan(c), sp.pi)]
    inverse = {sp.exp: sp.log, sp.log: sp.exp, sp.sinh: sp.asinh, sp.tanh: sp.atanh,
               sp.asinh: sp.sinh, sp.atan: sp.tan, sp.asin: sp.sin, sp.acos: sp.cos,
               sp.atanh: sp.tanh}.get(type(e))
    if inverse is not None:
        return e.args[0], [(inverse(c), sp.Integer(0))]
    if isinstance(e, sp.Abs):
        return e.args[0], [(c, sp.Integer(0)), (-c, sp.Integer(0))]
    if e.is_Pow:
        b, k = e.args
        if not k.has(TIME):
            if k == -1:
                return b, [(1 / c, sp.Integer(0))]
            if k == 2:
                return b, [(sp.sqrt(c), sp.Integer(0)), (-sp.sqrt(c), sp.Integer(0))]
            if k == sp.Rational(1, 2):
                return b, [(c ** 2, sp.Integer(0))]
            return None
        if not b.has(TIME):  # b**u = c
            return k, [(sp.log(c) / sp.log(b), sp.Integer(0))]
    return None


def time_roots(g) -> tuple | None:
    """The times where g, an expression of t and parameters, is zero: families (C, P) of
    parameter expressions, t = C + P n for every integer n (P = 0: the one time C), with
    values that are not real numbers where there is none (asin(2): NaN, which the runtimes
    skip).  None where t does not occur in one place, under sums and products by parameters
    and the functions _invert knows, with only sums and products below a periodic one.  The
    families may hold times where g only touches zero: the solver then steps onto a time
    where nothing changes."""
    if not _one_place(g, TIME):
        return None
    forms = [(sp.Integer(0), sp.Integer(0))]
    e = g
    while e != TIME:
        if e.is_Add or e.is_Mul:
            inner = next(a for a in e.args if a.has(TIME))
            rest = e.func(*[a for a in e.args if a is not inner])
            forms = [(c - rest, p) for c, p in forms] if e.is_Add else \
                [(c / rest, p / rest) for c, p in forms]
            e = inner
            continue
        if any(p != 0 for _, p in forms):
            return None  # a periodic family through a function: not a family of t
        step = [_invert(e, c) for c, _ in forms]
        if any(s is None for s in step):
            return None
        e = step[0][0]
        forms = [f for _, fs in step for f in fs]
        if len(forms) > MAX_FAMILIES:
            return None
    return tuple((C, P) for C, P in forms if not (C.is_number and (  # none there: asin(2)
        C.has(sp.zoo, sp.nan, sp.oo, -sp.oo) or C.is_extended_real is False)))


def _bit(cond) -> sp.Expr:
    return sp.Piecewise((sp.Integer(1), cond), (sp.Integer(0), True))


def _at_start(sel: Selected, new: dict) -> dict:
    """Every relation's and discrete value's value at t0, for the start's first pass: each
    reads the values at t0 of what it reads (the time relations', the time sources', the other
    relations' and the discrete values' initial values), not their values before the start, so
    that the modes a run starts in are those the conditions at t0 give (a switch whose
    condition holds at t0 starts closed).  Evaluated in an order where what a value reads
    comes first (depth first, iteratively); a value that reads itself through others (a
    cycle) reads its value before the start there.  A relation that reads a signal of a time
    source (`Sw(on > 0)`, on an instance's argument `square(...)`) reads it written out
    (sel.starts), so that it too reads the source's value at t0."""
    written = dict(sel.starts)
    items = {r.symbol: written.get(r.symbol, r.relation) for r in sel.state + sel.discrete}
    items.update({d.symbol: d.init for d in sel.discretes})
    first = {r.symbol: new[r.symbol] for r, _, _ in sel.time}
    first.update({q.symbol: q.value() for q in sel.squares})
    done, busy = set(first), set()
    for root in items:
        work = [root]
        while work:
            sym = work[-1]
            if sym in done:
                work.pop()
                continue
            busy.add(sym)
            todo = sorted((u for u in free_symbols(items[sym])
                           if u in items and u not in done and u not in busy), key=str)
            if todo:
                work.append(todo[0])
                continue
            first[sym] = items[sym].xreplace(first)
            done.add(sym)
            busy.discard(sym)
            work.pop()
    return first


def update_stores(sel: Selected, states) -> tuple[list, list]:
    """update's results over model symbols: the state after the event iteration's step (one
    per state, ordered as states), then each discrete value; and the event-time values each
    when-block's condition reads.  Every right side reads the values before the event; in
    the start's first pass, the values at t0 (_at_start)."""
    new: dict = {}
    for r, _, after in sel.time:
        new[r.symbol] = after
    first = _at_start(sel, new)
    for k, r in enumerate(sel.state):
        new[r.symbol] = sp.Or(sp.And(FIRST, first[r.symbol]),
                              sp.And(sp.Not(FIRST), sp.Ne(new_value(k), 0)))
    for r in sel.discrete:
        new[r.symbol] = sp.Or(sp.And(FIRST, first[r.symbol]), sp.And(sp.Not(FIRST), r.relation))
    old = {sym: sp.Or(sp.And(FIRST, cond), sp.And(sp.Not(FIRST), sym))
           for sym, cond in new.items()}
    fires = []
    for w in sel.whens:
        now = w.condition.xreplace({**new, INITIAL: FIRST})
        before = w.condition.xreplace({**old, INITIAL: sp.false})
        fires.append(sp.And(now, sp.Not(before)))
    values: dict = {}
    at_t0: dict = {}  # (the actions' and the discrete values' right sides share their
    after: dict = {}  #  subexpressions: each substituted once, bgc.symbolic.canonical)
    for w, fire in zip(sel.whens, fires):
        for a in w.actions:  # (at the start, "just before" is the values at t0)
            expr = sp.Piecewise((xreplace(a.expr, first, at_t0), FIRST), (a.expr, True)) \
                if free_symbols(a.expr) & first.keys() else a.expr
            values.setdefault(a.symbol, []).append((expr, fire))
    out = []
    for st in states:
        out.append(sp.Piecewise(*values[st.symbol], (st.symbol, True))
                   if st.symbol in values else st.symbol)
    for r in sel.state:  # a guard's value is not a number once it fails: the run stops
        out.append(sp.Piecewise((sp.Integer(1), new[r.symbol]), (sp.sqrt(r.indicator), True))
                   if r.needs else _bit(new[r.symbol]))
    for sym in [r.symbol for r, _, _ in sel.time] + [r.symbol for r in sel.discrete]:
        out.append(_bit(new[sym]))
    for s in sel.squares:
        out.append(s.value())
    for d in sel.discretes:
        start = sp.Piecewise((first[d.symbol], FIRST), (d.symbol if d.next is None else
                                                        xreplace(d.next, new, after), True))
        out.append(sp.Piecewise(*values[d.symbol], (start, True)) if d.symbol in values
                   else start)
    return out


def timers(sel: Selected) -> list[tuple]:
    """(time, source) of each time the solver steps onto, source the Relation, Square,
    TimeTable or InputSlot it belongs to: the time relations' times (but those beyond a
    double: never), the time sources' next edges, and the next crossing of each state
    relation of t alone whose times are known."""
    relation = {r.symbol: r for r in sel.state}
    crossings = [(C if P == 0 else PeriodicNext(TIME, P, C), relation[sym])
                 for sym, forms in sel.crossings if forms for C, P in forms
                 if not (P == 0 and never(_time(C)))]
    return [(at, r) for r, at, _ in sel.time if not never(at)] + \
        [(s.next(), s) for s in sel.squares if s.next() is not None] + crossings


def next_times(sel: Selected) -> list:
    """The times of timers(sel): the results of the program's next_time, in order."""
    return [at for at, _ in timers(sel)]


def log_names(sel: Selected) -> tuple[tuple[str, ...], tuple[str, ...]]:
    names = [r.text for r in sel.state] + [r.text for r, _, _ in sel.time] + \
        [r.text for r in sel.discrete] + [s.text for s in sel.squares] + \
        [d.name for d in sel.discretes]
    kinds = ["relation"] * (len(sel.state) + len(sel.time) + len(sel.discrete)) + \
        [s.kind for s in sel.squares] + ["discrete"] * len(sel.discretes)
    return tuple(names), tuple(kinds)


def leaves(graph_events) -> set:
    """The symbols that are constant between events: relations' values, square waves,
    discrete variables (the equations treat them as parameters)."""
    relations, squares, discretes, _ = graph_events
    return {r.symbol for r in relations} | {s.symbol for s in squares} | \
        {d.symbol for d in discretes} | {INITIAL, TOLERANCE}


def check(sel: Selected | None, es) -> None:
    """A kept when-block may not reinit a state that the scene's causality makes dependent."""
    if sel is None:
        return
    from ..base.diagnostics import fail
    dependent = {s.state: s for s in es.stores}
    for w in sel.whens:
        for a in w.actions:
            if a.kind == "reinit" and a.symbol in dependent:
                fail(a.span, f"'{a.name}' cannot be reinit: '{dependent[a.symbol].element}' is "
                             "in derivative causality, so its state follows from the rest of "
                             "the model")
