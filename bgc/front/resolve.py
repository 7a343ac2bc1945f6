"""Stage 2, resolve: AST -> Graph (elements, bonds, signals, scenes) with SymPy expressions.

Expressions are built node by node from the grammar's tree; no string ever becomes an expression.
Model variables are SymPy symbols named as the modeller writes them (`m`, `x`, `mx.p`, `vx.f`,
`rod.lambda`); the equations stage defines the element variables in terms of bond variables.
The builder keeps its own stack (an expression may be as long as the model allows, its depth
is what the parser admits), and builds a chain of `+`/`-` or `*`/`/` as one SymPy sum or
product, so that a sum of n terms costs n, not n^2.
"""
from __future__ import annotations

import math
import sys
from dataclasses import replace

import sympy as sp

from . import ast
from ..symbolic.algebra import Max, Min
from ..base.diagnostics import Collector, ModelError, Note, Span, fail
from .graph import (TIME, InputInfo, check_effect_names, model_effects, Bond, Constraint, Element,
                    Expr, Graph, Parameter, Scene, Signal, check_ports, part_name, var,
                    variable_name, written)
from .events import INITIAL, RELATIONS, SOURCES, Action, Discrete, EventTable, When, is_condition
from .instantiate import output_refs, path_name
from ..ir import Table, TableGuard
from .kinds import KINDS, SWITCHED, known_kinds
from .spelling import as_written
from .tables import EXTRAPOLATE, INTERP, MAX_TABLE_ROWS, MAX_TABLES, build, check_rows, read_csv
from ..base.resources import (MAX_EXTREMUM_ARGUMENTS, MAX_LITERAL_DIGITS, MAX_MATRIX_ENTRIES,
                              MAX_SCENES, MAX_SYMBOLIC_EXPONENT)

FUNCTIONS = {  # name -> (sympy function, arity)
    "sin": (sp.sin, 1), "cos": (sp.cos, 1), "tan": (sp.tan, 1), "asin": (sp.asin, 1),
    "acos": (sp.acos, 1), "atan": (sp.atan, 1), "atan2": (sp.atan2, 2), "sinh": (sp.sinh, 1),
    "cosh": (sp.cosh, 1), "tanh": (sp.tanh, 1), "exp": (sp.exp, 1), "log": (sp.log, 1),
    "sqrt": (sp.sqrt, 1), "abs": (sp.Abs, 1), "sign": (sp.sign, 1), "min": (Min, None),
    "max": (Max, None),
}

FIELDS_ONE_PORT = ("e", "f")
MAX_EXACT_INTEGER = 2 ** 53  # integral literals up to this are exact SymPy integers
MAX_EXACT_POWER = 64  # number ** integer with a larger exponent is computed in floating point
LOG10_MAX_DOUBLE = math.log10(sys.float_info.max)
MIN_NORMAL_DOUBLE = sys.float_info.min


class _Scope:
    """What a name means: parameter, signal, element, or a law's own variable."""

    def __init__(self, params, signals, elements):
        self.params = params  # name -> decl (in order)
        self.signals = signals
        self.elements = elements
        self.local: dict[str, sp.Symbol] = {}
        self.params_only = False
        self.visible_params: set[str] | None = None
        self.entries = 0  # of the vectors and matrices built so far, over the whole model
        self.discretes: dict = {}  # name -> DiscreteDecl
        self.events = EventTable()  # the relations and time sources met, numbered in order
        self.owner: str | None = None  # the element whose law is being built
        self.when_condition = False  # building a when-block's condition (initial() allowed)
        self.tables: list = []  # bgc.front.tables.TableData, in the order met
        self.inputs: list = []  # graph.InputInfo, in declaration order
        self.directory = "."  # the model file's: its table files are read relative to it (a
        #                       library's, relative to the library)
        self.constants: dict = {}  # the model file's (indices in scenes: `outputs s[N].q`)
        self.text = ""  # the model file's text: conditions are named as written in it

    def charge(self, n: int, span: Span):
        """Count n more vector or matrix entries against MAX_MATRIX_ENTRIES, before or as
        they are built: each operation on vectors costs what it builds."""
        self.entries += n
        if self.entries > MAX_MATRIX_ENTRIES:
            fail(span, f"the model is too large: its expressions build more than "
                       f"{MAX_MATRIX_ENTRIES} vector and matrix entries in all")


class _ExprBuilder:
    def __init__(self, scope: _Scope, diags: Collector | None):
        self.scope = scope
        self.diags = diags
        self.refs: list = []

    def build(self, node, condition: bool = False) -> Expr:
        """The expression of node: a number (a condition if asked: a `when` block's)."""
        self.refs = []
        self.noevent = 0
        value = self._evaluate(node)
        if condition and not is_condition(value):
            fail(node.span, "a condition is needed here (a relation such as x > 0), "
                            "not a number")
        if not condition:
            self._number_operand(value, node)
        if value.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
            fail(node.span, "expression is not finite (division by zero?)")
        if value.has(sp.I):
            fail(node.span, "expression is not a real number")
        for number in sorted(value.atoms(sp.Number), key=abs):
            _check_double(number, node.span)
        _check_exponents(value, node.span)
        return Expr(value, tuple(self.refs), node.span)

    def _evaluate(self, root):
        """Post-order evaluation with an explicit stack; values accumulate on `done`."""
        done: list = []
        todo: list = [(None, root)]
        while todo:
            action, node = todo.pop()
            if action is not None:
                action(node, done)
                if not done or is_condition(done[-1]):
                    continue
                if _is_matrix(done[-1]):
                    self.scope.charge(len(done[-1]), root.span)
                elif done[-1].is_Number:  # before a function can take it: sinh(1e308)
                    _check_double(done[-1], _span_of(node))
                continue
            if isinstance(node, ast.BinOp) and node.op in "+-*/":
                operands = _chain(node)
                todo.append((self._combine, (node.op in "+-", operands)))
                todo.extend((None, n) for _, n in reversed(operands))
            elif isinstance(node, ast.BinOp):  # ^
                todo.append((self._power, node))
                todo.extend(((None, node.right), (None, node.left)))
            elif isinstance(node, ast.Neg):
                todo.append((_negate, node))
                todo.append((None, node.operand))
            elif isinstance(node, ast.Call) and node.func == "noevent":
                if len(node.args) != 1:
                    fail(node.span, f"noevent() takes 1 argument, got {len(node.args)}")
                todo.append((self._end_noevent, node))
                todo.append((None, node.args[0]))
                todo.append((self._begin_noevent, node))
            elif isinstance(node, ast.Call) and node.func == "table":
                source, x = self._check_table(node)
                todo.append((self._table, node))
                todo.append((None, x))
                if isinstance(source, ast.Vector):
                    todo.append((None, source))
            elif isinstance(node, ast.Call) and node.func in SOURCES:
                self._check_source(node)
                todo.append((self._source, node))
                todo.extend((None, a) for a in reversed(node.args))
            elif isinstance(node, ast.Call):
                self._check_call(node)
                todo.append((self._apply, node))
                todo.extend((None, a) for a in reversed(node.args))
            elif isinstance(node, ast.Compare):
                todo.append((self._compare, node))
                todo.extend(((None, node.right), (None, node.left)))
            elif isinstance(node, ast.BoolOp):
                todo.append((self._boolop, node))
                todo.extend((None, a) for a in reversed(node.items))
            elif isinstance(node, ast.IfExpr):
                todo.append((self._ifexpr, node))
                todo.append((None, node.orelse))
                for cond, value in reversed(node.branches):
                    todo.extend(((None, value), (None, cond)))
            elif isinstance(node, ast.Vector):
                todo.append((self._vector, node))
                todo.extend((None, a) for a in reversed(node.items))
            elif isinstance(node, ast.Index):
                todo.append((self._index, node))
                todo.extend(((None, node.index), (None, node.base)))
            else:
                done.append(self._leaf(node))
                if _is_matrix(done[-1]):
                    self.scope.charge(len(done[-1]), root.span)
        (value,) = done
        return value

    # -- conditions (docs/hybrid.md)

    def _number_operand(self, v, node):
        if is_condition(v):
            fail(node.span, "a condition is not a number: write 'if C then 1 else 0' for "
                            "its value")

    def _condition_operand(self, v, node):
        if not is_condition(v):
            fail(node.span, "a condition is needed here (a relation such as x > 0), not a "
                            "number")

    def _begin_noevent(self, node, done):
        self.noevent += 1

    def _end_noevent(self, node, done):
        self.noevent -= 1
        self._number_operand(done[-1], node.args[0])

    def _compare(self, node: ast.Compare, done):
        b = done.pop()
        a = done.pop()
        for v, n in ((a, node.left), (b, node.right)):
            self._number_operand(v, n)
            if _is_matrix(v):
                fail(n.span, f"a relation compares scalars, not {_shape(v)}")
        rel = RELATIONS[node.op](a, b)
        if rel in (sp.true, sp.false) or not rel.free_symbols - self._constants():
            done.append(rel)  # of parameters alone: no event
            return
        if self.noevent:
            done.append(rel)  # evaluated as it is, at every call
            return
        if node.op in ("==", "!=") and not rel.free_symbols <= self._constants() | set(
                var(n) for n in self.scope.discretes):
            fail(node.span, f"'{node.op}' on a quantity that varies continuously is almost "
                            "never exactly true; write a crossing with <, <=, > or >=")
        done.append(self.scope.events.relation(rel, node, self.scope.owner,
                                               self._written(node)))

    def _written(self, node, suffix: str = "") -> str | None:
        """node as the model writes it (bgc.front.spelling), suffix after it; None if unknown."""
        text = as_written(node, self.scope.text, self.scope.local)
        return text + suffix if text else None

    def _constants(self) -> set:
        return {var(n) for n in self.scope.params}

    def _boolop(self, node: ast.BoolOp, done):
        items = done[len(done) - len(node.items):]
        del done[len(done) - len(node.items):]
        for v, n in zip(items, node.items):
            self._condition_operand(v, n)
        op = {"and": sp.And, "or": sp.Or, "not": sp.Not}[node.op]
        done.append(op(*items))

    def _ifexpr(self, node: ast.IfExpr, done):
        n = 2 * len(node.branches) + 1
        items = done[len(done) - n:]
        del done[len(done) - n:]
        pairs = []
        for k, (cond, value) in enumerate(node.branches):
            c, v = items[2 * k], items[2 * k + 1]
            self._condition_operand(c, cond)
            self._number_operand(v, value)
            pairs.append((v, c))
        orelse = items[-1]
        self._number_operand(orelse, node.orelse)
        values = [v for v, _ in pairs] + [orelse]
        if any(_is_matrix(v) for v in values):
            fail(node.span, "the branches of 'if' are scalars (write one 'if' per entry)")
        done.append(sp.Piecewise(*pairs, (orelse, True)))

    def _check_source(self, node: ast.Call):
        low, high = SOURCES[node.func]
        if not low <= len(node.args) <= high:
            want = str(low) if low == high else f"{low} or {high}"
            fail(node.span, f"{node.func}() takes {want} argument{'s' * (high > 1)}, got "
                            f"{len(node.args)}")
        if self.scope.params_only:
            fail(node.span, f"{node.func}() varies in time: only parameters are allowed here")

    def _source(self, node: ast.Call, done):
        """step, ramp, pulse, square: their time events; initial()."""
        n = len(node.args)
        args = done[len(done) - n:] if n else []
        del done[len(done) - n:]
        for a, sub in zip(args, node.args):
            self._number_operand(a, sub)
            if _is_matrix(a) or a.free_symbols - self._constants():
                fail(sub.span, f"the arguments of {node.func}() are parameters or numbers")
        if node.func == "initial":
            if not self.scope.when_condition:
                fail(node.span, "initial() is a when-block's condition (true at the start of "
                                "a run only)")
            done.append(INITIAL)
            return
        ev = self.scope.events
        if node.func == "square":
            period, duty = args[0], args[1]
            t0 = args[2] if n > 2 else sp.Integer(0)
            if period.is_Number and not period > 0:
                fail(node.args[0].span, "the period of square() must be positive")
            if duty.is_Number and not 0 <= duty <= 1:
                fail(node.args[1].span, "the duty of square() is a fraction, from 0 to 1")
            done.append(ev.square(period, duty, t0, node, self._written(node)))
            return
        on = ev.relation(sp.GreaterThan(TIME, args[0]), node, None, self._written(node))
        if node.func == "step":
            done.append(sp.Piecewise((sp.Integer(1), on), (sp.Integer(0), True)))
        elif node.func == "ramp":
            done.append(sp.Piecewise((TIME - args[0], on), (sp.Integer(0), True)))
        else:  # pulse(t0, width)
            if args[1].is_Number and args[1] < 0:
                fail(node.args[1].span, "the width of pulse() cannot be negative")
            off = ev.relation(sp.GreaterThan(TIME, args[0] + args[1]), node, None,
                              self._written(node, ": end"))
            done.append(sp.Piecewise((sp.Integer(1), sp.And(on, sp.Not(off))),
                                     (sp.Integer(0), True)))

    def _combine(self, item, done):
        additive, operands = item
        values = done[len(done) - len(operands):]
        del done[len(done) - len(operands):]
        for (_, n), v in zip(operands, values):
            self._number_operand(v, n)
        if any(_is_matrix(v) for v in values):
            done.append(_matrix_chain(additive, operands, values, self.scope))
            return
        if additive:
            done.append(sp.Add(*[v if s > 0 else -v for (s, _), v in zip(operands, values)]))
            return
        factors = []
        for (s, n), v in zip(operands, values):
            if s < 0 and v.is_zero:
                fail(n.span, "division by zero")
            factors.append(v if s > 0 else 1 / v)
        done.append(sp.Mul(*factors))

    def _power(self, node, done):
        b = done.pop()
        a = done.pop()
        self._number_operand(a, node.left)
        self._number_operand(b, node.right)
        if _is_matrix(a) or _is_matrix(b):
            fail(node.span, "'^' takes scalars, not vectors or matrices")
        if a.is_Number and b.is_Number:
            done.append(_number_power(a, b, node.span))
        elif a.is_number and b.is_Rational and max(abs(b.p), b.q) > MAX_EXACT_POWER:
            # a constant that is not a number yet (sqrt(15)) to a large exact exponent: SymPy
            # would compute 15^(18^64/2) exactly (forever); in floating point, as for numbers
            try:
                x = float(a)
            except (TypeError, OverflowError):
                fail(node.span, "value does not fit a double")
            done.append(_number_power(sp.Float(x), b, node.span))
        elif b.is_Rational and abs(b) > MAX_SYMBOLIC_EXPONENT:
            # refused before SymPy builds it: (15/p)^(3^17) would compute 15^(3^17) exactly
            _refuse_exponent(sp.Pow(a, b, evaluate=False), node.span)
        else:
            done.append(a ** b)

    def _apply(self, node, done):
        args = done[len(done) - len(node.args):]
        del done[len(done) - len(node.args):]
        for a, sub in zip(args, node.args):
            self._number_operand(a, sub)
        if node.func == "diag":
            if len(args) == 1 and _is_matrix(args[0]) and args[0].cols == 1:
                args = list(args[0])
            if any(_is_matrix(a) for a in args):
                fail(node.span, "diag() takes scalars, or one vector")
            self.scope.charge(len(args) ** 2, node.span)
            done.append(sp.ImmutableMatrix(sp.diag(*args)))
            return
        if any(_is_matrix(a) for a in args):
            fail(node.span, f"{node.func}() takes scalars, not vectors or matrices")
        func, _ = FUNCTIONS[node.func]
        value = func(*args)
        if not value.free_symbols and not value.is_Number:
            _check_constant(value, node.span)
        done.append(value)

    def _vector(self, node: ast.Vector, done):
        """[a, b, ...]: a column vector of scalars, or a matrix whose rows are [..] vectors."""
        items = done[len(done) - len(node.items):]
        del done[len(done) - len(node.items):]
        for v, sub in zip(items, node.items):
            self._number_operand(v, sub)
        if not any(_is_matrix(v) for v in items):
            done.append(sp.ImmutableMatrix(len(items), 1, list(items)))
            return
        if not all(_is_matrix(v) and v.cols == 1 for v in items):
            fail(node.span, "a matrix is written [[a, b], [c, d]]: every row a vector")
        width = items[0].rows
        for item, sub in zip(items, node.items):
            if item.rows != width:
                fail(sub.span, f"this row has {item.rows} entries, the first one {width}")
        done.append(sp.ImmutableMatrix([list(v) for v in items]))

    def _index(self, node: ast.Index, done):
        i = done.pop()
        base = done.pop()
        if not _is_matrix(base):
            fail(node.span, "only a vector or a matrix can be indexed")
        if _is_matrix(i) or not i.is_Integer:
            fail(node.index.span, "an index is a whole number (0-based)")
        rows = base.rows
        if not 0 <= int(i) < rows:
            fail(node.index.span, f"index {int(i)} is out of range (0 .. {rows - 1})")
        if base.cols == 1:
            done.append(base[int(i), 0])
        else:
            done.append(sp.ImmutableMatrix(base.row(int(i)).T))

    # -- tables (bgc.front.tables)

    def _check_table(self, node: ast.Call):
        """table(SOURCE, X, interp = ..., extrapolate = ..., column = "..."): (SOURCE, X)."""
        if self.scope.params_only:
            fail(node.span, "a table cannot be used here: only parameters are allowed")
        plain = [a for a in node.args if not isinstance(a, ast.KwArg)]
        if len(plain) != 2 or any(isinstance(a, ast.KwArg) for a in node.args[:2]):
            fail(node.span, "table() takes a file (\"road.csv\") or rows ([[x0, y0], [x1, y1], "
                            "...]), then the abscissa X, then any of interp = linear | step | "
                            "cubic, extrapolate = hold | linear | error, column = \"name\"")
        source, x = plain
        if isinstance(x, ast.Str):
            fail(x.span, "the abscissa of a table is an expression, not a string")
        seen = set()
        for a in node.args[2:]:
            if a.name not in ("interp", "extrapolate", "column"):
                fail(a.span, f"table() has no option '{a.name}' (it has interp, extrapolate, "
                             "column)")
            if a.name in seen:
                fail(a.span, f"'{a.name}' is given twice")
            seen.add(a.name)
            if a.name == "column":
                if not isinstance(a.value, ast.Str):
                    fail(a.value.span, 'the column is a string: column = "name"')
                if isinstance(source, ast.Vector):
                    fail(a.span, "column = picks a column of a file; a table written as rows "
                                 "has one")
                continue
            choices = INTERP if a.name == "interp" else EXTRAPOLATE
            if not (isinstance(a.value, ast.Name) and a.value.name in choices):
                shown = a.value.name if isinstance(a.value, ast.Name) else "this"
                fail(a.value.span, f"{a.name} is one of {', '.join(choices)}, not {shown}")
        if not isinstance(source, (ast.Str, ast.Vector, ast.Field)) or (
                isinstance(source, ast.Field) and source.field != "csv"):
            fail(source.span, "a table's data is a file (\"road.csv\", or road.csv) or rows "
                              "[[x0, y0], [x1, y1], ...]")
        return source, x

    def _table(self, node: ast.Call, done):
        source = node.args[0]
        x = done.pop()
        rows = done.pop() if isinstance(source, ast.Vector) else None
        xarg = node.args[1]
        self._number_operand(x, xarg)
        if _is_matrix(x):
            fail(xarg.span, "the abscissa of a table is a scalar")
        options = {a.name: a.value for a in node.args[2:]}
        interp = options["interp"].name if "interp" in options else "linear"
        extrapolate = options["extrapolate"].name if "extrapolate" in options else "hold"
        if len(self.scope.tables) >= MAX_TABLES:
            fail(node.span, f"a model has at most {MAX_TABLES} tables")
        if rows is None:
            import os
            shown = source.text if isinstance(source, ast.Str) else f"{source.owner}.csv"
            origin = source.span.origin  # a component's text: its library file
            where = os.path.dirname(origin.name) if origin is not None and origin.file \
                else self.scope.directory
            path = os.path.join(where, shown)
            column = options.get("column")
            xs, ys, _, _ = read_csv(path, path, column.text if column else None, source.span,
                                    column.span if column else None)
            name = shown
        else:
            if rows.cols != 2:
                fail(source.span, "a table written as rows has two columns: [[x0, y0], [x1, y1], "
                                  "...]")
            if rows.rows > MAX_TABLE_ROWS:
                fail(source.span, f"the table has {rows.rows} rows; the limit is {MAX_TABLE_ROWS}")
            xs, ys = [], []
            for i in range(rows.rows):
                for v, store in ((rows[i, 0], xs), (rows[i, 1], ys)):
                    if not v.is_Number:
                        fail(source.items[i].span, "a table's rows are numbers")
                    store.append(float(v))
            check_rows(xs, ys, [it.span for it in source.items], source.span)
            name = "rows"
        k = len(self.scope.tables)
        time = x == TIME
        try:
            data = build(name, xs, ys, interp, extrapolate, time, path if rows is None else "")
        except OverflowError:
            fail(source.span, "the table's slopes are too large for a double (rows too close "
                              "for the change of y)")
        self.scope.tables.append(data)
        if time:
            piece = self.scope.events.time_table(  # (named as written: the event log, check)
                k, self._written(node) or f"table({name}, t)", node.span)
        else:
            piece = sp.Integer(-1)
        needs = {piece} if time else x.free_symbols
        if extrapolate == "error" and needs:
            self.scope.events.guard(
                sp.GreaterThan(TableGuard(sp.Integer(k), x), 0),
                f"{self._written(node) or f'table {k} ({name})'} is read outside its rows, x "
                f"from {xs[0]!r} to {xs[-1]!r} (extrapolate = error)", node.span, needs)
        done.append(Table(sp.Integer(k), x, piece, sp.Integer(0)))

    def _check_call(self, node: ast.Call):
        for a in node.args:
            if isinstance(a, (ast.Str, ast.KwArg)):
                fail(a.span, f"{node.func}() takes no {'string' if isinstance(a, ast.Str) else 'named'} "
                             "arguments")
        if node.func == "diag":
            if not node.args:
                fail(node.span, "diag() takes at least one argument")
            return
        if node.func not in FUNCTIONS:
            fail(node.span, f"unknown function '{node.func}'")
        _, arity = FUNCTIONS[node.func]
        if arity is not None and len(node.args) != arity:
            fail(node.span, f"{node.func}() takes {arity} argument{'s' * (arity > 1)}, "
                            f"got {len(node.args)}")
        if arity is None and len(node.args) < 2:
            fail(node.span, f"{node.func}() takes at least 2 arguments")
        if arity is None and len(node.args) > MAX_EXTREMUM_ARGUMENTS:
            fail(node.span, f"{node.func}() takes at most {MAX_EXTREMUM_ARGUMENTS} arguments, "
                            f"got {len(node.args)} (nest them for more)")

    def _leaf(self, node):
        if isinstance(node, ast.Num):
            return _number(node)
        if isinstance(node, ast.Name):
            return self._name(node)
        if isinstance(node, ast.Field):
            return self._field(node)
        if isinstance(node, ast.Member):
            fail(node.span, f"'.{node.name}' follows something that is not a name")
        fail(node.span, "unexpected expression")

    def _name(self, node: ast.Name):
        s = self.scope
        if node.name in s.local:
            return s.local[node.name]
        if node.name == "t":
            if s.params_only:
                fail(node.span, "'t' cannot be used here: only parameters are allowed")
            return TIME
        if node.name in s.params:
            if s.visible_params is not None and node.name not in s.visible_params:
                fail(node.span, f"parameter '{node.name}' is used before it is defined",
                     Note(s.params[node.name].span, f"'{node.name}' is defined here"))
            self.refs.append((node.name, node.span))
            return var(node.name)
        if node.name in s.discretes:
            declared = Note(s.discretes[node.name].name.span, f"'{node.name}' is declared here")
            if s.visible_params is not None:  # (a parameter's definition)
                fail(node.span, f"a parameter cannot depend on a discrete variable: '{node.name}' "
                                "changes at events, a parameter is fixed for the run", declared)
            if s.params_only:
                fail(node.span, f"'{node.name}' is a discrete variable: only parameters are "
                                "allowed here", declared)
            self.refs.append((node.name, node.span))
            return var(node.name)
        if node.name in s.signals:
            if s.params_only:
                fail(node.span, f"'{node.name}' is a signal: only parameters are allowed here")
            self.refs.append((node.name, node.span))
            n = _dim_of(s.signals[node.name])
            if n is not None:
                return sp.ImmutableMatrix([var(part_name(node.name, i)) for i in range(n)])
            return var(node.name)
        if node.name in s.elements:
            fail(node.span, f"'{node.name}' is an element; name one of its variables "
                            f"({node.name}.e, {node.name}.f, ...)")
        fail(node.span, f"unknown name '{node.name}'")

    def _field(self, node: ast.Field):
        s = self.scope
        if s.params_only:
            fail(node.span, f"'{node.owner}.{node.field}' cannot be used here: only parameters "
                            "are allowed")
        decl = s.elements.get(node.owner)
        if decl is None:
            what = "a parameter" if node.owner in s.params else (
                "a signal" if node.owner in s.signals else None)
            if what:
                fail(node.span, f"'{node.owner}' is {what} and has no field '{node.field}'")
            fail(node.span, f"unknown element '{node.owner}'")
        allowed = _fields_of(decl)
        if node.field not in allowed:
            options = ", ".join(f"{node.owner}.{f}" for f in allowed) or "none"
            fail(node.span, f"'{node.owner}' ({decl.kind.name}) has no variable "
                            f"'{node.field}' (it has: {options})")
        if node.field == "residual":
            fail(node.span, f"'{node.owner}.residual' can only be asked for as an output")
        self.refs.append((node.owner, node.span))
        n = _dim_of(decl)
        if n is not None:
            return sp.ImmutableMatrix([var(variable_name(part_name(node.owner, i), node.field))
                                       for i in range(n)])
        return var(variable_name(node.owner, node.field))


def _is_matrix(v) -> bool:
    return isinstance(v, sp.MatrixBase)


def _dim_of(decl) -> int | None:
    """The components of a vector signal or multiport (its output side), None for scalars."""
    d = getattr(decl, "dim", None)
    if d is None:
        return None
    n = d.m if d.m is not None else d.n
    return None if n == 1 and d.n == 1 else n


def _matrix_chain(additive, operands, values, scope: _Scope):
    """A chain of + and - (or * and /) with vectors or matrices among its operands; a matrix
    product is charged to the scope before it is computed."""
    acc = values[0]
    if additive:
        acc = acc if operands[0][0] > 0 else -acc
        for (sign, n), v in zip(operands[1:], values[1:]):
            if _is_matrix(acc) != _is_matrix(v) or (_is_matrix(v) and acc.shape != v.shape):
                fail(n.span, f"cannot add {_shape(v)} to {_shape(acc)}")
            acc = acc + v if sign > 0 else acc - v
        return acc
    for (sign, n), v in zip(operands[1:], values[1:]):
        if sign < 0:
            if _is_matrix(v):
                fail(n.span, "division by a vector or a matrix")
            if v.is_zero:
                fail(n.span, "division by zero")
            acc = acc / v
        elif _is_matrix(acc) and _is_matrix(v):
            if acc.cols != v.rows:
                fail(n.span, f"cannot multiply {_shape(acc)} by {_shape(v)}")
            scope.charge(acc.rows * acc.cols * v.cols, n.span)
            acc = acc * v
        else:
            acc = acc * v
    return sp.ImmutableMatrix(acc) if _is_matrix(acc) else acc


def _shape(v) -> str:
    if not _is_matrix(v):
        return "a scalar"
    if v.cols == 1:
        return f"a vector of {v.rows}"
    return f"a {v.rows}x{v.cols} matrix"


def _chain(node: ast.BinOp):
    """The operands of a chain of + and - (or of * and /) as [(sign, node)], left to right:
    a - (b + c) gives [(+1, a), (-1, b), (-1, c)]; for products the sign says divide."""
    group = "+-" if node.op in "+-" else "*/"
    out, stack = [], [(1, node)]
    while stack:
        sign, n = stack.pop()
        if isinstance(n, ast.BinOp) and n.op in group:
            stack.append((sign if n.op in "+*" else -sign, n.right))
            stack.append((sign, n.left))
        else:
            out.append((sign, n))
    return out


def _span_of(item) -> Span:
    """The span of what an action of _evaluate built: a node, or a chain (see _combine)."""
    if isinstance(item, tuple):
        operands = item[1]
        return operands[0][1].span.join(operands[-1][1].span)
    return item.span


def _negate(node, done):
    if is_condition(done[-1]):
        fail(node.span, "a condition is not a number: write 'not C' to negate it")
    done.append(-done.pop())


def _number(node: ast.Num):
    text = node.text
    if text.isdigit():
        digits = text.lstrip("0")
        if len(digits) > MAX_LITERAL_DIGITS:  # before int(), which refuses over 4300 digits
            fail(node.span, f"number {text[:20]}... does not fit a double")
        value = int(text)
        if value <= MAX_EXACT_INTEGER:
            return sp.Integer(value)
        try:
            x = float(value)  # rounded to the nearest double, as the docs say
        except OverflowError:  # 309 digits beyond 1.8e308
            fail(node.span, f"number {text[:20]}... does not fit a double (the largest is "
                            "about 1.8e308)")
    else:
        x = float(text)  # the grammar admits decimal numbers only
    if not math.isfinite(x):
        fail(node.span, f"number {text} does not fit a double")
    if x != 0.0 and abs(x) < MIN_NORMAL_DOUBLE:
        fail(node.span, f"number {text} is too small for a normal double")
    if x.is_integer() and abs(x) <= MAX_EXACT_INTEGER:
        return sp.Integer(int(x))  # 2.0 is the integer 2: no 1.0*x in the equations
    return sp.Float(x)


def _number_power(a, b, span):
    """a ** b for numbers, refused when it does not fit a double, decided from the magnitude
    before computing it; exact only for small integer exponents, else in floating point."""
    if a.is_negative and not b.is_Integer:
        fail(span, "expression is not a real number (a negative number to a fractional power)")
    if a.is_zero:
        if b.is_negative:
            fail(span, "division by zero (0 to a negative power)")
        return sp.Integer(0) if b != 0 else sp.Integer(1)
    magnitude = float(b) * math.log10(abs(float(a)))
    if magnitude > LOG10_MAX_DOUBLE:
        fail(span, "number does not fit a double")
    if b.is_Integer and abs(int(b)) <= MAX_EXACT_POWER and (a.is_Rational or abs(magnitude) < 300):
        return a ** b
    try:
        x = math.pow(float(a), float(b))
    except OverflowError:  # at the edge of the range, where the magnitude test rounds
        fail(span, "number does not fit a double")
    if abs(x) < MIN_NORMAL_DOUBLE:
        fail(span, "number is too small for a normal double (it would be 0)")
    return sp.Float(x)


def _check_double(number, span):
    """A constant that the generated code would compute as inf or 0 is refused."""
    try:
        x = float(number)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        fail(span, "number does not fit a double")
    if not number.is_zero and abs(x) < MIN_NORMAL_DOUBLE:
        fail(span, "number is too small for a normal double (it would be 0)")


def _check_exponents(value, span):
    """x^n with n a whole number beyond MAX_SYMBOLIC_EXPONENT is refused before any symbolic
    work on it: SymPy's assumptions expand it to decide whether it is real (minutes for n =
    1000).  Checked on the built expression, since products and powers merge (x^40 * x^40)."""
    for p in sorted(value.atoms(sp.Pow), key=sp.default_sort_key):
        if p.exp.is_Integer and abs(int(p.exp)) > MAX_SYMBOLIC_EXPONENT and not p.base.is_Number:
            _refuse_exponent(p, span)


def _refuse_exponent(p, span):
    fail(span, f"the power {written(p)} has too large an exponent for symbolic work "
               f"(at most {MAX_SYMBOLIC_EXPONENT}); give the exponent as a parameter "
               "to have the power computed numerically")


def _check_constant(value, span):
    """A function of numbers (exp(1000), asin(2)) must be a real number that fits a double,
    as the generated code computes it (one call at a time, in doubles)."""
    try:
        z = complex(value.evalf(20))
    except (OverflowError, TypeError, ValueError):
        fail(span, "value does not fit a double")
    if z.imag != 0:
        fail(span, "expression is not a real number")
    if not math.isfinite(z.real):
        fail(span, "value does not fit a double")


def _fields_of(decl: ast.ElementDecl) -> tuple[str, ...]:
    k = decl.kind.name
    if k in SWITCHED:
        return FIELDS_ONE_PORT
    if k == "0":
        base = ("e",)
    elif k == "1":
        base = ("f",)
    elif k in KINDS and KINDS[k].ports == 1:
        base = FIELDS_ONE_PORT + ((KINDS[k].state,) if KINDS[k].state else ())
    else:
        base = ()
    if decl.constraint is not None:
        base = base + ("lambda", "residual")
    return base


# ---------------------------------------------------------------- declarations

def _collect_names(model: ast.Model, diags: Collector):
    params, signals, elements, first = {}, {}, {}, {}
    for d in model.decls:
        if isinstance(d, (ast.ParamDecl, ast.SignalDecl, ast.IntegralDecl, ast.ElementDecl,
                          ast.DiscreteDecl, ast.InputDecl)):
            name = d.name.name
            if name == "t":
                diags.error(d.name.span, "'t' is time and cannot be declared")
                continue
            if name in first:
                diags.error(d.name.span, f"'{name}' is declared twice",
                            Note(first[name], f"first declaration of '{name}'"))
                continue
            first[name] = d.name.span
            if isinstance(d, ast.DiscreteDecl):
                continue  # resolve() collects them (names taken here, so checked once)
            table = (params if isinstance(d, ast.ParamDecl) else
                     signals if isinstance(d, (ast.SignalDecl, ast.IntegralDecl, ast.InputDecl))
                     else elements)
            table[name] = d
    return params, signals, elements


def _model_decl(model: ast.Model, diags: Collector):
    decls = [d for d in model.decls if isinstance(d, ast.ModelDecl)]
    if not model.decls or not isinstance(model.decls[0], ast.ModelDecl):
        span = model.decls[0].span if model.decls else Span(1, 1, 1, 2)
        diags.error(span, "a model file must start with 'model NAME'")
        diags.raise_if_errors()
    for extra in decls[1:]:
        diags.error(extra.span, "only one 'model' statement is allowed per file",
                    Note(decls[0].span, "the model is declared here"))
    return decls[0]


def _guard(diags: Collector, fn, *args):
    """Run fn; turn its ModelError into collected diagnostics (so one stage reports them all)."""
    try:
        return fn(*args)
    except ModelError as exc:
        diags.items.extend(exc.diagnostics)
        return None


def _parameters(params, scope: _Scope, diags: Collector):
    out, seen = [], set()
    for name, d in params.items():
        scope.params_only, scope.visible_params = True, seen
        e = _guard(diags, _ExprBuilder(scope, diags).build, d.expr)
        if e is not None and _is_matrix(e.value):
            diags.error(d.expr.span, f"parameter '{name}' is {_shape(e.value)}: parameters are "
                                     "scalars (write vectors where they are used)")
            e = None
        seen.add(name)
        if e is not None:
            out.append(Parameter(name, e, d.doc, d.span, d.unit))
    scope.params_only, scope.visible_params = False, None
    return out


def _element(d: ast.ElementDecl, scope: _Scope, diags: Collector) -> Element | None:
    kname = d.kind.name
    dim = _element_dim(d)
    if d.is_junction:
        constraint = _constraint(d, scope) if d.constraint is not None else None
        return Element(d.name.name, kname, None, None, None, tuple(e.name for e in d.effects),
                       constraint, d.doc, d.span, d.name.span, dim)
    if kname in SWITCHED:
        return _switched(d, scope, diags)
    if kname not in KINDS:
        if kname.isdigit():
            fail(d.kind.span, f"unknown junction kind '{kname}': junctions are 0 or 1")
        fail(d.kind.span, f"unknown kind '{kname}' (known: {known_kinds()})")
    spec = KINDS[kname]
    if len(d.args) != 1:
        fail(d.span, f"{kname} takes one argument, got {len(d.args)}")
    arg = d.args[0]
    value = law = None
    if arg.law is None:
        value = _ExprBuilder(scope, diags).build(arg.expr)
    else:
        if arg.law.name not in spec.laws:
            allowed = " or ".join(f"'{v} = ...'" for v in spec.laws) or "no law form"
            fail(arg.law.span, f"{kname} law must be written {allowed}")
        law = (arg.law.name, _with_own_vars(d, scope, diags, arg.expr))
    init = _init(d, spec, scope, diags)
    return Element(d.name.name, kname, value, law, init, tuple(e.name for e in d.effects),
                   None, d.doc, d.span, d.name.span, dim)


def _junction_switch(d: ast.ElementDecl, scope: _Scope, diags: Collector) -> Element:
    """A controlled junction `J : 1 switch(COND)` (`0`): on while COND holds, a plain
    junction; off, its common flow (effort) zero on all its bonds.  It is the junction with an
    ideal switch `J.switch` on one more bond: a 1-junction's common flow is the switch's flow,
    so the switch is closed while on; a 0-junction's common effort is the switch's effort, so
    it is closed while off."""
    if d.constraint is not None:
        fail(d.span, "a constraint junction cannot also be switched")
    if d.dim is not None:
        fail(d.dim.span, "a switched junction is scalar (one switch per junction)")
    cond = _ExprBuilder(scope, diags).build(d.switch, condition=True)
    if d.kind.name == "0":
        cond = replace(cond, value=sp.Not(cond.value))
    constraint = Constraint("switch", None, "none", (cond,), None, d.span)
    return Element(f"{d.name.name}.switch", "0", None, None, None,
                   tuple(e.name for e in d.effects), constraint,
                   f"the switch of junction '{d.name.name}'", d.span, d.name.span)


def _switched(d: ast.ElementDecl, scope: _Scope, diags: Collector) -> Element:
    """A switched one-port as the constraint junction it is in one of its modes: the ideal
    diode `D` blocks as a junction whose flow balance (its one bond's flow) must stay zero,
    its effort the multiplier, and conducts as a junction of effort zero (bgc.middle.contact)."""
    kname = d.kind.name
    if d.dim is not None:
        fail(d.dim.span, f"{kname} is a scalar one-port")
    if len(d.args) != SWITCHED[kname]:
        if kname == "D":
            fail(d.span, f"D takes no arguments: write '{d.name.name} : D'")
        if kname == "Sw":
            fail(d.span, f"Sw takes one argument, its condition: Sw(COND), closed while COND "
                         f"holds, got {len(d.args)}")
        fail(d.span, f"{kname} takes {SWITCHED[kname]} arguments, Fr(Fc, Fs): the sliding "
                     f"and the sticking friction force, got {len(d.args)}")
    if d.inits:
        fail(d.inits[0].span, f"{kname} has no state to initialise")
    gains = ()
    if kname == "Sw":
        if d.args[0].law is not None:
            fail(d.args[0].span, "Sw takes its condition as a plain argument: Sw(COND)")
        gains = (_ExprBuilder(scope, diags).build(d.args[0].expr, condition=True),)
    if kname == "Fr":
        if any(a.law is not None for a in d.args):
            fail(d.span, "Fr takes its forces as plain arguments: Fr(Fc, Fs)")
        gains = tuple(_ExprBuilder(scope, diags).build(a.expr) for a in d.args)
        for g in gains:
            if _is_matrix(g.value):
                fail(g.span, "a friction force is a scalar")
            if g.value.is_Number and g.value < 0:
                fail(g.span, "a friction force is not negative")
    constraint = Constraint({"D": "diode", "Fr": "friction", "Sw": "switch"}[kname], None, "none",
                            gains, None, d.span)
    return Element(d.name.name, "0", None, None, None, tuple(e.name for e in d.effects),
                   constraint, d.doc, d.span, d.name.span, None, origin=None)


def _element_dim(d: ast.ElementDecl) -> tuple[int, int] | None:
    """(n, m) of a multiport, None for a scalar element; KIND[n->m] for two-ports only."""
    if d.dim is None:
        return None
    n, m = d.dim.n, d.dim.m
    if n < 1 or (m is not None and m < 1):
        fail(d.dim.span, "a dimension is at least 1")
    if m is not None and (d.is_junction or d.kind.name not in KINDS
                          or KINDS[d.kind.name].ports != 2):
        fail(d.dim.span, f"'[{n}->{m}]' belongs to two-ports (TF, MTF, GY, MGY); "
                         f"write '{d.kind.name}[{n}]'")
    m = n if m is None else m
    return None if n == m == 1 else (n, m)


def _with_own_vars(d, scope, diags, node) -> Expr:
    own = {v: var(variable_name(d.name.name, v)) for v in ("e", "f")}
    spec = KINDS[d.kind.name]
    if spec.state:
        own[spec.state] = var(variable_name(d.name.name, spec.state))
    scope.local = own
    scope.owner = d.name.name
    try:
        return _ExprBuilder(scope, diags).build(node)
    finally:
        scope.local = {}
        scope.owner = None


# ---------------------------------------------------------------- events


def _declare_discretes(model: ast.Model, scope: _Scope):
    """The discrete variables' names in scope (before any expression is built: a parameter
    that reads one is told so)."""
    for d in (d for d in model.decls if isinstance(d, ast.DiscreteDecl)):
        if d.name.name == "t" or d.name.name in scope.params or d.name.name in \
                scope.signals or d.name.name in scope.elements:
            continue  # reported by _collect_names
        scope.discretes[d.name.name] = d


def _discretes(scope: _Scope, diags: Collector) -> list[Discrete]:
    out = []
    for name, d in scope.discretes.items():
        scope.params_only = True
        try:
            e = _guard(diags, _ExprBuilder(scope, diags).build, d.expr)
        finally:
            scope.params_only = False
        if e is not None and _is_matrix(e.value):
            diags.error(d.expr.span, f"discrete variable '{name}' is a scalar, but this is "
                                     f"{_shape(e.value)}")
        elif e is not None:
            out.append(Discrete(name, var(name), e.value, d.doc, d.span))
    return out


def _when(d: ast.WhenBlock, scope: _Scope, diags: Collector) -> When:
    scope.when_condition = True
    try:
        cond = _ExprBuilder(scope, diags).build(d.condition, condition=True)
    finally:
        scope.when_condition = False
    actions, seen = [], {}
    for st in d.stmts:
        if isinstance(st, ast.Reinit):
            sym = _state_symbol(st.target, scope, diags)
            name, kind = sym.name, "reinit"
        else:
            name = st.name.name
            if name not in scope.discretes:
                what = ("a parameter" if name in scope.params else "a signal" if name in
                        scope.signals else None)
                hint = f" ('{name}' is {what}; a state takes 'reinit')" if what else ""
                fail(st.name.span, f"'{name}' is not a discrete variable: a when-block assigns "
                                   f"discrete variables and reinits states{hint}")
            sym, kind = var(name), "assign"
        if name in seen:
            fail(st.span, f"'{name}' is set twice in this when-block",
                 Note(seen[name], "first here"))
        seen[name] = st.span
        expr = _ExprBuilder(scope, diags).build(st.expr)
        if _is_matrix(expr.value):
            fail(st.expr.span, f"'{name}' is a scalar, but this is {_shape(expr.value)}")
        actions.append(Action(kind, name, sym, expr.value, st.span))
    shown = cond.value.xreplace({r.symbol: r.relation for r in scope.events.relations})
    text = as_written(d.condition, scope.text) or \
        written(shown).replace("initial#", "initial()")
    return When(cond.value, text, tuple(actions), d.span)


def _state_symbol(target, scope: _Scope, diags: Collector):
    """The symbol of a state named in a reinit: X.p of an I, X.q of a C, or an integral
    signal; a component `X.p[k]`, `x[k]` of a multiport's or a vector integral's (k a whole
    number, or an expression of constants)."""
    node, k = target, None
    if isinstance(target, ast.Index):
        node = target.base
        k = _ExprBuilder(scope, diags).build(target.index).value
        if _is_matrix(k) or not k.is_Integer:
            fail(target.index.span, "an index is a whole number (0-based)")
        k = int(k)
    if isinstance(node, ast.Name):
        name, owner, fld = node.name, None, None
    elif isinstance(node, ast.Field):
        name, owner, fld = f"{node.owner}.{node.field}", node.owner, node.field
    else:
        fail(target.span, "reinit takes a state: X.p of an I, X.q of a C, or an integral signal")
    shown = name if k is None else f"{name}[{k}]"
    if owner is None:
        d = scope.signals.get(name)
        if isinstance(d, ast.IntegralDecl):
            _check_part(name, _dim_of(d), k, target)
            return var(name if k is None else part_name(name, k))
        if name in scope.discretes:
            fail(target.span, f"'{name}' is a discrete variable: assign it without 'reinit'")
    else:
        d = scope.elements.get(owner)
        spec = KINDS.get(d.kind.name) if d is not None else None
        if spec is not None and spec.state and spec.state == fld:
            _check_part(name, _dim_of(d), k, target)
            return var(variable_name(owner if k is None else part_name(owner, k), fld))
    fail(target.span, f"'{shown}' is not a state: reinit takes X.p of an I, X.q of a C, or an "
                      "integral signal")


def _check_part(name: str, n: int | None, k: int | None, target):
    """A reinit names one scalar state: a scalar unindexed, or component k of a vector of n
    (refused out of range, or a vector reinit whole)."""
    if n is None and k is None:
        return
    if n is None:
        fail(target.index.span, f"'{name}' is a scalar: it has no index")
    if k is None:
        fail(target.span, f"'{name}' has {n} components: reinit them one by one "
                          f"({name}[0] = ...)")
    if not 0 <= k < n:
        fail(target.index.span, f"index {k} is out of range (0 .. {n - 1})")


def _init(d, spec, scope, diags):
    if not d.inits:
        return None
    if len(d.inits) > 1:
        fail(d.inits[1].span, f"'{d.name.name}' has more than one init clause")
    clause = d.inits[0]
    allowed = (spec.state, "f" if spec.state == "p" else "e") if spec.state else ()
    if clause.var.name not in allowed:
        if not allowed:
            fail(clause.span, f"{d.kind.name} has no state to initialise")
        fail(clause.var.span, f"{d.kind.name} is initialised by 'init {allowed[0]} = ...' or "
                              f"'init {allowed[1]} = ...'")
    scope.params_only = True
    try:
        return (clause.var.name, _ExprBuilder(scope, diags).build(clause.expr))
    finally:
        scope.params_only = False


def _constraint(d: ast.ElementDecl, scope) -> Constraint:
    c = d.constraint
    kind = c.kind.name if c.kind else None
    annotation = None
    if c.annotation is not None:
        which, node, span = c.annotation
        if kind == "nonholonomic":
            fail(span, f"'{which} = ...' belongs to holonomic constraints only")
        if which == "init":
            scope.params_only = True
        try:
            annotation = (which, _ExprBuilder(scope, None).build(node))
        finally:
            scope.params_only = False
    restitution = None
    if kind == "unilateral":
        if annotation is None or annotation[0] != "phi":
            fail(c.span, "a unilateral constraint gives its gap, which must stay >= 0: "
                         "constraint unilateral(phi = EXPR)")
        scope.params_only = True
        try:
            restitution = _ExprBuilder(scope, None).build(c.restitution) \
                if c.restitution is not None else None
        finally:
            scope.params_only = False
        if restitution is not None:
            _check_size(restitution, None, "the coefficient of restitution")
        if restitution is not None and restitution.value.is_Number and not \
                0 <= restitution.value <= 1:
            fail(restitution.span, "the coefficient of restitution is from 0 to 1")
    elif c.restitution is not None:
        fail(c.restitution.span, "restitution(E) belongs to unilateral constraints: "
                                 "constraint unilateral(phi = ...) restitution(E)")
    corr = c.corrector
    name, gains, cspan = "none", (), None
    if corr is not None:
        name, cspan = corr.kind, corr.span
        if name == "pd" and kind == "unilateral":
            fail(corr.span, "a unilateral constraint takes a pid(alpha, beta) corrector, not pd")
        if name == "pid" and kind == "nonholonomic":
            fail(corr.span, "a nonholonomic constraint takes a pd(gamma) corrector, not pid")
        if name == "pd" and kind == "holonomic":
            fail(corr.span, "a holonomic constraint takes a pid(alpha, beta) corrector, not pd")
        gains = tuple(_ExprBuilder(scope, None).build(a) for a in corr.args)
    return Constraint(kind, annotation, name, gains, cspan, c.span, restitution)


def _signal(d, scope, diags) -> Signal:
    if isinstance(d, ast.InputDecl):
        return _input(d, scope, diags)
    if d.dim is not None and d.dim.m is not None:
        fail(d.dim.span, f"a signal has one dimension: write '{d.name.name}[{d.dim.n}]'")
    n = _dim_of(d)
    expr = _ExprBuilder(scope, diags).build(d.expr)
    _check_size(expr, n, f"signal '{d.name.name}'")
    init = None
    if isinstance(d, ast.IntegralDecl):
        scope.params_only = True
        try:
            init = _ExprBuilder(scope, diags).build(d.init)
        finally:
            scope.params_only = False
        _check_size(init, n, f"the initial value of '{d.name.name}'", broadcast=True)
    return Signal(d.name.name, expr, init, d.span, n, d.unit)


def _input(d: ast.InputDecl, scope, diags) -> Signal:
    """An input: a signal whose value, between two of its breakpoints, is the line through
    its discrete values (the segment's start, value there and slope: bgc.front.events.InputSlot)."""
    default = sp.Integer(0)
    if d.expr is not None:
        scope.params_only = True
        try:
            e = _ExprBuilder(scope, diags).build(d.expr)
        finally:
            scope.params_only = False
        if _is_matrix(e.value):
            fail(d.expr.span, f"input '{d.name.name}' is a scalar, but its default is "
                              f"{_shape(e.value)}")
        default = e.value
    j = len(scope.inputs)
    t0, u0, s0 = scope.events.input(j, d.name.name, default, d.span)
    scope.inputs.append(InputInfo(d.name.name, default, d.doc, d.span, d.unit))
    return Signal(d.name.name, Expr(u0 + s0 * (TIME - t0), (), d.span), None, d.span,
                  unit=d.unit)


def _check_size(e: Expr, n: int | None, what: str, broadcast: bool = False) -> None:
    """e is a scalar when n is None, else a vector of n (or, with broadcast, a scalar)."""
    v = e.value
    if n is None and _is_matrix(v):
        fail(e.span, f"{what} is a scalar, but this is {_shape(v)}")
    if n is not None and _is_matrix(v) and v.shape != (n, 1):
        fail(e.span, f"{what} is a vector of {n}, but this is {_shape(v)}")
    if n is not None and not _is_matrix(v) and not broadcast:
        fail(e.span, f"{what} is a vector of {n}, but this is a scalar")


def _bonds(model, elements, params, signals, diags: Collector):
    bonds, seen = [], {}
    for chain in (d for d in model.decls if isinstance(d, ast.BondChain)):
        ok = True
        for node in chain.nodes:
            if node.name not in elements:
                what = ("a parameter" if node.name in params else
                        "a signal" if node.name in signals else None)
                diags.error(node.span, f"bond to '{node.name}', which is {what}, not an element"
                            if what else f"bond to undeclared node '{node.name}'")
                ok = False
        if not ok:
            continue
        for a, b in zip(chain.nodes, chain.nodes[1:]):
            if a.name == b.name:
                diags.error(a.span.join(b.span), f"bond from '{a.name}' to itself")
                continue
            key = f"{a.name}->{b.name}"
            seen[key] = seen.get(key, 0) + 1
            label = key if seen[key] == 1 else f"{key}#{seen[key]}"
            bonds.append(Bond(a.name, b.name, label, a.span.join(b.span), chain.ports))
    return bonds


def _scene(d: ast.SceneDecl, scope: _Scope, known_effects, diags: Collector) -> Scene:
    effects = effects_span = outputs = time = solver = None
    effect_spans = ()
    sets = []
    scope.params_only = True
    try:
        for s in d.stmts:
            if isinstance(s, ast.SceneEffects):
                effects = () if s.names is None else tuple(n.name for n in s.names)
                effects_span = s.span
                effect_spans = () if s.names is None else tuple(n.span for n in s.names)
                check_effect_names(effects, effect_spans, known_effects, diags,
                                   f"scene '{d.name.name}'")
            elif isinstance(s, ast.SceneOutputs):
                outputs = output_refs(s.refs, scope.constants)
            elif isinstance(s, ast.SceneTime):
                b = _ExprBuilder(scope, diags)
                time = (b.build(s.start), b.build(s.stop),
                        b.build(s.every) if s.every is not None else None)
            elif isinstance(s, ast.SceneSolver):
                opts = tuple((k.name, _ExprBuilder(scope, diags).build(v)) for k, v in s.options)
                solver = (s.name.name, opts, s.span)
            elif isinstance(s, ast.SceneSet):
                name = path_name(s.name, scope.constants)
                if name.name not in scope.params:
                    fail(name.span, f"'set' names a parameter; '{name.name}' is not one")
                sets.append((name.name, _ExprBuilder(scope, diags).build(s.expr), s.span))
    finally:
        scope.params_only = False
    return Scene(d.name.name, d.doc, effects, effects_span, outputs, time, solver, tuple(sets),
                 d.span, effect_spans)


def _model_directory(path: str) -> str:
    """Where a model's table files are read: the model file's directory (the working
    directory for a model given as text)."""
    import os
    if not path or path.startswith("<"):
        return ""
    return os.path.dirname(path)


def resolve(model: ast.Model) -> Graph:
    """Check names, kinds and bonds; build every expression; collect all errors, then stop."""
    diags = Collector()
    mdecl = _model_decl(model, diags)
    params, signals, elements = _collect_names(model, diags)
    scope = _Scope(params, signals, elements)
    scope.directory = _model_directory(model.path)
    scope.constants = dict(model.constants)
    scope.text = model.text
    _declare_discretes(model, scope)
    parameters = _parameters(params, scope, diags)
    discretes = _discretes(scope, diags)
    order = {id(d): k for k, d in enumerate(model.decls)}
    els = [replace(e, order=order[id(d)]) for d, e in
           ((d, _guard(diags, _element, d, scope, diags)) for d in elements.values()) if e]
    sigs = [replace(s, order=order[id(d)]) for d, s in
            ((d, _guard(diags, _signal, d, scope, diags)) for d in signals.values()) if s]
    bonds = _bonds(model, elements, params, signals, diags)
    for d in elements.values():  # controlled junctions: a switch on one more bond
        if isinstance(d, ast.ElementDecl) and d.switch is not None:
            sw = _guard(diags, _junction_switch, d, scope, diags)
            if sw:
                els.append(replace(sw, order=order[id(d)]))
                bonds.append(Bond(d.name.name, sw.name, f"{d.name.name}->{sw.name}", d.span))
    whens = [w for w in (_guard(diags, _when, d, scope, diags) for d in model.decls
                         if isinstance(d, ast.WhenBlock)) if w]
    check_ports(els, bonds, diags)
    scenes, scene_names = [], {}
    known_effects = model_effects(els)
    for d in (d for d in model.decls if isinstance(d, ast.SceneDecl)):
        if len(scene_names) == MAX_SCENES:
            diags.error(d.name.span, f"a model has at most {MAX_SCENES} scenes (each is "
                                     "checked in full)")
            break
        if d.name.name in scene_names:
            diags.error(d.name.span, f"scene '{d.name.name}' is declared twice",
                        Note(scene_names[d.name.name], "first declaration"))
            continue
        scene_names[d.name.name] = d.name.span
        sc = _guard(diags, _scene, d, scope, known_effects, diags)
        if sc:
            scenes.append(sc)
    diags.raise_if_errors()
    return Graph(mdecl.name.name, mdecl.doc, model.path, tuple(parameters), tuple(els),
                 tuple(bonds), tuple(sigs), tuple(scenes), diags.warnings,
                 ports=tuple(model.ports), instances=tuple(model.instances),
                 relations=tuple(scope.events.relations), squares=tuple(scope.events.squares),
                 discretes=tuple(discretes), whens=tuple(whens), tables=tuple(scope.tables),
                 inputs=tuple(scope.inputs), constants=tuple(model.constants),
                 libraries=tuple(model.libraries))
