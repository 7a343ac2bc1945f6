"""Conditions that hold a Piecewise, made safe from SymPy's rewrite of them.

SymPy builds each (expression, condition) pair of a Piecewise by folding a condition that holds
a Piecewise and rewriting the result as an ITE; where the inner Piecewise's own condition is a
symbol (bgc's event values, as `step(t0)` is written: Piecewise((1, event#k), (0, True))) that
rewrite takes the symbol for always true and drops it: (1, x > 2*step(3)) becomes (1, x > 2),
silently.  `unnest` writes such a condition as the boolean it means, with no Piecewise inside:
each piece of the folded condition and-ed with "its condition is the first that holds".  The
pair's constructor is wrapped to do so for every Piecewise built anywhere (sympy's xreplace and
subs included), once, when this module is imported: the packages that build expressions
import it first (bgc.front, bgc.middle, bgc.symbolic, bgc.ir, bgc.codegen, bgc.analysis)."""
from __future__ import annotations

import sympy as sp
from sympy.functions.elementary.piecewise import ExprCondPair


def unnest(cond):
    """cond as a boolean without a Piecewise inside (cond itself where it holds none)."""
    if not isinstance(cond, sp.Basic) or not cond.has(sp.Piecewise):
        return cond
    if isinstance(cond, (sp.And, sp.Or)):
        return cond.func(*[unnest(a) for a in cond.args])
    if isinstance(cond, sp.Not):
        return sp.Not(unnest(cond.args[0]))
    folded = sp.piecewise_fold(cond)
    if not isinstance(folded, sp.Piecewise):
        if folded.has(sp.Piecewise):
            raise ValueError(f"a condition that cannot be taken apart: {cond}")
        return folded
    out, before = sp.false, []
    for value, c in folded.args:
        out = sp.Or(out, sp.And(*[sp.Not(b) for b in before], c, unnest(value)))
        before.append(c)
    return out


def indicator(test) -> sp.Expr:
    """1 where test holds, else 0."""
    return sp.Piecewise((sp.Integer(1), unnest(test)), (sp.Integer(0), True))


def _guarded(new):
    def __new__(cls, expr, cond):
        return new(cls, expr, unnest(cond))
    __new__.guarded = True
    return staticmethod(__new__)


if not getattr(ExprCondPair.__new__, "guarded", False):
    ExprCondPair.__new__ = _guarded(ExprCondPair.__new__)
