"""Unilateral constraint junctions (docs/hybrid.md): contact, impact and release as events.

`J : 0 constraint unilateral(phi = EXPR) restitution(E) corrector pid(a, b)` keeps Phi >= 0.
It is the paper's holonomic constraint junction with a mode, a discrete value `J.active`:

  inactive  no force: lambda = 0 (the multiplier's equation is lambda = 0);
  active    the holonomic junction: Phi'' + 2 a Phi' + b^2 Phi = 0 determines lambda.

Its events, built here as the language's own (relations, discrete variables, when-blocks),
so that the step driver and the event iteration handle them as any other:

  contact   inactive and Phi < 0: an impact.  The momenta of the storages on the junction's
            bonds jump by an impulse along the constraint's direction, the least change of
            kinetic energy that gives Phi'+ = -E Phi'- (Newton's law of restitution) while the
            bilateral constraint junctions on the same storages keep Phi'+ = 0 (a rod stays
            rigid when its bob strikes a wall): with G the rows' derivatives by the momenta
            and K by the velocities (bgc.middle.reduce's _Weights: the kinetic metric),
            (G K^T) Lambda = target - Phi', dp = K^T Lambda.  When the rebound is too small to
            leave the surface (E = 0, or below 1e-6 of the largest impact speed so far) the
            junction becomes active instead: contact that stays closed; so it does when the
            rebound's apex, (E Phi')^2 / (2 |Phi''|), is below 10 atol, a height that the
            run's tolerance on the states cannot resolve.
  release   active and lambda would pull: the free motion would separate (lambda times
            d Phi''/d lambda below zero); the junction becomes inactive.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import product

import sympy as sp

from ..symbolic.algebra import Heaviside, Max, Min
from ..base.diagnostics import fail
from ..symbolic.differentiate import partial
from ..front.events import INITIAL, TOLERANCE, Action, Discrete, Relation, When
from ..front.graph import TIME, var
from . import groups
from .system import Equation, der

SWITCHED = ("diode", "friction", "switch")  # one-ports that are constraint junctions in one of their modes
MAX_IMPACT_ROWS = 3  # rows that take part in one impact, solved symbolically
REST = sp.Float(1e-6)  # a rebound below this fraction of the largest impact speed stays put
EPS = sp.Float(2.0 ** -52)  # a double's epsilon
LOCATED = sp.Float(1e-12)  # a located state event's resolution in t, relative to t (the step
#                            drivers' bgc_find_event, drive.py's _find_event)


def _magnitude(e) -> sp.Expr:
    """The size of what e is computed from: the sum of its terms' sizes (|e| itself where it
    is one term), so that the floating point resolves e to about eps times this, however
    much the terms cancel (a mass's velocity against a belt's: both 0.5, f = 0)."""
    terms = e.args if isinstance(e, sp.Add) else (e,)
    return sp.Add(*[sp.Abs(a) for a in terms])


def _width(flow) -> sp.Expr:
    """A switched element's switching width on its flow (docs/hybrid.md): 10 atol, and never
    below what the floating point resolves at the flow's current values (16 eps times its
    terms' size, ten times over): where atol is finer than that, a flow that is zero to
    rounding must not read as a reversal, and a width the arithmetic cannot hold would flip
    the mode to and fro (false chattering)."""
    return 10 * Max(TOLERANCE, 16 * EPS * _magnitude(flow))


def _rate(e, states) -> sp.Expr:
    """e's time derivative along the model (e written in the states and t)."""
    return sp.Add(*[partial(e, s) * der(s) for s in sorted(e.free_symbols & states.keys(),
                                                           key=lambda s: s.name)],
                  partial(e, TIME))


def direction(c) -> sp.Symbol:
    """A friction element's sliding direction, +1 or -1."""
    return var(f"{c.junction}.dir")


def active(c) -> sp.Symbol:
    """The discrete value that says whether junction c is in contact."""
    return var(f"{c.junction}.active")


def holds(c) -> sp.Basic:
    """When junction c's constraint holds (its law determines the multiplier; else the
    multiplier is free: zero, or a sliding friction's force).  A switched one-port that is the
    dual junction (bgc.middle.causality: it imposes its flow) holds its effort at zero while closed
    or
    conducting, where the other form holds its flow at zero while open or blocking: the same
    mode, `active` (open, blocking), holds the other way round."""
    return sp.Eq(active(c), 0) if c.dual else sp.Ne(active(c), 0)


def with_contact_events(sys, infos, weigh, defs, leaf, cycle):
    """The equation system with the events of its unilateral junctions and switched one-ports
    added; leaf, cycle: bgc.middle.reduce's leaf forms (an expression written in the states) and
    the exception they raise on an algebraic loop."""
    relations, squares, discretes, whens = (list(x) for x in sys.es.events)
    cdefs = {c.junction: c for c in sys.es.constraints}
    multipliers = {c.multiplier for c in sys.es.constraints}
    states = {st.symbol: st for st in sys.es.states}
    order = {st.symbol: k for k, st in enumerate(sys.es.states)}
    bilateral = [i for i in infos if i.kind in ("holonomic", "nonholonomic")]
    memo: dict = {}

    def expandable(s):
        return s in defs and not sys.is_leaf(s)

    metric = _metric(sys, leaf, defs, expandable, memo, cycle)
    gaps = {i.junction: dict(weigh(cdefs[i.junction].balance)) for i in infos
            if i.kind == "unilateral"}
    temporaries: list = []

    def define(c, expr):  # a frictional impact's intermediate value, as a step of the run
        if expr.is_Number or expr.is_Symbol:
            return expr
        s = sp.Symbol(f"{c.junction}.impulse#{len(temporaries)}", real=True)
        temporaries.append(s)
        sys.add(Equation(s, expr, True, c.junction, c.span))
        return s

    # what moves with the states: the states and a coupled field's flows (M f = p), whose
    # rates the steps compute
    moving = dict.fromkeys([*states, *[f for _, f, _ in sys.es.momenta if f not in states]])
    held = {j: [] for j in gaps}  # the friction's stop, at each contact's release
    moved = {j: set() for j in gaps}
    grouped = set()
    def reads(info):  # the multipliers the rate of a balance in the states reads
        out = set()
        for s in sorted(info.balance.free_symbols & states.keys(), key=order.get):
            try:
                out |= leaf(sys.eqs[der(s)].expr, defs, expandable, memo).free_symbols
            except (cycle, KeyError):
                continue
        return out & multipliers

    for group in groups.find(infos, cdefs, reads):
        relations, discretes, whens = _coupled(sys, group, cdefs, states, leaf, defs,
                                               expandable, memo, cycle, weigh, bilateral,
                                               order, metric, relations, discretes, whens)
        grouped |= {i.junction for i in group}
    for info in (i for i in infos if i.kind in SWITCHED and i.junction not in grouped):
        c = cdefs[info.junction]
        if c.dual:  # (the mode at the start: its d[k] are set by the start's first pass)
            start = info.balance > 0 if info.kind == "diode" else c.gains[0].xreplace(
                {r.symbol: r.relation for r in relations})
            if not info.balance.free_symbols & multipliers:  # (else coupled: no jump, the
                #                  block of the multipliers holds its effort at zero)
                relations, whens = _closing(sys, c, info, states, order, leaf, defs,
                                            expandable, memo, cycle, relations, whens, start)
            switch = {"diode": _dual_diode, "switch": _switch}[info.kind]
            relations, discretes, whens = switch(c, info, {}, states, relations, discretes,
                                                 whens)
            continue
        K_d = dict(weigh(c.balance))  # (none: a resistive path, whose flow stops at once)
        block = _impulse(c, info.balance, K_d, sp.Integer(0), bilateral, cdefs, weigh,
                         order, metric)[0] if K_d else {}
        if info.kind == "friction":
            stops = [cdefs[j] for j in sorted(gaps) if _parallel(gaps[j], K_d)]
            if stops:
                _suspend(sys, c, stops)
            for s in stops:  # released, the contact leaves the friction holding: at rest
                held[s.junction] += [Action("reinit", states[p].name, p, new, c.span)
                                     for p, new in block.items() if p not in moved[s.junction]]
                moved[s.junction] |= set(block)
            loads = [i for i in infos if i.kind == "unilateral" and cdefs[i.junction]
                     .multiplier in set().union(*[g.free_symbols for g in c.gains])]
            relations, discretes, whens = _friction(c, info, block, states, relations,
                                                    discretes, whens, stops, loads, moving)
            for i in loads:  # released, its contact's friction holds nothing
                held[i.junction].append(Action("assign", f"{c.junction}.stick", active(c),
                                               sp.Integer(0), c.span))
            continue
        switch = {"diode": _diode, "switch": _switch}[info.kind]
        relations, discretes, whens = switch(c, info, block, states, relations, discretes,
                                             whens)
    gaps_all = [i for i in infos if i.kind == "unilateral"]
    for info in gaps_all:
        c = cdefs[info.junction]
        J = c.junction
        on = sp.Ne(active(c), 0)
        E = c.restitution if c.restitution is not None else sp.Integer(0)
        v = info.balance  # Phi' in the states
        K_u = dict(weigh(c.balance))
        if not K_u:
            fail(c.name_span, f"unilateral constraint '{J}': its flows are not the velocities "
                              "of I elements in integral causality (an impact moves momenta); "
                              "this is not supported yet")
        fastest = var(f"{J}.vmax")
        speed = sp.Abs(v)
        top = Max(fastest, speed)
        # Phi'' of the free motion (the junction is open at an impact: its lambda is zero):
        # through the momenta by G = K W, and the rest of the states as Phi' reads them
        own = sorted(K_u, key=order.get)
        G_u = sp.Matrix([[K_u[p] for p in own]]) * metric(c, own)
        accel = sp.Add(*[G_u[0, i] * der(p) for i, p in enumerate(own)],
                       *[partial(v, s) * der(s) for s in sorted(
                           (v.free_symbols & states.keys()) - set(own), key=order.get)],
                       partial(v, TIME))
        # a rebound whose apex, (E v)^2 / (2 |Phi''|), the run's tolerance cannot resolve
        low = (E * speed) ** 2 <= -20 * TOLERANCE * accel
        rests = sp.And(v < 0, sp.Or(E * speed <= REST * top, low))
        stays = sp.Piecewise((sp.Integer(1), rests), (sp.Integer(0), True))
        # the rebound's Phi'; resting, none (the contact then closes with Phi' = 0)
        target = sp.Piecewise((sp.Integer(0), rests), (-E * v, v < 0), (v, True))
        together, at = [], [c.multiplier]  # the other gaps on these storages that close
        #                                      at the same instant, and their multipliers
        for o in gaps_all:
            K_o = gaps[o.junction]
            if o is info or not set(K_o) & set(K_u):
                continue
            co = cdefs[o.junction]
            E_o = co.restitution if co.restitution is not None else sp.Integer(0)
            touching = sp.Ne(active(co), 0)
            takes = sp.Or(touching, sp.And(o.phi <= 10 * TOLERANCE, o.balance < 0))
            together.append((o.balance, K_o, sp.Piecewise((sp.Integer(0), touching),
                                                          (-E_o * o.balance, True)), takes))
            at.append(co.multiplier)
        frictions = _tangential(c, at, infos, cdefs, weigh, grouped)
        new_p, moved, G, modes = _impulse(c, v, K_u, target, bilateral, cdefs, weigh, order,
                                          metric, together, frictions, at[1:], define)
        try:  # d Phi''/d lambda: Phi' in the momenta, times each momentum's rate by lambda
            rates = {p: leaf(sys.eqs[der(p)].expr, defs, expandable, memo) for p in moved}
        except (cycle, KeyError):
            fail(c.name_span, f"unilateral constraint '{J}': the forces on its storages could "
                              "not be written in the states (an algebraic loop); not "
                              "supported yet")
        pull = sp.Add(*[G[i] * partial(rates[p], c.multiplier) for i, p in enumerate(moved)])
        for f in frictions:  # (its force mu |lambda|: mu lambda sign(pull), the same wherever
            #                  the contact holds, lambda pushing, and zero where it is open;
            #                  linear, so its block is solved by LU, not by Newton iterations
            #                  across abs's corner)
            if f.of == c.multiplier:
                law = sys.eqs[f.c.multiplier]
                way = sp.sign(pull) if not pull.is_number else sp.Integer(sp.sign(pull))
                sys.add(replace(law, expr=law.expr.xreplace(
                    {sp.Abs(c.multiplier): way * c.multiplier})))
        n = len(relations)
        # an impact: Phi < 0 while closing (Phi' < 0).  Just after one, Phi' > 0 and the
        # relation is false at once, so the next landing is its own crossing even where a
        # fixed step holds the whole flight (Phi < 0 alone stayed true across it)
        touch = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((Min(-info.phi, -v), sp.Not(on)), (sp.Integer(-1), True)), 0),
            f"{J}: contact (phi < 0)", c.name_span, None)
        # a friction of this contact that sticks beyond its cone breaks away first: sliding,
        # the contact may hold (a sleeve jammed on its pole by the friction's moment)
        breaking = sp.Or(*[sp.And(sp.Ne(active(f.c), 0), sp.Abs(f.c.multiplier) > f.c.gains[1])
                           for f in frictions if f.of == c.multiplier])
        leave = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
            sp.Piecewise((-pull * c.multiplier, sp.And(on, sp.Not(breaking))),
                         (sp.Integer(-1), True)), 0),
            f"{J}: release (lambda would pull)", c.name_span, None)
        relations += [touch, leave]
        discretes += [
            Discrete(f"{J}.active", active(c),
                     sp.Piecewise((sp.Integer(1), info.phi <= 0), (sp.Integer(0), True)),
                     "1: in contact", c.name_span),
            Discrete(f"{J}.vmax", fastest, sp.Integer(0), "the largest impact speed so far",
                     c.name_span)]
        slips = tuple(a for f, stick, way in modes for a in (
            Action("assign", f"{f.c.junction}.stick", active(f.c), stick, c.span),
            Action("assign", f"{f.c.junction}.dir", direction(f.c), way, c.span)))
        impact = tuple(Action("reinit", states[p].name, p, new_p[p], c.span) for p in moved) + (
            *slips, Action("assign", f"{J}.active", active(c), stays, c.span),
            Action("assign", f"{J}.vmax", fastest, top, c.span))
        whens += [When(touch.symbol, touch.text, impact, c.span),
                  When(leave.symbol, leave.text,
                       (Action("assign", f"{J}.active", active(c), sp.Integer(0), c.span),
                        *held[J]), c.span)]
    return replace(sys.es, events=(tuple(relations), tuple(squares), tuple(discretes),
                                   tuple(whens)))


def _coupled(sys, group, cdefs, states, leaf, defs, expandable, memo, cycle, weigh, bilateral,
             order, metric, relations, discretes, whens):
    """A group of coupled switches and diodes (bgc.middle.groups): their laws made the group's,
    the switches' modes from their conditions, the diodes' chosen together."""
    def law(m, expr):
        return Equation(m.lam, expr, False, m.c.junction, m.c.span)

    def leaf_rate(s):
        try:
            return leaf(sys.eqs[der(s)].expr, defs, expandable, memo)
        except (cycle, KeyError):
            fail(cdefs[group[0].junction].name_span,
                 "the rates of the storages the coupled switched elements act on could not be "
                 "written in the states (an algebraic loop); not supported yet")

    rates = groups.rate_of(states.keys(), leaf_rate)
    members, every = groups.rewrite(sys, group, cdefs, active, holds, _width,
                                    lambda e: _rate(e, states), law, rates, direction)
    lams = [m.lam for m in members]
    stops = {}
    for m in members:
        K = dict(weigh(m.c.balance))
        if K and not m.dual:
            free = m.B.xreplace({x: sp.Integer(0) for x in lams})
            stops[m.c.junction] = _impulse(m.c, free, K, sp.Integer(0), bilateral, cdefs,
                                           weigh, order, metric)[0]
    for m in members:
        if m.kind == "switch":
            relations, discretes, whens = _switch(m.c, m.info, {}, states, relations,
                                                  discretes, whens)
    return groups.events(sys, members, every, stops, rates, relations, discretes, whens)


def _impulse(c, v, K_v, target, bilateral, cdefs, weigh, order, metric, together=(),
             frictions=(), gaps=(), define=None):
    """The momenta after the impulse that brings row v (its derivatives by the velocities
    K_v) to target while the bilateral rows on the same storages stay at zero, by the least
    change of kinetic energy: with W = M^-1 the velocities' derivatives by the momenta
    (metric), (K W K^T) Lambda = target - rows and dp = K^T Lambda.  together: other gaps'
    rows (row, K, target, whether it takes part): a gap closed at the same instant, or in
    contact, takes part with its own target; else its Lambda is zero.  frictions: the
    friction elements at these contacts (_Tangential), whose tangential impulses take part
    (_frictional); gaps: the together rows' multipliers; define: (c, expr) -> the symbol of
    a new equation of the system computing expr (the frictional impulse's intermediate values,
    computed as steps of the event's update).  {p: new p}, the momenta moved, v's derivatives
    by them (G = K W), and
    the frictions' modes after the impulse ([(stick, dir)], 0/1 and +-1 expressions)."""
    rows = [(v, K_v, target, sp.true)]
    for b in bilateral:
        K_b = dict(weigh(cdefs[b.junction].balance))
        if set(K_b) & set(K_v):
            rows.append((b.balance, K_b, sp.Integer(0), sp.true))
    rows += list(together)
    if len(rows) > MAX_IMPACT_ROWS:
        fail(c.name_span, f"'{c.junction}': {len(rows)} constraint rows take part in its "
                          f"impulse; at most {MAX_IMPACT_ROWS} are supported")
    normal = len(rows)
    index = {c.multiplier: 0}  # each contact's row among the rows
    index.update({lam: normal - len(gaps) + k for k, lam in enumerate(gaps)})
    rows += [(f.row, f.K, sp.Integer(0), rows[index[f.of]][3]) for f in frictions]
    moved = sorted(set().union(*[set(K) for _, K, _, _ in rows]), key=order.get)
    W = metric(c, moved)
    K = sp.Matrix([[Kr.get(p, sp.Integer(0)) for p in moved] for _, Kr, _, _ in rows])
    G = K * W
    m = len(rows)
    A = G * K.T
    rhs = sp.Matrix([t - row for row, _, t, _ in rows])
    for j, (_, _, _, takes) in enumerate(rows):
        if takes is not sp.true:  # a row that does not take part: Lambda_j = 0
            on = sp.Piecewise((sp.Integer(1), takes), (sp.Integer(0), True))
            A[j, :] = on * A[j, :] + (1 - on) * sp.Matrix([[int(k == j) for k in range(m)]])
            rhs[j] = on * rhs[j]
    if frictions:
        impulse, modes = _frictional(c, A, rhs, K, moved, normal, frictions,
                                     [r[3] for r in rows], G * K.T, index, define)
    else:
        impulse, modes = _solve_impulse(c, A, rhs), []
    new_p = {p: p + sp.Add(*[K[k, i] * impulse[k] for k in range(m)])
             for i, p in enumerate(moved)}
    return new_p, moved, [G[0, i] for i in range(len(moved))], modes


@dataclass(frozen=True)
class _Tangential:
    """A friction element at a contact, in that contact's impacts (LANGUAGE 10b): its flow
    (the slip, in the states) and its derivatives by the velocities, its coefficients (its
    forces mu |lambda| sliding, mu0 |lambda| at most sticking, lambda the contact's
    multiplier), and that multiplier."""
    c: object
    row: sp.Expr
    K: dict
    mu: sp.Expr
    mu0: sp.Expr
    of: sp.Symbol


def _frictional(c, A, rhs, K, moved, normal, frictions, takes, A0, index, define):
    """The impulse of a frictional impact (Glocker and Pfeiffer's, at the impulse level):
    each friction row either sticks, its slip zero after the impact and its impulse inside
    the cone |Lambda_t| <= mu0 Lambda_n, or slides the way s it slips after the impact,
    Lambda_t = -s mu Lambda_n (the normal impulse Lambda_n pushes: it raises Phi').  The
    combinations of the rows' modes are enumerated (3^k), sticking before sliding, and the
    first admissible is taken: for one contact some combination always is (mu <= mu0), and at
    a boundary, within rounding, sticking is taken.  The impulse, and the modes [(stick, dir)]
    the frictions leave it in, as 0/1 arithmetic (bgc.middle.groups: exact in every backend).
    Every entry, every elimination's intermediate value and every solution is a step of the
    event's update (define): the work and the code grow as 3^k m^3, not as closed forms'
    nested expressions; with at most MAX_IMPACT_ROWS normal rows, each with its friction,
    that is at most 27 blocks of 6 rows."""
    m, k = A.rows, len(frictions)
    names: dict = {}

    def held(e):  # a step for each entry that is not a number (each computed once)
        if e.is_Number:
            return e
        if e not in names:
            names[e] = define(c, e)
        return names[e]
    Ah = A.applyfunc(held)
    A0h = A0.applyfunc(held)
    bh = rhs.applyfunc(held)
    rows = [held(f.row) for f in frictions]
    widths = [held(_width(f.row)) for f in frictions]
    pieces = []
    for bits in product((groups.STICK, groups.PLUS, groups.MINUS), repeat=k):
        A2, b2 = Ah.copy(), bh.copy()
        for q, (f, bit) in enumerate(zip(frictions, bits)):
            j = normal + q
            if bit != groups.STICK:  # (sliding: its impulse set by the normal one)
                way = 1 if bit == groups.PLUS else -1
                A2[j, :] = sp.Matrix([[int(i == j) for i in range(m)]])
                A2[j, index[f.of]] += way * held(f.mu)
                b2[j] = sp.Integer(0)
        lam = _eliminate(c, A2, b2, define)
        ok = sp.Integer(1)
        for q, (f, bit) in enumerate(zip(frictions, bits)):
            j, n = normal + q, index[f.of]
            if bit == groups.STICK:  # (|Lambda_t| <= mu0 Lambda_n, to rounding)
                mu0 = held(f.mu0)
                cone = define(c, mu0 * lam[n] + 16 * EPS * (Max(lam[j], -lam[j])
                                                          + Max(lam[n], -lam[n]) * mu0))
                ok *= Heaviside(cone - lam[j], 1) * Heaviside(cone + lam[j], 1)
            else:
                way = 1 if bit == groups.PLUS else -1
                after = define(c, rows[q] + sp.Add(*[A0h[j, i] * lam[i] for i in range(m)]))
                ok *= Heaviside(way * after + widths[q] / 2, 1)
        pieces.append((bits, lam, define(c, ok)))
    weights, rest = [], sp.Integer(1)  # (the first admissible: ok times none before it)
    for _, _, ok in pieces:
        weights.append(define(c, rest * ok))
        rest = define(c, rest * (1 - ok))
    stuck = pieces[0][1]  # (none admissible, to rounding: sticking, the boundary's side)
    impulse = [define(c, sp.Add(*[w * lam[i] for w, (_, lam, _) in zip(weights, pieces)],
                                rest * stuck[i])) for i in range(m)]
    modes = []
    for q, f in enumerate(frictions):
        mode, way = active(f.c), direction(f.c)
        stick = sp.Add(*[w for w, (bits, _, _) in zip(weights, pieces)
                         if bits[q] == groups.STICK], rest)
        slide = sp.Add(*[w * (1 if bits[q] == groups.PLUS else -1)
                         for w, (bits, _, _) in zip(weights, pieces)
                         if bits[q] != groups.STICK])
        taking = takes[normal + q]
        on = sp.Integer(1) if taking is sp.true else sp.Piecewise((sp.Integer(1), taking),
                                                                   (sp.Integer(0), True))
        modes.append((f, on * stick + (1 - on) * mode, on * (slide + stick * way)
                      + (1 - on) * way))
    return sp.Matrix(impulse), modes


def _eliminate(c, A, b, define) -> list:
    """The solution of A x = b by Gaussian elimination in the order of the rows, without
    pivoting (the blocks here are K M^-1 K^T's rows, positive definite, and rows of the
    identity), each intermediate value a step (define); a pivot that is zero whatever the
    values is refused."""
    n = A.rows
    M = [[A[i, q] for q in range(n)] + [b[i]] for i in range(n)]
    for k in range(n):
        if M[k][k] == 0:
            fail(c.name_span, f"'{c.junction}': the rows of its frictional impact are not "
                              "independent: the impulse is not determined")
        for i in range(k + 1, n):
            if M[i][k] == 0:
                continue
            r = define(c, M[i][k] / M[k][k])
            M[i] = [define(c, M[i][q] - r * M[k][q]) if q > k else
                    (sp.Integer(0) if q == k else M[i][q]) for q in range(n + 1)]
    x = [sp.Integer(0)] * n
    for k in reversed(range(n)):
        x[k] = define(c, (M[k][n] - sp.Add(*[M[k][q] * x[q] for q in range(k + 1, n)]))
                      / M[k][k])
    return x


def _tangential(c, multipliers, infos, cdefs, weigh, grouped) -> list:
    """The friction elements whose forces are proportional to the normal force of the
    contact c or of a gap that impacts with it (multipliers: theirs): Fr(mu*abs(c.lambda),
    mu0*abs(c.lambda)), Coulomb friction at the contact (LANGUAGE 10b).  Their tangential
    impulses take part in the impact."""
    out = []
    for info in infos:
        if info.kind != "friction":
            continue
        f = cdefs[info.junction]
        read = [lam for lam in multipliers if any(lam in g.free_symbols for g in f.gains)]
        if not read:
            continue
        if len(read) > 1:
            fail(f.span, f"friction '{f.junction}' reads the normal forces of two contacts; "
                         "a frictional contact's forces are proportional to one")
        lam = read[0]
        if info.junction in grouped:
            fail(f.span, f"friction '{f.junction}' at the contact whose multiplier it reads is "
                         "coupled with switches or diodes: its frictional impacts are not "
                         "supported yet")
        mu, mu0 = (_proportional(g, lam) for g in f.gains)
        if mu is None or mu0 is None:
            fail(f.span, f"friction '{f.junction}': at a contact, its forces must be "
                         f"proportional to abs({lam.name}) (Fr(mu*abs({lam.name}), "
                         f"mu0*abs({lam.name}))), for its impulse in an impact")
        K = dict(weigh(f.balance))
        if not K:
            fail(f.span, f"friction '{f.junction}': its flow is not a velocity of I elements "
                         "in integral causality, so an impact of its contact cannot move it")
        out.append(_Tangential(f, info.balance, K, mu, mu0, lam))
    return out


def _proportional(g, lam):
    """k where g = k*abs(lam), k free of lam; else None."""
    size = sp.Dummy("n", nonnegative=True)
    h = sp.expand(g.xreplace({sp.Abs(lam): size}))
    if lam in h.free_symbols:
        return None
    k = sp.diff(h, size)
    if size in k.free_symbols or sp.expand(h - k * size) != 0:
        return None
    return k


def _nonnegative(x) -> sp.Expr:
    """1 where x >= 0, else 0, as arithmetic on sign(x) (-1, 0 or 1): exact, and no
    condition holds x, whose Piecewise pieces (the rows that take part) SymPy would fold."""
    s = sp.sign(x)
    return (s + 1) * (2 - s) / 2


def _solve_impulse(c, A, rhs):
    try:
        return A.LUsolve(rhs)
    except (ValueError, ZeroDivisionError):  # (sympy's NonInvertibleMatrixError included)
        fail(c.name_span, f"'{c.junction}': the constraint rows that take part in its impulse "
                          "are not independent (K M^-1 K^T is singular): the impact's momentum "
                          "change is not determined")


MAX_FIELD_IMPULSE = 3  # a coupled field's M(q) inverted symbolically for an impulse, at most


def _metric(sys, leaf, defs, expandable, memo, cycle):
    """W(c, moved): the velocities' derivatives by the momenta moved (M^-1 on them).  A point
    mass's velocity is written in the momenta; a coupled field's parts solve M(q) v = p
    together (implicit equations, bgc.middle.system), so its block of W is M's inverse, computed
    symbolically for fields of up to MAX_FIELD_IMPULSE parts."""
    flows = {p: (f, sign) for p, f, sign in sys.es.momenta}
    by_flow = {f: p for p, (f, _) in flows.items()}
    dependent: list = []  # (store, the momenta its state follows), on first use

    def coupled_through_dependent(c, moved):
        """Refuse an impulse on momenta that a storage in derivative causality follows: its
        momentum is not a state, so the impulse's metric (the states' M^-1) would leave out
        its inertia.  One momentum moved, followed by that storage alone, is exact (the
        target fixes the one velocity)."""
        if not dependent:
            dependent.append(None)
            for st in sys.es.stores:
                try:
                    e = leaf(st.state, defs, expandable, memo)
                except (cycle, KeyError):
                    continue
                dependent.append((st, e.free_symbols & flows.keys()))
        for entry in dependent[1:]:
            st, follows = entry
            hit = follows & set(moved)
            if hit and (len(follows) > 1 or len(moved) > 1):
                fail(c.name_span, f"'{c.junction}': its impulse moves "
                                  f"{', '.join(sorted(p.name for p in moved))}, whose "
                                  f"velocities the inertia '{st.element}' in derivative "
                                  f"causality follows (its {st.state.name} is not a state): "
                                  "an impulse through a dependent inertia is not supported; "
                                  "write the bodies' inertia as one coupled field I[n](M) in "
                                  "independent coordinates")

    def implicit(p):
        eq = sys.eqs.get(flows[p][0]) if p in flows else None
        return eq if eq is not None and not eq.explicit else None

    def W(c, moved):
        coupled_through_dependent(c, moved)
        index = {p: i for i, p in enumerate(moved)}
        out = sp.zeros(len(moved), len(moved))
        done: set = set()
        try:
            for i, p in enumerate(moved):
                if p in done:
                    continue
                if implicit(p) is None:
                    f, sign = flows[p]
                    velocity = leaf(sign * f, defs, expandable, memo)
                    for k, q in enumerate(moved):
                        out[i, k] = partial(velocity, q)
                    done.add(p)
                    continue
                field, todo = [], [p]  # the field's parts: those its equations couple
                while todo:
                    q = todo.pop()
                    if q in field:
                        continue
                    field.append(q)
                    todo += [by_flow[g] for g in implicit(q).expr.free_symbols
                             if g in by_flow and implicit(by_flow[g]) is not None]
                field.sort(key=lambda q: moved.index(q) if q in index else len(moved))
                if len(field) > MAX_FIELD_IMPULSE:
                    fail(c.name_span, f"'{c.junction}' acts on a coupled inertia field of "
                                      f"{len(field)} parts; an impulse through its M(q) is "
                                      f"computed for fields of up to {MAX_FIELD_IMPULSE} parts")
                M = sp.Matrix(len(field), len(field), lambda a, b: leaf(
                    partial(implicit(field[a]).expr, flows[field[b]][0]) * flows[field[b]][1],
                    defs, expandable, memo))
                inverse = M.inv()
                for a, qa in enumerate(field):
                    for b, qb in enumerate(field):
                        if qa in index and qb in index:
                            out[index[qa], index[qb]] = inverse[a, b]
                done |= set(field)
        except (cycle, KeyError):
            fail(c.name_span, f"'{c.junction}': the velocities of the storages it acts on could "
                              "not be written in the states (an algebraic loop); not supported")
        except ValueError:  # (a singular M: sympy's NonInvertibleMatrixError)
            fail(c.name_span, f"'{c.junction}': the mass matrix of the field it acts on is "
                              "singular")
        return out
    return W


def _closing(sys, c, info, states, order, leaf, defs, expandable, memo, cycle, relations,
             whens, start):
    """A dual switched one-port (a switch that closes a loop of capacitors, a diode across a
    capacitor): when its effort is held at zero (closed, conducting) the storages it joins must
    agree, so their stored quantities jump at once, along the one direction its flow moves
    them, to where its effort is zero: charge is conserved, and the energy that the jump loses
    is what an arc or a tiny resistance would dissipate.  With D the states' rates by its flow
    (the multiplier) and B its effort in the states, the jump is D * Delta with
    Delta = -B / (dB/dx . D): exact for linear storages (one Newton step otherwise).  At the
    start of a run in that mode (start: the mode's condition in the model's own terms), the
    same: an inconsistent start made consistent."""
    J = c.junction
    B = info.balance  # its effort, in the states
    moved = sorted(B.free_symbols & states.keys(), key=order.get)
    try:
        D = {s: partial(leaf(sys.eqs[der(s)].expr, defs, expandable, memo), c.multiplier)
             for s in moved}
    except (cycle, KeyError):
        fail(c.name_span, f"'{J}': the rates of the storages it joins could not be written in "
                          "the states (an algebraic loop); not supported yet")
    slope = sp.Add(*[partial(B, s) * D[s] for s in moved])
    if slope == 0:
        fail(c.name_span, f"'{J}' holds an effort that its own flow cannot change: closed or "
                          "conducting, it would fix the storages it joins, whatever they "
                          "hold; the model is not determined in that mode")
    jump = -B / slope
    n = len(relations)
    closes = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
        sp.Piecewise((sp.Integer(1), holds(c)), (sp.Integer(-1), True)), 0),
        f"{J}: closes (e = 0)", c.name_span, None)
    transfer = tuple(Action("reinit", states[s].name, s, s + D[s] * jump, c.span)
                     for s in moved if D[s] != 0)
    at_start = tuple(Action("reinit", a.name, a.symbol,
                            sp.Piecewise((a.expr, start), (a.symbol, True)), c.span)
                     for a in transfer)
    return relations + [closes], whens + [When(closes.symbol, closes.text, transfer, c.span),
                                          When(INITIAL, f"{J}: the start", at_start, c.span)]


def _dual_diode(c, info, block, states, relations, discretes, whens):
    """The ideal diode as the dual junction (it imposes its flow, the multiplier; its effort,
    the balance, is written in the states): blocking (`D.blocking` = 1), its flow zero; it
    starts to conduct where its effort would turn positive, and conducting, its effort held at
    zero (_closing), it blocks where its flow would turn negative."""
    J = c.junction
    blocking = sp.Ne(active(c), 0)
    n = len(relations)
    forward = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
        sp.Piecewise((info.balance, blocking), (sp.Integer(-1), True)), 0),
        f"{J}: forward (e > 0)", c.name_span, None)
    reverse = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
        sp.Piecewise((-c.multiplier - _width(c.multiplier), sp.Not(blocking)),
                     (sp.Integer(-1), True)), 0), f"{J}: reverse (f < 0)", c.name_span, None)
    mode = Discrete(f"{J}.blocking", active(c),
                    sp.Piecewise((sp.Integer(0), info.balance > 0), (sp.Integer(1), True)),
                    "1: blocking, 0: conducting", c.name_span,
                    sp.Piecewise((sp.Integer(0), forward.symbol), (sp.Integer(1), reverse.symbol),
                                 (active(c), True)))
    return relations + [forward, reverse], discretes + [mode], whens


def _diode(c, info, block, states, relations, discretes, whens):
    """The ideal diode's mode, `D.active` (1: blocking, its flow held at zero by its
    multiplier, the effort; 0: conducting, its effort zero).  A mode, not a when-block: after
    each pass of the event iteration it blocks where its flow would turn negative and conducts
    where its effort would turn positive, so that the start takes whichever mode the state
    calls for (where e = f = 0 both are right: it starts blocking)."""
    J = c.junction
    blocking = sp.Ne(active(c), 0)
    n = len(relations)
    forward = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
        sp.Piecewise((c.multiplier, blocking), (sp.Integer(-1), True)), 0),
        f"{J}: forward (e > 0)", c.name_span, None)
    # (reverse below its width: at the start of conduction the flow is zero to rounding)
    reverse = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
        sp.Piecewise((-info.balance - _width(info.balance), sp.Not(blocking)),
                     (sp.Integer(-1), True)), 0), f"{J}: reverse (f < 0)", c.name_span, None)
    mode = Discrete(f"{J}.blocking", active(c),
                    sp.Piecewise((sp.Integer(0), info.balance > 0), (sp.Integer(1), True)),
                    "1: blocking, 0: conducting", c.name_span,
                    sp.Piecewise((sp.Integer(0), forward.symbol), (sp.Integer(1), reverse.symbol),
                                 (active(c), True)))
    # blocking, the storages that carried its flow take the state that stops it: when it
    # blocks, and at the start where it starts blocking
    transfer = When(reverse.symbol, reverse.text, tuple(
        Action("reinit", states[p].name, p, new, c.span) for p, new in block.items()), c.span)
    return relations + [forward, reverse], discretes + [mode], \
        whens + [transfer, _at_start(c, transfer, blocking)]


def _at_start(c, transfer: When, mode) -> When:
    """transfer's jumps at the start, where the element starts in the mode that needs them
    (mode: its condition on the element's discrete value, read at t0): the initial state made
    consistent with the initial mode (docs/hybrid.md, section 4)."""
    return When(INITIAL, f"{c.junction}: the start", tuple(
        replace(a, expr=sp.Piecewise((a.expr, mode), (a.symbol, True)))
        for a in transfer.actions), c.span)


def _switch(c, info, stop, states, relations, discretes, whens):
    """The ideal switch `Sw(COND)`: closed (effort zero) while COND holds, open (flow zero,
    its effort the multiplier) otherwise; its mode `S.open` follows COND after each pass of
    the event iteration.  Opening, the storages that carried its flow take the state that
    stops it (an inductor's current falls to zero at once)."""
    J = c.junction
    cond = c.gains[0]
    mode = Discrete(f"{J}.open", active(c),
                    sp.Piecewise((sp.Integer(0), cond), (sp.Integer(1), True)),
                    "1: open, 0: closed", c.name_span,
                    sp.Piecewise((sp.Integer(0), cond), (sp.Integer(1), True)))
    opening = []
    if stop:  # (a resistive path has no storages to stop)
        n = len(relations)
        flows = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
            sp.Piecewise((sp.Integer(1), sp.Ne(active(c), 0)), (sp.Integer(-1), True)), 0),
            f"{J}: opens", c.name_span, None)
        relations = relations + [flows]
        opens = When(flows.symbol, flows.text, tuple(
            Action("reinit", states[p].name, p, new, c.span) for p, new in stop.items()),
            c.span)
        opening = [opens, _at_start(c, opens, sp.Ne(active(c), 0))]
    return relations, discretes + [mode], whens + opening


def _parallel(a: dict, b: dict) -> bool:
    """Whether two rows, {momentum: coefficient}, hold the same velocity (one a multiple of
    the other): then, both active, their multipliers share one load."""
    if not a or set(a) != set(b):
        return False
    first = min(a, key=lambda p: p.name)
    return all(sp.expand(a[p] * b[first] - b[p] * a[first]) == 0 for p in a)


def _suspend(sys, c, stops):
    """Dry friction on storages that a unilateral junction also holds (a motor pressed against
    its end stop): while a contact is closed the velocity is held by the contact, and both
    multipliers would carry the same load, indeterminate between them.  The friction's
    sticking row is then suspended (its force zero, the contact takes the load); when the
    contact releases, the row holds again, and the friction sticks or breaks away as the
    load then says."""
    law = sys.eqs[c.multiplier]
    closed = sp.Or(*[sp.Ne(active(s), 0) for s in stops])
    (row, stick), (free, _) = law.expr.args
    sys.add(replace(law, expr=sp.Piecewise((c.multiplier, sp.And(stick, closed)),
                                           (row, stick), (free, True))))


def _friction(c, info, stop, states, relations, discretes, whens, stops=(), loads=(),
              moving=None):
    """Dry friction `Fr(Fc, Fs)`: its mode `F.stick` (1: sticking, its flow held at zero, its
    effort the multiplier; 0: sliding, effort Fc times its direction `F.dir`, +1 or -1).
    Sliding, it sticks where its flow reverses continuously (below its width, _width), the
    storages then taking the state that stops it; where the flow jumps across zero (an
    impact's rebound) it slides on the other way.  Sticking, it breaks away where the force
    that holds it exceeds Fs, and slides the way that force pushes.  While a unilateral
    junction on the same storages (stops) is closed it sticks, suspended (_suspend).  The
    multiplier's law while sliding is lambda = Fc dir, from the constraint junction's
    (bgc.middle.reduce).  loads: the contacts (unilateral junctions' infos) whose normal
    forces its forces are proportional to (LANGUAGE 10b): while one is open the friction
    carries no force and does not stick where its flow reverses (two frictions of one body
    would otherwise both hold it, their rows dependent); its contact's impacts set its mode,
    its contact's release frees it.  moving: the symbols whose rates the run computes (the
    states and a coupled field's flows), for the reversal's resolution."""
    J = c.junction
    Fc, Fs = c.gains
    stick = sp.Ne(active(c), 0)
    loaded = sp.And(*[sp.Ne(active(i), 0) for i in loads]) if loads \
        else sp.true
    way = var(f"{J}.dir")
    n = len(relations)
    width = _width(info.balance)
    slows = Relation(sp.Symbol(f"event#{n}"), sp.StrictGreaterThan(
        sp.Piecewise((-way * info.balance - width, sp.And(sp.Not(stick), loaded)),
                     (sp.Integer(-1), True)), 0), f"{J}: stops (f reverses)", c.name_span, None)
    breaks = Relation(sp.Symbol(f"event#{n + 1}"), sp.StrictGreaterThan(
        sp.Piecewise((sp.Abs(c.multiplier) - Fs, stick), (sp.Integer(-1), True)), 0),
        f"{J}: breaks away (|e| > Fs)", c.name_span, None)
    # a located reversal leaves |f| at the width, plus what the crossing's location in t
    # leaves of it (its resolution, relative to t, times |f'|): ten times the width and
    # twice that cover it; a rebound leaves |f| far above
    crept = sp.Abs(info.balance) <= 10 * width + 2 * LOCATED * sp.Abs(TIME) * sp.Abs(
        _rate(info.balance, states if moving is None else moving))
    closed = [sp.Ne(active(s), 0) for s in stops]
    mode = Discrete(f"{J}.stick", active(c),
                    sp.Piecewise((sp.Integer(1), sp.Or(sp.And(sp.Eq(info.balance, 0),
                                                              *[i.phi <= 0 for i in loads]),
                                                       *closed)),
                                 (sp.Integer(0), True)),
                    "1: sticking, 0: sliding", c.name_span,
                    sp.Piecewise(*[(sp.Integer(1), on) for on in closed],
                                 (sp.Integer(0), breaks.symbol),
                                 (sp.Integer(1), sp.And(slows.symbol, crept)),
                                 (active(c), True)))
    direction = Discrete(f"{J}.dir", way,
                         sp.Piecewise((sp.Integer(-1), info.balance < 0), (sp.Integer(1), True)),
                         "the sliding direction", c.name_span,
                         sp.Piecewise((sp.sign(c.multiplier), breaks.symbol),
                                      (-way, slows.symbol), (way, True)))
    transfer = When(slows.symbol, slows.text, tuple(
        Action("reinit", states[p].name, p, sp.Piecewise((new, crept), (p, True)), c.span)
        for p, new in stop.items()), c.span)
    return relations + [slows, breaks], discretes + [mode, direction], whens + [transfer]
