"""Coupled switched one-ports (docs/hybrid.md, section 13; docs/architecture.md): a switch and
its freewheeling diode on one node, whose modes are chosen together.

Switches and diodes whose flow (or effort) balances, written in the states, read one
another's multipliers are one group (bgc.middle.causality gives them the causality the sources
and storages leave them).  Each member j is a constraint junction with a multiplier lambda_j
and a balance B_j(x, lambda); in a mode it either holds (its row B_j = 0: blocking or open for
a member that imposes its effort, conducting or closed for one that imposes its flow) or is
free (lambda_j = 0).  In a mode, a held row that still reads a held multiplier is algebraic;
one that reads none (every multiplier in it free: a switch open beside a blocking diode holds
the coil's current at zero) holds storages alone, and is replaced by its time derivative
(index reduction, as for the paper's holonomic constraints).  The multipliers' laws
(rewrite_laws) say so, mode by mode, for the step's linear block.

The modes themselves are chosen by the group's selection, built here as the discrete values'
next values and a state jump that the event iteration applies on every pass: for every
combination of the members' modes (the switches' from their conditions), the held rows are
solved for the held multipliers, symbolically (at most MAX_MEMBERS members, 2^n
combinations); a combination is admissible where its linear block is regular and every diode
obeys its complementarity conditions (conducting: f >= -w/2; blocking: e <= w/2, w the switching
width of bgc.middle.contact); it is consistent where its storage rows hold (|B_j| <= w/2), else
it needs a jump: the storages move along the held multipliers' directions (the impulse) to
where the storage rows hold and the algebraic rows' impulses balance, and the conditions are
then checked after the jump.  The order: the current modes where admissible and consistent,
then the first admissible and consistent combination, then the first admissible one after a
jump; none: the run stops, naming the members.  The diodes' relations (forward where e
exceeds w, reverse where f falls below -w) locate the events, as for a single diode.
"""
from __future__ import annotations

import itertools

import sympy as sp

from ..base.diagnostics import fail
from ..front.events import ALWAYS, Action, Discrete, Relation, When
from ..symbolic.differentiate import partial
from . import contact
from .system import der

MEMBERS = ("diode", "switch")
MAX_MEMBERS = 6  # a group's members: 2^6 mode combinations solved symbolically, at most
from .system import TIME
# the selection's value where no combination is consistent: not a number, so the run stops
# there (a guard's way, bgc.front.events), naming the member's mode
NO_MODE = sp.sqrt(-1 - sp.Abs(TIME))


def find(infos, cdefs) -> list[list]:
    """The groups (lists of ConstraintInfo, in declaration order) of two or more switches and
    diodes whose balances read one another's multipliers."""
    members = [i for i in infos if i.kind in MEMBERS]
    by_multiplier = {i.multiplier: i for i in members}
    parent = {i.junction: i.junction for i in members}

    def root(j):
        while parent[j] != j:
            parent[j] = parent[parent[j]]
            j = parent[j]
        return j

    for i in members:
        for lam in sorted(i.balance.free_symbols & by_multiplier.keys(), key=str):
            a, b = root(i.junction), root(by_multiplier[lam].junction)
            if a != b:
                parent[max(a, b)] = min(a, b)
    out: dict = {}
    for i in members:
        out.setdefault(root(i.junction), []).append(i)
    groups = [g for g in out.values() if len(g) > 1]
    for g in groups:
        if len(g) > MAX_MEMBERS:
            fail(g[0].name_span, f"{_names(g)} are {len(g)} coupled switched elements: their "
                                 f"modes are chosen together for up to {MAX_MEMBERS}")
    return groups


def _names(group) -> str:
    return ", ".join(f"'{i.junction}'" for i in group)


def rewrite_laws(sys, group, cdefs, states):
    """Each member's multiplier law, mode by mode: held, its row B = 0 while a held multiplier
    is in it, else the row's time derivative (its storages alone); free, lambda = 0."""
    from .system import Equation
    multipliers = {i.multiplier: i for i in group}
    for info in group:
        c = cdefs[info.junction]
        others = sorted(info.balance.free_symbols & multipliers.keys(), key=str)
        free = info.balance.xreplace({m: sp.Integer(0) for m in others})
        rate = contact._rate(free, states)
        # (a row of no storage: that mode is never chosen, its block singular; lambda = 0
        # there keeps the block regular before the start's selection has run)
        row = sp.Piecewise((c.balance, sp.Or(*[contact.holds(cdefs[multipliers[m].junction])
                                               for m in others])),
                           (rate if rate != 0 else c.multiplier, True))
        law = sp.Piecewise((row, contact.holds(c)), (c.multiplier, True))
        old = sys.eqs[c.multiplier]
        sys.add(Equation(c.multiplier, law, False, old.origin, old.span))


def _bit_holds(c, bit: int) -> bool:
    """Whether member c's row holds when its discrete value (open, blocking) is bit."""
    return bool(bit) != bool(c.dual)


def _linear(rows, unknowns, span, group):
    """(A, b) with rows = A u + b, refused where a row is not linear in the unknowns."""
    A = sp.Matrix([[partial(r, u) for u in unknowns] for r in rows])
    if any(a.free_symbols & set(unknowns) for a in A):
        fail(span, f"the rows of the coupled switched elements {_names(group)} are not linear "
                   "in their multipliers; not supported")
    zero = {u: sp.Integer(0) for u in unknowns}
    b = sp.Matrix([r.xreplace(zero) for r in rows])
    return A, b


def _solve(A, b):
    """A^-1 b, or None where A is singular whatever the state."""
    if A.shape[0] == 0:
        return []
    det = sp.expand(A.det())
    if det == 0:
        return None
    return list(A.LUsolve(b))


class _Mode:
    """One combination of the members' modes, solved."""

    def __init__(self, bits, group, cdefs, rates, states, relations_new):
        self.bits = bits
        cs = [cdefs[i.junction] for i in group]
        held = [i for i, c, b in zip(group, cs, bits) if _bit_holds(c, b)]
        free = {i.multiplier: sp.Integer(0) for i, c, b in zip(group, cs, bits)
                if not _bit_holds(c, b)}
        unknowns = [i.multiplier for i in held]
        self.pure = []  # (member, its storage row B(x)) of the rows that hold storages alone
        rows = []
        for i in held:
            B = i.balance.xreplace(free)
            if B.free_symbols & set(unknowns):
                rows.append(B)
                continue
            self.pure.append((i, B))
            rows.append(sp.Add(*[partial(B, s) * rates[s].xreplace(free)
                                 for s in sorted(B.free_symbols & states, key=str)]))
        span = group[0].name_span
        A, b = _linear(rows, unknowns, span, group)
        sol = _solve(A, -b)
        self.regular = sol is not None
        if not self.regular:
            return
        self.value = {**free, **dict(zip(unknowns, sol))}
        # the jump: the storages move along the held multipliers' directions
        self.jump = None
        if self.pure:
            moved = [s for s in sorted(states, key=str)
                     if rates[s].xreplace(free).free_symbols & set(unknowns)]
            D = {s: [partial(rates[s].xreplace(free), u) for u in unknowns] for s in moved}
            J = []
            rhs = []
            for i in held:
                B = i.balance.xreplace(free)
                pure = dict(self.pure).get(i)
                if pure is not None:
                    J.append([sp.Add(*[partial(pure, s) * D[s][k] for s in moved
                                       if s in pure.free_symbols]) for k in range(len(unknowns))])
                    rhs.append(-pure)
                else:
                    J.append([partial(B, u) for u in unknowns])
                    rhs.append(sp.Integer(0))
            impulse = _solve(sp.Matrix(J), sp.Matrix(rhs))
            if impulse is not None:
                self.jump = {s: s + sp.Add(*[D[s][k] * impulse[k] for k in range(len(unknowns))])
                             for s in moved}
        self.group, self.cdefs, self.relations_new = group, cdefs, relations_new

    def conditions(self, after=None):
        """The members' complementarity conditions in this mode (after: the state it jumps
        to), and the switches' modes their conditions give."""
        out = []
        for i, bit in zip(self.group, self.bits):
            c = self.cdefs[i.junction]
            if i.kind == "switch":
                out.append(sp.Not(c.gains[0]) if bit else c.gains[0])
                continue
            lam = self.value[i.multiplier]
            other = i.balance.xreplace(self.value)
            e, f = (other, lam) if c.dual else (lam, other)
            if after is not None:
                e, f = e.xreplace(after), f.xreplace(after)
            if bit:  # blocking
                out.append(e <= contact._width(e) / 2)
            else:
                out.append(f >= -contact._width(f) / 2)
        return out

    def consistent(self):
        return [sp.Abs(B) <= contact._width(B) / 2 for _, B in self.pure]


def contact_open(c):
    """A switch's mode from its condition: 1 open, 0 closed."""
    return sp.Piecewise((sp.Integer(0), c.gains[0]), (sp.Integer(1), True))


def events(group, cdefs, rates, states, names, relations, discretes, whens):
    """The group's relations, discrete values and jump (see the module's docstring)."""
    modes = []
    for bits in itertools.product((0, 1), repeat=len(group)):
        m = _Mode(bits, group, cdefs, rates, states, None)
        if m.regular:
            modes.append(m)
    current = [sp.Eq(contact.active(cdefs[i.junction]), 0) for i in group]

    def is_current(m):
        return sp.And(*[sp.Eq(contact.active(cdefs[i.junction]), b)
                        for i, b in zip(group, m.bits) if i.kind != "switch"])

    ordered = []  # (mode, condition, state after) in the order the selection tries them
    for m in modes:
        ordered.append((m, sp.And(is_current(m), *m.consistent(), *m.conditions()), None))
    for m in modes:
        ordered.append((m, sp.And(*m.consistent(), *m.conditions()), None))
    for m in modes:
        if m.pure and m.jump is not None:
            ordered.append((m, sp.And(*m.conditions(m.jump)), m.jump))
    del current
    start = ordered[len(modes):]  # at t0: no current mode
    chosen, first = _chosen(ordered), _chosen(start)
    for k, i in enumerate(group):
        c = cdefs[i.junction]
        J = i.junction
        pick, init = (_bit(k, sel) for sel in (chosen, first))
        if i.kind == "switch":
            discretes.append(Discrete(f"{J}.open", contact.active(c), contact_open(c),
                                      "1: open, 0: closed", c.name_span, contact_open(c)))
            continue
        blocking = sp.Ne(contact.active(c), 0)
        lam, other = c.multiplier, i.balance
        e, f = (other, lam) if c.dual else (lam, other)
        n = len(relations)
        forward = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((e - contact._width(e), blocking), (sp.Integer(-1), True)), 0),
            f"{J}: forward (e > 0)", c.name_span, None)
        reverse = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
            sp.Piecewise((-f - contact._width(f), sp.Not(blocking)), (sp.Integer(-1), True)),
            0), f"{J}: reverse (f < 0)", c.name_span, None)
        relations += [forward, reverse]
        discretes.append(Discrete(f"{J}.blocking", contact.active(c), init,
                                  "1: blocking, 0: conducting", c.name_span, pick,
                                  (forward.symbol, reverse.symbol)))
    jumped = sorted(set().union(*[set(j) for _, _, j in ordered if j]), key=str)
    if jumped:
        actions = tuple(Action("reinit", names[s], s, sp.Piecewise(
            *[(j[s], sel) for (_, _, j), (_, sel) in zip(ordered, chosen)
              if j and s in j], (s, True)), group[0].span) for s in jumped)
        whens.append(When(ALWAYS, f"{_names(group)}: the modes chosen together", actions,
                          group[0].span))
    return relations, discretes, whens


def _chosen(ordered) -> list:
    """Per entry (mode, condition, jump) of the selection's order: (mode, whether it is the
    first whose condition holds)."""
    out, before = [], []
    for m, cond, _ in ordered:
        out.append((m, sp.And(cond, *[sp.Not(b) for b in before])))
        before.append(cond)
    return out


def _bit(k, chosen):
    """Member k's discrete value from the chosen entry: 1, 0, or not a number (no mode)."""
    ones = sp.Or(*[sel for m, sel in chosen if m.bits[k]])
    zeros = sp.Or(*[sel for m, sel in chosen if not m.bits[k]])
    return sp.Piecewise((sp.Integer(1), ones), (sp.Integer(0), zeros), (NO_MODE, True))
