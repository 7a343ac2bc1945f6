"""Sums and products built as SymPy builds them, without its general flattening where it would
only sort.

The passes rewrite expressions whose parts become other parts: new symbols (constants,
temporaries, the program's variables for the model's), derivatives, values.  Rebuilding a
sum or product through `Add(*args)` or `Mul(*args)`, SymPy spends most of its time finding that
nothing combines.  `new(cls, args)` takes the short way only for arguments it has checked that
the constructor would keep as they are (finite rational or float numbers, which it adds or
multiplies in the constructor's order; symbols, indexed variables, functions other than exp,
powers of a base that is not a number, and in a sum the products, in a product the sums; no
two terms with the same rest, no two factors with the same base; a nested sum or product taken
in after the others, as the constructor does), then sorts them with the constructor's own key:
the result is the constructor's, node for node (the same arguments in the same order).
Anything else goes to the constructor: a number times a sum (which it distributes), a zero
product, exp, I, infinities, terms or factors that combine.  `tests/test_ir.py` compares the
two on hand-picked cases and on every sum and product built while compiling whole models
(VERIFY).
"""
from __future__ import annotations

import sympy as sp
from sympy.core.sympify import _sympify  # the constructor's strict conversion of a number
from sympy.functions.elementary.exponential import ExpBase as _ExpBase  # exp, exp_polar

from .walk import DESCEND, fold
from ..base.resources import compile_memo

_SORT_KEY = sp.core.basic._args_sortkey
_ZERO, _ONE = sp.S.Zero, sp.S.One
_GLOBAL = sp.core.parameters.global_parameters  # (its evaluate off: the constructor itself)
_CANONICAL = compile_memo()  # a term c*s or a factor b**e -> whether the constructor rebuilds it
VERIFY = False  # tests: compare every short-way result with the constructor's


def _finite_number(a) -> bool:
    return isinstance(a, (sp.Rational, sp.Float)) and a.is_finite


def _plain(a) -> bool:
    """A symbol, an indexed variable, or a function applied (not exp, whose base is E, nor
    exp_polar: Mul takes them as powers)."""
    return a.is_Symbol or a.is_Indexed or (isinstance(a, sp.Function)
                                           and not isinstance(a, _ExpBase))


def _rebuilt_as_is(a, make) -> bool:
    """Whether make() (how Add's or Mul's flattening rebuilds the term or factor a) gives a."""
    found = _CANONICAL.get(a)
    if found is None:
        b = make()
        found = _CANONICAL[a] = type(b) is type(a) and b == a
    return found


def _pow_key(a):
    """The base of a factor a of a product, when the constructor keeps a as it is; else None.
    (Mul.flatten: a factor b**e goes in as (b, e), e split as c*t and rebuilt; b**e rebuilt.)"""
    if _plain(a) or a.is_Add:
        return a
    if a.is_Pow:
        b, e = a.args
        if b.is_Number or b.is_NumberSymbol or not b.is_commutative:
            return None
        c, t = e.as_coeff_Mul()

        def make():
            return sp.Pow(b, c * t)

        return b if _rebuilt_as_is(a, make) else None
    return None


def _term_key(a):
    """The rest s of a term a = c*s of a sum, when the constructor keeps a as it is; else
    None.  (Add.flatten: a product goes in as its coefficient and rest, rebuilt as c*s.)"""
    if _plain(a):
        return a
    if a.is_Pow:
        return None if a.base.is_Number or a.base.is_NumberSymbol else a
    if a.is_Mul:
        c, s = a.as_coeff_Mul()
        if c is _ONE:
            return a if s is a else None
        if not _finite_number(c) or c.is_zero:
            return None
        if len(a.args) > 2 or s.is_Add:
            return s  # rebuilt from the same arguments, unevaluated
        if s.is_Mul:
            return None
        return s if _rebuilt_as_is(a, lambda: new(sp.Mul, (c, s))) else None
    return None


def new(cls, args):
    """cls(*args) for cls Add or Mul: the short way where it is the same (see above).  As the
    constructor does, a sum's terms that are sums, a product's factors that are products, are
    taken in after the others, and the numbers added or multiplied in that order."""
    if (cls is not sp.Add and cls is not sp.Mul) or not _GLOBAL.evaluate:
        return cls(*args)
    add = cls is sp.Add
    args = [a if isinstance(a, sp.Basic) else _sympify(a) for a in args]  # (as it does)
    seq = [a for a in args if a is not (_ZERO if add else _ONE)]
    if len(seq) < 2:  # (the constructor's first step, before any flattening)
        return _checked(cls, args, seq[0] if seq else (_ZERO if add else _ONE))
    if not add and len(seq) == 2:  # Mul's rule of two: a rational times a sum or c*(a sum)
        a, b = seq
        if a.is_Rational or b.is_Rational:
            a, b = (b, a) if b.is_Rational else (a, b)
            if not a.is_zero and isinstance(b, sp.Expr) and b.as_coeff_Mul()[1].is_Add:
                return _checked(cls, args, None)
    coeff = _ZERO if add else _ONE
    rest = []
    keys = set()
    i = 0
    while i < len(seq):
        a = seq[i]
        i += 1
        if a.is_Number:
            if not _finite_number(a):
                return _checked(cls, args, None)
            coeff = coeff + a if add else coeff * a
            continue
        if not isinstance(a, sp.Expr) or a.is_commutative is not True:
            return _checked(cls, args, None)
        if (a.is_Add if add else a.is_Mul):
            seq.extend(a.args)
            continue
        key = _term_key(a) if add else _pow_key(a)
        if key is None or key in keys:
            return _checked(cls, args, None)
        keys.add(key)
        rest.append(a)
    if add:
        keep = coeff is not _ZERO
    else:
        if coeff.is_zero or (len(rest) == 1 and rest[0].is_Add):
            return _checked(cls, args, None)  # a zero product; a number times a sum distributes
        keep = coeff is not _ONE
    if len(rest) + keep < 2:
        return _checked(cls, args, None)
    rest.sort(key=_SORT_KEY)
    if keep:
        rest.insert(0, coeff)
    return _checked(cls, args, cls._from_args(rest, True))


def _checked(cls, args, fast):
    if fast is None:
        return cls(*args)
    if VERIFY:
        slow = cls(*args)
        if not (slow == fast and slow.args == fast.args and type(slow) is type(fast)):
            raise AssertionError(f"bgc bug: {cls.__name__}{tuple(args)} is {slow}, not {fast}")
    return fast


def xreplace(expr, rule: dict, memo: dict | None = None):
    """expr.xreplace(rule), node for node as SymPy builds it (every changed node rebuilt by its
    constructor, evaluated; sums and products by `new`), in one walk (bgc.symbolic.walk).
    memo: the subexpressions already rebuilt under the same rule (expressions that share them,
    as the entries of one matrix at one random point do: bgc.symbolic.algebra), each rebuilt
    once."""
    def leaf(e):
        if e in rule:
            return rule[e]
        return e if not e.args else DESCEND

    return fold(expr, {} if memo is None else memo, leaf, _rebuilt)


def _rebuilt(e, new_args):
    if all(a is b for a, b in zip(new_args, e.args)):
        return e
    cls = type(e)
    return new(cls, new_args) if cls is sp.Add or cls is sp.Mul else e.func(*new_args)


# free symbols, remembered: the passes ask for the symbols of the same statements again and
# again (every pruning, every rewrite; the event selection, every mode's next value), and
# SymPy walks the whole expression each time, as a tree
_BASIC_FREE = sp.Basic.__dict__["free_symbols"]
_FREE_OF_ARGS: dict = {}  # type -> whether its free symbols are its arguments' (Basic's rule)
_FREE = compile_memo()  # expression -> frozenset of its free symbols


def _free_of_args(cls) -> bool:
    rule = _FREE_OF_ARGS.get(cls)
    if rule is None:
        owner = next((k for k in cls.__mro__ if "free_symbols" in k.__dict__), None)
        rule = _FREE_OF_ARGS[cls] = owner is not None and \
            owner.__dict__["free_symbols"] is _BASIC_FREE
    return rule


def free_symbols(expr) -> frozenset:
    """expr.free_symbols as a frozenset, remembered for every subexpression (one walk,
    bgc.symbolic.walk); nodes that define their own free symbols (symbols, Indexed,
    Derivative) are asked."""
    found = _FREE.get(expr)
    if found is not None:
        return found
    return fold(expr, _FREE, _free_leaf, _union)


def _free_leaf(e):
    if not e.args or not _free_of_args(type(e)):
        return frozenset(e.free_symbols)
    return DESCEND


def _union(e, values):
    return frozenset().union(*values)
