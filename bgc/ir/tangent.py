"""Forward differentiation of a program's statements (bgc.ir), with bgc.symbolic.differentiate's
`directional` for each expression: every derivative the generated code computes that is not a
block's own Jacobian comes from here — the right side's J*v (`jvp`), and the outputs'
derivative along v for an FMU's directional derivatives (bgc.codegen.lower.with_tangent).  Through a
linear block A z = b the tangent solves A dz = db - dA z with A's factors; through a Newton
block dz = -J^-1 dr with J factored at the solution.
"""
from __future__ import annotations

from dataclasses import replace

import sympy as sp

from . import program as ir
from ..symbolic.differentiate import ZERO, directional, is_zero


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
    forward = Forward(seeds, plans, fresh)
    for s in f.body:
        forward.statement(s)
    return ir.Function(name, f.args + ("v",), f.size, tuple(forward.out)), forward.fresh


class Forward:
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
        return directional(expr, self.tan) if ir.free_symbols(expr) & self.tan.keys() else ZERO

    def bind(self, target, value):
        """target's tangent is value: a new assignment unless it is zero or trivial."""
        if is_zero(value):
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
            if not is_zero(d):
                terms[row_at[i]].append(d * s.unknowns[col_at[k]])
        self.resolve(s, [self.of(b) - sp.Add(*t) for b, t in zip(s.rhs, terms)])

    def newton(self, s: ir.Newton):
        """The body's tangents with z held, dz = -J^-1 dr, then the body's full tangents."""
        held = Forward(self.tan, self.plans, self.fresh)
        held.out = self.out
        for a in s.body:
            held.bind(a.target, held.of(a.expr))
        self.fresh = held.fresh
        self.resolve(s, [-held.of(r) for r in s.residuals])
        for a in s.body:
            self.bind(a.target, self.of(a.expr))

    def resolve(self, s, rows):
        if all(is_zero(r) for r in rows):
            return
        lu = self.plans[s.block].lu
        numbered = [self.new() for _ in rows]  # in the unknowns' own order, as reduce found them
        targets = tuple(numbered[c] for c in lu.col_of)
        self.out.append(ir.Resolve(s.block, targets, tuple(rows)))
        self.tan.update(zip(s.unknowns, targets))



def jacobian(f: ir.Function, name: str, n: int, plans, fresh: int) -> tuple[ir.Function, int]:
    """The function `name` (f's arguments) whose result k*n + j is d(result k of f)/dx_j, its
    nonzero entries stored (the caller zeroes the rest): f's statements once, then for each
    state j that f reads, their tangents along the unit vector e_j (through a linear block by
    its factors, one Resolve per column).  For the constraint rows that read the flows of a
    coupled field, which solve M(q) f = p."""
    reads = set().union(*[e.free_symbols | set(e.atoms(sp.Indexed))
                          for s in f.body for e in ir.expressions(s)]) if f.body else set()
    primal = [replace(s, final_factor=True) if isinstance(s, ir.Newton) else s
              for s in f.body if not isinstance(s, ir.Store)]
    out = list(primal)
    for j in range(n):
        if ir.X[j] not in reads:
            continue
        forward = Forward({ir.X[j]: sp.Integer(1)}, plans, fresh)
        for s in f.body:
            if isinstance(s, ir.Store):
                d = forward.of(s.expr)
                if not is_zero(d):
                    forward.out.append(ir.Store(s.index * n + j, ir.integral_floats(d)))
                continue
            mark = len(forward.out)
            forward.statement(s)
            del forward.out[mark]  # s itself, which the primal part has
        out += forward.out
        fresh = forward.fresh
    return ir.Function(name, f.args, f.size * n, tuple(out)), fresh
