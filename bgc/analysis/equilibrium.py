"""`bgc steady`: an equilibrium of a model, dx/dt = 0, by Newton's method on the generated
right side with the Jacobian the compiler derives (bgc.analysis.operating).

The unknowns are the states at a time t (below); the equations are the right side and
the constraint rows (a holonomic constraint's position and velocity rows, a nonholonomic
one's velocity row), stacked.  With a Baumgarte corrector dx/dt = 0 already implies them; a
constraint without a corrector leaves its position undetermined, and the stacked rows fix it.
Algebraic blocks are solved inside the right side as in a run.

Each step is the least-squares (minimum-norm) solution of J dx = -F, damped by halving until
|F| decreases; the linear algebra is bgc.symbolic.orthogonal's, whose sums run in sequence, so an
equilibrium has the same bytes on every machine.  Where the Jacobian is singular, the equilibria
form a family (a free mass rests anywhere): the minimum-norm steps give the one nearest the initial
state, and the result says how many directions are free.  Where no step reduces |F| while |F| is
not small (a mass under a constant force), there is no equilibrium near the start: NoEquilibrium,
naming the state whose rate stays largest.

Events (bgc.front.events).  The right side reads discrete values that a run freezes between events:
its relations, time sources, modes and discrete variables.  They start as the scene's run
starts (its event iteration at (t0, x0): initial() true, the discrete variables at their
initial values), then the time sources are evaluated at a time t (the scene's start, or the
one asked: `--at t=T`; a when-block that makes fire is refused, as below).  An equilibrium must
stay from t on, so a model whose time sources are not constant from t on is refused (Driven),
located at each source: a time event still to come (a step, a pulse's start or end, a square wave's
edge, a table's breakpoint, the next crossing of sin(t) > 0.5), a law that reads t once the
discrete values are put in (sin(t), ramp), a table of t whose piece is not constant, a relation of
t whose crossings bgc cannot find.  The relations of the states are held during Newton's method and
then evaluated at its result: where they give other modes, Newton's method runs again in those
(`c.q < 1` holds at the start and not at the rest it gives), and modes that come back are refused,
the conditions that switch named (a relay: no equilibrium, the model slides).  A when-block that
the event iteration at t or at the result fires (its condition rose between the start and there)
would have fired on the way, so the discrete values are not the ones held: refused at the
when-block.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import sympy as sp

from .. import api, ir
from ..front import events
from . import operating
from ..symbolic import orthogonal
from ..base.diagnostics import Diagnostic, ModelError
from ..front.graph import TIME
from .operating import AnalysisArgumentError, AnalysisError

TOLERANCE = 1e-10  # each row's |F| relative to its terms' magnitudes (_scale)
MAX_ITERATIONS = 100
MAX_MODES = 20  # rounds of Newton's method, each in the modes the last one's point gives


class NoEquilibrium(AnalysisError):
    """Newton's method found no equilibrium (the message says why)."""


class Driven(api.BgcModelError, NoEquilibrium):
    """No equilibrium by the model's own text: time sources that are not constant from the
    time asked, a when-block that fires on the way, modes that switch at every candidate;
    str() is the located report (the model's errors' format)."""


@dataclass(frozen=True)
class Equilibrium:
    t: float
    states: tuple[tuple[str, float], ...]
    multipliers: tuple[tuple[str, float], ...]
    constraint_residuals: tuple[tuple[str, float], ...]
    residual: float  # max |dx/dt| at the equilibrium
    iterations: int
    free: int  # directions along which the equilibria form a family (the Jacobian's nullity)
    sources: tuple[str, ...] = ()  # the time sources evaluated at t, as written

    def lines(self) -> str:
        """`NAME = VALUE`, one a line: the states, the multipliers, the constraints'
        residuals, then the residual max |dx/dt|."""
        rows = self.states + self.multipliers + self.constraint_residuals + \
            (("residual", self.residual),)
        return "".join(f"{name} = {value:.17g}\n" for name, value in rows)

    def as_dict(self) -> dict:
        return {"t": self.t, "states": dict(self.states), "multipliers": dict(self.multipliers),
                "constraint_residuals": dict(self.constraint_residuals),
                "residual": self.residual, "iterations": self.iterations, "free": self.free}


def _system(ev: operating.Evaluator, t: float, x):
    """F(x) (the right side, then the constraint rows) and its Jacobian."""
    f = ev.rhs(t, x)
    if not ev.constraints:
        return f, None
    G, r = ev.constraint_rows(t, x)
    return np.concatenate([f, r]), G


def _residual(ev, t, x):
    try:
        F, _ = _system(ev, t, x)
    except AnalysisError:
        return None
    return F if np.all(np.isfinite(F)) else None


def solve(ev: operating.Evaluator, x0=None, t=None) -> Equilibrium:
    """The equilibrium nearest x0 (default: the scene's initial state) with the time
    sources at t (default: the scene's start), as the module's doc says; NoEquilibrium,
    Driven."""
    t = ev.t0 if t is None else float(t)
    x = ev.initial() if x0 is None else np.asarray(x0, dtype=float).copy()
    x = ev.settle(ev.t0, x, start=True)  # as the scene's run starts: d at (t0, x0)
    if t != ev.t0:  # the time sources at t: a when-block they make fire is refused
        before = ev.discrete_values()
        _refuse(ev, _fired(ev, x, ev.settle(t, x, start=False), before, t))
    _refuse(ev, _driven(ev, t, x))
    seen = [ev.discrete_values()]
    for _ in range(MAX_MODES):
        x, J, it = _newton(ev, t, x)
        before = ev.discrete_values()
        after = ev.settle(t, x, start=False)
        _refuse(ev, _fired(ev, x, after, before, t))
        now = ev.discrete_values()
        if now == before:
            _refuse(ev, _driven(ev, t, x))
            return _result(ev, t, x, J, it)
        if now in seen:
            break
        seen.append(now)
    _refuse(ev, _switching(ev, seen))
    raise NoEquilibrium(f"the modes did not settle in {MAX_MODES} rounds of Newton's method")


def _newton(ev, t, x):
    """Newton's method from x, the discrete values held: (x, J, iterations).  Every decision
    is relative, so that a model's units do not move it: a row of F is small against the
    magnitudes of its terms (_scale), steps and ranks are those of the equilibrated Jacobian
    (_equilibrated), and the line search measures F in the rows' own units."""
    F = _residual(ev, t, x)
    if F is None:
        raise NoEquilibrium(f"the right side is not finite at the initial state (t = {t:g})")
    goal = np.zeros(len(F))
    for it in range(MAX_ITERATIONS + 1):
        J = _jacobian(ev, t, x)
        goal = np.maximum(goal, TOLERANCE * _scale(F, J, x))
        if np.all(np.abs(F) <= goal):
            return (*_polish(ev, t, x, F, J), it)
        if it == MAX_ITERATIONS:
            break
        dx, rows, cols = _step(ev, J, F, x)
        if _converged(J, F, x, dx, cols):
            Ft = _residual(ev, t, x + dx)
            if Ft is not None:
                x, F = x + dx, Ft
            return (*_polish(ev, t, x, F, _jacobian(ev, t, x)), it + 1)
        step, norm = 1.0, orthogonal.norm(rows * F)
        while step >= 1e-8:
            trial = x + step * dx
            Ft = _residual(ev, t, trial)
            if Ft is not None and orthogonal.norm(rows * Ft) < (1 - 1e-4 * step) * norm:
                x, F = trial, Ft
                break
            step /= 2
        else:
            raise NoEquilibrium(_why(ev, x, F, J, it))
    raise NoEquilibrium(f"Newton's method did not converge in {MAX_ITERATIONS} iterations "
                        f"(max |dx/dt| = {np.abs(F[:ev.n]).max():.3g})")


def _scale(F, J, x):
    """Each row's magnitude of terms at x: |F - J x| + |J| |x| (for an affine F = A x + b,
    |b| plus the magnitudes of A's terms, which cancel at an equilibrium)."""
    with np.errstate(all="ignore"):  # (inf where the terms' magnitudes exceed double's)
        Jx = J * x[None, :]
        return np.abs(F - orthogonal.total(Jx, axis=1)) + orthogonal.total(np.abs(Jx), axis=1)


def _equilibrated(J):
    """(rows, cols): integer exponents such that J * 2^(rows_i + cols_j) has each row's and
    each column's largest magnitude near 1 (Ruiz's scaling, in powers of two, found on the
    entries' exponents so that nothing under- or overflows on the way), so that a row or a
    state in small or large units weighs as the others in a step and a rank."""
    e = np.where(J != 0.0, np.frexp(J)[1], -(1 << 20)).astype(np.int64)
    rows = np.zeros(J.shape[0], dtype=np.int64)
    cols = np.zeros(J.shape[1], dtype=np.int64)
    for _ in range(64):
        r = (e + rows[:, None] + cols[None, :]).max(axis=1, initial=-(1 << 20))
        c = (e + rows[:, None] + cols[None, :]).max(axis=0, initial=-(1 << 20))
        r = np.where(r > -(1 << 19), r, 0)
        c = np.where(c > -(1 << 19), c, 0)
        if not (np.any(np.abs(r) > 1) or np.any(np.abs(c) > 1)):
            break
        rows -= r // 2
        cols -= c // 2
    both = np.concatenate([rows, -cols])  # rows + k, cols - k scale as well: centred
    k = -(int(both.max(initial=0)) + int(both.min(initial=0))) // 2
    return np.clip(rows + k, -1000, 1000), np.clip(cols - k, -1000, 1000)


def _scaled(J, rows, cols):
    with np.errstate(all="ignore"):
        return np.ldexp(J, rows[:, None] + cols[None, :])


def _rank(J) -> int:
    return orthogonal.rank(_scaled(J, *_equilibrated(J)))


def _solve(J, F):
    """The Newton step of least norm in the equilibrated units, and the exponents."""
    rows, cols = _equilibrated(J)
    with np.errstate(all="ignore"):
        y = orthogonal.lstsq(_scaled(J, rows, cols), -np.ldexp(F, rows))[0]
        return np.ldexp(y, cols), rows, cols


def _step(ev, J, F, x):
    """The Newton step, the rows' weights and the columns' scales; NoEquilibrium where the
    step overflows: the equilibrium is beyond double's range."""
    dx, rows, cols = _solve(J, F)
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(x + dx))
    if not finite:
        raise NoEquilibrium(f"no equilibrium bgc steady can compute: Newton's step from "
                            f"{_where(ev, x)} leaves the range of double (about 1.8e308)")
    return dx, np.ldexp(1.0, rows), np.ldexp(1.0, cols)


def _converged(J, F, x, dx, cols) -> bool:
    """Whether x is an equilibrium to the last digits its rows can resolve, though a row's
    |F| is not small against its terms (a row of one term, p/L, at the rounding left by the
    others): the step solves the linearisation (J dx = -F to rounding in every row) and is
    small in the equilibrated units (|dx / cols| against the largest |x / cols|)."""
    with np.errstate(all="ignore"):
        Jdx = J * dx[None, :]
        linear = np.abs(F + orthogonal.total(Jdx, axis=1))
        solves = np.all(linear <= 1e-8 * (np.abs(F) + orthogonal.total(np.abs(Jdx), axis=1)))
        size = np.abs(x / cols).max(initial=0.0)
        return bool(solves and np.abs(dx / cols).max(initial=0.0) <= TOLERANCE * size)


def _polish(ev, t, x, F, J):
    """Up to three more full steps, each kept while it reduces |F| (Newton's method doubles
    the digits of a converged solution at each step): (x, J)."""
    for _ in range(3):
        dx, rows, _ = _solve(J, F)
        trial = x + dx
        Ft = _residual(ev, t, trial)
        if Ft is None or not orthogonal.norm(np.ldexp(Ft, rows)) < \
                orthogonal.norm(np.ldexp(F, rows)):
            break
        x, F, J = trial, Ft, _jacobian(ev, t, trial)
    return x, J


def _jacobian(ev, t, x) -> np.ndarray:
    J = ev.jacobian(t, x)
    if ev.constraints:
        J = np.vstack([J, ev.constraint_rows(t, x)[0]])
    if not np.all(np.isfinite(J)):
        raise NoEquilibrium(f"the Jacobian is not finite at {_where(ev, x)}")
    return J


def _why(ev, x, F, J, it) -> str:
    k = int(np.argmax(np.abs(F)))
    what = f"d({ev.states[k]})/dt = {F[k]:.6g}" if k < ev.n else \
        f"the residual of constraint row {ev.constraint_names()[k - ev.n]} = {F[k]:.6g}"
    rank = _rank(J)
    return (f"no equilibrium: after {it} Newton iterations no step reduces the right side, "
            f"which stays at {what} (the Jacobian has rank {rank} of {ev.n}: a state that "
            "integrates a nonzero constant, such as a free mass under a constant force, has "
            "no equilibrium)")


def _where(ev, x) -> str:
    return ", ".join(f"{s} = {v:.6g}" for s, v in zip(ev.states, x))


def _result(ev, t, x, J, it) -> Equilibrium:
    y = ev.outputs(t, x)
    outs = ev.all_outputs
    mult = tuple((name, float(y[outs.index(name)])) for name in ev.analysed.multipliers)
    res = tuple((name, float(y[outs.index(name)])) for name in ev.analysed.residuals)
    f = ev.rhs(t, x)
    return Equilibrium(float(t), tuple(zip(ev.states, (float(v) for v in x))), mult, res,
                       float(np.abs(f).max(initial=0.0)), it,
                       ev.n - _rank(J), time_sources(ev))


def parse_at(at, t0: float) -> float:
    """The time of `at`: None (the scene's start t0), "t=T" or a number T, not before t0;
    ValueError (AnalysisArgumentError before t0) for anything else."""
    if at is None:
        return t0
    if isinstance(at, (int, float)) and not isinstance(at, bool):
        T = float(at)
    elif isinstance(at, str) and at.strip().startswith("t="):
        try:
            T = float(at.strip()[2:])
        except ValueError:
            T = math.nan
    else:
        raise ValueError(f"--at expects t=TIME, got {at!r}")
    if not math.isfinite(T):
        raise ValueError(f"--at t=TIME: {at!r} is not a finite time")
    if T < t0:
        raise AnalysisArgumentError(f"--at t={T:g} is before the scene's start t0 = {t0:g}")
    return T


def steady(model, scene=None, params=None, effects=None, algebra="auto",
           at=None) -> Equilibrium:
    """An equilibrium of model's scene (bgc.steady; see the module's doc); effects replace
    the scene's, algebra as bgc.build's; at: "t=T" or a number T, the time the time sources
    are evaluated at (default: the scene's start)."""
    analysed = operating.build(model, scene, None, effects, None, algebra)
    ev = operating.Evaluator(analysed, params)
    return solve(ev, t=parse_at(at, ev.t0))


# ---------------------------------------------------------------- what is not constant
# An equilibrium x* at t is a state that stays: the right side at x* is zero at every time
# from t on.  So every time source must be constant from t on (no time event to come, no law
# that reads t), and the discrete values must be those a run holds at x* (the modes the
# relations give there), without a when-block that would have fired on the way.


def _refuse(ev, diagnostics) -> None:
    """Driven, with the diagnostics and the sentence that says what follows, if any."""
    if diagnostics:
        raise Driven(ModelError(diagnostics), ev.analysed.compiled.source)


def time_sources(ev) -> tuple[str, ...]:
    """The time sources of ev's model, as written: its time relations (step, pulse, `t >= 1`),
    square waves, tables of t, and relations of t whose crossings are known."""
    sel = ev.events
    if sel is None:
        return ()
    names = [r.text for r, _, _ in sel.time]
    names += [s.text for s in sel.squares if s.kind in ("square", "table")]
    names += [r.text for r in sel.state if r.relation.has(TIME)]
    return tuple(dict.fromkeys(names))


def _driven(ev, t: float, x) -> list[Diagnostic]:
    """A located error per time source that is not constant from t on (the discrete values
    ev holds are those at (t, x)), then the sentence that says what follows; [] if none."""
    found: dict = {}  # span -> its error (the first said of a source)
    sel = ev.events
    if sel is not None:
        first: dict = {}  # source -> its first time event after t
        for (_, source), tau in zip(events.timers(sel), ev.next_times(t, x)):
            if tau > t and math.isfinite(tau) and tau < first.get(source, math.inf):
                first[source] = tau
        for source, tau in first.items():
            found.setdefault(source.span, _error(
                source.span, f"'{source.text}' changes at t = {tau:.6g}, after t = {t:.6g}"))
        known = dict(sel.crossings)
        for r in sel.state:
            if r.relation.has(TIME) and known.get(r.symbol) is None:
                found.setdefault(r.span, _error(
                    r.span, f"'{r.text}' reads t: bgc cannot tell whether it changes after "
                            f"t = {t:.6g}"))
    for d in _reading_t(ev, t):
        found.setdefault(d.span, d)
    if not found:
        return []
    out = sorted(found.values(), key=lambda d: (d.span is None, _position(d.span)))
    return out + [_error(None, f"no equilibrium: the model is driven by time sources that are "
                               f"not constant from t = {t:.6g} on (bgc steady evaluates them "
                               "there, --at t=T at another time); simulate it to see where "
                               "it goes, or find its periodic orbit with bgc periodic where "
                               "the sources are periodic")]


def _position(span) -> tuple:
    return () if span is None else (span.origin is not None, span.line, span.col)


def _error(span, message, *notes) -> Diagnostic:
    return Diagnostic("error", span, message, tuple(notes))


def _slot_values(ev) -> dict:
    """Each discrete value's model symbol -> its value in ev (a relation's as a boolean)."""
    values = {}
    for sym, v in zip(ev.events.slots(), ev.discrete_values()):
        values[sym] = sp.Float(v) if not sym.name.startswith("event#") else \
            sp.true if v != 0 else sp.false
    return values


def _reading_t(ev, t: float) -> list[Diagnostic]:
    """A located error per law the right side (or a constraint row) reads t in, once the
    discrete values are put in (an input without data has slope 0, a step that has come is
    1), and per table of t whose piece at t is not constant."""
    compiled = ev.analysed.compiled
    reduced = compiled.reduced
    values = _slot_values(ev) if ev.events is not None else {}
    results = [ir.Store(k, r) for k, r in enumerate(reduced.rates)]
    results += [ir.Store(len(results) + k, r.expr) for k, r in enumerate(reduced.rows)]
    where = {e.target: e.span for e in compiled.system.equations}
    tables = {s.index: s for s in (ev.events.squares if ev.events else ())
              if s.kind == "table"}
    out: dict = {}
    for s in ir.prune(tuple(reduced.steps) + tuple(results)):
        exprs = ir.expressions(s) + (ir.inner_expressions(s) if isinstance(s, ir.Newton)
                                     else [])
        for e in exprs:
            if not e.has(TIME):
                continue
            e = e.xreplace(values)
            for k in _varying_tables(e, reduced.tables):
                source = tables.get(k)
                if source is not None:
                    out.setdefault(source.span, _error(
                        source.span, f"'{source.text}' varies from t = {t:.6g} on (the piece "
                                     "of its data there is not constant)"))
            e = e.replace(lambda a: isinstance(a, ir.Table) and a.args[1].has(TIME),
                          lambda a: sp.Integer(0))
            if e.has(TIME):
                span = _span_of(s, where, reduced)
                out.setdefault(span, _error(span, f"{_what(s, compiled)} reads t: it is not "
                                                  f"constant from t = {t:.6g} on"))
    return list(out.values())


def _varying_tables(e, tables) -> list[int]:
    """The tables of t in e whose piece (a number now) is not a constant polynomial."""
    out = []
    for a in e.atoms(ir.Table):
        k, X, piece, order = a.args
        if not X.has(TIME):
            continue
        if not piece.is_number:
            out.append(int(k))
            continue
        data = tables[int(k)]
        c = data.coefficients[4 * int(piece):4 * int(piece) + 4]
        if any(v != 0 for v in c[int(order) + 1:]):
            out.append(int(k))
    return out


def _span_of(s, where, reduced):
    """The span of the law a right side's statement comes from."""
    targets = ir.defines(s)
    for target in targets:
        if target in where:
            return where[target]
    if isinstance(s, ir.Store):
        n = len(reduced.rates)
        if s.index < n:
            return reduced.states[s.index].span
        row = reduced.rows[s.index - n]
        for c in reduced.constraints:
            if c.junction == row.junction:
                return c.span
    return None


def _what(s, compiled) -> str:
    """What a statement computes, for a message: the element or signal its law is of."""
    origin = {e.target: e.origin for e in compiled.system.equations}
    for target in ir.defines(s):
        if target in origin:
            return f"'{origin[target]}'"
    return "the model"


def _slot_sources(sel) -> list:
    """(text, span) of each discrete value, in the order of d (Selected.slots)."""
    return [(r.text, r.span) for r in sel.state] + [(r.text, r.span) for r, _, _ in sel.time] \
        + [(r.text, r.span) for r in sel.discrete] + [(q.text, q.span) for q in sel.squares] \
        + [(d.name, d.span) for d in sel.discretes]


def _fired(ev, x, after, before, t) -> list[Diagnostic]:
    """The when-blocks that the event iteration at (t, x) fired (a reinit moved the state,
    or a discrete variable changed): each condition rose between the scene's start and
    there, so a run would have fired it on the way, and the discrete values at the
    equilibrium are not the ones held.  [] if none."""
    sel = ev.events
    if sel is None:
        return []
    moved = {st.symbol for st, a, b in zip(ev.analysed.compiled.reduced.states, after, x)
             if a != b}
    now = ev.discrete_values()
    first = ev.discrete - len(sel.discretes)
    moved |= {sel.discretes[k - first].symbol for k in ev.held if now[k] != before[k]}
    out = [_error(w.span, f"'when {w.text}' would fire on the way from the start (t = "
                          f"{ev.t0:.6g}) to the equilibrium at t = {t:.6g}: its condition "
                          "holds there and not at the start")
           for w in sel.whens if any(a.symbol in moved for a in w.actions)]
    if not out:
        return []
    return out + [_error(None, "no equilibrium bgc steady can vouch for: the discrete values "
                               "at it follow from the run's events; simulate the model to see "
                               "where it goes")]


def _switching(ev, seen) -> list[Diagnostic]:
    """The conditions whose values differ between the rounds of Newton's method that came
    back to modes already tried: at each candidate they switch to a mode whose equilibrium
    switches them back (a relay, a model that chatters or slides on the switching surface)."""
    sources = _slot_sources(ev.events)
    changed = [k for k in range(ev.discrete) if len({d[k] for d in seen}) > 1]
    out = [_error(sources[k][1], f"'{sources[k][0]}' switches at every candidate "
                                 "equilibrium") for k in changed]
    return out + [_error(None, "no equilibrium: in each mode the conditions give, Newton's "
                               "method ends where they give another (the model switches or "
                               "slides there); simulate it to see where it goes")]
