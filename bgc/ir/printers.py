"""SymPy code printers for the generated C and Python: one expression to one line of code.

Both printers accept exactly the expressions the program IR allows (see bgc.ir) and
refuse anything else with `UnsupportedExpressionError` before printing a character, so that
broken code is never emitted.  They share the arithmetic layout (`_ArithmeticPrinting`): terms,
factors and powers come out in the same order with the same operations in both languages, so
the C program and the Python module compute bit-identical values wherever they call the same
libm functions.

Layout decisions (identical in C and Python):
  - every number prints as a double literal with 17 significant digits ("2.0",
    "0.33333333333333331");
  - x**n for a plain variable and 2 <= n <= 4 prints as x*x*...; (expr)**2 as a square helper;
    x**(1/2) as sqrt(x); x**-n as 1.0/(...); other powers as pow();
  - a + (-b) prints as a - b, and factors with negative rational exponents go below one "/";
  - for speed, sums add as a balanced tree: a + b + (c + d), so that n terms wait for
    log2(n) additions rather than n - 1; and in a product that divides by a variable, the
    simple factors (numbers, variables) are divided first, in parentheses, so that the
    division runs while the compound factors (sums, calls) are still being computed:
    S*(2.0*x[0]/(x[1] + 1.0)) (a division by a number alone stays 3.0*S/7.0).
"""
from __future__ import annotations

import re

import sympy as sp

from sympy.printing.c import C99CodePrinter
from sympy.printing.pycode import PythonCodePrinter

from sympy.core.relational import Relational
from sympy.functions.elementary.piecewise import ExprCondPair
from sympy.logic.boolalg import ITE, And, BooleanFalse, BooleanTrue, Not, Or

from ..symbolic.algebra import Heaviside
from .program import (ATOL, C, CLASSES, FUNCTIONS, D, P, R, T, V, X, InputNext, InputPart,
                      PeriodicNext, SquareNext, SquareWave, Table, TableGuard, TableNext,
                      TablePiece, as_expr)
_CLASSES = tuple(CLASSES.values()) + (Heaviside,)  # (bgc.symbolic.algebra's, printed as SymPy's)
_ARITY = {"atan2": (2, 2), "Min": (2, None), "Max": (2, None), "Heaviside": (1, 2)}
_TEMP = re.compile(r"w[0-9]+\Z")
_CONDITIONALS = (sp.Piecewise, ExprCondPair, Relational, And, Or, Not, ITE, BooleanTrue,
                 BooleanFalse)
_RELOPS = {"<": "<", "<=": "<=", ">": ">", ">=": ">=", "==": "==", "!=": "!="}
MAX_EXPANDED_POWER = 4  # x**n for 2 <= n <= 4 prints as x*x*...

PREC_ADD, PREC_MUL, PREC_ATOM = 1, 2, 3


class UnsupportedExpressionError(ValueError):
    """An expression outside what the code model allows (a bug in the stage that built it)."""


def float_literal(value: float) -> str:
    """A double literal with 17 significant digits, valid in both C and Python."""
    value = float(value)
    if value != value or value in (float("inf"), float("-inf")):
        raise UnsupportedExpressionError(f"non-finite constant {value!r}")
    text = "%.17g" % value
    if not any(c in text for c in ".en"):
        text += ".0"
    return text


# ---------------------------------------------------------------- validation


def check_expression(expr: sp.Basic, n_states: int, n_params: int, n_consts: int = 0) -> None:
    """Raise UnsupportedExpressionError unless `expr` uses only what the program IR allows
    (an explicit stack: no recursion however deep the expression)."""
    stack = [expr]
    while stack:
        e = stack.pop()
        if isinstance(e, (sp.Add, sp.Mul, sp.Pow)):  # (the most common first)
            stack.extend(e.args)
        elif isinstance(e, sp.Indexed):
            _check_indexed(e, n_states, n_params, n_consts)
        elif isinstance(e, sp.Symbol):
            if e.name not in (T.name, ATOL.name) and not _TEMP.match(e.name):
                raise UnsupportedExpressionError(f"unexpected symbol {e.name!r}")
        elif isinstance(e, (sp.Integer, sp.Rational, sp.Float)) or e in (sp.pi, sp.E):
            if isinstance(e, sp.Float):
                float_literal(float(e))
        elif type(e) in _CLASSES:
            _check_arity(e)
            stack.extend(e.args)
        elif type(e) in (InputPart, InputNext):
            if not (e.args[0].is_Integer and int(e.args[0]) >= 0):
                raise UnsupportedExpressionError(f"cannot print {e}")
            if type(e) is InputPart and not (e.args[2].is_Integer and 0 <= int(e.args[2]) <= 2):
                raise UnsupportedExpressionError(f"cannot print {e}")
            stack.append(e.args[1])
            if type(e) is InputPart:
                stack.append(e.args[3])
        elif type(e) in (Table, TableNext, TablePiece, TableGuard):
            if not (e.args[0].is_Integer and int(e.args[0]) >= 0):
                raise UnsupportedExpressionError(f"cannot print {e}")
            if type(e) is Table and not (e.args[3].is_Integer and 0 <= int(e.args[3]) <= 3):
                raise UnsupportedExpressionError(f"cannot print {e}")
            stack.extend(e.args[1:])
        elif isinstance(e, _CONDITIONALS) or type(e) in (SquareWave, SquareNext, PeriodicNext):
            if isinstance(e, Relational) and e.rel_op not in _RELOPS:
                raise UnsupportedExpressionError(f"cannot print {e}")
            stack.extend(e.args)
        else:
            raise UnsupportedExpressionError(f"cannot print {type(e).__name__}: {e}")


def _check_indexed(expr: sp.Indexed, n_states: int, n_params: int, n_consts: int) -> None:
    sizes = {X.name: n_states, P.name: n_params, C.name: n_consts, V.name: n_states,
             D.name: 2 ** 31, R.name: 2 ** 31}  # d and r: the program's event sizes
    if expr.base.name not in sizes or len(expr.indices) != 1:
        raise UnsupportedExpressionError(f"unexpected indexed variable {expr}")
    index = expr.indices[0]
    if not isinstance(index, sp.Integer) or not 0 <= int(index) < sizes[expr.base.name]:
        raise UnsupportedExpressionError(f"index out of range: {expr}")


def _check_arity(expr: sp.Function) -> None:
    low, high = _ARITY.get(type(expr).__name__, (1, 1))
    n = len(expr.args)
    if n < low or (high is not None and n > high):
        raise UnsupportedExpressionError(f"wrong number of arguments: {expr}")


# ---------------------------------------------------------------- shared layout


def _is_simple(expr: sp.Basic) -> bool:
    return isinstance(expr, (sp.Symbol, sp.Indexed))


def _split_coefficient(coeff: sp.Number) -> tuple[list, list]:
    """A positive coefficient as (numerator, denominator) factors: p/q with q not a power of
    two divides by q, which is more accurate than multiplying by the rounded 1/q."""
    if isinstance(coeff, sp.Rational) and coeff.q & (coeff.q - 1):
        return ([] if coeff.p == 1 else [sp.Integer(coeff.p)]), [sp.Integer(coeff.q)]
    return ([] if coeff == 1 else [coeff]), []


def _terms(expr: sp.Add):
    """The terms of a sum, numbers last (a - 1.0 rather than -1.0 + a)."""
    args = expr.args
    return [a for a in args if not a.is_Number] + [a for a in args if a.is_Number]


class _ArithmeticPrinting:
    """The language-independent part; subclasses supply names, indexing, squares and pow."""

    # set by subclasses
    FUNCTION_NAMES: dict[str, str] = {}

    def __init__(self, n_states: int, n_params: int, n_consts: int = 0, settings=None):
        super().__init__(dict(settings or {}, strict=True))
        self._n_states = n_states
        self._n_params = n_params
        self._n_consts = n_consts
        self.names: dict = {}  # program variable -> its storage text (default: its name)

    def doprint(self, expr, assign_to=None):
        if assign_to is not None:
            raise TypeError("assign_to is not supported; the templates write assignments")
        expr = as_expr(expr)
        check_expression(expr, self._n_states, self._n_params, self._n_consts)
        return self._print(expr)

    def _print(self, expr, **kwargs):
        if isinstance(expr, sp.Indexed):
            return self._print_index(expr.base, int(expr.indices[0]))
        if isinstance(expr, sp.Symbol):
            if expr == ATOL:
                return self.ATOL
            return self.names.get(expr, expr.name)
        if isinstance(expr, sp.Add):
            return self._print_sum(expr)
        if isinstance(expr, sp.Mul):
            return self._print_product(expr)
        if isinstance(expr, sp.Pow):
            return self._print_power(expr)
        if type(expr) in _CLASSES:
            return self._print_call(expr)
        if isinstance(expr, sp.Piecewise):
            return self._print_piecewise(expr)
        if isinstance(expr, Relational):
            return f"({self._print(expr.lhs)} {_RELOPS[expr.rel_op]} {self._print(expr.rhs)})"
        if isinstance(expr, (And, Or)):
            op = self.LOGIC["and" if isinstance(expr, And) else "or"]
            return "(" + f" {op} ".join(self._print(a) for a in expr.args) + ")"
        if isinstance(expr, Not):
            return f"({self.LOGIC['not']}{self._print(expr.args[0])})"
        if isinstance(expr, ITE):  # (SymPy's own form of some conditions: if a then b else c)
            return self._conditional(*(self._print(a) for a in expr.args))
        if isinstance(expr, (BooleanTrue, BooleanFalse)):
            return self.LOGIC["true" if isinstance(expr, BooleanTrue) else "false"]
        if type(expr) in (InputPart, InputNext):
            a = expr.args
            rest = [str(int(a[0])), self._print(a[1])]
            if type(expr) is InputPart:
                rest += [str(int(a[2])), self._print(a[3])]
            return f"{self.FUNCTION_NAMES[type(expr).__name__]}(w, {', '.join(rest)})"
        if type(expr) in (Table, TableNext, TablePiece, TableGuard):
            name = self.FUNCTION_NAMES[type(expr).__name__]
            rest = [self._print(a) for a in expr.args[1:3]]
            if type(expr) is Table:
                rest.append(str(int(expr.args[3])))
            return f"{name}({self._table_ref(int(expr.args[0]))}, {', '.join(rest)})"
        if type(expr) in (SquareWave, SquareNext, PeriodicNext):
            name = self.FUNCTION_NAMES[type(expr).__name__]
            return f"{name}({', '.join(self._print(a) for a in expr.args)})"
        if isinstance(expr, sp.Rational):
            return float_literal(int(expr.p) / int(expr.q))
        if isinstance(expr, sp.Float) or expr in (sp.pi, sp.E):
            return float_literal(float(expr))
        raise UnsupportedExpressionError(f"cannot print {type(expr).__name__}: {expr}")

    # -- precedence of what _print produces

    def _precedence(self, expr: sp.Basic) -> int:
        if isinstance(expr, sp.Add):
            return PREC_ADD
        if isinstance(expr, sp.Mul):
            return PREC_MUL
        if isinstance(expr, sp.Pow):
            return self._power_precedence(expr)
        return PREC_ATOM

    def _power_precedence(self, expr: sp.Pow) -> int:
        base, exp = expr.base, expr.exp
        if exp == 1:
            return self._precedence(base)
        if exp == sp.S.Half:
            return PREC_ATOM
        if exp.is_Rational and exp.is_negative:
            return PREC_MUL
        if exp.is_Integer and _is_simple(base) and int(exp) <= MAX_EXPANDED_POWER:
            return PREC_MUL
        return PREC_ATOM

    def _operand(self, expr: sp.Basic, level: int) -> str:
        text = self._print(expr)
        if self._precedence(expr) < level or text.startswith("-"):
            return f"({text})"
        return text

    # -- arithmetic

    def _print_sum(self, expr: sp.Add) -> str:
        # Add's own argument order is canonical (SymPy sorts it structurally, independent of
        # hashing), and cheap, unlike as_ordered_terms' polynomial ordering
        return self._balanced_sum([self._print(term) for term in _terms(expr)])

    def _balanced_sum(self, texts: list[str]) -> str:
        """texts added as a balanced tree: the first half (itself balanced) + (the second)."""
        if len(texts) == 1:
            return texts[0]
        half = (len(texts) + 1) // 2
        left, right = self._balanced_sum(texts[:half]), self._balanced_sum(texts[half:])
        if len(texts) - half > 1:
            return f"{left} + ({right})"
        return f"{left} - {right[1:]}" if right.startswith("-") else f"{left} + {right}"

    def _print_product(self, expr: sp.Mul) -> str:
        coeff, rest = expr.as_coeff_Mul()
        sign = "-" if coeff.is_negative else ""
        coeff = -coeff if coeff.is_negative else coeff
        numer, denom = _split_coefficient(coeff)
        for factor in rest.as_ordered_factors():
            if factor.is_Pow and factor.exp.is_Rational and factor.exp.is_negative:
                denom.append(sp.Pow(factor.base, -factor.exp, evaluate=False))
            else:
                numer.append(factor)
        simple = [f for f in numer if f.is_Number or _is_simple(f)]
        if simple and len(simple) < len(numer) and not all(f.is_Number for f in denom):
            compound = [f for f in numer if not (f.is_Number or _is_simple(f))]
            return sign + "".join(self._operand(f, PREC_MUL) + "*" for f in compound) + \
                "(" + self._quotient(simple, denom) + ")"  # S*(a/d): d divides while S adds up
        return sign + self._quotient(numer, denom)

    def _quotient(self, numer: list, denom: list) -> str:
        text = "*".join(self._operand(f, PREC_MUL) for f in numer) if numer else "1.0"
        if denom:
            text = self._dividend(text)
        if len(denom) == 1:
            text += "/" + self._operand(denom[0], PREC_ATOM)
        elif denom:
            text += "/(" + "*".join(self._operand(f, PREC_MUL) for f in denom) + ")"
        return text

    def _print_power(self, expr: sp.Pow) -> str:
        base, exp = expr.base, expr.exp
        if exp == 1:
            return self._print(base)
        if exp == sp.S.Half:
            return f"{self.FUNCTION_NAMES['sqrt']}({self._print(base)})"
        if exp.is_Rational and exp.is_negative:
            return self._dividend("1.0") + "/" + \
                self._operand(sp.Pow(base, -exp, evaluate=False), PREC_ATOM)
        if exp.is_Integer and _is_simple(base) and int(exp) <= MAX_EXPANDED_POWER:
            return "*".join([self._print(base)] * int(exp))
        if exp == 2:
            return self._print_square(base)
        return self._print_pow_call(self._print(base), self._print(exp))

    # -- functions

    def _print_call(self, expr: sp.Function) -> str:
        name = type(expr).__name__
        args = [self._print(a) for a in expr.args]
        if name == "Heaviside":
            half = args[1] if len(args) > 1 else float_literal(0.5)
            return f"{self.FUNCTION_NAMES[name]}({args[0]}, {half})"
        if name in ("Min", "Max"):
            return self._print_extremum(self.FUNCTION_NAMES[name], args)
        return f"{self.FUNCTION_NAMES[name]}({', '.join(args)})"

    def _print_extremum(self, func: str, args: list[str]) -> str:
        text = args[0]
        for arg in args[1:]:
            text = f"{func}({text}, {arg})"
        return text

    def _print_piecewise(self, expr: sp.Piecewise) -> str:
        """if c1 then a elif c2 then b else d, nested from the last branch out."""
        pairs = list(expr.args)
        if pairs[-1].cond != sp.true:
            raise UnsupportedExpressionError(f"a conditional without an else: {expr}")
        text = self._print(pairs[-1].expr)
        for p in reversed(pairs[:-1]):
            text = self._conditional(self._print(p.cond), self._print(p.expr), text)
        return text

    # -- language hooks

    def _dividend(self, text: str) -> str:
        """The left operand of a division as printed (the Python fallback's is a float64)."""
        return text

    LOGIC: dict = {}

    def _conditional(self, cond: str, then: str, orelse: str) -> str:
        raise NotImplementedError

    def _print_index(self, base: sp.IndexedBase, index: int) -> str:
        raise NotImplementedError

    def _print_square(self, base: sp.Basic) -> str:
        raise NotImplementedError

    def _print_pow_call(self, base: str, exp: str) -> str:
        raise NotImplementedError


# ---------------------------------------------------------------- C

# libm's functions that a C compiler may fold at compile time with a rounding of its own
LIBM = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh",
        "atanh", "exp", "log")


class CPrinter(_ArithmeticPrinting, C99CodePrinter):
    """C99: x[i], parameters as struct fields p-><field>, constants as p->c[k] (the struct
    carries them), helpers bgc_sq/bgc_sign/... ."""

    FUNCTION_NAMES = {**{f: f for f in FUNCTIONS}, "Abs": "fabs", "sign": "bgc_sign",
                      "Min": "bgc_min", "Max": "bgc_max", "Heaviside": "bgc_heaviside",
                      "SquareWave": "bgc_square", "SquareNext": "bgc_square_next",
                      "PeriodicNext": "bgc_periodic_next",
                      "Table": "bgc_table", "TableNext": "bgc_table_next",
                      "TablePiece": "bgc_table_piece", "TableGuard": "bgc_table_guard",
                      "InputPart": "bgc_input",
                      "InputNext": "bgc_input_next"}
    LOGIC = {"and": "&&", "or": "||", "not": "!", "true": "1", "false": "0"}
    ATOL = "w->atol"

    def _conditional(self, cond, then, orelse):
        return f"({cond} ? {then} : {orelse})"

    def __init__(self, n_states: int, param_fields: tuple[str, ...], n_consts: int = 0):
        super().__init__(n_states, len(param_fields), n_consts)
        self._param_fields = tuple(param_fields)

    def _print_index(self, base, index):
        if base.name in (X.name, V.name):
            return f"{base.name}[{index}]"
        if base.name == C.name:
            return f"p->c[{index}]"
        if base.name == D.name:
            return f"p->d[{index}]"
        if base.name == R.name:
            return f"r[{index}]"
        return f"p->{self._param_fields[index]}"

    def _print_square(self, base):
        return f"bgc_sq({self._print(base)})"

    def _print_call(self, expr):
        # a libm function of numbers alone: computed at run time, as in Python (bgc_opaque)
        if type(expr).__name__ in LIBM and not expr.free_symbols:
            args = [f"bgc_opaque({self._print(a)})" for a in expr.args]
            return f"{self.FUNCTION_NAMES[type(expr).__name__]}({', '.join(args)})"
        return super()._print_call(expr)

    def _print_power(self, expr):
        if not expr.free_symbols and not (expr.exp.is_Integer or expr.exp == sp.S.Half):
            return f"pow(bgc_opaque({self._print(expr.base)}), {self._print(expr.exp)})"
        return super()._print_power(expr)

    def _table_ref(self, k):
        return f"&bgc_tables[{k}]"

    def _print_pow_call(self, base, exp):
        return f"pow({base}, {exp})"


# ---------------------------------------------------------------- Python


_PY_FAST = {**{f: f"math.{f}" for f in FUNCTIONS}, "Abs": "abs", "sign": "_sign",
            "Min": "min", "Max": "max", "Heaviside": "_heaviside", "SquareWave": "_square",
            "SquareNext": "_square_next", "PeriodicNext": "_periodic_next", "Table": "_table",
            "TableNext": "_table_next",
            "TablePiece": "_table_piece", "TableGuard": "_table_guard", "InputPart": "_input",
            "InputNext": "_input_next"}
_PY_IEEE = {**_PY_FAST, **{f: f"_c_{f}" for f in ("sin", "cos", "tan", "asin", "acos", "atan",
                                                     "atan2", "sinh", "cosh", "tanh", "asinh",
                                                     "atanh", "exp", "log", "sqrt")}}


class PythonPrinter(_ArithmeticPrinting, PythonCodePrinter):
    """Python: x[i], p[j], and constant k as p[n_params + k] (the module's functions take the
    parameters followed by their constants); `ieee=False` uses math (fast, raises on domain
    errors), `ieee=True` the runtime's _c_* functions on numpy.float64 values (the platform's
    libm through math, as the C program's, with C's inf and nan where math raises; for the
    fallback).  Squares are _sq(a) = a * a, as C's bgc_sq: a ** 2 on a float is libm's pow,
    which now and then rounds differently."""

    def __init__(self, n_states: int, n_params: int, ieee: bool = False, n_consts: int = 0):
        super().__init__(n_states, n_params, n_consts)
        self._ieee = ieee
        self.FUNCTION_NAMES = _PY_IEEE if ieee else _PY_FAST

    LOGIC = {"and": "and", "or": "or", "not": "not ", "true": "True", "false": "False"}
    ATOL = "w.atol"

    def _conditional(self, cond, then, orelse):
        return f"({then} if {cond} else {orelse})"

    def _print_index(self, base, index):
        if base.name == C.name:
            return f"p[{self._n_params + index}]"
        if base.name == D.name:  # after the parameters and the constants
            return f"p[{self._n_params + self._n_consts + index}]"
        return f"{base.name}[{index}]"  # x, p, v or r, checked

    def _print_extremum(self, func, args):
        return f"{func}({', '.join(args)})"  # min(a, b, c) == min(min(a, b), c) exactly

    def _dividend(self, text):
        # a division of Python floats by zero raises, whatever the operands came from (a
        # literal min() or a conditional picked, a table's value): the fallback divides a
        # numpy.float64, which gives C's inf or nan, the same bits where both are finite
        if self._ieee:
            return f"numpy.float64({text})"
        return text

    def _print_square(self, base):
        return f"_sq({self._print(base)})"

    def _table_ref(self, k):
        return f"_TABLES[{k}]"

    def _print_pow_call(self, base, exp):
        return f"{'_c_pow' if self._ieee else 'math.pow'}({base}, {exp})"
