"""Forward differentiation of one expression: the hot path of the symbolic work.

`directional(expr, tangents)` is the derivative of expr along the direction that gives each
symbol s the tangent `tangents[s]` (symbols not in the map have tangent zero): one bottom-up
pass over the expression tree, with the sum, product, power and chain rules, building only
the nonzero parts.  `partial(expr, s)` is the special case {s: 1}.

SymPy's `diff` goes through `Derivative` and costs about 0.6 ms for a two-term product; this
costs what building the result costs (a measured 20x less), which decides whether a model of
thousands of equations differentiates in a second or in a minute.  The pass keeps its own stack:
it does not recurse however deep the expression is.

`tangent(function, ...)` is the same forward mode over a program's statements (bgc.ir): every
derivative the generated code computes that is not a block's own Jacobian comes from it — the
right side's J*v (`jvp`), and the outputs' derivative along v for an FMU's directional
derivatives (bgc.lower.with_tangent).
"""
from __future__ import annotations

from dataclasses import replace

import sympy as sp

from . import ir

ZERO = sp.S.Zero
_PIECEWISE_CONSTANT = (sp.sign, sp.Heaviside)  # derivative zero almost everywhere


def directional(expr: sp.Expr, tangents: dict) -> sp.Expr:
    """d expr along the direction; DiracDelta terms (from sign/abs/Heaviside) are dropped."""
    if not tangents:
        return ZERO
    done: dict = {}
    stack = [(expr, False)]
    while stack:
        e, ready = stack.pop()
        if e in done:
            continue
        if e.is_Symbol or e.is_Indexed:
            done[e] = tangents.get(e, ZERO)
            continue
        if e.is_Atom or not e.args:
            done[e] = ZERO
            continue
        if not ready:
            stack.append((e, True))
            stack.extend((a, False) for a in e.args if a not in done)
            continue
        done[e] = _rule(e, [done[a] for a in e.args])
    return done[expr]


def partial(expr: sp.Expr, symbol) -> sp.Expr:
    return directional(expr, {symbol: sp.S.One})


def _rule(e, d):
    args = e.args
    if all(x == 0 for x in d):
        return ZERO
    if e.is_Add:
        return sp.Add(*[x for x in d if x != 0])
    if e.is_Mul:
        terms = []
        for k, dk in enumerate(d):
            if dk != 0:
                terms.append(sp.Mul(*(args[:k] + (dk,) + args[k + 1:])))
        return sp.Add(*terms)
    if e.is_Pow:
        base, exp = args
        db, dx = d
        out = ZERO
        if db != 0:
            out = exp * base ** (exp - 1) * db
        if dx != 0:
            out = out + e * sp.log(base) * dx
        return out
    if isinstance(e, _PIECEWISE_CONSTANT):
        return ZERO
    if hasattr(e, "fdiff"):  # functions, Min and Max
        terms = []
        for k, dk in enumerate(d):
            if dk != 0:
                f = e.fdiff(k + 1)
                if f.has(sp.DiracDelta):
                    f = f.replace(lambda a: isinstance(a, sp.DiracDelta), lambda a: ZERO)
                if f.has(sp.Derivative):
                    raise TypeError(f"no derivative known for {e}")  # pragma: no cover
                if f != 0:
                    terms.append(f * dk)
        return sp.Add(*terms)
    raise TypeError(f"cannot differentiate {type(e).__name__}: {e}")  # pragma: no cover


# ---------------------------------------------------------------- statements


def tangent(f: ir.Function, name: str, seeds: dict, plans,
            fresh: int) -> tuple[ir.Function, int]:
    """The function `name` (f's arguments and v) that computes f's results' derivatives along
    seeds (a symbol -> its tangent): each statement of f followed by its tangent.  An
    assignment's tangent is the directional derivative of its expression; through a linear
    block A z = b the tangent solves A dz = db - dA z with A's factors; through a Newton block
    dz = -J^-1 (dr/du du), J factored at the solution (so the Newton statement asks for its
    final factors).  New program variables are w<fresh>, ...; a trivial tangent (a number, a
    symbol, a negated one) is substituted instead of assigned.  Returns the function
    (unpruned) and the next free variable number."""
    forward = _Forward(seeds, plans, fresh)
    for s in f.body:
        forward.statement(s)
    return ir.Function(name, f.args + ("v",), f.size, tuple(forward.out)), forward.fresh


class _Forward:
    """The statements of a tangent function as they are derived (out), and each variable's
    tangent so far."""

    def __init__(self, seeds, plans, fresh):
        self.tan = dict(seeds)  # symbol -> its tangent (a symbol or an expression)
        self.plans, self.fresh = plans, fresh
        self.out: list = []

    def new(self) -> sp.Symbol:
        self.fresh += 1
        return ir.W(self.fresh - 1)

    def of(self, expr):
        return directional(expr, self.tan) if expr.free_symbols & self.tan.keys() else ZERO

    def bind(self, target, value):
        """target's tangent is value: a new assignment unless it is zero or trivial."""
        if value == 0:
            return
        value = ir.integral_floats(value)
        if ir.trivial(value):
            self.tan[target] = value
            return
        d = self.new()
        self.out.append(ir.Assign(d, value))
        self.tan[target] = d

    def statement(self, s):
        if isinstance(s, ir.Assign):
            self.out.append(s)
            self.bind(s.target, self.of(s.expr))
        elif isinstance(s, ir.Store):
            self.out.append(ir.Store(s.index, self.of(s.expr)))
        elif isinstance(s, ir.Solve):
            self.out.append(s)
            self.solve(s)
        elif isinstance(s, ir.Newton):
            self.out.append(replace(s, final_factor=True))
            self.newton(s)
        else:  # pragma: no cover - a tangent function is not differentiated again
            raise TypeError(f"no tangent of {type(s).__name__}")

    def solve(self, s: ir.Solve):
        """A dz = db - dA z, row by row in the plan's order."""
        lu = self.plans[s.block].lu
        row_at, col_at = ir.positions(lu.row_of), ir.positions(lu.col_of)
        terms = [[] for _ in s.rhs]
        for (i, k), e in zip(self.plans[s.block].pattern, s.matrix):
            d = self.of(e)
            if d != 0:
                terms[row_at[i]].append(d * s.unknowns[col_at[k]])
        self.resolve(s, [self.of(b) - sp.Add(*t) for b, t in zip(s.rhs, terms)])

    def newton(self, s: ir.Newton):
        """The body's tangents with z held, dz = -J^-1 dr, then the body's full tangents."""
        held = _Forward(self.tan, self.plans, self.fresh)
        held.out = self.out
        for a in s.body:
            held.bind(a.target, held.of(a.expr))
        self.fresh = held.fresh
        self.resolve(s, [-held.of(r) for r in s.residuals])
        for a in s.body:
            self.bind(a.target, self.of(a.expr))

    def resolve(self, s, rows):
        if all(r == 0 for r in rows):
            return
        lu = self.plans[s.block].lu
        numbered = [self.new() for _ in rows]  # in the unknowns' own order, as reduce found them
        targets = tuple(numbered[c] for c in lu.col_of)
        self.out.append(ir.Resolve(s.block, targets, tuple(rows)))
        self.tan.update(zip(s.unknowns, targets))

