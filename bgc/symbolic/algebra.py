"""Small symbolic helpers that more than one stage uses: inverting a law, testing for zero,
antiderivatives of constraint balances, and the language's min() and max().

Nothing here calls a general SymPy solver: an equation is inverted only where its inverse is
clean by construction (degree one in the unknown, or the unknown occurring once under
functions with a real inverse), so the work is bounded by the size of the expression and can
never hang; an expression larger than bgc.base.resources allows is not inverted, tested or
expanded at all.  Everything else is left to a numeric solve in the generated code.
"""
from __future__ import annotations

import cmath
import math
import random

import mpmath  # SymPy's own dependency: the 30-digit determinant of is_singular
import sympy as sp

from .canonical import xreplace
from .walk import DESCEND, fold
from .differentiate import partial
from ..base.resources import MAX_EXPANDED_TERMS, MAX_GCD_BITS, expanded_terms, fits

# f(u) = w  ->  u = inverse(w), for functions that are bijections of the reals (or of their
# range onto the reals, where the inverse then gives NaN outside the range, as it should).
_INVERSES = {
    sp.exp: sp.log,
    sp.log: sp.exp,
    sp.sinh: sp.asinh,
    sp.tanh: sp.atanh,
}


class _Extremum(sp.Function):
    """The least or greatest of the arguments as written: numbers are folded, nothing else is
    compared or merged.  (SymPy's own Min and Max compare every pair of arguments through the
    assumptions system and merge nested ones: minutes for a hundred arguments.)"""

    @classmethod
    def eval(cls, *args):
        numbers = [a for a in args if a.is_Number]
        if any(a is sp.nan for a in numbers):  # (SymPy refuses to compare a NaN)
            return sp.nan
        if len(numbers) == len(args):
            return cls.pick(numbers)
        if len(numbers) > 1:
            return cls(*[a for a in args if not a.is_Number], cls.pick(numbers))
        return None

    def _eval_evalf(self, prec):
        """The numeric value once every argument has one (max(a*exp(3), 5) at a = 2): float()
        and evalf() of an extremum of constants, which SymPy cannot compute by itself."""
        args = [a._eval_evalf(prec) if not a.is_Number else a for a in self.args]
        if all(a is not None and a.is_Number for a in args):
            return sp.nan if any(a is sp.nan for a in args) else self.pick(args)
        return None

    def fdiff(self, argindex=1):
        """Heaviside of how far the argument leads the others (1/2 at a tie), as SymPy's."""
        others = self.args[:argindex - 1] + self.args[argindex:]
        rest = others[0] if len(others) == 1 else self.func(*others)
        lead = self.args[argindex - 1] - rest
        return sp.Heaviside(lead if isinstance(self, Max) else -lead)


class Max(_Extremum):
    pick = staticmethod(max)


class Min(_Extremum):
    pick = staticmethod(min)


class Heaviside(sp.Function):
    """Heaviside(x, H0): 0 where x < 0, 1 where x > 0, H0 at 0; evaluated for a number x
    only (SymPy's asks the assumptions system whether x is negative, positive or real,
    which for a large x, an impulse solved in closed form, costs minutes).  Printed as
    SymPy's (by name); its derivative is zero (piecewise constant)."""
    nargs = 2

    @classmethod
    def eval(cls, arg, H0):
        if arg.is_Number and H0.is_Number:
            return sp.Heaviside(arg, H0)
        return None

    def fdiff(self, argindex=1):
        return sp.Integer(0)

    @property
    def pargs(self):  # (SymPy's printers of its own Heaviside read these)
        return self.args


def linear_solution(equation: sp.Expr, unknown: sp.Symbol) -> sp.Expr | None:
    """The solution of equation == 0 when it has degree one in unknown with a coefficient
    free of it: -(equation - a*unknown)/a.  None otherwise."""
    a = partial(equation, unknown)
    if a == 0 or a.has(unknown):
        return None
    rest = equation - a * unknown
    if rest.has(unknown):
        rest = expand_bounded(rest)
        if rest is None or rest.has(unknown):
            return None
    if a.is_Add and a.free_symbols and sp.count_ops(a) + sp.count_ops(rest) < 40:
        tidy = cancel_bounded(-rest / a)  # a compound coefficient; a monomial divides cleanly
        if tidy is not None:
            return tidy
    return -rest / a


def peel(equation: sp.Expr, unknown: sp.Symbol) -> sp.Expr | None:
    """Solve equation == 0 for unknown where the unknown occurs exactly once, under sums,
    products, odd integer powers and exp/log/sinh/tanh: undo them one by one.  None when
    that does not apply (then the equation has no clean closed-form inverse)."""
    if _occurrences(equation, unknown) != 1:
        return None
    lhs, rhs = equation, sp.Integer(0)
    while lhs != unknown:
        if lhs.is_Add or lhs.is_Mul:
            inside = [a for a in lhs.args if a.has(unknown)]
            outside = [a for a in lhs.args if not a.has(unknown)]
            if lhs.is_Add:
                rhs = rhs - sp.Add(*outside)
            else:
                rhs = rhs / sp.Mul(*outside)
            (lhs,) = inside
        elif lhs.is_Pow:
            base, exp = lhs.args
            if base.has(unknown) and exp.is_Integer and int(exp) % 2 == 1:
                n = int(exp)
                root = sp.sign(rhs) * sp.Abs(rhs) ** sp.Rational(1, abs(n)) if abs(n) != 1 \
                    else rhs
                rhs = root if n > 0 else 1 / root
                lhs = base
            elif exp.has(unknown) and base.is_Number and base.is_positive and base != 1:
                rhs = sp.log(rhs) / sp.log(base)
                lhs = exp
            else:
                return None
        elif type(lhs) in _INVERSES and len(lhs.args) == 1:
            rhs = _INVERSES[type(lhs)](rhs)
            (lhs,) = lhs.args
        else:
            return None
    return rhs


def _occurrences(expr: sp.Expr, symbol: sp.Symbol) -> int:
    """How often symbol occurs as a leaf of expr's tree (an explicit stack, no recursion)."""
    count, stack = 0, [expr]
    while stack:
        e = stack.pop()
        if e == symbol:
            count += 1
        elif e.args:
            stack.extend(a for a in e.args if a.has(symbol))
    return count


def solve_for(equation: sp.Expr, unknown: sp.Symbol) -> sp.Expr | None:
    """A clean closed form of the unknown from equation == 0, or None (see the module doc;
    None too for an equation beyond bgc.base.resources' limits)."""
    if not fits(equation):
        return None
    return linear_solution(equation, unknown) if _degree_one(equation, unknown) \
        else peel(equation, unknown)


_LINEAR_ARGUMENT = {  # f(a z + b) -> its antiderivative times a
    sp.sin: lambda u: -sp.cos(u), sp.cos: sp.sin, sp.exp: sp.exp,
    sp.sinh: sp.cosh, sp.cosh: sp.sinh,
}


def antiderivative(expr: sp.Expr, z: sp.Symbol) -> sp.Expr | None:
    """An antiderivative of expr in z, term by term after expansion, for terms that are a
    factor free of z times z^r, (a z + b)^r, or sin, cos, exp, sinh or cosh of a z + b (a, b
    free of z).  None for anything else, or beyond bgc.base.resources' limits: no general
    integrator runs, so the work is bounded by the size of expr."""
    expanded = expand_bounded(expr)
    if expanded is None:
        return None
    out = []
    for term in sp.Add.make_args(expanded):
        free, inside = term.as_independent(z, as_Add=False)
        part = _antiderivative_of_factor(inside, z)
        if part is None:
            return None
        out.append(free * part)
    return sp.Add(*out)


def _antiderivative_of_factor(f, z):
    if f == 1:
        return z
    if f.is_Pow:
        base, r = f.args
        slope = _slope(base, z)
        if slope is None or r.has(z):
            return None
        return sp.log(base) / slope if r == -1 else base ** (r + 1) / (slope * (r + 1))
    if f == z:
        return z ** 2 / 2
    if type(f) in _LINEAR_ARGUMENT and len(f.args) == 1:
        slope = _slope(f.args[0], z)
        return None if slope is None else _LINEAR_ARGUMENT[type(f)](f.args[0]) / slope
    return None


def _slope(u, z):
    """a when u = a z + b with a, b free of z (a != 0), else None."""
    a = partial(u, z)
    return a if a != 0 and not a.has(z) else None


def cancel_bounded(expr, nodes: int = 600):
    """sp.cancel(expr), or None when the work it would do is beyond bgc.base.resources' limits.
    cancel writes expr as one fraction p/q (no bigger than `nodes` before), expands p and q
    (expanded_terms bounds that) and divides out their greatest common divisor, which SymPy
    finds by its heuristic gcd: gcd_bits estimates, before any of it, how large the integers
    of that heuristic grow."""
    if not fits(expr, nodes):
        return None
    p, q = expr.as_numer_denom()
    if not (fits(p) and fits(q)) or max(expanded_terms(p), expanded_terms(q)) > \
            MAX_EXPANDED_TERMS or gcd_bits(p, q) > MAX_GCD_BITS:
        return None
    return sp.cancel(expr)


def lu_solution_nodes(A, b, limit: int) -> int:
    """An upper bound of the nodes (as a tree) of the solution of A x = b that SymPy's LUsolve
    builds, known before it starts (limit + 1 when past limit): its elimination and
    substitutions, without simplification, make each new entry of the ones it combines
    (a - l*u: their nodes and three, the Add, the Mul and its -1; x / d likewise, d**-1),
    structural zeros staying zero, the pivot the first nonzero entry down its column as
    SymPy takes it.  (SymPy's own folding makes most results smaller; a number times a sum
    distributed over it can make one a little larger: fits() checks the result.)"""
    m = A.rows
    size = [[_nodes(A[i, k], limit) if A[i, k] != 0 else 0 for k in range(m)]
            for i in range(m)]
    rhs = [_nodes(b[i], limit) if b[i] != 0 else 0 for i in range(m)]
    cap = limit + 1
    for k in range(m):
        pivot = next((r for r in range(k, m) if size[r][k]), None)
        if pivot is None:
            return cap  # (singular: _matrix_in_outer has refused it before)
        size[k], size[pivot] = size[pivot], size[k]
        rhs[k], rhs[pivot] = rhs[pivot], rhs[k]
        for i in range(k + 1, m):
            if not size[i][k]:
                continue
            size[i][k] = min(size[i][k] + size[k][k] + 3, cap)  # l = a / pivot
            for j in range(k + 1, m):
                if size[k][j]:
                    size[i][j] = min(size[i][j] + size[i][k] + size[k][j] + 3, cap)
            if rhs[k]:
                rhs[i] = min(rhs[i] + size[i][k] + rhs[k] + 3, cap)
    total = 0
    for i in range(m - 1, -1, -1):
        for j in range(i + 1, m):
            if size[i][j] and rhs[j]:
                rhs[i] = min(rhs[i] + size[i][j] + rhs[j] + 3, cap)
        rhs[i] = min(rhs[i] + size[i][i] + 3, cap)
        total = min(total + rhs[i], cap)
    return total


def _nodes(expr, limit: int) -> int:
    """expr's nodes as a tree, counted to limit + 1 at most."""
    count, stack = 0, [expr]
    while stack and count <= limit:
        e = stack.pop()
        count += 1
        stack.extend(e.args)
    return count


def gcd_bits(p, q) -> float:
    """An estimate of the bits of the integers that SymPy's heuristic gcd of the polynomials p
    and q builds (sympy.polys.heuristicgcd): it evaluates both at an integer x for one
    variable, then recurses on the next variable with the values as coefficients, x being
    about the square root of the smaller norm, so that a variable of degree d in both
    multiplies the bits by 1 + d/2 (a variable in one only leaves the smaller norm as it
    was).  The start: 5 bits (x is 2 min(norm) + 29 for norms of 1) plus the bits of the
    largest number.  A sum of N reciprocals of parameters, over one denominator, shares its
    N parameters with the numerator at degree 2: 5 * 2^N bits.  The product stops once past
    MAX_GCD_BITS (what matters is whether it is, whatever the order of the variables)."""
    numbers = p.atoms(sp.Number) | q.atoms(sp.Number)
    bits = 5.0 + max([0] + [53 if not n.is_Rational else
                            abs(n.p).bit_length() + n.q.bit_length() for n in numbers])
    dp, dq = _degrees(p), _degrees(q)
    for g in dp.keys() & dq.keys():
        bits *= 1 + min(dp[g], dq[g]) / 2
        if bits > MAX_GCD_BITS:
            break
    return bits


def _degrees(expr) -> dict:
    """An upper bound of expr's degree in each variable of its polynomial form (symbols, and
    functions or non-integer powers, which SymPy's polynomials take as variables of their
    own): sums take the largest, products add, an integer power multiplies."""
    return fold(expr, {}, _degree_leaf, _degree)


def _degree_leaf(e):
    if e.is_Number:
        return {}
    polynomial = e.is_Add or e.is_Mul or (e.is_Pow and e.exp.is_Integer and e.exp > 0)
    return DESCEND if polynomial else {e: 1}


def _degree(e, degrees):
    if e.is_Pow:
        return {g: k * int(e.exp) for g, k in degrees[0].items()}
    out: dict = {}
    for d in degrees:
        for g, k in d.items():
            out[g] = max(out.get(g, 0), k) if e.is_Add else out.get(g, 0) + k
    return out


def expand_bounded(expr):
    """sp.expand(expr), or None when expr is beyond bgc.base.resources' limits or its expansion
    would build more than MAX_EXPANDED_TERMS terms."""
    if not fits(expr) or expanded_terms(expr) > MAX_EXPANDED_TERMS:
        return None
    return sp.expand(expr)


def _degree_one(equation, unknown) -> bool:
    d = partial(equation, unknown)
    return d != 0 and not d.has(unknown)


def is_zero(expr: sp.Expr, points: int = 3, seed: int = 0) -> bool:
    """Whether expr is identically zero: structurally after cancellation, or else by its value
    at random points in 30-digit arithmetic (zero at several random points of an analytic
    function of real arguments, it is zero: the probability of a false 'zero' is nil).
    Cheap and bounded, unlike simplify; False for an expression too large to test."""
    if not fits(expr):
        return False
    if expr.is_Add or expr.is_Mul:
        expanded = expand_bounded(expr)
        expr = expr if expanded is None else expanded
    if expr == 0:
        return True
    if not expr.free_symbols:
        try:
            return abs(complex(expr.evalf(30))) < 1e-25
        except (TypeError, ValueError):
            return False
    rng = random.Random(seed)
    symbols = sorted(expr.free_symbols, key=str)
    for _ in range(points):
        values = {s: sp.Float(rng.uniform(0.3, 1.7), 30) for s in symbols}
        try:
            v = complex(expr.xreplace(values).evalf(30))
        except (TypeError, ValueError, ZeroDivisionError):
            return False
        if not abs(v) < 1e-20:
            return False
    return True


def is_singular(rows: int, entries, points: int = 3, seed: int = 0) -> bool:
    """Whether the square matrix with these (row, column, expression) entries is singular
    whatever the values of its symbols: at random points, in 30-digit arithmetic, its rows
    scaled to unit length, elimination with partial pivoting meets a pivot below 1e-20 (a
    rank lost to the working precision's rounding, not to conditioning: the determinant
    against Hadamard's bound, tried before, falls below any fixed threshold as the matrix
    grows, a 32 x 32 mass matrix of a chain well within it).  A matrix singular at several
    random points is singular identically.  False when the entries together are too large to
    evaluate (bgc.base.resources.fits)."""
    if not fits(sp.Tuple(*(e for _, _, e in entries))):
        return False
    rng = random.Random(seed)
    symbols = sorted(set().union(*[e.free_symbols for _, _, e in entries]) if entries else (),
                     key=str)
    with mpmath.workdps(30):
        for _ in range(points):
            values = {s: sp.Float(rng.uniform(0.3, 1.7), 30) for s in symbols}
            a = mpmath.zeros(rows, rows)
            memo: dict = {}
            for i, j, e in entries:
                try:
                    a[i, j] = mpmath.mpf(sp.Float(xreplace(e, values, memo).evalf(30), 30))
                except (TypeError, ValueError):
                    return False  # not a real number there: no conclusion
            if not _loses_rank(a, rows):
                return False
    return True


def _loses_rank(a, n: int) -> bool:
    """Elimination with partial pivoting of the n x n mpmath matrix a, its rows first scaled to
    unit length: whether a pivot falls below 1e-20 (a zero row counts)."""
    tiny = mpmath.mpf("1e-20")
    for i in range(n):
        norm = mpmath.sqrt(sum(a[i, j] ** 2 for j in range(n)))
        if norm == 0:
            return True
        for j in range(n):
            a[i, j] /= norm
    for k in range(n):
        piv = max(range(k, n), key=lambda i: abs(a[i, k]))
        if abs(a[piv, k]) < tiny:
            return True
        if piv != k:
            for j in range(n):
                a[k, j], a[piv, j] = a[piv, j], a[k, j]
        for i in range(k + 1, n):
            f = a[i, k] / a[k, k]
            if f:
                for j in range(k + 1, n):
                    a[i, j] -= f * a[k, j]
    return False


def is_symmetric(entries, points: int = 2, seed: int = 1) -> bool:
    """Whether the square matrix with these (row, column, expression) entries is symmetric
    whatever the values of its symbols: its pattern, and its values at random points to 1e-12
    relative (two analytic functions equal at random points are equal)."""
    values = {(i, j): e for i, j, e in entries}
    if any((j, i) not in values for i, j in values) or not fits(sp.Tuple(*values.values())):
        return False
    pairs = [(i, j) for i, j in values if i < j]
    if not pairs:
        return True
    rng = random.Random(seed)
    symbols = sorted(set().union(*[e.free_symbols for e in values.values()]), key=str)
    for _ in range(points):
        point = {s: sp.Float(rng.uniform(0.3, 1.7), 20) for s in symbols}
        memo: dict = {}
        for i, j in pairs:
            try:
                a = complex(xreplace(values[(i, j)], point, memo).evalf(20))
                b = complex(xreplace(values[(j, i)], point, memo).evalf(20))
            except (TypeError, ValueError, ZeroDivisionError):
                return False
            if not abs(a - b) <= 1e-12 * (abs(a) + abs(b)):
                return False
    return True


# ---------------------------------------------------------------- evaluation in doubles

_COMPLEX_FUNCTIONS = {
    sp.sin: cmath.sin, sp.cos: cmath.cos, sp.tan: cmath.tan, sp.asin: cmath.asin,
    sp.acos: cmath.acos, sp.atan: cmath.atan, sp.sinh: cmath.sinh, sp.cosh: cmath.cosh,
    sp.tanh: cmath.tanh, sp.exp: cmath.exp, sp.log: cmath.log,
}


class _Beyond(Exception):
    """A value beyond a double's range: .node, the subexpression that takes it."""

    def __init__(self, node):
        super().__init__(node)
        self.node = node


def _in_doubles(e, values: dict) -> complex:
    """e in complex doubles, node by node as the generated code computes it (NaN where a value
    is undefined or unknown); _Beyond as soon as one is infinite."""
    args = [_in_doubles(a, values) for a in e.args]  # every argument, even after a NaN
    try:
        if not args:
            z = complex(values[e] if e in values else e) if e.is_number or e in values \
                else complex(math.nan)
        elif e.is_Add:
            z = sum(args, 0j)
        elif e.is_Mul:
            z = 1 + 0j
            for a in args:
                z *= a
        elif e.is_Pow:
            base, exp = args
            z = base ** (exp.real if exp.imag == 0 else exp)
        elif e.func in _COMPLEX_FUNCTIONS:
            z = _COMPLEX_FUNCTIONS[e.func](args[0])
        elif all(a.imag == 0 for a in args) and isinstance(e, (sp.Abs, sp.sign, sp.atan2,
                                                                  _Extremum)):
            x = [a.real for a in args]
            if isinstance(e, sp.Abs):
                z = complex(abs(x[0]))
            elif isinstance(e, sp.atan2):
                z = complex(math.atan2(*x))
            elif isinstance(e, sp.sign):
                z = complex(math.copysign(1.0, x[0]) if x[0] != 0 else 0.0)
            else:  # max, min
                z = complex(e.pick(x))
        else:
            z = complex(math.nan)
    except OverflowError:
        raise _Beyond(e) from None
    except (ZeroDivisionError, ValueError, TypeError):
        z = complex(math.nan)
    if math.isinf(z.real) or math.isinf(z.imag):
        raise _Beyond(e)
    return z


def beyond_double(expr, values: dict):
    """The first subexpression of expr (or expr itself) that at these values (symbol -> number)
    is beyond a double's range (exp(b) at b = 1e12), computed in doubles one node at a time as
    the generated code does; None if there is none.  Checked before SymPy evaluates such an
    expression: its floats have no range, and sin(exp(1e12)) needs pi to a trillion bits."""
    try:
        _in_doubles(expr, values)
    except _Beyond as beyond:
        return beyond.node
    except RecursionError:
        return None
    return None
