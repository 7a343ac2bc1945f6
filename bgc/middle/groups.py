"""Coupled switched one-ports (docs/hybrid.md, section 13): modes chosen together.

Ideal switches and diodes whose flow balances read one another's multipliers (a switch and
its freewheeling diode: the node between them has its voltage from the one and its current
through the other) are one system.  Each keeps its multiplier and its mode (`S.open`,
`D.blocking`), and the block of the multipliers is solved as one, but:

  the rows  an element whose mode holds its constraint (open: f = 0; blocking: f = 0, or as
            the dual junction, conducting: e = 0) contributes its balance B = 0 where B reads
            a multiplier of the group that is held too (an algebraic row), and dB/dt = 0 where
            it reads none (a state row: the storages' flow is held, as an inductor's current
            by a blocking diode with the switch open); an element whose mode frees it has its
            multiplier zero.  So every combination of modes is one linear block, and the
            combinations no run can reach (a closed switch shorting the source through a
            conducting diode) are singular ones: never chosen, never an error.
  the modes at t0 and after each pass of the event iteration, the switches take theirs from
            their conditions, and the diodes' follow from the complementarity conditions of
            all of them together, with the storages' states held: the combinations are
            enumerated (at most 2^MAX_COUPLED, each block solved in closed form here), and
            the first is taken in which every conducting diode's flow is at least -width/2
            and every blocking diode's effort at most 0, and whose state rows hold; where none
            does without a jump of the states (a diode's current that has reversed), the first
            whose signs hold with its state rows then made to hold.  The current modes come
            first while no diode's relation has crossed (a relation just crossed is taken as
            crossed: the mode it leaves is not taken again at that instant).
  the jumps entering a combination with a state row (the switch open and the diode blocking),
            the storages take the state that stops its flow (the impulse of section 7 with a
            zero target), at the pass after the modes changed, where the selection keeps them.
"""
from __future__ import annotations

from itertools import product

import sympy as sp
from sympy.solvers.solveset import NonlinearError

from ..base.diagnostics import fail
from ..front.events import INITIAL, Action, Discrete, Relation, When
from ..front.graph import TIME
from ..symbolic.algebra import Max, Min
from ..symbolic.conditions import indicator
from ..symbolic.differentiate import partial
from ..symbolic.walk import DESCEND, fold

EPS = sp.Float(2.0 ** -52)  # a double's epsilon
LOCATED = sp.Float(1e-12)  # a located event's resolution in t, relative (bgc.middle.contact)
MAX_COUPLED = 8  # switched one-ports in a group: 2^8 = 256 combinations (an H-bridge's eight)
KINDS = ("diode", "friction", "switch")


def find(infos, cdefs, reads=None) -> list[list]:
    """The groups of coupled switched one-ports (two or more each, one of them a diode or a
    switch), in declaration order: D, Sw and Fr elements joined where one's balance reads
    another's multiplier, or where the rate of a balance written in the states alone reads
    another's (reads(info): those multipliers; a freewheel and a clutch on one shaft, two
    diodes in series with a coil).  Friction elements coupled only with one another keep
    their own events (bgc.middle.contact._friction)."""
    members = [i for i in infos if i.kind in KINDS]
    by_multiplier = {cdefs[i.junction].multiplier: i for i in members}
    parent = {i.junction: i.junction for i in members}
    rank = order(members)

    def root(j):
        while parent[j] != j:
            parent[j] = parent[parent[j]]
            j = parent[j]
        return j

    for i in members:
        read = i.balance.free_symbols & by_multiplier.keys()
        if not read and reads is not None:
            read = reads(i) & by_multiplier.keys()
        for m in sorted(read, key=lambda s: s.name):
            o = by_multiplier[m]
            if i.kind == "friction" and o.kind == "friction":
                continue
            a, b = root(i.junction), root(o.junction)
            if a != b:
                parent[max(a, b, key=rank.get)] = min(a, b, key=rank.get)
    groups: dict = {}
    for i in members:
        groups.setdefault(root(i.junction), []).append(i)
    return [g for g in groups.values()
            if len(g) > 1 and any(i.kind != "friction" for i in g)]


def order(members) -> dict:
    return {i.junction: k for k, i in enumerate(members)}


STICK, PLUS, MINUS = 1, 2, 3  # a friction element's modes in a combination: sticking, sliding
#                               the positive way, the negative way


class _Member:
    """One element of a group: its multiplier, its mode, its balance in the states.  A
    diode's or a switch's mode is 0 or 1 (1: open or blocking); a friction element's is STICK,
    PLUS or MINUS, held as two discrete values, `F.stick` (1: sticking) and `F.dir`."""

    def __init__(self, info, c, active, holds, width, direction):
        self.info, self.c = info, c
        self.kind = info.kind
        self.diode = info.kind == "diode"
        self.friction = info.kind == "friction"
        self.dual = c.dual
        self.lam = c.multiplier
        self.mode = active(c)
        self.dir = direction(c) if self.friction else None
        self.holds = holds(c)
        self.B = info.balance
        self.width = width
        self.values = (STICK, PLUS, MINUS) if self.friction else (0, 1)
        if self.friction and self.dual:
            fail(c.name_span, f"dry friction '{c.junction}' imposes its flow here (the dual "
                              "form) and is coupled with a switch or a diode: not supported "
                              "yet")

    def held(self, bit: int) -> bool:
        """Whether mode value `bit` (1: open, blocking or sticking) holds the constraint."""
        return bit == 0 if self.dual else bit == 1

    def sliding(self, bit: int) -> sp.Expr:
        """The multiplier of a friction element sliding in mode `bit`: Fc the way it slides."""
        return self.c.gains[0] * (1 if bit == PLUS else -1)

    def free(self) -> sp.Expr:
        """The multiplier's law while its mode frees it (lambda = 0; sliding, Fc dir)."""
        return self.lam - self.c.gains[0] * self.dir if self.friction else self.lam

    def now(self, bit: int) -> sp.Expr:
        """1 where the member is in mode `bit` now, else 0."""
        if not self.friction:
            return self.mode if bit == 1 else 1 - self.mode
        if bit == STICK:
            return self.mode
        return (1 - self.mode) * (1 + self.dir) / 2 if bit == PLUS else \
            (1 - self.mode) * (1 - self.dir) / 2

    def effort(self, lam: dict, B):
        return B if self.dual else lam[self.lam]

    def flow(self, lam: dict, B):
        return lam[self.lam] if self.dual else B


def rewrite(sys, group, cdefs, active, holds, width, rate, law_equation, rates, direction):
    """The group's members and the combinations of their modes (bgc.middle.groups._Combination),
    with each multiplier's law made the group's (the module's rows).  rate(e): e's time
    derivative through der() of its states; rates(e): the same written in the states and the
    multipliers.  In a combination whose block is singular (never chosen) every multiplier is
    zero, so that the modes the event iteration starts from are no error; where no combination
    is consistent the diodes' modes are 2, whose rows are singular: the run stops there with
    the block's elements named."""
    """The group's members, with each multiplier's law made the group's (the module's rows)."""
    members = [_Member(i, cdefs[i.junction], active, holds, width, direction) for i in group]
    if sum(len(m.values) > 2 for m in members) + len(members) > MAX_COUPLED:
        fail(members[0].c.name_span, f"{len(members)} switched elements are coupled here "
                                     f"({', '.join(repr(m.c.junction) for m in members)}); "
                                     f"their modes are chosen together for up to {MAX_COUPLED}")
    lams = {m.lam: m for m in members}
    every = {c.multiplier for c in cdefs.values()}
    for m in members:
        other = sorted((m.B.free_symbols & every) - lams.keys(), key=lambda s: s.name)
        if other:
            fail(m.c.name_span, f"'{m.c.junction}' is coupled with the constraint of "
                                f"'{other[0].name.removesuffix('.lambda')}', which is not a "
                                "switch or a diode: not supported yet")
    every = [_Combination(bits, members, rates)
             for bits in product(*[m.values for m in members])]
    singular = sp.Add(*[_in(k, members) for k in every if not k.ok])
    lost = sp.Or(*[sp.Eq(m.mode, 2) for m in members if m.diode or m.friction])
    for m in members:
        read = [lams[s] for s in sorted(m.B.free_symbols & lams.keys(), key=lambda s: s.name)]
        free = m.B.xreplace({s: sp.Integer(0) for s in lams})
        pinned = [(k.pin[1] - k.pin[2], _in(k, members) > sp.Rational(1, 2))
                  for k in every if k.pin is not None and k.pin[0] is m]
        pinned += [(rate(k.derived[1]), _in(k, members) > sp.Rational(1, 2))
                   for k in every if k.derived is not None and k.derived[0] is m]
        law = sp.Piecewise((sp.Integer(0), lost), (m.lam, singular > sp.Rational(1, 2)),
                           *pinned, (m.free(), sp.Not(m.holds)),
                           (m.B, sp.Or(*[r.holds for r in read])),
                           (rate(free), True))
        sys.eqs[m.lam] = law_equation(m, law)  # (in its place in the equations' order)
    return members, every


def _in(k, members) -> sp.Expr:
    """1 where the members' modes are k's, else 0 (modes 0 and 1: a product of them)."""
    out = sp.Integer(1)
    for m, b in zip(members, k.bits):
        out *= m.now(b)
    return out


class _Combination:
    """One combination of the members' modes: its block in closed form, or None (singular)."""

    def __init__(self, bits, members, rates):
        self.bits = bits
        self.held = [m.held(b) for m, b in zip(members, bits)]
        unknowns = [m.lam for m, h in zip(members, self.held) if h]
        free = {m.lam: m.sliding(b) if m.friction else sp.Integer(0)
                for m, h, b in zip(members, self.held, bits) if not h}
        rows, self.state_rows = [], []
        for m, h in zip(members, self.held):
            if not h:
                continue
            if any(s in unknowns for s in m.B.free_symbols):
                rows.append(m.B.xreplace(free))
            else:
                self.state_rows.append(m)
                rows.append(rates(m.B.xreplace(free)).xreplace(free))
        self.lam = dict(free)
        self.ok = True
        if unknowns:
            try:
                A, b = sp.linear_eq_to_matrix([sp.expand(r) for r in rows], unknowns)
            except NonlinearError:
                fail(members[0].c.name_span, "the block of the coupled switched elements "
                                             f"{', '.join(repr(m.c.junction) for m in members)}"
                                             " is not linear in their multipliers: not "
                                             "supported yet")
            if sp.simplify(A.det()) == 0:
                self.ok = False
                A, b = self._constrained(A, b, unknowns, members, rates)
                if self.ok:
                    solution = A.LUsolve(b)
                    self.lam.update({u: solution[k] for k, u in enumerate(unknowns)})
                    return
                self._undetermined(A, b, unknowns, members)
                return
            solution = A.LUsolve(b)
            self.lam.update({u: sp.simplify(solution[k]) if sp.count_ops(solution[k]) < 60
                             else solution[k] for k, u in enumerate(unknowns)})


    pin = None  # (the member whose row gives way, the multiplier pinned, its value)
    derived = None  # (the member whose row gives way, the constraint on the states it derives)

    def _constrained(self, A, b, unknowns, members, rates):
        """A block singular whatever the state whose rows together hold the states (a
        capacitor tied to the source through two conducting diodes of a bridge: y^T A = 0,
        and g = y^T b, a relation of the states and t, must be zero): the row of one member
        gives way to g's rate, as a member's own state row does (its storages then follow
        the source; the combination is taken only where g holds already)."""
        n = len(unknowns)
        if A.rank(simplify=True) != n - 1 or A.row_join(b).rank(simplify=True) != n:
            return A, b
        (y,) = A.T.nullspace(simplify=True)
        g = sp.simplify((y.T * b)[0])
        if g.has(*unknowns):
            return A, b
        held = [m for m, h in zip(members, self.held) if h]
        for r in range(n):
            if y[r] == 0:
                continue
            row = sp.expand(rates(g))
            try:
                a, c = sp.linear_eq_to_matrix([row], unknowns)
            except NonlinearError:
                return A, b
            A2, b2 = A.copy(), b.copy()
            A2[r, :], b2[r, 0] = a, c[0]
            if sp.simplify(A2.det()) != 0:
                self.derived = (held[r], g)
                self.ok = True
                return A2, b2
        return A, b
    feasible = sp.Integer(1)  # (pinned: 1 where some value of the free direction is admissible)

    def _undetermined(self, A, b, unknowns, members):
        """A block singular whatever the state but consistent, with one free direction (a
        floating source while every diode of a bridge blocks: its potential is undetermined):
        the multipliers are lam_p + s v, and s is pinned at the middle of the interval where
        every diode's sign test holds (LANGUAGE's "any split that satisfies them"): the row
        of one member gives way to lam_j = s.  Where that interval is empty the combination
        is not admissible; where the direction's coefficients are not numbers, or there is
        more than one free direction, it stays singular."""
        n = len(unknowns)
        if A.rank(simplify=True) != n - 1 or A.row_join(b).rank(simplify=True) != n - 1:
            return
        (v,) = A.nullspace(simplify=True)
        held = [m for m, h in zip(members, self.held) if h]
        # (a friction element's force is the one pinned where there is one: the middle of its
        # cone is then exact, zero where Fs = 0 shrinks the cone to a point)
        j = next((i for i in sorted(range(n), key=lambda i: not held[i].friction)
                  if v[i].is_number and v[i] != 0), None)
        if j is None or not all(x.is_number for x in v):
            return
        cols = [c for c in range(n) if c != j]
        for r in range(n):
            rows = [k for k in range(n) if k != r]
            sub = A.extract(rows, cols)
            if sp.simplify(sub.det()) != 0:
                break
        else:
            return
        solution = sub.LUsolve(b.extract(rows, [0]))
        S = sp.Symbol("s#")
        lam = dict(self.lam)
        for i, c in enumerate(cols):
            lam[unknowns[c]] = solution[i] + S * v[c] / v[j]
        lam[unknowns[j]] = S
        lows, highs, fixed = [], [], []
        for m, bit in zip(members, self.bits):
            if not (m.diode or m.friction):
                continue
            B = m.B.xreplace(lam)
            if m.friction and bit == STICK:  # (inside its cone: -Fs <= lambda <= Fs)
                Fs = m.c.gains[1]
                tests = [lam[m.lam] - Fs, -lam[m.lam] - Fs]
            elif m.friction:  # (sliding: not against the way it slides)
                f = m.flow(lam, B)
                way = 1 if bit == PLUS else -1
                tests = [-way * f - m.width(f.xreplace({S: 0})) / 2]
            elif bit == 1:
                tests = [m.effort(lam, B)]
            else:
                f = m.flow(lam, B)
                tests = [-f - m.width(f.xreplace({S: 0})) / 2]
            for g in tests:  # (each g <= 0)
                a, c = sp.diff(g, S), g.xreplace({S: 0})
                if not a.is_number:
                    return
                if a == 0:
                    fixed.append(c <= 0)
                else:
                    (lows if a < 0 else highs).append(-c / a)
        lo = (lows[0] if len(lows) == 1 else Max(*lows)) if lows else None
        hi = (highs[0] if len(highs) == 1 else Min(*highs)) if highs else None
        value = (lo + hi) / 2 if lo is not None and hi is not None else \
            lo if lo is not None else hi if hi is not None else sp.Integer(0)
        tests = [_is(t) for t in fixed] + ([_is(lo <= hi)] if lo is not None and hi is not None
                                           else [])
        self.feasible = sp.Mul(*tests) if tests else sp.Integer(1)
        held = [m for m, h in zip(members, self.held) if h]
        self.pin = (held[r], unknowns[j], value)
        self.lam = {u: e.xreplace({S: value}) for u, e in lam.items()}
        self.ok = True


def _friction_test(m, bit, lam, signs, rates) -> sp.Expr:
    """1 where friction element m can be in mode `bit` with the multipliers `lam`, else 0:
    sticking, its force inside the cone (signs: not pinned, where the combination's
    feasibility holds it); sliding, its flow not against the way it slides and, at rest
    (within its width), its acceleration that way."""
    if bit == STICK:
        return _is(sp.Abs(lam[m.lam]) <= m.c.gains[1] + _band(m, lam)) if signs else \
            sp.Integer(1)
    way = 1 if bit == PLUS else -1
    f = way * m.B.xreplace(lam)
    w = m.width(m.B)
    moving = _is(f > w)
    accel = way * rates(m.B).xreplace(lam)
    return moving + (1 - moving) * _is(f >= -w / 2) * _is(accel >= 0)


def _band(m, lam) -> sp.Expr:
    """What rounding leaves of a friction element's force against its cone Fs: 16 eps of the
    group's multipliers and Fs (a force pinned inside a cone that Fs = 0 shrinks to a point
    is zero only to rounding of the others' sizes)."""
    return 16 * EPS * (sp.Add(*[sp.Abs(v) for v in lam.values()]) + sp.Abs(m.c.gains[1]))


def _is(test) -> sp.Expr:
    """1 where test holds, else 0: the selection is arithmetic on 0 and 1 (exact in every
    backend), so that SymPy never rewrites its conditions as one boolean formula (nor drops
    a time source's step inside one: bgc.symbolic.conditions)."""
    return indicator(test)


def _first(pieces, default, finite: dict) -> sp.Expr:
    """The value of the first (value, c) whose c (0 or 1) is 1, else default: c*v + (1-c)*rest,
    folded from the end (a loop, not a recursion); finite: _times's memo."""
    out = default
    for value, c in reversed(pieces):
        out = _times(c, value, finite) + (1 - c) * out
    return out


def events(sys, members, every, stops, rates, relations, discretes, whens):
    """The group's relations, modes and jumps (the module's selection).  rates(e): e's time
    derivative written in the states and the multipliers; every: the combinations;
    stops[junction]: the momenta's values that stop that member's flow (its balance's free
    form), or {}."""
    diodes = [m for m in members if m.diode]
    frictions = [m for m in members if m.friction]
    switches = [m for m in members if m.kind == "switch"]
    combos = [c for c in every if c.ok]
    finite: dict = {}  # (_times)
    fired = []  # the diodes' relations (the events that locate their changes), as for one
    for m in diodes:
        n = len(relations)
        blocking = sp.Ne(m.mode, 0)
        e, f = (m.B, m.lam) if m.dual else (m.lam, m.B)
        forward = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((e, blocking), (sp.Integer(-1), True)), 0),
            f"{m.c.junction}: forward (e > 0)", m.c.name_span, None)
        reverse = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
            sp.Piecewise((-f - m.width(f), sp.Not(blocking)), (sp.Integer(-1), True)), 0),
            f"{m.c.junction}: reverse (f < 0)", m.c.name_span, None)
        relations = relations + [forward, reverse]
        fired.append(_is(sp.Or(forward.symbol, reverse.symbol)))
    for m in frictions:  # (as one friction element's: bgc.middle.contact._friction)
        n = len(relations)
        stick = sp.Ne(m.mode, 0)
        slows = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((-m.dir * m.B - m.width(m.B), sp.Not(stick)), (sp.Integer(-1), True)),
            0), f"{m.c.junction}: stops (f reverses)", m.c.name_span, None)
        breaks = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
            sp.Piecewise((sp.Abs(m.lam) - m.c.gains[1] - _band(m, {o.lam: o.lam for o in members}),
                          stick), (sp.Integer(-1), True)), 0),
            f"{m.c.junction}: breaks away (|e| > Fs)", m.c.name_span, None)
        relations = relations + [slows, breaks]
        fired.append(_is(sp.Or(slows.symbol, breaks.symbol)))
    closed = {m.lam: _is(m.c.gains[0]) for m in switches}  # 1: closed, from its condition

    def admissible(k, rows_hold):
        lam, out = k.lam, k.feasible
        for m, b in zip(members, k.bits):
            if m.friction:
                out *= _friction_test(m, b, lam, k.pin is None, rates)
            if m.diode and k.pin is None:  # (pinned: feasible holds the sign tests)
                B = m.B.xreplace(lam)
                if b == 1:
                    out *= _is(m.effort(lam, B) <= 0)
                else:
                    f = m.flow(lam, B)
                    out *= _is(f >= -m.width(f) / 2)
        if rows_hold:  # (each within its width and what the located crossing resolves of
            #             it: 1e-12 relative in t, times its rate through t, four times over)
            held = [(m, m.B.xreplace(lam)) for m in k.state_rows]
            if k.derived is not None:
                held.append(k.derived)
            for m, g in held:
                slack = 4 * LOCATED * sp.Abs(TIME) * sp.Abs(partial(g, TIME))
                out *= _is(sp.Abs(g) <= m.width(g) + slack)
        elif k.derived is not None or any(m.dual or not stops.get(m.c.junction)
                                          for m in k.state_rows):
            return sp.Integer(0)  # (no jump of momenta makes these rows hold: an effort held
            #                        at zero on capacitors, a row of no storage's state)
        return out

    def matches(k):  # 1 where the switches' conditions give k's bits
        out = sp.Integer(1)
        for m, b in zip(members, k.bits):
            if m.kind == "switch":
                out *= closed[m.lam] if b == 0 else 1 - closed[m.lam]
        return out

    def current(k):  # 1 where the diodes and the friction elements are in k's modes now
        out = sp.Integer(1)
        for m, b in zip(members, k.bits):
            if m.kind != "switch":
                out *= m.now(b)
        return out

    unchanged = sp.Integer(1)
    for m in switches:
        unchanged *= closed[m.lam] * (1 - m.mode) + (1 - closed[m.lam]) * m.mode
    quiet = sp.Integer(1)
    for x in fired:
        quiet *= 1 - x
    tests = {(id(k), rows): admissible(k, rows) for k in combos for rows in (True, False)}
    regular = 1 - sp.Add(*[_in(k, members) for k in every if not k.ok])  # (the modes now)
    stay = regular * unchanged * quiet + (1 - unchanged) * sp.Add(
        *[current(k) * matches(k) * tests[id(k), True] for k in combos])

    def chosen(m, now, value, lost):
        """m's next value: `now` while the modes stay, value(bit) of the first admissible
        combination, else `lost`."""
        i = members.index(m)
        pieces = [(now, stay)]
        for rows in (True, False):
            for k in combos:
                pieces.append((value(k.bits[i]),
                               (1 - current(k)) * matches(k) * tests[id(k), rows]))
        return _first(pieces, lost, finite)

    nexts, kept = {}, sp.Integer(1)
    for m in diodes:  # (no consistent combination: 2)
        nexts[m.lam] = chosen(m, m.mode, sp.Integer, sp.Integer(2))
        discretes = discretes + [Discrete(
            f"{m.c.junction}.blocking", m.mode, sp.Integer(1),  # (the start's next pass chooses)
            "1: blocking, 0: conducting", m.c.name_span, nexts[m.lam])]
        kept *= 1 - (nexts[m.lam] - m.mode) ** 2
    for m in frictions:  # (it starts sticking where its flow is zero, else sliding its way)
        stick = chosen(m, m.mode, lambda b: sp.Integer(int(b == STICK)), sp.Integer(2))
        way = chosen(m, m.dir, lambda b: m.dir if b == STICK else sp.Integer(
            1 if b == PLUS else -1), m.dir)
        discretes = discretes + [
            Discrete(f"{m.c.junction}.stick", m.mode, sp.Piecewise(
                (sp.Integer(1), sp.Eq(m.B, 0)), (sp.Integer(0), True)),
                "1: sticking, 0: sliding", m.c.name_span, stick),
            Discrete(f"{m.c.junction}.dir", m.dir, sp.Piecewise(
                (sp.Integer(-1), m.B < 0), (sp.Integer(1), True)),
                "the sliding direction", m.c.name_span, way)]
        kept *= (1 - (stick - m.mode) ** 2) * (1 - (way - m.dir) ** 2 / 4)
    # entering a mode that holds a flow, the jump is taken where the modes now are admissible
    # with it (a when-block reads the relations' values before its pass, which still say
    # what made the modes change: `kept` would read them as changing again)
    taken = sp.Add(*[current(k) * matches(k) * tests[id(k), False] for k in combos])
    states = {st.symbol: st for st in sys.es.states}
    for m in members:
        stop = stops.get(m.c.junction) or {}
        if not stop or m.dual:
            continue
        read = [o for o in members if o.lam in m.B.free_symbols]
        row = sp.And(m.holds, *[sp.Not(o.holds) for o in read])
        n = len(relations)
        enters = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((sp.Integer(1), row), (sp.Integer(-1), True)), 0),
            f"{m.c.junction}: its flow held", m.c.name_span, None)
        relations = relations + [enters]
        whens = whens + [
            When(enters.symbol, enters.text, tuple(
                Action("reinit", states[p].name, p, _times(taken, new, finite) + (1 - taken) * p,
                       m.c.span)
                for p, new in stop.items()), m.c.span),
            When(INITIAL, f"{m.c.junction}: the start", tuple(
                Action("reinit", states[p].name, p,
                       _times(_is(row) * kept, new, finite) + (1 - _is(row) * kept) * p,
                       m.c.span)
                for p, new in stop.items()), m.c.span)]
    return relations, discretes, whens


def _times(a, b, memo: dict) -> sp.Expr:
    """a*b as SymPy builds it.  Where b is zero, SymPy asks whether a factor of a is infinite
    (the product is then NaN), which for a mode's selection walks all of it through the
    assumptions system; where a is finite by construction (_finite) the product is zero."""
    if b is sp.S.Zero and _finite(a, memo):
        return sp.S.Zero
    return a * b


_FINITE = (sp.Add, sp.Mul, sp.Abs, sp.Piecewise, Max, Min)  # finite where their arguments are


def _finite(e, memo: dict) -> bool:
    """Whether e is finite by construction: finite numbers and symbols, combined by sums,
    products, powers to a whole exponent >= 0, abs, Max, Min and Piecewise (its values)."""
    def leaf(x):
        if x.is_Number or x.is_Symbol:
            return x.is_finite is True
        if isinstance(x, sp.Pow):
            return DESCEND if x.exp.is_Integer and x.exp >= 0 else False
        return DESCEND if isinstance(x, _FINITE) else False

    def children(x):
        if isinstance(x, sp.Piecewise):
            return [pair.expr for pair in x.args]
        return [x.base] if isinstance(x, sp.Pow) else x.args

    return fold(e, memo, leaf, lambda x, values: all(values), children)


def rate_of(states_of, leaf_rate):
    """e's time derivative: its states' rates (leaf_rate(s): der(s) written in the states and
    the multipliers) and its own dependence on t."""
    def rate(e):
        return sp.Add(*[partial(e, s) * leaf_rate(s)
                        for s in sorted(e.free_symbols & states_of, key=lambda s: s.name)],
                      partial(e, TIME))
    return rate
