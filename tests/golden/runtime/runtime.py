# ====================================================================== runtime ===
# bgc's Python runtime: model-independent, the same in every generated module.  Its parts,
# bgc/runtime/*.py joined (runtime.py first), are one module, imported by the tests and linted,
# and the text bgc.codegen.emit.python_runtime() inlines verbatim, so a generated module stays
# one file that needs only numpy.  A generated module is, in order: its docstring, the
# runtime, the solver tables (_METHODS, SOLVERS, _SOLVER_LIST, printed from bgc/solvers.py),
# the model part (templates/python_module.py.j2), then `_bind_model()` and the `main()` call.
# The model part comes after the runtime so that its definitions replace the neutral ones
# below by ordinary rebinding of module globals: the solver path reads _N, _rhs, ... as plain
# globals, as fast as if the runtime had none.  The runtime is the C runtime's api.h contract
# in Python and does the C runtime's arithmetic in the same order (docs/architecture.md, "Byte
# parity").
#
# ---------------------------------------------------------------- the contract
# (a) What the model part provides (each defined below with a neutral value: a model of no
#     states, parameters, outputs, constraints or blocks; a module that defines fewer names
#     than these is not a model).  Lists are ordered as the arrays that use them.
#
#   MODEL                 str: the model's display name
#   STATES, OUTPUTS       lists of str: the states' and outputs' display names
#   CONSTRAINTS           list of (junction: str, level: "position" | "velocity"), per row
#   SCENE                 dict: t0, t_end, dt, solver, rtol, atol (floats, solver a name of
#                         SOLVERS) and step (a float, or None: adaptive)
#   _IDENT                str: the identifier the module was generated as (the CSV's name)
#   _PARAM_NAMES          list of str: the parameters' names
#   _N                    int: len(STATES)
#   _AUTONOMOUS           bool: the right side does not read t
#   _POSITION_ROWS, _VELOCITY_ROWS  lists of int: the constraint rows of each level
#   _VELOCITY_MOVABLE     list of bool per state: projection onto the velocity rows may move it
#   _WORK_DOUBLES, _WORK_INTS  int: the workspace's sizes (_Work: w.v, w.iv)
#   _BLOCK_NAMES          list of str per algebraic block solved numerically: its unknowns
#   _BLOCKS               list per block of the fields of _Block (its size, its factorisation
#                         plan from bgc/sparse.py, its offsets in the workspace and its unrolled
#                         factor and solve functions or None)
#   _JAC_COLORS           list of tuples of int: the Jacobian's columns of each colour
#   _JAC_COLUMNS          list of tuples of int: the rows each column of the Jacobian touches
#   _JAC_LU               a large sparse model only (else None): _SparseLU, the plan of the
#                         stiff solvers' sparse LU (bgc/sparse.py, IterationPlan)
#   _fill_params(p, given) -> p
#                         sets p[j] (a list of floats, ordered as _PARAM_NAMES) to parameter
#                         j's default for every j not in the set given, in order
#   _constants(p) -> list of float: the constants computed from the parameters p
#   _init(p) -> list of _N floats: the initial state
#   _rhs(t, x, p, w, out), _out(t, x, p, w, out), _jvp(t, x, p, w, v, out)
#                         dx/dt, the outputs, J v (J = d rhs / d x) into out; x a list or
#                         numpy array of _N floats, p the parameters followed by the constants
#                         (_with_constants), w a _Work; return nothing; raise _BlockFailure
#                         when an algebraic block fails (through _block_solve, _newton)
#   _residual(t, x, p), _scale(t, x, p) -> list: r and s per constraint row (|r| <= 1e-9 s)
#   _position_jac(t, x, p), _velocity_jac(t, x, p) -> list: the rows' Jacobians, row-major
#   _velocity_metric(t, x, p) -> list: the velocity rows' Jacobian times the mass matrix (the
#                         projection's kinetic metric), row-major
#   _INDICATOR_STRICT     list of bool per state relation (a model with events, docs/hybrid.md):
#                         it holds when its indicator is > 0 (True) or >= 0
#   _NUM_TIMERS           int: the results of _next_time
#   _DISCRETE_NAMES       list of str per discrete value d (the event log's names); d follows
#                         the constants in p
#   _DISCRETE_LOG         list of int, two per discrete value: how the event log shows its
#                         change (_LOG_PLAIN, 0; _LOG_TABLE k: table k's values; _LOG_INPUT j:
#                         input j's values, one row for its segment's three)
#   _events(t, x, p, w, out), _next_time(t, x, p, w, out), _update(t, x, p, w, r, out)
#                         the indicators; the time events' next times; the state and d after
#                         one pass of the event iteration (r: the state relations' values, then
#                         1.0 at the run's start) (C's bgc_model_events, _next_time, _update)
#   _INPUT_NAMES          list of str per input (`input NAME`): simulate()'s inputs= and
#                         --input name them
#   _TABLES               tuple per lookup table (a model with tables, bgc/tables.py) of (n,
#                         error, x, origin, coef): what _table reads
#   _METHODS, SOLVERS, _SOLVER_LIST  the solver tables: name -> dict of the family, its step
#                         control and tableau; the names in order; their help text
#
# (b) What the runtime provides: to users, the names in __all__ (the generated module's
#     docstring describes them); to the model part's generated code, the names in
#     _MODEL_HELPERS below (math and numpy too), which bgc's code printers and templates
#     emit calls to: _sq, _sign, _heaviside, the libm wrappers _c_* with C's infinities and
#     NaNs, the algebraic-block solves _block_solve, _block_resolve, _newton (which read
#     _BLOCK_TABLE and the workspace _Work; they raise _BlockFailure), _Work itself (the
#     constraint rows of a coupled field make one for their block), and _bind_model.
#
# _bind_model() derives the runtime's tables from the model part (the blocks, PARAMETERS, the
# explicit solvers' vector kind); the generated module calls it after its model part, and a
# test that binds a model of its own by assigning the names above calls it too.

import bisect
import math
import os
import signal
import sys
import threading
import time  # process_time(): the processor time a run reports in its stats

import numpy

__all__ = [
    "MODEL", "STATES", "OUTPUTS", "CONSTRAINTS", "SCENE", "PARAMETERS", "SOLVERS", "MAX_STEPS",
    "USAGE", "METRIC_KINDS", "BATCH_COLUMNS",
    "rhs", "outputs", "jvp", "jacobian", "simulate", "rows", "batch", "batch_rows", "main",
    "request_stop", "SimulationError", "ConstraintError", "BlockError",
]
_MODEL_HELPERS = (
    "_sq", "_sign", "_heaviside", "_c_exp", "_c_log", "_c_sqrt", "_c_sin", "_c_cos", "_c_tan",
    "_c_asin", "_c_acos", "_c_atan", "_c_atan2", "_c_sinh", "_c_cosh", "_c_tanh", "_c_asinh",
    "_c_atanh", "_c_pow", "_block_solve", "_block_resolve", "_newton", "_Work", "_bind_model",
    "_square", "_square_next", "_periodic_next", "_table", "_table_next", "_table_piece",
    "_table_guard", "_input",
    "_input_next", "_F64",
)
# (a)'s names, for the tests that check both sides of the contract (tests/test_pyruntime.py).
_MODEL_NAMES = (
    "MODEL", "STATES", "OUTPUTS", "CONSTRAINTS", "SCENE", "_IDENT", "_PARAM_NAMES", "_N",
    "_AUTONOMOUS", "_POSITION_ROWS", "_VELOCITY_ROWS", "_VELOCITY_MOVABLE", "_WORK_DOUBLES",
    "_WORK_INTS", "_BLOCK_NAMES", "_BLOCKS", "_JAC_COLORS", "_JAC_COLUMNS", "_fill_params",
    "_constants", "_init", "_rhs", "_out", "_jvp", "_residual", "_scale", "_position_jac",
    "_velocity_jac", "_velocity_metric", "_METHODS", "SOLVERS", "_SOLVER_LIST",
)

# ---------------------------------------------------------------- the model part's names
# Neutral values (see the contract above); the model part redefines every one of them.

MODEL = ""
STATES = []
OUTPUTS = []
CONSTRAINTS = []
SCENE = {"t0": 0.0, "t_end": 1.0, "dt": 0.1, "solver": "dopri5", "rtol": 1e-6, "atol": 1e-9,
         "step": None}
_IDENT = "model"
_PARAM_NAMES = []
_N = 0
_AUTONOMOUS = True
_POSITION_ROWS = []
_VELOCITY_ROWS = []
_VELOCITY_MOVABLE = []
_WORK_DOUBLES = 0
_WORK_INTS = 0
_BLOCK_NAMES = []
_BLOCKS = []
_JAC_COLORS = []
_JAC_COLUMNS = []
_JAC_LU = None
_METHODS = {}
SOLVERS = ()
_SOLVER_LIST = ""
_INDICATOR_STRICT = []
_NUM_TIMERS = 0
_DISCRETE_NAMES = []
_DISCRETE_LOG = []
_TABLES = ()
_INPUT_NAMES = []
_LOG_PLAIN, _LOG_INPUT, _LOG_TABLE = 0, 1, 2  # _DISCRETE_LOG (bgc/ir.py LOG_*, api.h)
_NUM_JUMPS = 0  # the sensitivities' parameters whose jumps _update carries (api.h's
#                 BGC_NUM_JUMPS: r and its results have as many more, see _event_iteration)


def _fill_params(p, given):
    return p


def _constants(p):
    return []


def _init(p):
    return []


def _rhs(t, x, p, w, out):
    pass


def _out(t, x, p, w, out):
    pass


def _jvp(t, x, p, w, v, out):
    pass


def _residual(t, x, p):
    return []


def _scale(t, x, p):
    return []


def _position_jac(t, x, p):
    return []


def _velocity_jac(t, x, p):
    return []


def _velocity_metric(t, x, p):
    return []


_events = _next_time = _out  # a model without events: nothing to evaluate (the event
_update = _jvp                # functions take the arguments of these; docs/hybrid.md)


# ---------------------------------------------------------------- the runtime

_EPS = sys.float_info.epsilon



class SimulationError(RuntimeError):
    """A non-finite value, a step size too small or an algebraic block that failed; .times and
    .rows hold the rows computed before it."""

    def __init__(self, message, t, times, rows):
        super().__init__(message)
        self.t = t
        self.times = times
        self.rows = rows


class ConstraintError(RuntimeError):
    """The initial conditions violate a constraint (or cannot be projected onto them)."""

    def __init__(self, message, messages=()):
        super().__init__(message)
        self.messages = list(messages) or [message]


class BlockError(RuntimeError):
    """An algebraic block solved in the model functions was singular or did not converge."""


class _Failure(Exception):
    def __init__(self, message, t):
        super().__init__(message)
        self.t = t


class _BlockFailure(Exception):
    _HOW = {1: "is singular", 2: "did not converge", 3: "has a non-finite residual"}

    def __init__(self, block, failure, t):
        super().__init__("at t = %.17g: algebraic block %d (%s) %s" % (
            t, block + 1, _BLOCK_NAMES[block], self._HOW[failure]))
        self.t = t


def _sign(a):
    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else a)


def _heaviside(a, at_zero):
    return 1.0 if a > 0.0 else (0.0 if a < 0.0 else (at_zero if a == 0.0 else a))


def _sq(a):
    return a * a  # as C's bgc_sq (a ** 2 on a float is libm's pow, not always a * a)


class _F64:
    """The workspace (or a block's unknowns in it) as a model function's IEEE variant reads
    it: each value a numpy.float64, so that a division by a zero it holds gives C's inf or
    nan instead of raising as a Python float does; writes go to the list itself."""
    __slots__ = ("values",)

    def __init__(self, values):
        self.values = values

    def __getitem__(self, i):
        return numpy.float64(self.values[i])

    def __setitem__(self, i, value):
        self.values[i] = value


def _square_period(t, period, t0):
    """bgc_square_period: the period k >= 0 that holds t, its edges computed as written; NaN
    where the edges near t are not apart (finer than the time's resolution)."""
    q = (t - t0) / period
    k = float(math.floor(q)) if math.isfinite(q) else math.nan
    if k < 0.0:
        k = 0.0
    if not k + 1.0 > k:
        return math.nan
    while k > 0.0 and t0 + k * period > t:
        k -= 1.0
    while t0 + (k + 1.0) * period <= t:
        if not t0 + (k + 1.0) * period > t0 + k * period:
            return math.nan
        k += 1.0
    return k


def _square(t, period, duty, t0):
    """square(period, duty, t0) at t (the value after an edge at t), as bgc_square."""
    if not period > 0.0 or not math.isfinite(t):
        return math.nan
    if t < t0:
        return 0.0
    k = _square_period(t, period, t0)
    if k != k:
        return math.nan
    return 1.0 if t < t0 + (k + duty) * period else 0.0


def _square_next(t, period, duty, t0):
    """The square wave's first edge after t, as bgc_square_next."""
    if not period > 0.0 or not math.isfinite(t):
        return math.nan
    if t < t0:
        return t0
    k = _square_period(t, period, t0)
    if k != k:
        return math.nan
    down = t0 + (k + duty) * period
    return down if t < down else t0 + (k + 1.0) * period


def _periodic_next(t, period, c):
    """bgc_periodic_next: the first of the times c + period*n after t."""
    if period < 0.0:
        period = -period
    if not period > 0.0 or not math.isfinite(period) or not math.isfinite(c) \
            or not math.isfinite(t):
        return math.nan
    q = (t - c) / period
    k = float(math.floor(q)) if math.isfinite(q) else math.nan
    if not (k + 1.0 > k and k - 1.0 < k):  # beyond 2^53 periods: the times are not apart
        return math.nan
    while c + k * period > t:
        k -= 1.0
    while c + (k + 1.0) * period <= t:
        if not c + (k + 1.0) * period > c + k * period:
            return math.nan
        k += 1.0
    return c + (k + 1.0) * period


def _count_upto(x, n, X):
    """bgc_count_upto: how many of x[:n] (non-decreasing, finite) are at or below X (not
    NaN)."""
    return bisect.bisect_right(x, X, 0, n)


def _input(w, j, t, part, default):
    """bgc_input: input j's data at t: the segment's start (part 0), value (1), slope (2)."""
    series = w.inputs[j] if w.inputs is not None else None
    if series is None:
        return default if part == 1 else 0.0
    if t != t:
        return math.nan
    ts, us = series
    lo = _count_upto(ts, len(ts), t)
    if lo == 0 or lo == len(ts):
        return (us[0] if lo == 0 else us[-1]) if part == 1 else 0.0
    k = lo - 1
    if part == 0:
        return ts[k]
    if part == 1:
        return us[k]
    return (us[k + 1] - us[k]) / (ts[k + 1] - ts[k])


def _input_value(w, j, t, side):
    """bgc_input_value: input j's value at t from its data, the limit from the left (side 0)
    or the right (1), a sample's own value at its time (the event log's values)."""
    series = w.inputs[j] if w.inputs is not None else None
    if series is None or t != t:
        return math.nan
    ts, us = series
    n = len(ts)
    lo = bisect.bisect_right(ts, t) if side else bisect.bisect_left(ts, t)
    if side == 0 and lo < n and ts[lo] == t:
        return us[lo]
    if side != 0 and lo > 0 and ts[lo - 1] == t:
        return us[lo - 1]
    if lo == 0 or lo == n:
        return us[0 if lo == 0 else n - 1]
    k = lo - 1
    return us[k] + (us[k + 1] - us[k]) / (ts[k + 1] - ts[k]) * (t - ts[k])


def _input_next(w, j, t):
    """bgc_input_next: input j's first sample after t (inf: none)."""
    series = w.inputs[j] if w.inputs is not None else None
    if series is None:
        return math.inf
    if t != t:
        return math.nan
    ts = series[0]
    lo = _count_upto(ts, len(ts), t)
    return ts[lo] if lo < len(ts) else math.inf


def _input_series(inputs=None, path=None):
    """The inputs' data for a run, one (t, u) of floats (or None) per input, from a dict
    {name: (t, values)} and/or a CSV file (--input); ValueError for people."""
    out = [None] * len(_INPUT_NAMES)
    given = []
    for one in ([] if path is None else [path] if isinstance(path, str) else path):
        given += _read_input_file(one)
    for name, data in (inputs or {}).items():
        try:
            ts, us = data
            ts = [float(v) for v in ts]
            us = [float(v) for v in us]
        except (TypeError, ValueError):
            raise ValueError("the data of input '%s' is a pair (t, values) of numbers"
                             % name) from None
        given.append((name, ts, us, "input '%s'" % name))
    for name, ts, us, where in given:
        if name not in _INPUT_NAMES:
            raise ValueError("%s: '%s' is not an input of the model (its inputs: %s)"
                             % (where, name, ", ".join(_INPUT_NAMES) or "none"))
        if out[_INPUT_NAMES.index(name)] is not None:
            raise ValueError("%s: input '%s' is given twice" % (where, name))
        if len(ts) != len(us) or not ts:
            raise ValueError("%s: t and the values must be as many, at least one" % where)
        if not all(math.isfinite(v) for v in ts + us):
            raise ValueError("%s: the data must be finite numbers" % where)
        k = _input_order(ts)
        if k is not None:
            raise ValueError("%s: %s" % (where, _input_order_problem(ts, k, "at t[%d]" % k)))
        out[_INPUT_NAMES.index(name)] = (tuple(ts), tuple(us))
    return out if any(s is not None for s in out) else None


def _input_order(ts, k=None):
    """The first index from k on (else from 1) where an input's times break their order (None:
    none): t does not decrease, and a repeated t, a jump, is two samples, never three."""
    for k in range(1, len(ts)) if k is None else (k,) if k >= 1 else ():
        if ts[k] < ts[k - 1] or (k >= 2 and ts[k] == ts[k - 1] == ts[k - 2]):
            return k
    return None


def _input_order_problem(ts, k, at):
    """What is wrong at index k (_input_order), there being `at` ("here": as main.c says it)."""
    if ts[k] < ts[k - 1]:
        return "t decreases %s (t does not decrease from row to row; a repeated t is a " \
               "jump)" % at
    return "the same t a third time %s (a jump is two rows of the same t)" % at


def _read_input_file(path):
    """(name, t, u, where) per input column of an --input CSV file."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError("cannot read the input file '%s': %s"
                         % (path, getattr(error, "strerror", None) or error)) from None
    head = [h.strip() for h in lines[0].split(",")] if lines else []
    if "t" not in head:
        raise ValueError("%s: the header has no column 't'" % path)
    if len(set(head)) != len(head):
        raise ValueError("%s: a column is named twice in the header" % path)
    for name in head:
        if name != "t" and name not in _INPUT_NAMES:
            raise ValueError("%s: '%s' is not an input of the model (its inputs: %s)"
                             % (path, name, ", ".join(_INPUT_NAMES) or "none"))
    columns = [[] for _ in head]
    for number, line in enumerate(lines[1:], 2):
        if not line.strip(" \t\r"):
            continue
        cells = [c.strip(" \t\r") for c in line.split(",")]
        if len(cells) != len(head):
            raise ValueError("%s:%d: this row has %d fields, the header %d"
                             % (path, number, len(cells), len(head)))
        for k, cell in enumerate(cells):
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v) or cell.lower().lstrip("+-") in ("inf", "nan", "infinity"):
                raise ValueError("%s:%d: '%s' is not a finite number" % (path, number, cell))
            columns[k].append(v)
        t = columns[head.index("t")]
        if _input_order(t, len(t) - 1) is not None:
            raise ValueError("%s:%d: %s" % (path, number,
                                            _input_order_problem(t, len(t) - 1, "here")))
    if not columns[0]:
        raise ValueError("%s: no rows of data" % path)
    t = columns[head.index("t")]
    return [(name, t, columns[k], path) for k, name in enumerate(head) if name != "t"]


def _table_find(T, X):
    """bgc_table_find: the piece holding X, the number of rows with x <= X."""
    return _count_upto(T[2], T[0], X)


def _table(T, X, piece, order):
    """bgc_table: table T = (n, error, x, origin, coef) at X, or its derivative of order 1 to
    3, in piece `piece` (or X's piece if piece < 0)."""
    if X != X:
        return math.nan
    s = int(piece) if piece >= 0.0 else _table_find(T, X)
    c = T[4]
    a, b, cc, d = c[4 * s], c[4 * s + 1], c[4 * s + 2], c[4 * s + 3]
    dx = X - T[3][s]
    if order == 0:
        return a + dx * (b + dx * (cc + dx * d))
    if order == 1:
        return b + dx * (2.0 * cc + dx * (3.0 * d))
    if order == 2:
        return 2.0 * cc + dx * (6.0 * d)
    return 6.0 * d if order == 3 else 0.0


def _table_guard(T, X):
    """bgc_table_guard: how far X is within the table's rows (negative outside)."""
    lo, hi = X - T[2][0], T[2][T[0] - 1] - X
    return hi if hi < lo else lo


def _table_limit(T, t, piece):
    """bgc_table_limit: the table's value at t in piece `piece`, the row there at the right
    end of a piece that is not constant (the event log's value before a breakpoint)."""
    s, c = int(piece), T[4]
    if 0 <= s < T[0] and T[2][s] == t and (c[4 * s + 1] != 0.0 or c[4 * s + 2] != 0.0
                                            or c[4 * s + 3] != 0.0):
        return c[4 * (s + 1)]
    return _table(T, t, piece, 0)


def _table_piece(T, t):
    return math.nan if t != t else float(_table_find(T, t))


def _table_next(T, t):
    if t != t:
        return math.nan
    s = _table_find(T, t)
    return T[2][s] if s < T[0] else math.inf


# The model functions' IEEE variant (run when the math variant raised) calls these: the C
# program's functions, bit for bit.  math calls the platform's libm, as C does (numpy's exp,
# log, power, tanh, ... are SIMD kernels of their own that round differently); where math
# raises, C99 Annex F's result.  numpy.float64 results keep the arithmetic around them IEEE.

def _libm(f, fails):
    def call(*args):
        try:
            return numpy.float64(f(*args))
        except (ValueError, OverflowError):
            return numpy.float64(fails(*args))
    return call


def _pow_fails(x, y):
    """C's pow(x, y) where math.pow raises: x < 0, y not an integer: nan; an overflow or
    0 to a negative power: inf, negative for a negative x and an odd integer y."""
    if x < 0.0 and y != math.floor(y):
        return math.nan
    odd = y == math.floor(y) and math.fmod(y, 2.0) != 0.0
    return math.copysign(math.inf, x) if odd else math.inf


_c_exp = _libm(math.exp, lambda x: math.inf)
_c_log = _libm(math.log, lambda x: -math.inf if x == 0.0 else math.nan)
_c_sqrt = _libm(math.sqrt, lambda x: math.nan)
_c_sin = _libm(math.sin, lambda x: math.nan)
_c_cos = _libm(math.cos, lambda x: math.nan)
_c_tan = _libm(math.tan, lambda x: math.nan)
_c_asin = _libm(math.asin, lambda x: math.nan)
_c_acos = _libm(math.acos, lambda x: math.nan)
_c_atan = _libm(math.atan, lambda x: math.nan)
_c_atan2 = _libm(math.atan2, lambda y, x: math.nan)
_c_sinh = _libm(math.sinh, lambda x: math.copysign(math.inf, x))
_c_cosh = _libm(math.cosh, lambda x: math.inf)
_c_tanh = _libm(math.tanh, lambda x: math.nan)
_c_asinh = _libm(math.asinh, lambda x: math.nan)
_c_atanh = _libm(math.atanh, lambda x: math.copysign(math.inf, x) if abs(x) == 1.0 else math.nan)
_c_pow = _libm(math.pow, _pow_fails)


# ---------------------------------------------------------------- workspace


class _Block:
    __slots__ = ("m", "dense", "symmetric", "nnz", "diag", "lptr", "lpos", "lrow", "uptr", "upos", "ucol",
                 "upd", "prow", "pcol", "save", "lu", "dense_off", "b", "scale", "z", "r", "zt",
                 "rt", "piv", "how", "factor", "lsolve")

    def __init__(self, values):
        for key, value in zip(self.__slots__, values):
            setattr(self, key, value)


_BLOCK_TABLE = []  # _Block per entry of _BLOCKS (_bind_model)


class _Work:
    """The model functions' workspace: values shared between their parts, the blocks' storage
    (each Newton block's last solution is its next starting value), the Newton tolerance."""

    __slots__ = ("v", "iv", "rtol", "atol", "d", "band", "gmax", "started", "inputs")

    def __init__(self, rtol=None, atol=None):
        self.v = [0.0] * max(_WORK_DOUBLES, 1)
        self.iv = [0] * max(_WORK_INTS, 1)
        self.d = [0.0] * len(_DISCRETE_NAMES)  # the discrete values between runs (bgc_work)
        self.band = [0.0] * len(_INDICATOR_STRICT)  # and per state relation its hysteresis
        self.gmax = [0.0] * len(_INDICATOR_STRICT)  # band, its indicator's largest magnitude
        self.started = False
        self.inputs = None  # one (t, u) or None per input (bgc_work.inputs)
        self.rtol = SCENE["rtol"] if rtol is None else rtol
        self.atol = SCENE["atol"] if atol is None else atol


# ---------------------------------------------------------------- linear solves


def _row_scales(b, a, base):
    m = b.m
    scale = [0.0] * m
    for q in range(b.nnz):
        i = q // m if b.dense else b.prow[q]
        v = abs(a[base + q])
        if v > scale[i]:
            scale[i] = v
    return scale


def _lu_dense(m, a, base, piv, pbase, scale):
    """LU with partial pivoting of the m x m matrix at a[base:], in place; False if singular."""
    for k in range(m):
        r = k
        for i in range(k + 1, m):
            if abs(a[base + i * m + k]) > abs(a[base + r * m + k]):
                r = i
        piv[pbase + k] = r
        pivot = a[base + r * m + k]
        if not (abs(pivot) > 1e-14 * scale[r]) or not math.isfinite(pivot):
            return False
        if r != k:
            scale[k], scale[r] = scale[r], scale[k]
            for j in range(m):
                a[base + k * m + j], a[base + r * m + j] = a[base + r * m + j], a[base + k * m + j]
        for i in range(k + 1, m):
            f = a[base + i * m + k] / a[base + k * m + k]
            a[base + i * m + k] = f
            for j in range(k + 1, m):
                a[base + i * m + j] -= f * a[base + k * m + j]
    return True


def _lu_dense_solve(m, a, base, piv, pbase, x, xbase):
    # _lu_dense swapped whole rows (multipliers included): all the swaps first
    for k in range(m):
        r = piv[pbase + k]
        if r != k:
            x[xbase + k], x[xbase + r] = x[xbase + r], x[xbase + k]
    for k in range(m):
        for i in range(k + 1, m):
            x[xbase + i] -= a[base + i * m + k] * x[xbase + k]
    for i in range(m - 1, -1, -1):
        total = x[xbase + i]
        for j in range(i + 1, m):
            total -= a[base + i * m + j] * x[xbase + j]
        x[xbase + i] = total / a[base + i * m + i]


def _lu_static(b, a, base, scale):
    """LU in the plan's static order, in place; False if a pivot fails its test (one sign for
    a symmetric matrix, else the threshold; clearly nonzero for its row)."""
    q = 0
    lptr, lpos, uptr, upos, upd = b.lptr, b.lpos, b.uptr, b.upos, b.upd
    sign = -1.0 if b.m > 0 and a[base + b.diag[0]] < 0.0 else 1.0
    for k in range(b.m):
        pivot = a[base + b.diag[k]]
        if b.symmetric:
            if not sign * pivot > 1e-14 * scale[k] or not math.isfinite(pivot):
                return False
        else:
            largest = abs(pivot)
            for l in range(lptr[k], lptr[k + 1]):
                v = abs(a[base + lpos[l]])
                if v > largest:
                    largest = v
            if not (abs(pivot) >= 0.1 * largest and abs(pivot) > 1e-14 * scale[k]) \
                    or not math.isfinite(pivot):
                return False
        for l in range(lptr[k], lptr[k + 1]):
            f = a[base + lpos[l]] / pivot
            a[base + lpos[l]] = f
            for u in range(uptr[k], uptr[k + 1]):
                a[base + upd[q]] -= f * a[base + upos[u]]
                q += 1
    return True


def _lu_static_solve(b, a, base, x, xbase):
    for k in range(b.m):
        for l in range(b.lptr[k], b.lptr[k + 1]):
            x[xbase + b.lrow[l]] -= a[base + b.lpos[l]] * x[xbase + k]
    for k in range(b.m - 1, -1, -1):
        total = x[xbase + k]
        for u in range(b.uptr[k], b.uptr[k + 1]):
            total -= a[base + b.upos[u]] * x[xbase + b.ucol[u]]
        x[xbase + k] = total / a[base + b.diag[k]]


def _block_factor(w, b):
    """Factor the matrix assembled at b.save: the static order (unrolled in the model part
    when the plan is small: b.factor), else densely; False if singular.  Records which in
    w.iv[b.how]."""
    if b.factor is not None and b.factor(w.v):
        w.iv[b.how] = 0
        return True
    return _block_factor_general(w, b)


def _block_factor_general(w, b):
    """_block_factor when the model part has no unrolled factorisation or it failed."""
    v = w.v
    scale = _row_scales(b, v, b.save)
    if not b.dense:
        if b.factor is None:
            v[b.lu:b.lu + b.nnz] = v[b.save:b.save + b.nnz]
            if _lu_static(b, v, b.lu, scale):
                w.iv[b.how] = 0
                return True
        m = b.m
        v[b.dense_off:b.dense_off + m * m] = [0.0] * (m * m)
        for q in range(b.nnz):
            v[b.dense_off + b.prow[q] * m + b.pcol[q]] = v[b.save + q]
    else:
        v[b.dense_off:b.dense_off + b.nnz] = v[b.save:b.save + b.nnz]
    w.iv[b.how] = 1
    return _lu_dense(b.m, v, b.dense_off, w.iv, b.piv, scale)


def _block_lsolve(w, b, xbase):
    if w.iv[b.how] == 0 and b.lsolve is not None:
        b.lsolve(w.v, xbase)
    elif w.iv[b.how] == 0:
        _lu_static_solve(b, w.v, b.lu, w.v, xbase)
    else:
        _lu_dense_solve(b.m, w.v, b.dense_off, w.iv, b.piv, w.v, xbase)


def _block_solve(w, k, t):
    b = _BLOCK_TABLE[k]
    if not _block_factor(w, b):
        raise _BlockFailure(k, 1, t)
    _block_lsolve(w, b, b.b)


def _block_resolve(w, k, t):
    b = _BLOCK_TABLE[k]
    _block_lsolve(w, b, b.b)


def _norm2(v, base, m):
    s = 0.0  # summed in C's order (the builtin sum is compensated from Python 3.12 on)
    for i in range(base, base + m):
        s += v[i] * v[i]
    return math.sqrt(s)


_NEWTON_MAXIT = 50


def _newton(w, k, f, t, x, p, final_factor):
    """Newton's method from the unknowns' last values, damped (Armijo), as the C runtime.
    The names are bound locally and the norms summed inline: the same operations, fewer
    lookups, since a hard block runs this tens of times per right-hand side."""
    b = _BLOCK_TABLE[k]
    m, v = b.m, w.v
    bz, br, bb, save = b.z, b.r, b.b, b.save
    factor, lsolve, iv, how = b.factor, b.lsolve, w.iv, b.how
    rows = range(m)
    zt = [0.0] * m
    rt = [0.0] * m
    isfinite, sqrt = math.isfinite, math.sqrt
    f(t, x, p, w, v, bz, v, br, v, save)
    norm = _norm2(v, br, m)
    if not isfinite(norm) or not all(isfinite(v[bz + i]) for i in rows):
        for i in rows:
            v[bz + i] = 0.0
        f(t, x, p, w, v, bz, v, br, v, save)
        norm = _norm2(v, br, m)
        if not isfinite(norm):
            raise _BlockFailure(k, 3, t)
    atol, rtol, eps4 = w.atol, w.rtol, 4.0 * _EPS
    it = 0
    while norm > 0.0:
        if it == _NEWTON_MAXIT:
            raise _BlockFailure(k, 2, t)
        it += 1
        if factor is not None and factor(v):  # _block_factor and _block_lsolve, inline
            iv[how] = 0
        elif not _block_factor_general(w, b):
            raise _BlockFailure(k, 1, t)
        for i in rows:
            v[bb + i] = -v[br + i]
        if iv[how] == 0 and lsolve is not None:
            lsolve(v, bb)
        else:
            _block_lsolve(w, b, bb)
        small = True  # a full step this small ends the iteration (quadratic convergence)
        near = True  # one within the tolerance ends it where the residual cannot decrease
        for i in rows:
            dz, z = v[bb + i], v[bz + i]
            if abs(dz) > 0.01 * (atol + rtol * abs(z)) and abs(dz) > eps4 * abs(z):
                small = False
            if abs(dz) > atol + rtol * abs(z):
                near = False
        lam = 1.0
        if m == 1:  # the scalar block, most common: the same operations without the loops
            z0, d0 = v[bz], v[bb]
            while True:
                zt[0] = z0 + lam * d0
                f(t, x, p, w, zt, 0, rt, 0, None, 0)
                r0 = rt[0]
                trial = sqrt(0.0 + r0 * r0)
                if small or trial <= (1.0 - 1e-4 * lam) * norm or lam < 1e-3:
                    break
                lam *= 0.5
        else:
            while True:
                for i in rows:
                    zt[i] = v[bz + i] + lam * v[bb + i]
                f(t, x, p, w, zt, 0, rt, 0, None, 0)
                trial = 0.0  # _norm2(rt, 0, m), inline
                for r in rt:
                    trial += r * r
                trial = sqrt(trial)
                if small or trial <= (1.0 - 1e-4 * lam) * norm or lam < 1e-3:
                    break
                lam *= 0.5
        v[bz:bz + m] = zt
        v[br:br + m] = rt
        # no decrease even at the shortest step: the residual at its rounding's floor (bgc_newton)
        near = near and not small and not (trial <= (1.0 - 1e-4 * lam) * norm)
        norm = trial
        if not isfinite(norm):
            raise _BlockFailure(k, 3, t)
        if small or near:
            break
        f(t, x, p, w, v, bz, v, br, v, save)
    if final_factor:
        f(t, x, p, w, v, bz, v, br, v, save)
        if not _block_factor(w, b):
            raise _BlockFailure(k, 1, t)


# ---------------------------------------------------------------- public functions


_WORK = []


def _work():
    if not _WORK:
        _WORK.append(_Work())
    return _WORK[0]


def _vector(v, n, what):
    values = numpy.asarray(v, dtype=float).reshape(-1).tolist()
    if len(values) != n:
        raise ValueError(f"{what} must have {n} elements, not {len(values)}")
    return values


def _public(function, t, x, p, size, *extra):
    p = _with_constants(_vector(p, len(_PARAM_NAMES), "p"))
    out = [0.0] * size
    try:
        function(float(t), _vector(x, _N, "x"), p, _work(), *extra, out)
    except _BlockFailure as failure:
        raise BlockError(str(failure)) from None
    return numpy.array(out, dtype=float)


def rhs(t, x, p):
    """dx/dt at (t, x) with parameters p (a 1-D array ordered as PARAMETERS)."""
    return _public(_rhs, t, x, p, _N)


def outputs(t, x, p):
    """The outputs at (t, x), ordered as OUTPUTS."""
    return _public(_out, t, x, p, len(OUTPUTS))


def jvp(t, x, p, v):
    """J v, the derivative of rhs with respect to x along v (derived symbolically)."""
    return _public(_jvp, t, x, p, _N, _vector(v, _N, "v"))


def jacobian(t, x, p):
    """J = d rhs / d x at (t, x), shape (len(STATES), len(STATES)): one jvp per colour of
    the Jacobian's columns (columns of a colour share no row)."""
    p = _with_constants(_vector(p, len(_PARAM_NAMES), "p"))
    x = _vector(x, _N, "x")
    J = numpy.zeros((_N, _N))
    try:
        _jacobian_into(float(t), x, p, _work(), J)
    except _BlockFailure as failure:
        raise BlockError(str(failure)) from None
    return J


def _jacobian_into(t, x, p, w, J, values=False):
    """bgc_jacobian_into: J's structural entries at (t, x), one J v per colour of columns, into
    the matrix J, or with values into J's structural values column by column
    (bgc_jacobian_values)."""
    v = [0.0] * _N
    jv = [0.0] * _N
    for cols in _JAC_COLORS:
        for j in cols:
            v[j] = 1.0
        _jvp(t, x, p, w, v, jv)
        for j in cols:
            v[j] = 0.0
            if values:
                q = _JAC_LU.colstart[j]
                for i in _JAC_COLUMNS[j]:
                    J[q] = jv[i]
                    q += 1
            else:
                for i in _JAC_COLUMNS[j]:
                    J[i, j] = jv[i]


def _param_values(overrides):
    """All parameter values: the overrides {index: value}, the rest from their defaults."""
    p = [0.0] * len(_PARAM_NAMES)
    for j, value in overrides.items():
        p[j] = float(value)
    return _fill_params(p, overrides)


def _with_constants(p):
    """The parameters followed by the constants computed from them, as the model functions
    take them."""
    return list(p) + _constants(p) + [0.0] * len(_DISCRETE_NAMES)




# ---------------------------------------------------------------- constraints


def _check_constraints(t, x, p, allow=False):
    """Messages for the violated constraint rows at (t, x); with allow (a run started off its
    constraints on purpose, --allow-inconsistent) only for the rows that are not finite."""
    r, s = _residual(t, x, p), _scale(t, x, p)
    return [
        ("initial conditions violate constraint '%s' (%s): residual = %.17g"
         % (CONSTRAINTS[k][0], CONSTRAINTS[k][1], r[k])) if math.isfinite(r[k]) else
        ("at t = %.17g: the %s residual of constraint '%s' is not finite: the model is undefined "
         "at the initial state with these parameters (a zero mass, say)"
         % (t, CONSTRAINTS[k][1], CONSTRAINTS[k][0]))
        for k in range(len(CONSTRAINTS))
        if not (abs(r[k]) <= 1e-9 * s[k] or (allow and math.isfinite(r[k])))
    ]


def _solve(m, A, b):
    """Gaussian elimination with partial pivoting (A row-major m x m); None if singular."""
    scale = 0.0
    for a in A:
        scale = max(scale, abs(a))
    for k in range(m):
        piv = k
        for i in range(k + 1, m):
            if abs(A[i * m + k]) > abs(A[piv * m + k]):
                piv = i
        if not abs(A[piv * m + k]) > 1e-14 * scale:
            return None
        if piv != k:
            for j in range(m):
                A[k * m + j], A[piv * m + j] = A[piv * m + j], A[k * m + j]
            b[k], b[piv] = b[piv], b[k]
        for i in range(k + 1, m):
            f = A[i * m + k] / A[k * m + k]
            for j in range(k, m):
                A[i * m + j] -= f * A[k * m + j]
            b[i] -= f * b[k]
    for i in range(m - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, m):
            total -= A[i * m + j] * b[j]
        b[i] = total / A[i * m + i]
    return b


def _project_rows(t, x, p, rows, jac, metric, movable):
    """Gauss-Newton minimum-norm projection onto rows, in the metric W that metric() gives as
    K = J W^-1 (None: the identity); None or the reason it failed."""
    m, n = len(rows), _N
    for it in range(51):
        r, s = _residual(t, x, p), _scale(t, x, p)
        z = [r[k] for k in rows]
        if all(abs(z[i]) <= 1e-9 * s[k] for i, k in enumerate(rows)):
            return None
        if it == 50:
            return "no convergence after 50 iterations"
        J = jac(t, x, p)
        K = J if metric is None else metric(t, x, p)
        if movable is not None:
            J = [0.0 if not movable[c % n] else v for c, v in enumerate(J)]
            K = J if metric is None else [0.0 if not movable[c % n] else v
                                          for c, v in enumerate(K)]
        A = [0.0] * (m * m)
        for i in range(m):
            for j in range(m):
                total = 0.0
                for k in range(n):
                    total += K[i * n + k] * J[j * n + k]
                A[i * m + j] = total
        if _solve(m, A, z) is None:
            return "the constraint Jacobian is singular"
        for k in range(n):
            dx = 0.0
            for i in range(m):
                dx += K[i * n + k] * z[i]
            x[k] -= dx
    return None


def _project_initial(t, x, p):
    why = _project_rows(t, x, p, _POSITION_ROWS, _position_jac, None, None)
    level = "position"
    if why is None:
        why = _project_rows(t, x, p, _VELOCITY_ROWS, _velocity_jac, _velocity_metric,
                            _VELOCITY_MOVABLE)
        level = "velocity"
    if why is not None:
        raise ConstraintError(
            "cannot project the initial conditions onto the %s constraints: %s" % (level, why))


# ---------------------------------------------------------------- settings


class _Settings:
    __slots__ = ("t0", "t_end", "dt", "solver", "rtol", "atol", "step", "max_steps", "h0",
                 "order0", "hmax", "event_rows", "on_event", "inputs", "error_states")

    def __init__(self, **values):
        values.setdefault("h0", 0.0)  # a run that goes on from an earlier one (bgc_settings):
        values.setdefault("order0", 0)  # its step size and radau's order
        values.setdefault("hmax", float(SCENE.get("hmax") or 0.0))  # events (docs/hybrid.md)
        values.setdefault("event_rows", False)
        values.setdefault("on_event", None)
        values.setdefault("inputs", None)
        values.setdefault("error_states", 0)  # the first error_states weighed (0: all)
        for key in self.__slots__:
            setattr(self, key, values[key])


MAX_STEPS = 100000  # the most steps accepted between two output times, unless set (0: no limit)


def _settings(t_end=None, dt=None, solver=None, rtol=None, atol=None, step=None,
              max_steps=None, max_step=None, event_rows=False, on_event=None, inputs=None,
              error_states=None):
    given = {"t_end": t_end, "dt": dt, "solver": solver, "rtol": rtol, "atol": atol, "step": step,
             "max_steps": max_steps, "hmax": max_step, "error_states": error_states}
    values = dict(SCENE, max_steps=MAX_STEPS, event_rows=bool(event_rows), on_event=on_event,
                  inputs=inputs)
    values["hmax"] = float(values.get("hmax") or 0.0)
    values.update((k, v) for k, v in given.items() if v is not None)
    for key in ("t0", "t_end", "dt", "rtol", "atol"):
        values[key] = float(values[key])
    values["step"] = 0.0 if values["step"] is None else float(values["step"])
    values["hmax"] = float(values["hmax"])
    s = _Settings(**values)
    message = _check_settings(s)
    if message:
        raise ValueError(message)
    return s


def _check_settings(s):
    if not all(math.isfinite(v) for v in (s.t0, s.t_end, s.dt, s.rtol, s.atol, s.step, s.hmax)):
        return "settings must be finite numbers"
    if s.hmax < 0.0:
        return "--max-step must be positive (0: no bound)"
    if not s.dt > 0.0:
        return "--dt must be positive"
    if s.t_end < s.t0:
        return "--t-end must not be before the start time"
    if not (s.rtol > 0.0 and s.atol > 0.0):
        return "--rtol and --atol must be positive"
    if s.step < 0.0:
        return "--step must be positive"
    if not (0 <= s.error_states <= _N and s.error_states == int(s.error_states)):
        return "--error-states must be a whole number from 0 (all) to %d" % _N
    if not (s.max_steps >= 0 and s.max_steps == int(s.max_steps)):
        return "--max-steps must be a whole number from 0 (no limit) to 1e15"
    if s.solver not in SOLVERS:
        return "unknown solver"
    if not (s.t_end - s.t0) / s.dt <= 1e9:
        return "too many output rows (more than 1e9): increase --dt"
    return None


# ---------------------------------------------------------------- simulate


def _overrides(params):
    given = {}
    for name, value in (params or {}).items():
        if name not in _PARAM_NAMES:
            raise ValueError("unknown parameter '%s'" % name)
        given[_PARAM_NAMES.index(name)] = float(value)
    return given


def _initial_state(s, p, project_initial, allow_inconsistent=False):
    """x0 for the run: initialised, checked finite, projected if asked, constraints checked
    (only for finite residuals with allow_inconsistent).  p: the parameters and their
    constants."""
    j = _first_nonfinite(p[:len(_PARAM_NAMES)])
    if j >= 0:
        raise SimulationError("parameter '%s' is not finite" % _PARAM_NAMES[j], s.t0,
                              numpy.zeros(0), numpy.zeros((0, len(OUTPUTS))))
    x0 = _init(p)
    i = _first_nonfinite(x0)
    if i >= 0:
        raise SimulationError(str(_fail(s.t0, "state", STATES[i])), s.t0, numpy.zeros(0),
                              numpy.zeros((0, len(OUTPUTS))))
    if project_initial:
        _project_initial(s.t0, x0, p)
    messages = _check_constraints(s.t0, x0, p, allow_inconsistent)
    if messages:
        raise ConstraintError("; ".join(messages), messages)
    return x0


def rows(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
         project_initial=False, stats=None, max_steps=None, allow_inconsistent=False,
         max_step=None, event_rows=False, events=None, inputs=None, input=None,
         error_states=None):
    """Runs the model, yielding each output row (t, y) as it is computed (y a list ordered as
    OUTPUTS): memory does not grow with the run's length.  A failure raises SimulationError
    after the rows before it (its .times and .rows are then empty: they were yielded).
    stats: a dict that receives the solver's counters.  allow_inconsistent: start from
    initial values that violate the constraints, neither refused nor projected (the
    correctors pull them back); it excludes project_initial.  max_step: every solver's
    largest step (a fixed step longer is cut to it); event_rows: two rows at each event (its left and right limits); events: a
    list that receives (t, event, change) for every change at an event, or a file name that
    receives them as CSV (the program's --events).  inputs: {name: (t, values)}, the data of
    the model's inputs (interpolated linearly, held outside, each t a time event; an input
    without data keeps its default); input: a CSV file of such data, as --input reads it.
    error_states: the adaptive solvers' error control weighs the first error_states states
    only (the others follow the steps chosen for them); None or 0: all."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")
    log = None
    if events is None or isinstance(events, list):
        on_event = (lambda t, what, change: events.append((t, what, change))) \
            if events is not None else None
    else:  # a file name: the event log's CSV, as --events writes it
        log = open(events, "w", encoding="utf-8", newline="")
        log.write("t,event,change\n")
        on_event = _event_writer(log)
    s = _settings(t_end, dt, solver, rtol, atol, step, max_steps, max_step, event_rows,
                  on_event, _input_series(inputs, input), error_states)
    p = _with_constants(_param_values(_overrides(params)))
    x0 = _initial_state(s, p, project_initial, allow_inconsistent)
    st = _new_stats() if stats is None else stats
    st.update(_new_stats())
    try:
        for t, y in _integrate(s, p, x0, st):
            yield t, y
    except _Failure as failure:
        raise SimulationError(str(failure), failure.t, numpy.zeros(0),
                              numpy.zeros((0, len(OUTPUTS)))) from None
    finally:
        if log is not None:
            log.close()


def simulate(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
             project_initial=False, out=None, max_steps=None, allow_inconsistent=False,
             max_step=None, event_rows=False, events=None, inputs=None, input=None,
             error_states=None):
    """Runs the model; returns (t, Y) with Y[k] the outputs at t[k].  None: the scene's value.
    out: a file name or a text file: the CSV is written there row by row as the run goes
    (header first, as the program writes it) and nothing is kept: returns the number of rows.
    max_step, event_rows, events, inputs, input, error_states: as rows()."""
    run = rows(t_end, dt, solver, rtol, atol, params, step, project_initial,
               max_steps=max_steps, allow_inconsistent=allow_inconsistent, max_step=max_step,
               event_rows=event_rows, events=events, inputs=inputs, input=input,
               error_states=error_states)
    if out is not None:
        return _stream(run, out)
    times, values = [], []
    try:
        for t, y in run:
            times.append(t)
            values.append(y)
    except SimulationError as error:
        raise SimulationError(str(error), error.t, numpy.array(times, dtype=float),
                              numpy.array(values, dtype=float).reshape(len(times), len(OUTPUTS))) \
            from None
    return (numpy.array(times, dtype=float),
            numpy.array(values, dtype=float).reshape(len(times), len(OUTPUTS)))


def _stream(run, out):
    if not hasattr(out, "write"):
        with open(out, "w", encoding="utf-8", newline="") as f:
            return _stream(run, f)
    out.write(",".join(["t"] + OUTPUTS) + "\n")
    count = 0
    for t, y in run:
        out.write(_row_text(t, y))
        count += 1
    return count


def _row_text(t, y):
    return ",".join(["%.17g" % t] + ["%.17g" % v for v in y]) + "\n"


# ---------------------------------------------------------------- command line

USAGE = (
    " [--t-end T] [--dt DT] [--solver NAME] [--rtol R] [--atol A]\n"
    "       [--step H] [--max-steps N] [-p NAME=VALUE ...] [--stats] [--progress]\n"
    "       [--project-initial | --allow-inconsistent]\n"
    "       [--max-step H] [--error-states N] [--event-rows] [--events FILE] [--input FILE]\n"
    "       [--batch FILE|- [--metric KIND:OUTPUT ...] [--trajectories DIR]]\n"
)
_WITH_VALUE = ("--t-end", "--dt", "--solver", "--rtol", "--atol", "--step", "--max-steps", "-p",
               "--max-step", "--events", "--input", "--error-states")
_NUMBER_CHARS = frozenset("0123456789+-.eE")


class _UsageError(Exception):
    pass


def _usage():
    return "usage: " + _IDENT + USAGE


def _help():
    s = _settings()
    lines = [
        _usage() + "Simulates the model and writes CSV (t and the outputs) to stdout.",
        "  --t-end T          end time (%.17g; the start time is %.17g)" % (s.t_end, s.t0),
        "  --dt DT            output interval (%.17g)" % s.dt,
        "  --solver NAME      the solver (%s), one of those listed below" % s.solver,
        "  --rtol R           relative tolerance of the adaptive solvers (%.17g)" % s.rtol,
        "  --atol A           absolute tolerance of the adaptive solvers (%.17g)" % s.atol,
        "  --step H           step of the fixed-step solvers (default: dt)",
        "  --max-steps N      the most steps between two output times (%d; 0: no limit)"
        % s.max_steps,
        "  --max-step H       every solver's largest step (default: no bound)",
        "  --error-states N   the error control weighs the first N states only (0: all)",
        "  --event-rows       two rows at each event: its left and right limits",
        "  --events FILE      the event log: t,event,change, a row per change",
        "  --input FILE       the inputs' data: CSV, a column t and one per input",
        "  -p NAME=VALUE      set a parameter; derived parameters follow",
        "  --project-initial  project the initial state onto the constraints",
        "  --allow-inconsistent  start from an initial state that violates the constraints",
        "                     (the correctors pull it back): neither refused nor projected",
        "  --stats            print the solver's counters to stderr",
        "  --progress         report the progress on stderr: lines bgc-progress T T0 T_END",
        "  --batch FILE       one run per line of FILE (- for stdin): NAME=VALUE words;",
        "                     writes a CSV row per run: run,status,metrics,steps,rejected,",
        "                     rhs,cpu,message",
        "  --metric K:OUTPUT  with --batch: a column, K one of final, max, min, maxabs, rms",
        "  --trajectories DIR with --batch: each run's CSV also to DIR/run-NNNNNN.csv",
        "solvers:",
    ]
    lines += ["  %-8s %s" % (name, m["summary"]) for name, m in _METHODS.items()]
    if PARAMETERS:
        lines.append("parameters (NAME = default):")
    lines += ["  %s = %.17g" % (name, value) for name, value in PARAMETERS.items()]
    sys.stdout.write("\n".join(lines) + "\n")


def _parse_number(option, text):
    """A decimal number (digits, sign, '.', exponent: no hex, inf or nan), finite."""
    if text and set(text) <= _NUMBER_CHARS:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if math.isfinite(value):
            return value
    raise _UsageError("error: invalid value for %s: '%s'\n" % (option, text))


def _parse_param(text, given):
    name, eq, value = text.rpartition("=")
    if not eq or not name:
        raise _UsageError("error: -p expects NAME=VALUE, got '%s'\n" % text)
    if name not in _PARAM_NAMES:
        raise _UsageError("error: unknown parameter '%s'\n" % name)
    given[_PARAM_NAMES.index(name)] = _parse_number(name, value)


def _apply_option(name, value, options, given):
    if name == "-p":
        _parse_param(value, given)
    elif name == "--solver":
        if value not in SOLVERS:
            raise _UsageError(
                "error: unknown solver '%s' (expected %s)\n" % (value, _SOLVER_LIST))
        options["solver"] = value
    elif name == "--step":
        options["step"] = _parse_number(name, value)
        if not options["step"] > 0.0:
            raise _UsageError("error: --step must be positive\n")
    elif name == "--max-step":
        options["max_step"] = _parse_number(name, value)
        if not options["max_step"] > 0.0:
            raise _UsageError("error: --max-step must be positive\n")
    elif name == "--events":
        options["events"] = value
    elif name == "--input":
        options.setdefault("input", []).append(value)
    elif name == "--max-steps":
        n = _parse_number(name, value)
        if not (0.0 <= n <= 1e15 and n == math.floor(n)):
            raise _UsageError(
                "error: --max-steps must be a whole number from 0 (no limit) to 1e15\n")
        options["max_steps"] = int(n)
    elif name == "--error-states":
        n = _parse_number(name, value)
        if not (0.0 <= n <= _N and n == math.floor(n)):
            raise _UsageError("error: --error-states must be a whole number from 0 (all) to "
                              "%d\n" % _N)
        options["error_states"] = int(n)
    else:
        options[name[2:].replace("-", "_")] = _parse_number(name, value)


def _parse_args(argv):
    """(options, given parameters, flags), or None after --help."""
    options, given, flags = {}, {}, set()
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg in ("-h", "--help"):
            _help()
            return None
        if arg in ("--project-initial", "--allow-inconsistent", "--stats", "--progress",
                   "--event-rows"):
            flags.add(arg)
            if {"--project-initial", "--allow-inconsistent"} <= flags:
                raise _UsageError(
                    "error: --project-initial and --allow-inconsistent exclude each other\n")
            i += 1
            continue
        name, eq, value = arg.partition("=") if arg.startswith("--") else (arg, "", "")
        if name not in _WITH_VALUE:
            raise _UsageError("error: unknown option '%s'\n%s" % (arg, _usage()))
        if not eq:
            if i + 1 >= len(argv):
                raise _UsageError("error: option '%s' needs a value\n%s" % (arg, _usage()))
            i += 1
            value = argv[i]
        _apply_option(name, value, options, given)
        i += 1
    return options, given, flags


def _csv_field(text):
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _event_writer(f):
    """The event log's rows (--events), as the C program writes them."""
    def write(t, what, change):
        f.write("%.17g,%s,%s\n" % (t, _csv_field(what), _csv_field(change)))
    return write


def _stop_on_signals():
    """SIGINT and SIGTERM stop the run at its next step, its rows written (as the C program
    does); the handlers they replace, to restore.  None outside the main thread."""
    replaced = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            replaced.append((sig, signal.signal(sig, lambda number, frame: request_stop(number))))
    return replaced


def _die_with_parent():
    """Started by bgc (BGC_PARENT_PID in the environment: bgc's process id), the program dies
    with it instead of running on as an orphan when bgc is killed: a thread watches the parent
    and ends the process when it has gone (as bgc_die_with_parent in the C program).  Run by
    anything else, this does nothing."""
    try:
        parent = int(os.environ.get("BGC_PARENT_PID", ""))
    except ValueError:
        return

    def watch():
        while os.getppid() == parent:
            time.sleep(0.2)
        os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))

    threading.Thread(target=watch, daemon=True).start()


def _write_failed(error):
    """The CSV could not be written: the message bgc simulate reads ("cannot write the output:
    REASON"); what stdout still holds goes nowhere, so that leaving does not fail again."""
    sys.stderr.write("error: cannot write the output: %s\n" % (error.strerror or error))
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


def _progress_reporter(s):
    """--progress: a line "bgc-progress T T0 T_END" on stderr at the first row, then as the
    rows pass at most ten a second (bgc simulate draws them as a bar)."""
    last = [None]

    def report(t):
        now = time.monotonic()
        if last[0] is None or now - last[0] >= 0.1:
            last[0] = now
            sys.stderr.write("bgc-progress %.17g %.17g %.17g\n" % (t, s.t0, s.t_end))
            sys.stderr.flush()
    return report


def main(argv=None):
    """The command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    _die_with_parent()
    if any(a == "--batch" or a.startswith("--batch=") for a in argv):
        return _batch_main(argv)  # (batch mode, at the end)
    try:
        parsed = _parse_args(argv)
    except _UsageError as error:
        sys.stderr.write(str(error))
        return 2
    if parsed is None:
        return 0
    options, given, flags = parsed
    log_path = options.pop("events", None)
    input_path = options.pop("input", None)
    try:
        s = _settings(event_rows="--event-rows" in flags, **options)
        s.inputs = _input_series(None, input_path) if input_path is not None else None
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    p = _with_constants(_param_values(given))
    try:
        x0 = _initial_state(s, p, "--project-initial" in flags,
                            "--allow-inconsistent" in flags)
    except ConstraintError as error:
        sys.stderr.write("".join("error: %s\n" % m for m in error.messages))
        return 1
    except SimulationError as error:
        sys.stderr.write("error: %s\n" % error)
        return 3
    log = None
    if log_path is not None:
        try:
            log = open(log_path, "w", encoding="utf-8", newline="")
        except OSError as error:
            sys.stderr.write("error: cannot write the event log '%s': %s\n"
                             % (log_path, error.strerror or error))
            return 2
        log.write("t,event,change\n")
        s.on_event = _event_writer(log)
    stats = _new_stats()
    failure = lost = None
    out = sys.stdout
    handlers = _stop_on_signals()
    progress = _progress_reporter(s) if "--progress" in flags else None
    try:
        out.write(",".join(["t"] + OUTPUTS) + "\n")
        for t, y in _integrate(s, p, x0, stats):
            out.write(_row_text(t, y))
            if progress is not None:
                progress(t)
        out.flush()
    except _Failure as error:
        failure = error
    except OSError as error:  # the CSV cannot be written (a full disk, a closed pipe)
        lost = error
    finally:
        for sig, handler in handlers:
            signal.signal(sig, handler)
        request_stop(0)
        if log is not None:
            try:
                log.close()
            except OSError as error:
                lost = lost or error
    if failure is not None:
        try:
            out.flush()
        except OSError as error:
            lost = error
    if lost is not None:
        _write_failed(lost)
        return 3
    if "--stats" in flags:
        sys.stderr.write(_stats_line(stats) + "\n")
    if failure is not None:
        sys.stderr.write("error: %s\n" % failure)
        return 3
    return 0


# ================================================================== drive ===
# The step driver (_drive, as bgc_drive in the C runtime's drive.c; the contract between the
# driver and a method family is _Family's docstring) and the run of a solver (_integrate); the
# families follow (erk.py, stiff.py).  The arithmetic is the C runtime's, in the same order.

def _output_count(s):
    """As bgc_output_count: at least 1 when t_end > t0, so that t0 and t_end are rows whatever
    dt; 0 when they are the same time (one row)."""
    n = math.ceil((s.t_end - s.t0) / s.dt - 1e-6)
    return n if n > 1 else 1 if s.t_end > s.t0 else 0


def _output_time(s, k, n):
    return s.t_end if k >= n else s.t0 + k * s.dt


def _hmin(t):
    """Steps below this are too small to resolve at t (16 ulps of t; the least normal at 0)."""
    return max(16.0 * _EPS * abs(t), sys.float_info.min)


def _first_nonfinite(v):
    for i, a in enumerate(v):
        if not math.isfinite(a):
            return i
    return -1


def _fail(t, what, name):
    return _Failure("at t = %.17g: %s '%s' is not finite" % (t, what, name), t)


def _fail_step(t, h, worst):
    if worst >= 0:
        message = "at t = %.17g: step size too small (h = %.3g), limited by state '%s'" % (
            t, h, STATES[worst])
    else:
        message = "at t = %.17g: step size too small (h = %.3g)" % (t, h)
    return _Failure(message, t)


_STOP = [0]  # a signal's number: the run stops at its next accepted step (request_stop)


def request_stop(sig):
    """Asks a run in progress to stop at its next accepted step, as a failure ("interrupted by
    signal sig"), the rows before it kept; a signal handler may call it.  0 clears it."""
    _STOP[0] = sig


def _accept(run, t):
    """Counts an accepted step ending at t; raises _Failure if a stop was asked or the step
    budget since the last output is spent."""
    run.st["steps"] += 1
    if _STOP[0]:
        raise _Failure("at t = %.17g: interrupted by signal %d" % (t, _STOP[0]), t)
    if run.s.max_steps > 0 and run.st["steps"] - run.steps_out > run.s.max_steps:
        raise _Failure("at t = %.17g: step budget spent: %d steps since the %s at t = %.17g "
                       "(the step size runs away; --max-steps raises the budget)"
                       % (t, run.s.max_steps, "event" if run.from_event else "output",
                          run.t_out), t)


def _block_failed(failure):
    return _Failure(str(failure), failure.t)


def _new_stats():
    return {"steps": 0, "rejected": 0, "rhs": 0, "jac": 0, "lu": 0, "solves": 0,
            "switched": False, "t_switch": 0.0, "cpu": 0.0, "h_next": 0.0, "order_next": 0,
            "events": 0, "locate_evals": 0}


def _stats_line(st):
    line = ("stats: steps=%(steps)d rejected=%(rejected)d rhs=%(rhs)d jac=%(jac)d lu=%(lu)d "
            "solves=%(solves)d" % st)
    if st["switched"]:
        line += " stiff_from=%.17g" % st["t_switch"]
    if _DISCRETE_NAMES:
        line += " events=%d locate=%d" % (st["events"], st["locate_evals"])
    return line + " cpu=%.6e" % st["cpu"]


class _Stiff(Exception):
    """An auto run's explicit phase found the problem stiff."""


class _Run:
    """A run in progress (see bgc_run in the C runtime): a run function is a generator that
    integrates from (run.t, y) to s.t_end, yields the rows (t, outputs) of the output times
    run.kout .. run.nout as it passes them, keeps run.t and run.y at its last accepted step,
    and returns; or raises _Failure, _Stiff (run.h: its last step size)."""

    __slots__ = ("s", "p", "w", "st", "nout", "kout", "t", "h", "y", "detect_stiffness",
                 "steps_out", "t_out", "from_event", "m", "name", "fixed", "doff", "g", "t_next",
                 "t_event", "chain", "kout_ev", "events_out", "sliding", "passes", "last",
                 "chain_from", "sliding_from", "out_from", "band", "gmax")

    def __init__(self, s, p, w, st, y):
        self.s, self.p, self.w, self.st = s, p, w, st
        self.steps_out, self.t_out = st["steps"], s.t0  # the steps at the last output, its t
        self.from_event = False  # (or at the last event: the step budget counts from either)
        self.nout, self.kout = _output_count(s), 1
        self.t, self.h, self.y = s.t0, s.h0, y
        self.detect_stiffness = False
        self.m, self.name, self.fixed = None, "", False  # the method running, see _run_solver
        # events (bgc_run's): d at p[doff:], the indicators at run.t, the next time event,
        # the last event's time and the events in a row closer than the resolution
        self.doff = len(p) - len(_DISCRETE_NAMES)
        # per state relation: its hysteresis band (0: none) and its indicator's largest
        # magnitude so far (bgc_run's band, gmax; _relation), kept in the workspace
        self.band, self.gmax = w.band, w.gmax
        self.g = []
        self.t_next, self.t_event, self.chain = math.inf, -math.inf, 0
        # the events since an output row (kout_ev: run.kout then) are bounded as steps are
        self.kout_ev, self.events_out = 0, 0
        self.sliding = 0  # accepted steps in a row, each ended at a located (state) event
        # what keeps changing, for the chattering messages: the event iteration's passes so
        # far, the pass that last changed each discrete value (-1: none yet), and the passes
        # where the chains the driver bounds began (events in a row, steps cut short, events
        # since an output row)
        self.passes = 0
        self.last = [-1] * len(_DISCRETE_NAMES)
        self.chain_from = self.sliding_from = self.out_from = 0

    def f(self, t, y):
        """dy/dt as a numpy vector; a failed algebraic block raises _BlockFailure."""
        out = [0.0] * _N
        _rhs(t, y.tolist(), self.p, self.w, out)
        return numpy.array(out, dtype=float)

    def fv(self, t, y):
        """dy/dt for the explicit solvers, in _V's kind of vector."""
        if _V is _ArrayVectors:
            return self.f(t, y)
        out = [0.0] * _N
        _rhs(t, y, self.p, self.w, out)
        return out

    def emit(self, t, x):
        if isinstance(x, numpy.ndarray):
            x = x.tolist()
        y = [0.0] * len(OUTPUTS)
        try:
            _out(t, x, self.p, self.w, y)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        j = _first_nonfinite(y)
        if j >= 0:
            raise _fail(t, "output", OUTPUTS[j])
        self.steps_out, self.t_out, self.from_event = self.st["steps"], t, False
        yield t, y

    def emit_step(self, c, until, inclusive=True):
        """The output times in (c.t, until] (until excluded if not inclusive) after an
        accepted step: c.tph from c.y1, the others from the dense output (bgc_emit_step)."""
        while self.kout <= self.nout:
            tk = _output_time(self.s, self.kout, self.nout)
            if tk > until or (tk == until and not inclusive):
                break
            yield from self.emit(tk, c.y1 if tk == c.tph else c.at(tk))
            self.kout += 1


class _Dense:
    """The state inside the step just accepted (bgc_dense): the family's dense output, or
    the cubic Hermite interpolant for a family without one (event location only)."""

    __slots__ = ("run", "dense", "t", "h", "tph", "y", "y1", "fn", "f0", "f1")

    def __init__(self, run, dense, t, h, tph, y, y1):
        self.run, self.dense, self.t, self.h, self.tph, self.y, self.y1 = \
            run, dense, t, h, tph, y, y1
        self.fn = self.f0 = self.f1 = None

    def at(self, tk):
        if tk == self.tph:
            return self.y1
        if self.dense is not None:
            if self.fn is None:
                self.fn = self.dense()
            return self.fn((tk - self.t) / self.h)
        run = self.run
        if self.f0 is None:
            run.st["rhs"] += 2
            try:
                self.f0 = _as_list(run.f(self.t, numpy.asarray(self.y, dtype=float)))
                self.f1 = _as_list(run.f(self.tph, numpy.asarray(self.y1, dtype=float)))
            except _BlockFailure as failure:
                raise _block_failed(failure) from None
        th, h = (tk - self.t) / self.h, self.h
        y, y1, f0, f1 = _as_list(self.y), _as_list(self.y1), self.f0, self.f1
        return [(1.0 - th) * y[i] + th * y1[i]
                + th * (th - 1.0) * ((1.0 - 2.0 * th) * (y1[i] - y[i]) + (th - 1.0) * h * f0[i]
                                     + th * h * f1[i]) for i in range(_N)]


def _as_list(v):
    return v.tolist() if isinstance(v, numpy.ndarray) else list(v)


# ---------------------------------------------------------------- events
# A model's events (docs/hybrid.md), as the C runtime's drive.c handles them: the indicators
# checked at the end of every accepted step, the first change of a state relation located on
# the dense output (Illinois), time events stepped onto, the event iteration at an event.

MAX_EVENT_ITERATIONS = 100  # events at one instant (passes that change something) allowed
NAMED_CHANGES = 6  # the discrete values a chattering message names, at most


def _holds(k, g):
    return g > 0.0 if _INDICATOR_STRICT[k] else g >= 0.0


# Hysteresis (docs/hybrid.md, "Knees"; drive.c's BGC_BAND_REL): a state relation that changed
# its value at an event keeps it until its indicator goes back beyond zero by more than its
# band: the larger of what the indicator changes by in the time's resolution along the
# derivative after the event (_bands) and BAND_REL times the largest magnitude the indicator
# has had in the run.
BAND_REL = 1e-12


def _level(run, k, g):
    """bgc_level: relation k's indicator g moved by its band (g itself without one)."""
    b = run.band[k]
    if b > 0.0:
        return g + b if run.p[run.doff + k] != 0.0 else g - b
    return g


def _relation(run, k, g):
    """bgc_relation: the value relation k takes at g (within its band, the one it has)."""
    if run.band[k] > 0.0:
        if run.p[run.doff + k] != 0.0:
            return _level(run, k, g) >= 0.0
        return _level(run, k, g) > 0.0
    return _holds(k, g)


def _seen(run, g):
    """bgc_seen: the indicators at an accepted point: their largest magnitudes, and the end
    of the band of a relation whose indicator is beyond it on the relation's own side."""
    p, off, band, gmax = run.p, run.doff, run.band, run.gmax
    for k in range(len(_INDICATOR_STRICT)):
        a = abs(g[k])
        if a > gmax[k]:
            gmax[k] = a
        b = band[k]
        if b > 0.0 and (g[k] > b if p[off + k] != 0.0 else g[k] < -b):
            band[k] = 0.0


def _changed(run, g):
    p, off = run.p, run.doff
    for k in range(len(_INDICATOR_STRICT)):
        if _relation(run, k, g[k]) != (p[off + k] != 0.0):
            return k
    return -1


def _indicators(run, t, x):
    g = [0.0] * len(_INDICATOR_STRICT)
    try:
        _events(t, _as_list(x), run.p, run.w, g)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    for k, v in enumerate(g):
        if not math.isfinite(v):
            raise _fail(t, "event condition", _DISCRETE_NAMES[k])
    return g


def _set_next_time(run, t, x):
    run.t_next = math.inf
    if not _NUM_TIMERS:
        return
    tau = [0.0] * _NUM_TIMERS
    try:
        _next_time(t, _as_list(x), run.p, run.w, tau)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    for v in tau:
        if v > t and v < run.t_next:
            run.t_next = v


def _log(run, t, what, change):
    if run.s.on_event is not None:
        run.s.on_event(t, what, change)


def _log_discrete(run, t, k, old, new, shown):
    """bgc_log_discrete: the event log's row of discrete value k changing from old to new;
    the input whose row this pass wrote last (its three values are consecutive: one row)."""
    kind, j = _DISCRETE_LOG[2 * k], _DISCRETE_LOG[2 * k + 1]
    if kind == _LOG_INPUT:
        if j != shown:
            _log(run, t, _INPUT_NAMES[j], "%.17g -> %.17g" % (_input_value(run.w, j, t, 0),
                                                             _input_value(run.w, j, t, 1)))
        return j
    if kind == _LOG_TABLE:
        T = _TABLES[j]
        _log(run, t, _DISCRETE_NAMES[k], "%.17g -> %.17g" % (_table_limit(T, t, old),
                                                            _table(T, t, new, 0)))
    else:
        _log(run, t, _DISCRETE_NAMES[k], "%.17g -> %.17g" % (old, new))
    return -1


def _chattering(run, t, head, since, tail):
    """bgc_chattering: the run's failure, naming every discrete value a pass since the pass
    `since` changed (conditions first, at most NAMED_CHANGES of them, then how many more)."""
    changing = [_DISCRETE_NAMES[k] for k, p in enumerate(run.last) if p >= since]
    named = ["'%s'" % n for n in changing[:NAMED_CHANGES]]
    if len(changing) > NAMED_CHANGES:
        named.append("%d more" % (len(changing) - NAMED_CHANGES))
    what = (", ".join(named[:-1]) + " and " + named[-1]) if len(named) > 1 else \
        (named[0] if named else "the state")
    verb = " keep changing: " if len(changing) > 1 else " keeps changing: "
    return _Failure("at t = %.17g: chattering: %s (%s%s%s)" % (t, head, what, verb, tail), t)


def _bands(run, t, x):
    """bgc_bands: the bands of the relations that changed in the last pass, at (t, x) after
    it: each at least what its indicator changes by over the time's resolution tau along the
    derivative there (x + tau f)."""
    f = [0.0] * _N
    try:
        _rhs(t, x, run.p, run.w, f)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    tau = max(1e-12 * abs(t), _hmin(t))
    xt = [x[i] + tau * f[i] for i in range(_N)]
    g0 = _indicators(run, t, x)
    g1 = _indicators(run, t + tau, xt)
    band, last = run.band, run.last
    for k in range(len(_INDICATOR_STRICT)):
        if last[k] == run.passes:
            d = abs(g1[k] - g0[k])
            if d > band[k]:
                band[k] = d


def _jumps_after(run, t, x, dtau):
    """bgc_jumps_after: S -= f+ dtau/dp for each parameter, f+ the right side at (t, x)."""
    if not any(d != 0.0 for d in dtau):
        return
    f = [0.0] * _N
    try:
        _rhs(t, x, run.p, run.w, f)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    n = _N // (1 + _NUM_JUMPS)
    for j in range(_NUM_JUMPS):
        for i in range(n):
            x[n + j * n + i] = x[n + j * n + i] - f[i] * dtau[j]


def _event_iteration(run, t, x, start):
    """bgc_event_iteration: update until nothing changes; x (a list) is updated; run.g the
    indicators there after it.  With the sensitivities' jumps (_NUM_JUMPS): S changes
    nothing else and is not logged; the first pass's dtau/dp goes back into the later ones,
    then _jumps_after."""
    G, p, off = len(_INDICATOR_STRICT), run.p, run.doff
    J, ND = _NUM_JUMPS, len(_DISCRETE_NAMES)
    n = _N // (1 + J)
    dtau = [0.0] * J
    changed, it = True, 0
    while changed:
        if it > MAX_EVENT_ITERATIONS:  # the last pass still changed something
            raise _chattering(run, t, "more than %d events at one instant, the event "
                              "iteration does not settle" % MAX_EVENT_ITERATIONS,
                              run.passes - 1, "a Zeno model?")
        g = _indicators(run, t, x)
        gmax = run.gmax
        for k in range(G):
            if abs(g[k]) > gmax[k]:
                gmax[k] = abs(g[k])
        r = [1.0 if _relation(run, k, g[k]) else 0.0 for k in range(G)]
        r.append(1.0 if start and it == 0 else 0.0)
        if J:
            r.append(1.0 if not start and it == 0 else 0.0)
            r += dtau
        out = [0.0] * (_N + ND + J)
        try:
            _update(t, x, p, run.w, r, out)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        dtau = out[_N + ND:]
        if not all(math.isfinite(d) for d in dtau):
            raise _Failure("at t = %.17g: the event's time has no derivative (an event that "
                           "grazes: its indicator's rate along the motion is zero), so the "
                           "sensitivities cannot pass it" % t, t)
        changed = False
        for i in range(_N):
            if not math.isfinite(out[i]):
                raise _fail(t, "state after the event", STATES[i])
            if out[i] != x[i] and i >= n:
                x[i] = out[i]
            elif out[i] != x[i]:
                changed = True
                if not start and run.s.on_event is not None:
                    _log(run, t, STATES[i], "%.17g -> %.17g" % (x[i], out[i]))
                x[i] = out[i]
        shown = -1
        crossed = False
        for k in range(len(_DISCRETE_NAMES)):
            v = out[_N + k]
            if not math.isfinite(v):
                raise _fail(t, "discrete value", _DISCRETE_NAMES[k])
            if v != p[off + k]:
                changed = True
                run.last[k] = run.passes
                if k < G:  # a relation that changed: its band (none at the start)
                    run.band[k] = 0.0 if start and it == 0 else BAND_REL * run.gmax[k]
                    crossed = crossed or not (start and it == 0)
                if not start and run.s.on_event is not None:
                    shown = _log_discrete(run, t, k, p[off + k], v, shown)
                p[off + k] = v
        if crossed:
            _bands(run, t, x)
        it += 1
        run.passes += 1
    if J and not start:
        _jumps_after(run, t, x, dtau)
    _seen(run, g)
    run.g = g


def _margin(run, k, g):
    """bgc_margin: how far relation k's indicator g is from changing (negative: changed)."""
    level = _level(run, k, g)
    return level if run.p[run.doff + k] != 0.0 else -level


def _hidden(run, c, gb):
    """bgc_hidden: (tm, g there) where a relation that changes and changes back inside the
    step has changed (at the middle, then at the turn of the parabola through its margins at
    the start, the middle and the end), or None."""
    ta, h = c.t, c.tph - c.t
    best = 2.0
    tm = ta + 0.5 * h
    ga = run.g
    for probe in range(2):
        g = _indicators(run, tm, c.at(tm))
        run.st["locate_evals"] += 1
        if _changed(run, g) >= 0:
            return tm, g
        if probe == 1:
            break
        for k in range(len(g)):
            s0, sm = _margin(run, k, ga[k]), _margin(run, k, g[k])
            s1 = _margin(run, k, gb[k])
            a2 = 2.0 * (s0 - 2.0 * sm + s1)
            a1 = 4.0 * sm - 3.0 * s0 - s1
            if a2 > 0.0:
                s = -a1 / (2.0 * a2)
                if s > 0.0 and s < 1.0 and s0 + s * (a1 + s * a2) < 0.0 and s < best:
                    best = s
        if best >= 2.0:
            break
        tm = ta + best * h
    return None


def _find_event(run, c):
    """bgc_find_event: None, or (te, the state there: a list); run.sliding counted."""
    G = len(_INDICATOR_STRICT)
    due = c.tph >= run.t_next
    gb = _indicators(run, c.tph, c.y1) if G else []
    tb = c.tph
    if not G or _changed(run, gb) < 0:
        hidden = _hidden(run, c, gb) if G else None
        if hidden is None:
            run.sliding = 0
            if due:
                return c.tph, _as_list(c.y1)
            run.g = gb
            _seen(run, gb)
            return None
        tb, gb = hidden
    ga, ta, wa, wb, moved = list(run.g), c.t, 1.0, 1.0, 0
    p, off = run.p, run.doff
    h = c.tph - c.t  # the time's resolution is relative to the step too (an event near t = 0)
    probed = False
    for it in range(200):
        at = max(abs(ta), abs(tb))  # (1e-12 relative in t, the resolution relative to h too)
        scale = max(at, h)
        tol = max(1e-12 * at, max(4.0 * _EPS * scale, sys.float_info.min))
        if tb - ta <= tol:
            break
        frac = 1.0
        for k in range(G):
            if _relation(run, k, gb[k]) != (p[off + k] != 0.0):
                a, b = wa * _level(run, k, ga[k]), wb * _level(run, k, gb[k])
                d = a - b  # 0: C's quotient is inf or nan, refused below as q = 0.5 is
                q = a / d if d != 0.0 else 0.5
                if not (q >= 0.0 and q <= 1.0) or (q == 0.0 and probed):
                    q = 0.5
                if q < frac:
                    frac = q
        if it >= 100:
            frac = 0.5
        if frac == 0.0:  # an indicator exactly 0 at ta: probed once at the time's resolution,
            probed = True  # then bisected (where rounding holds it at 0, the secant stalls)
        tm = ta + frac * (tb - ta)
        tm = max(tm, ta + 0.5 * tol)
        tm = min(tm, tb - 0.5 * tol)
        gm = _indicators(run, tm, c.at(tm))
        run.st["locate_evals"] += 1
        if _changed(run, gm) >= 0:
            tb, gb, wb = tm, gm, 1.0
            wa = 0.5 * wa if moved > 0 else 1.0
            moved = 1
        else:
            ta, ga, wa = tm, gm, 1.0
            wb = 0.5 * wb if moved < 0 else 1.0
            moved = -1
    run.sliding += 1
    if run.sliding == 1:
        run.sliding_from = run.passes
    return tb, _as_list(c.at(tb))


def _after_event(run, t, x):
    """bgc_after_event: the event, the rows at t (its right limit; those within the time's
    resolution of t too)."""
    yield from _handle_event(run, t, x)
    while run.kout <= run.nout:
        tk = _output_time(run.s, run.kout, run.nout)
        if tk - t > _hmin(t):
            break
        yield from run.emit(tk, x)
        run.kout += 1
    run.t = t


def _handle_event(run, t, x):
    """bgc_handle_event: the rows at the event (--event-rows), its iteration, the next time
    event; a run whose events come closer than it resolves stops."""
    run.st["events"] += 1
    if run.kout != run.kout_ev:  # the first event since an output row
        run.kout_ev, run.events_out = run.kout, run.st["events"] - 1
        run.out_from = run.passes
    scale = max(abs(t), abs(run.t_event))
    # (the run's first event has none before it: t_event is -inf, and so is the scale)
    if math.isfinite(run.t_event) and t - run.t_event <= max(1e-12 * scale, _hmin(t)):
        run.chain += 1
    else:
        run.chain, run.chain_from = 0, run.passes
    run.t_event = t
    run.steps_out, run.t_out, run.from_event = run.st["steps"], t, True  # a new step budget
    if run.s.event_rows:
        yield from run.emit(t, x)
    _event_iteration(run, t, x, False)
    if run.chain >= MAX_EVENT_ITERATIONS:
        raise _chattering(run, t, "%d events in a row, each within 1e-12 relative of the one "
                          "before" % run.chain, run.chain_from,
                          "a Zeno model, the switching outruns the time's resolution")
    # every step cut short by a state event: at most a hundredth of the step budget in a row,
    # and at least 1000
    if run.s.max_steps > 0 and \
            run.sliding >= (run.s.max_steps // 100 if run.s.max_steps > 100000 else 1000):
        raise _chattering(run, t, "%d steps in a row, each cut short by an event" % run.sliding,
                          run.sliding_from, "a sliding mode or a Zeno model? --max-steps "
                          "raises the limit, a hundredth of it")
    # the events since the last output row: as many as the step budget, and at least 1000 (a
    # small step budget is for a step size that runs away, not for events)
    if run.s.max_steps > 0 and \
            run.st["events"] - run.events_out > max(run.s.max_steps, 1000):
        raise _chattering(run, t, "%d events since the last output row"
                          % (run.st["events"] - run.events_out - 1), run.out_from,
                          "a Zeno model? --max-steps raises the budget")
    if run.s.event_rows:
        yield from run.emit(t, x)
    _set_next_time(run, t, x)


# Byte parity with the C runtime: sums in C's sequence (never numpy.sum, dot or @, whose
# pairwise or SIMD order depends on the machine; never the builtin sum, compensated from
# Python 3.12 on), bgc_max's choice for a NaN.

def _seq_sum(v):
    """0.0 + v_0 + v_1 + ... in this order, as C's `acc = 0.0; acc += v[l]` loops."""
    return 0.0 + float(numpy.add.accumulate(v)[-1]) if len(v) else 0.0


def _seq_minus(acc, terms):
    """acc - terms_0 - terms_1 - ... in this order (C's back substitution)."""
    if len(terms) < 2:
        return acc - terms[0] if len(terms) else acc
    return numpy.subtract.accumulate(numpy.concatenate(([acc], terms)))[-1]


def _c_max(a, b):
    """bgc_max element-wise: b where b > a, else a (a NaN b is never larger)."""
    return numpy.where(b > a, b, a)


def _worst(q):
    """C's running `if (q > big)` from big = -1: the first largest non-NaN q_i, or -1."""
    q = numpy.where(q == q, q, -1.0)
    i = int(numpy.argmax(q)) if len(q) else -1
    return i if i >= 0 and q[i] > -1.0 else -1


def _error_states(s):
    """bgc_error_states: the states the error control weighs (s.error_states, or all)."""
    return s.error_states if 0 < s.error_states < _N else _N


def _weights(s, y, y1):
    """Hairer's error-norm weights atol + rtol * max(|y_i|, |y1_i|) (bgc_weight)."""
    return s.atol + s.rtol * _c_max(numpy.abs(y), numpy.abs(y1))


def _initial_step(run, q, y, f0, hmax):
    """Hairer's initial step size guess (HINIT) for a method of order q."""
    s = run.s
    y, f0 = numpy.asarray(y, dtype=float), numpy.asarray(f0, dtype=float)
    E = _error_states(s)
    sk = s.atol + s.rtol * numpy.abs(y[:E])
    with numpy.errstate(all="ignore"):  # IEEE as in C: an overflow gives inf, then h = 0
        qf, qy = f0[:E] / sk, y[:E] / sk
        dnf, dny = _seq_sum(qf * qf), _seq_sum(qy * qy)
        h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else math.sqrt(dny / dnf) * 0.01
    h = min(h, hmax)
    run.st["rhs"] += 1
    try:
        f1 = run.f(run.t + h, y + h * f0)
    except _BlockFailure:
        return h  # a block failed there: start small, the step control takes over
    with numpy.errstate(all="ignore"):
        d = (f1[:E] - f0[:E]) / (s.atol + s.rtol * numpy.abs(y[:E]))
        der2 = float(numpy.float64(math.sqrt(_seq_sum(d * d))) / numpy.float64(h))
    der12 = max(math.sqrt(dnf), abs(der2))  # a NaN der2 is ignored
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else (0.01 / der12) ** (1.0 / q)
    if not h1 > 0.0:
        h1 = h * 1e-3
    return min(min(100.0 * h, h1), hmax)


def _substeps(span, h):
    r = span / h
    if not r < 1e15:
        return -1
    m = math.ceil(r - 1e-6)
    return 1 if m < 1 else m


# ---------------------------------------------------------------- the step driver
# The driver and the family type: a family is a subclass of _Family, whose docstring is the
# contract between them (both runtimes'); a step's outcomes, as drive.c's BGC_STEP_*:

_ACCEPT, _REJECT, _RETRY, _AGAIN = 0, 1, 2, 3


def _fail_small(run, t, h, bad, bad_kind, failure, worst):
    """A step size below _hmin: the message names what made the steps shrink."""
    if bad == -2:
        return _block_failed(failure)
    if bad in (-3, -4):
        what = ("the iteration matrix is singular" if bad == -3
                else "the Newton iteration does not converge")
        return _Failure("at t = %.17g: %s: %s (step size down to h = %.3g)"
                        % (t, run.name, what, h), t)
    if bad >= 0:
        return _fail(t, bad_kind, STATES[bad])
    return _fail_step(t, h, worst)


class _Grid:
    """Where a fixed-step run is: the k-th of n steps from ta to tb (the run's end on a span
    grid, else the output interval's)."""

    def __init__(self, run, span):
        s = run.s
        self.run, self.span = run, span
        self.step = s.step if s.step > 0.0 else s.dt
        if 0.0 < s.hmax < self.step:  # --max-step bounds a fixed step too
            self.step = s.hmax
        self.ta = self.tb = 0.0
        self.k = self.n = 0

    def next(self, t):
        """The next step's end from t and whether it is the run's last."""
        run = self.run
        if self.k >= self.n:
            self.ta, self.k = t, 0
            self.tb = run.s.t_end if self.span else _output_time(run.s, run.kout, run.nout)
            self.n = _substeps(self.tb - self.ta, self.step)
            if self.n < 0:
                raise _fail_step(t, self.step, -1)
        end = self.k + 1 >= self.n
        tph = self.tb if end else self.ta + (self.k + 1) * self.step
        last = end and (self.span or run.kout >= run.nout)
        if not self.span:  # each step from its grid point (the same value as the last end)
            t = self.ta + self.k * self.step
        if not tph - t >= _hmin(t):
            raise _fail_step(t, tph - t, -1)
        return tph, last


def _hmax(s):
    """bgc_hmax: the run's span, and --max-step if set."""
    span = s.t_end - s.t0
    return min(span, s.hmax) if s.hmax > 0.0 else span


def _drive(run, family, y):
    """One family's run from (run.t, y) to s.t_end: yields the rows as it passes them, keeps
    run.t and run.y at the last accepted step; raises _Failure, or _Stiff (run.h: the
    explicit phase's next step)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    hmax = _hmax(s)
    events = bool(_DISCRETE_NAMES)
    fam = family(run)
    h = fam.start(y)
    t = run.t
    reject = last = False
    bad, bad_kind, failure, wanted = -1, "", None, 0.0
    grid = _Grid(run, fam.span_grid)
    at_event = False
    while True:
        if run.t_next - t <= _hmin(t):  # a time event closer than a step can be
            t, at_event = run.t_next, True
        if at_event:  # the event at (t, y); the method starts afresh after it
            at_event = False
            x = _as_list(y)
            yield from _after_event(run, t, x)
            y = x if isinstance(y, list) else numpy.array(x, dtype=float)
            run.y = y
            if t >= s.t_end or run.kout > run.nout:
                return
            run.h = 0.0
            fam = family(run)
            h = fam.start(y)
            grid.k = grid.n  # a new grid from the event
            reject = last = False
            bad = -1
            continue
        if run.fixed:
            tph, last = grid.next(t)
            if run.t_next < tph:  # a time event inside: the step ends on it
                tph, last = run.t_next, False
            h = tph - t
        else:
            if not h >= _hmin(t):
                raise _fail_small(run, t, h, bad, bad_kind, failure, fam.worst)
            wanted = h
            if run.t_next < s.t_end and t + 1.01 * h - run.t_next > 0.0:
                h = run.t_next - t  # onto the time event
                tph = run.t_next
            else:
                if t + 1.01 * h - s.t_end > 0.0:
                    h = s.t_end - t
                    last = True
                tph = s.t_end if last else t + h
        outcome, y1, hnew, why = fam.step(t, h, tph, y)
        if outcome == _AGAIN:
            continue
        if outcome != _ACCEPT:
            if outcome == _RETRY:
                bad, bad_kind, failure = why
            reject, last = True, False
            st["rejected"] += 1
            h = hnew
            continue
        i = _first_nonfinite(y1)
        if i >= 0:
            raise _fail(tph, "state", STATES[i])
        _accept(run, tph)
        fam.accepted(tph, y1)
        c = _Dense(run, fam.dense, t, h, tph, y, y1)
        if events:
            found = _find_event(run, c)
            if found is not None:  # the step ends at the event
                te, ye = found
                yield from run.emit_step(c, te, False)
                y = ye if isinstance(y, list) else numpy.array(ye, dtype=float)
                t, at_event = te, True
                continue
        yield from run.emit_step(c, tph)
        y, t = y1, tph
        run.t, run.y = t, y
        grid.k += 1
        if fam.after(tph, y1, last):
            run.h = hnew
            raise _Stiff()
        if last:
            if not run.fixed:  # the step to go on with: the controller's, or the one cut short
                st["h_next"] = max(hnew, wanted)
            return
        if not run.fixed:
            hnew = min(hnew, hmax)
        if reject:
            hnew = min(hnew, h)
        reject, bad = False, -1
        h = fam.next_h(h, hnew)


class _Family:
    """A method family: the steps of one kind of method (_FixedSteps and _Erk in erk.py,
    _Rosenbrock and _Radau in stiff.py) as the step driver, _drive, takes them.  The family
    contract, written once for both runtimes, in the order the driver calls it (C's
    bgc_family in drive.c: start is items 1 and 2, step 3, accepted 5, prepare and dense 6,
    after 7, next_h 8, finish the end of 1; erk.c and stiff.c cite the items).  The driver
    owns the rest: output times, budgets, the checks of the accepted state, events, the
    switch of `auto`.

    1. family(run): the family's state for the method run.m (its row of _METHODS: tableau
       and step control, printed from bgc/solvers.py) on run's settings, with fixed steps
       when run.fixed (--step, or a fixed-step method).  A new one at the run's start and
       after every event (C: finish, then start), so a method restarts with no history.
    2. start(y) -> h: the evaluations the method needs at the first point (run.t, y) (f;
       Rosenbrock's f, df/dt and J; Radau's f and Newton weights) and the first step of an
       adaptive run: run.h bounded by _hmax when the run goes on from an earlier phase or
       run, else Hairer's estimate (_first_step, _initial_step); None on fixed steps.
    3. step(t, h, tph, y) -> (outcome, y1, hnew, why): one attempt from (t, y) over h to tph
       (t + h, but exactly the end or the time event on a step cut onto it).  _ACCEPT: y1
       is the new point, hnew the controller's next step; _REJECT: the error test failed,
       try hnew; _RETRY: the attempt failed (a non-finite value, an algebraic block, a
       singular iteration matrix, Newton's iteration), try hnew, and why = (bad, bad_kind,
       block failure) names the cause if the steps then fall below _hmin (bad >= 0 a
       non-finite component, bad_kind its kind; -1 the error test, -2 a block, -3 a
       singular matrix, -4 Newton); _AGAIN: the same step once more, not counted as
       rejected (Radau on a fixed step, with a fresh Jacobian).  The driver counts the
       attempt, checks y1 for non-finite values and hands on the accepted step.
    4. The error estimate is the family's, inside step: Hairer's RMS norm with the weights
       atol + rtol max(|y_i|, |y1_i|) over the first _error_states(s) states (_weights,
       _V.error_sums, _stiff_norm; DOP853 combines two estimates, Radau scales rtol and atol
       as RADAU5 does); the attribute worst (-1: none) keeps the component with the largest
       share of the last estimate, for the message when the steps become too small.  On
       fixed steps no error control: an attempt is accepted unless it fails, and a failure
       ends the run (Radau's Newton iteration first tries once more with a fresh Jacobian).
    5. accepted(tph, y1): after the driver has counted the step, before its outputs and the
       event search (an FSAL pair's last stage, when its error estimate does not use it).
    6. dense() -> at(theta): the state at t + theta h inside the step just accepted, made
       once, when an output time inside the step or the event search first needs it, valid
       until the next attempt (C: prepare, then dense).  A family without a dense output
       (dense None: the fixed-step methods) has a step end on every output time (span_grid
       False); the event search then uses the cubic Hermite interpolant (_Dense).
    7. after(tph, y1, last) -> bool: after the outputs, the evaluations at the new point that
       the next step starts from (f, or an FSAL pair's last stage; Rosenbrock's f, df/dt and
       J; Radau's f and weights), none after the run's last step; True when Hairer's
       stiffness test has fired on 15 accepted steps (an explicit pair under
       run.detect_stiffness: `auto`'s explicit phase), and the driver switches (_Stiff).
    8. next_h(h, hnew) -> h: the next step, from the controller's hnew once the driver has
       bounded it (by _hmax, and by h after a rejection); Radau keeps h, and its factored
       matrices, while hnew is at most 20 % more and Newton converged fast.
    9. A Jacobian only in the stiff families: J = d rhs / d x, the model's symbolic one
       (_stiff_jacobian: dense, or its structural values on a large sparse model, _JAC_LU),
       for Rosenbrock at every new point (items 2 and 7), for Radau at the first attempt,
       after a step whose Newton iteration contracted slowly and after a failed or rejected
       attempt unless J is fresh.  Their iteration matrices are factored by the runtime's
       own LU, C's operations in C's order (_lu, _zlu, _SparseMatrix: stiff.c's
       bgc_stiff_lu, bgc_stiff_zlu, the sparse LU of bgc_splu).
    10. Statistics: a family counts its own work in run.st as it goes: rhs for each f, jac,
       lu, solves, and order_next (Radau's order at the end); the driver counts steps,
       rejected, h_next, and the events and evaluations of the event search.
    11. Failures: an algebraic block's failure (_BlockFailure) in an adaptive attempt's stages
       is a _RETRY (item 3); on fixed steps, in the Jacobian, and in start, accepted, dense
       and after, it ends the run, as do a non-finite derivative at the first point and the
       fifth singular iteration matrix in a row: the family raises _Failure (_block_failed,
       _fail) with the C program's message (C: BGC_STEP_END or a nonzero return, the message
       in r->msg).
    12. span_grid (fixed steps only): True, the steps on one grid over the run and the
       outputs from the dense output; False, each output interval in steps that land on its
       end.

    The defaults below: span_grid True, worst -1, no dense output, accepted and after doing
    nothing, next_h taking hnew (C: NULL functions)."""

    span_grid = True
    worst = -1
    dense = None  # no output time falls inside a step of a family without a dense output

    def accepted(self, tph, y1):
        pass

    def after(self, tph, y1, last):
        return False

    def next_h(self, h, hnew):
        return hnew


# ---------------------------------------------------------------- integrate


def _run_solver(run, name):
    """Runs solver `name` from (run.t, run.y) with the driver."""
    m = _METHODS[name]
    family = {"fixed": _FixedSteps, "erk": _Erk, "rosenbrock": _Rosenbrock,
              "radau": _Radau}.get(m["family"])
    if family is None:
        raise ValueError("solver '%s' cannot run by itself" % name)
    run.m, run.name = m, name
    run.fixed = run.s.step > 0.0 or m["family"] == "fixed"
    y = run.y if family in (_FixedSteps, _Erk) else numpy.asarray(run.y, dtype=float)
    yield from _drive(run, family, y)


def _integrate(s, p, x0, st):
    """Runs the solver: yields the rows (t, outputs) as it computes them; st["cpu"]: the
    processor seconds it took (the consumer's time between rows excluded)."""
    cpu = 0.0
    rows = _integrate_from(s, p, x0, st)
    try:
        while True:
            start = time.process_time()
            try:
                row = next(rows)
            except StopIteration:
                return
            finally:
                cpu += time.process_time() - start
                st["cpu"] = cpu
            yield row
    finally:
        rows.close()


def _integrate_from(s, p, x0, st, w=None):
    y = numpy.array(x0, dtype=float)
    i = _first_nonfinite(y)
    if i >= 0:
        raise _fail(s.t0, "state", STATES[i])
    run = _Run(s, p, _Work(s.rtol, s.atol) if w is None else w, st, y)
    run.w.inputs = s.inputs
    st["h_next"], st["order_next"] = 0.0, 0
    if _DISCRETE_NAMES:  # the event iteration at the start (bgc_integrate)
        w = run.w
        p[run.doff:] = w.d
        x = y.tolist()
        _event_iteration(run, s.t0, x, not w.started)
        w.started = True
        _set_next_time(run, s.t0, x)
        y = run.y = numpy.array(x, dtype=float)
    try:
        yield from _integrate_run(run, s, y, st)
    finally:
        if _DISCRETE_NAMES:
            run.w.d = p[run.doff:]


def _integrate_run(run, s, y, st):
    yield from run.emit(s.t0, y)
    m = _METHODS[s.solver]
    if m["family"] != "auto":
        yield from _run_solver(run, s.solver)
        return
    run.detect_stiffness = True
    try:
        yield from _run_solver(run, m["explicit"])
    except _Stiff:
        st["switched"], st["t_switch"] = True, run.t
        run.detect_stiffness = False
        yield from _run_solver(run, m["stiff"])


# ==================================================================== erk ===
# The explicit Runge-Kutta families, read from _METHODS (printed from bgc/solvers.py), as
# erk.c's: the fixed-step methods and the embedded pairs.  An explicit step's cost beside the
# model's right side is a few vector operations per stage.  On a handful of states a numpy
# call costs more than a list comprehension over the whole vector, so the explicit solvers
# keep their states as lists up to _LIST_STATES states and as numpy vectors above; both kits
# compute the same values in the same order as the C runtime (bgc_combine: stage by stage,
# left to right).

_LIST_STATES = 48


def _weighted(w, count, stride=None):
    """The (weight, stage) pairs of w[j] (w[j][stride]) over j < count, zero weights dropped."""
    pairs = []
    for j in range(min(count, len(w))):
        a = w[j] if stride is None else w[j][stride]
        if a != 0.0:
            pairs.append((a, j))
    return tuple(pairs)


def _list_terms(acc, pairs, K):
    """acc + a_0 K_j0 + ... (up to four pairs, left to right; acc None: no acc)."""
    n = len(pairs)
    (a, i) = pairs[0]
    if n == 1:
        if acc is None:
            return [a * u for u in K[i]]
        return [s + a * u for s, u in zip(acc, K[i])]
    (b, j) = pairs[1]
    if n == 2:
        if acc is None:
            return [a * u + b * v for u, v in zip(K[i], K[j])]
        return [s + a * u + b * v for s, u, v in zip(acc, K[i], K[j])]
    (c, k) = pairs[2]
    if n == 3:
        if acc is None:
            return [a * u + b * v + c * w for u, v, w in zip(K[i], K[j], K[k])]
        return [s + a * u + b * v + c * w for s, u, v, w in zip(acc, K[i], K[j], K[k])]
    (d, l) = pairs[3]
    if acc is None:
        return [a * u + b * v + c * w + d * x for u, v, w, x in zip(K[i], K[j], K[k], K[l])]
    return [s + a * u + b * v + c * w + d * x
            for s, u, v, w, x in zip(acc, K[i], K[j], K[k], K[l])]


def _list_terms_into(y, h, pairs, K):
    """y + h * (a_0 K_j0 + ...) for up to four pairs, in one comprehension."""
    n = len(pairs)
    (a, i) = pairs[0]
    if n == 1:
        return [z + h * (a * u) for z, u in zip(y, K[i])]
    (b, j) = pairs[1]
    if n == 2:
        return [z + h * (a * u + b * v) for z, u, v in zip(y, K[i], K[j])]
    (c, k) = pairs[2]
    if n == 3:
        return [z + h * (a * u + b * v + c * w) for z, u, v, w in zip(y, K[i], K[j], K[k])]
    (d, l) = pairs[3]
    return [z + h * (a * u + b * v + c * w + d * x)
            for z, u, v, w, x in zip(y, K[i], K[j], K[k], K[l])]


class _ListVectors:
    """States as Python lists."""

    @staticmethod
    def vec(x):
        return x.tolist() if isinstance(x, numpy.ndarray) else x

    @staticmethod
    def combine(y, h, pairs, K):
        """y + h * sum a K_j over the pairs (y None: h * sum), four terms per comprehension."""
        n = len(pairs)
        if n == 0:
            acc = [0.0] * _N
        elif n <= 4 and y is not None:
            return _list_terms_into(y, h, pairs, K)
        else:
            acc = _list_terms(None, pairs[:4], K)
            for k in range(4, n, 4):
                acc = _list_terms(acc, pairs[k:k + 4], K)
        if y is None:
            return [h * u for u in acc]
        return [u + h * v for u, v in zip(y, acc)]

    @staticmethod
    def horner(y, q, theta):
        """y + theta (q_0 + theta (q_1 + ...))."""
        acc = q[-1]
        for qd in reversed(q[:-1]):
            acc = [u + theta * v for u, v in zip(qd, acc)]
        return [u + theta * v for u, v in zip(y, acc)]

    @staticmethod
    def error_sums(s, y, y1, e1, e2):
        """sum (e1_i / sk_i)^2, its largest term's index, and sum (e2_i / sk_i)^2 (e2 may be
        None), sk_i = atol + rtol * max(|y_i|, |y1_i|), over the states the error control
        weighs."""
        rtol, atol = s.rtol, s.atol
        err = err2 = 0.0
        worst, worst_q = -1, -1.0
        for i in range(_error_states(s)):
            sk = atol + rtol * max(abs(y[i]), abs(y1[i]))
            qq = e1[i] / sk
            qq = qq * qq
            err += qq
            if qq > worst_q:
                worst, worst_q = i, qq
            if e2 is not None:
                q2 = e2[i] / sk
                err2 += q2 * q2
        return err, worst, err2

    @staticmethod
    def distance2(u, v):
        acc = 0.0
        for a, b in zip(u, v):
            acc += (a - b) * (a - b)
        return acc


class _ArrayVectors:
    """States as numpy vectors."""

    @staticmethod
    def vec(x):
        return numpy.asarray(x, dtype=float)

    @staticmethod
    def combine(y, h, pairs, K):
        if pairs:
            a, j = pairs[0]
            acc = a * K[j]
            for a, j in pairs[1:]:
                acc = acc + a * K[j]
        else:
            acc = numpy.zeros(_N)
        return h * acc if y is None else y + h * acc

    @staticmethod
    def horner(y, q, theta):
        acc = q[-1]
        for qd in reversed(q[:-1]):
            acc = qd + theta * acc
        return y + theta * acc

    @staticmethod
    def error_sums(s, y, y1, e1, e2):
        E = _error_states(s)
        sk = _weights(s, y[:E], y1[:E])
        with numpy.errstate(all="ignore"):
            sq = e1[:E] / sk
            sq = sq * sq
            err = _seq_sum(sq)
            q2 = e2[:E] / sk if e2 is not None else None
            err2 = _seq_sum(q2 * q2) if e2 is not None else 0.0
        return err, _worst(sq), err2

    @staticmethod
    def distance2(u, v):
        with numpy.errstate(all="ignore"):
            d = u - v
            return _seq_sum(d * d)


_V = _ListVectors  # the vectors for _N states: lists up to _LIST_STATES (_bind_model)


def _erk_plan(m):
    """The method's _ErkPlan, made once (a run restarts its method at every event)."""
    plan = _ERK_PLANS.get(id(m))
    if plan is None or plan[0] is not m:
        plan = _ERK_PLANS[id(m)] = (m, _ErkPlan(m))
    return plan[1]


_ERK_PLANS = {}


class _ErkPlan:
    """A tableau's nonzero weights, ready for _V.combine."""

    def __init__(self, m):
        stages, c = m["stages"], m["c"]
        self.a = [_weighted(m["a"][i], i) for i in range(len(c))]
        self.b = _weighted(m["b"], stages)
        self.e = _weighted(m["e"], stages) if "e" in m else ()
        self.e2 = _weighted(m["e2"], stages) if m.get("e2") else None
        P = m.get("P")
        self.P = [_weighted(P, len(P), d) for d in range(len(P[0]))] if P else []


# ---------------------------------------------------------------- the families


class _FixedSteps(_Family):
    """The fixed-step methods: each step from f(t, y) afresh (no error estimate, no dense
    output: the driver lands a step on every output time)."""

    span_grid = False

    def __init__(self, run):
        m = run.m
        self.run, self.stages, self.c = run, m["stages"], m["c"]
        self.plan = _erk_plan(m)

    def start(self, y):
        return None

    def step(self, t, h, tph, y):
        run, c, combine = self.run, self.c, _V.combine
        y = _V.vec(y)
        K = [None] * self.stages
        try:
            K[0] = run.fv(t, y)
            i = _first_nonfinite(K[0])
            if i >= 0:
                raise _fail(t, "derivative of state", STATES[i])
            for i in range(1, self.stages):
                K[i] = run.fv(t + c[i] * h, combine(y, h, self.plan.a[i], K))
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        run.st["rhs"] += self.stages
        return _ACCEPT, combine(y, h, self.plan.b, K), h, None


class _Erk(_Family):
    """Embedded explicit pairs (bgc_family_erk): Hairer's error norm and controller, outputs
    by the dense output; on fixed steps no error control.  With run.detect_stiffness,
    Hairer's stiffness test fires _Stiff once it has held on 15 accepted steps."""

    def __init__(self, run):
        m = run.m
        self.run, self.m, self.plan = run, m, _erk_plan(m)
        self.stages, self.c = m["stages"], m["c"]
        self.last_stage = self.stages - 1
        self.fsal = m["fsal"]
        self.fsal_first = self.fsal and m["e"][self.last_stage] != 0.0
        self.stiff_i, self.stiff_j, self.stiff_bound = m.get("stiffness", (-1, -1, 0.0))
        self.expo1 = 1.0 / m["q"] - m["expo_beta"] * m["beta"]
        self.facold = 1e-4
        self.stiff_count = self.nonstiff_count = 0
        self.K = [None] * len(self.c)
        self.t = self.h = 0.0
        self.y = self.ys = self.ystiff = None

    def start(self, y):
        run = self.run
        run.st["rhs"] += 1
        try:
            self.K[0] = run.fv(run.t, _V.vec(y))
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        i = _first_nonfinite(self.K[0])
        if i >= 0:
            raise _fail(run.t, "derivative of state", STATES[i])
        return None if run.fixed else _first_step(run, y, self.K[0])

    def _error(self, h, y, y1):
        """Hairer's error norm (DOP853 combines its two estimates); NaN for an infinite
        stage."""
        s, plan, combine, K = self.run.s, self.plan, _V.combine, self.K
        e2 = plan.e2
        try:
            err, worst, err2 = _V.error_sums(
                s, y, y1, combine(None, 1.0 if e2 else h, plan.e, K),
                combine(None, 1.0, e2, K) if e2 else None)
        except (OverflowError, ValueError):  # an infinite stage: treated as NaN below
            return math.nan
        if err == err:
            self.worst = worst
        if _N == 0 or (self.run.fixed and err == err):
            return 0.0  # fixed steps: accepted as they are (a non-finite stage fails below)
        if e2:
            deno = err + 0.01 * err2
            if not deno > 0.0:
                deno = 1.0
            return abs(h) * err * math.sqrt(1.0 / (_error_states(s) * deno))
        return math.sqrt(err / _error_states(s))

    def _retry(self, h, tph, y1, failure):
        """A failed attempt: a much smaller step (on fixed steps, the end of the run)."""
        run = self.run
        if run.fixed:
            if failure is not None:
                raise _block_failed(failure) from None
            raise _fail(tph, "state", STATES[max(_first_nonfinite(y1), 0)])
        if failure is not None:
            return _RETRY, None, h * self.m["fac_min"], (-2, "", failure)
        bad, bad_kind = _first_nonfinite(y1), "state"
        for i in range(1, self.stages):
            if bad >= 0:
                break
            if self.K[i] is not None:
                bad, bad_kind = _first_nonfinite(self.K[i]), "derivative of state"
        return _RETRY, None, h * self.m["fac_min"], (bad, bad_kind, None)

    def step(self, t, h, tph, y):
        run, m, K, c = self.run, self.m, self.K, self.c
        st, combine, fv = run.st, _V.combine, run.fv
        y = _V.vec(y)
        y1 = None
        try:
            for i in range(1, self.stages):
                if self.fsal and i == self.last_stage:
                    break
                ys = combine(y, h, self.plan.a[i], K)
                if i == self.stiff_i:
                    self.ystiff = ys
                self.ys = ys
                K[i] = fv(tph if c[i] == 1.0 else t + c[i] * h, ys)
                st["rhs"] += 1
            y1 = combine(y, h, self.plan.b, K)
            if self.fsal_first:
                st["rhs"] += 1
                K[self.last_stage] = fv(tph, y1)
        except _BlockFailure as failure:  # an algebraic block failed in a stage
            return self._retry(h, tph, y1, failure)
        err = self._error(h, y, y1)
        if err != err:  # a non-finite stage
            return self._retry(h, tph, y1, None)
        safe, fac_min, fac_max, beta = m["safe"], m["fac_min"], m["fac_max"], m["beta"]
        fac11 = err ** self.expo1
        fac = fac11 / self.facold ** beta
        fac = max(1.0 / fac_max, min(1.0 / fac_min, fac / safe))
        if err <= 1.0:
            self.facold = max(err, 1e-4)
            self.t, self.h, self.y = t, h, y
            return _ACCEPT, y1, run.s.step if run.fixed else h / fac, None
        return _REJECT, None, h / min(1.0 / fac_min, fac11 / safe), None

    def accepted(self, tph, y1):
        """The last stage f(t + h, y1) of an FSAL pair whose estimate does not use it."""
        if self.fsal and not self.fsal_first:
            self.run.st["rhs"] += 1
            try:
                self.K[self.last_stage] = self.run.fv(tph, y1)
            except _BlockFailure as failure:
                raise _block_failed(failure) from None

    def dense(self):
        """The dense output: the extra stages, then y(theta) = y + theta (q_0 + theta (q_1 +
        ...)), q_d = h sum_i P[i][d] K_i."""
        run, t, h, y, K = self.run, self.t, self.h, self.y, self.K
        c, combine = self.c, _V.combine
        try:
            for i in range(self.stages, len(c)):
                K[i] = run.fv(t + c[i] * h, combine(y, h, self.plan.a[i], K))
                run.st["rhs"] += 1
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        q = [combine(None, h, pairs, K) for pairs in self.plan.P]
        horner = _V.horner
        return lambda theta: horner(y, q, theta)

    def after(self, tph, y1, last):
        """Hairer's stiffness test, h |f(Y_i) - f(Y_j)| / |Y_i - Y_j| for two stages at the
        same time; then f at the new point (the FSAL stage, or evaluated)."""
        run, K = self.run, self.K
        if run.detect_stiffness and self.stiff_i >= 0 and self.ystiff is not None:
            num = _V.distance2(K[self.stiff_j], K[self.stiff_i])
            den = _V.distance2(y1 if self.stiff_j == self.last_stage else self.ys, self.ystiff)
            if den > 0.0 and self.h * math.sqrt(num / den) > self.stiff_bound:
                self.nonstiff_count = 0
                self.stiff_count += 1
                if self.stiff_count == 15:
                    return True
            else:
                self.nonstiff_count += 1
                if self.nonstiff_count == 6:
                    self.stiff_count = 0
        try:
            if self.fsal:
                K[0] = K[self.last_stage]
            elif not last:
                run.st["rhs"] += 1
                K[0] = run.fv(tph, y1)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        return False


# ================================================================== stiff ===
# The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
# tableau of the family) and Radau IIA with 3, 5 or 7 stages, of fixed or variable order
# (RADAU5's and RADAU's design), as bgc_run_rosenbrock and bgc_run_radau in the C runtime (see
# there).  Byte parity: every floating-point operation is the C runtime's, in C's order, so
# both backends write the same bytes whatever BLAS or SIMD kernels numpy picks.  Hence no
# numpy.sum, dot, @ or linalg here: sums run in C's sequence (_seq_sum, a subtract.accumulate),
# the LU factorisations and solves are bgc_stiff_lu's and bgc_stiff_zlu's (row-vectorised
# where C's loops are element-wise independent), and complex arithmetic is done on real and
# imaginary parts as the C runtime's bgc_cmul and bgc_cdiv write it out: products (ac - bd) +
# i(ad + bc) with Annex G's recovery of infinities (libgcc's __muldc3), quotients as GCC 12's
# libgcc __divdc3.


def _stiff_norm(s, v, w):
    """bgc_stiff_norm: sqrt(mean((v_i / w_i)^2)) over the states the error control weighs (0
    without states) and the component with the largest share (the first; -1 if every share
    is NaN)."""
    if _N == 0:
        return 0.0, -1
    E = _error_states(s)
    with numpy.errstate(all="ignore"):
        q = v[:E] / w[:E]
        q = q * q
    return math.sqrt(_seq_sum(q) / E), _worst(q)


def _combine(weights, K, count):
    """sum_j weights[j] K[j] over j < count with a nonzero weight, left to right, for numpy
    vectors K[j] (the stiff solvers)."""
    acc = numpy.zeros(_N)  # C's acc = 0.0, then acc += a K_j
    for j in range(count):
        a = weights[j]
        if a != 0.0:
            acc = acc + a * K[j]
    return acc


# ---------------------------------------------------------------- complex arithmetic
# A complex number is a pair of floats (or of float arrays): real and imaginary part.

_RBIG = sys.float_info.max / 2
_RMIN = sys.float_info.min
_RMIN2 = sys.float_info.epsilon
_RMINSCAL = 1.0 / sys.float_info.epsilon
_RMAX2 = _RBIG * _RMIN2


def _box(v):
    """Annex G's boxing of an infinite part: +-1 if v is infinite, else +-0."""
    return math.copysign(1.0 if math.isinf(v) else 0.0, v)


def _muldc3(a, b, c, d):
    """(a + ib)(c + id) as libgcc's __muldc3 (gcc's inline product where not both parts are
    NaN), on floats."""
    ac, bd, ad, bc = a * c, b * d, a * d, b * c
    x, y = ac - bd, ad + bc
    if x != x and y != y:  # recover infinities that came out as NaN + iNaN
        recalc = False
        if math.isinf(a) or math.isinf(b):
            a, b = _box(a), _box(b)
            c = math.copysign(0.0, c) if c != c else c
            d = math.copysign(0.0, d) if d != d else d
            recalc = True
        if math.isinf(c) or math.isinf(d):
            c, d = _box(c), _box(d)
            a = math.copysign(0.0, a) if a != a else a
            b = math.copysign(0.0, b) if b != b else b
            recalc = True
        if not recalc and any(math.isinf(v) for v in (ac, bd, ad, bc)):
            a, b, c, d = (math.copysign(0.0, v) if v != v else v for v in (a, b, c, d))
            recalc = True
        if recalc:
            x = math.inf * (a * c - b * d)
            y = math.inf * (a * d + b * c)
    return x, y


def _divdc3(a, b, c, d):
    """(a + ib) / (c + id) as libgcc's __divdc3 (GCC 12's: Smith's method with scaling), on
    floats; where Python would raise on a division by zero, on numpy.float64 values (IEEE)."""
    try:
        return _divdc3_of(a, b, c, d)
    except ZeroDivisionError:
        with numpy.errstate(all="ignore"):
            x, y = _divdc3_of(*(numpy.float64(v) for v in (a, b, c, d)))
        return float(x), float(y)


def _divdc3_of(a, b, c, d):
    if abs(c) < abs(d):
        if abs(d) >= _RBIG:
            a, b, c, d = a / 2, b / 2, c / 2, d / 2
        if abs(d) < _RMIN2 or _tiny(a, b, d):
            a, b, c, d = a * _RMINSCAL, b * _RMINSCAL, c * _RMINSCAL, d * _RMINSCAL
        ratio = c / d
        denom = (c * ratio) + d
        if abs(ratio) > _RMIN:
            x, y = ((a * ratio) + b) / denom, ((b * ratio) - a) / denom
        else:
            x, y = ((c * (a / d)) + b) / denom, ((c * (b / d)) - a) / denom
    else:
        if abs(c) >= _RBIG:
            a, b, c, d = a / 2, b / 2, c / 2, d / 2
        if abs(c) < _RMIN2 or _tiny(a, b, c):
            a, b, c, d = a * _RMINSCAL, b * _RMINSCAL, c * _RMINSCAL, d * _RMINSCAL
        ratio = d / c
        denom = (d * ratio) + c
        if abs(ratio) > _RMIN:
            x, y = ((b * ratio) + a) / denom, (b - (a * ratio)) / denom
        else:
            x, y = (a + (d * (b / c))) / denom, (b - (d * (a / c))) / denom
    if x != x and y != y:  # recover infinities and zeros that came out as NaN + iNaN
        if c == 0.0 and d == 0.0 and (a == a or b == b):
            x, y = math.copysign(math.inf, c) * a, math.copysign(math.inf, c) * b
        elif (math.isinf(a) or math.isinf(b)) and math.isfinite(c) and math.isfinite(d):
            a, b = _box(a), _box(b)
            x, y = math.inf * (a * c + b * d), math.inf * (b * c - a * d)
        elif (math.isinf(c) or math.isinf(d)) and math.isfinite(a) and math.isfinite(b):
            c, d = _box(c), _box(d)
            x, y = 0.0 * (a * c + b * d), 0.0 * (b * c - a * d)
    return x, y


def _tiny(a, b, big):
    """__divdc3's test for scaling up a small numerator (big: the divisor's larger part)."""
    return ((abs(a) < _RMIN and abs(b) < _RMAX2 and abs(big) < _RMAX2)
            or (abs(b) < _RMIN and abs(a) < _RMAX2 and abs(big) < _RMAX2))


def _each(f, mask, x, y, *args):
    """x, y with f(*args_i) at the elements where mask holds (the rare cases of the vector
    complex operations, done one by one)."""
    args = numpy.broadcast_arrays(*args)
    x, y = numpy.array(x, dtype=float), numpy.array(y, dtype=float)
    for i in zip(*numpy.nonzero(mask)):
        x[i], y[i] = f(*(float(v[i]) for v in args))
    return x, y


def _cmul(a, b, c, d):
    """(a + ib)(c + id) element-wise (arrays or floats): gcc's inline product, __muldc3 where
    both parts are NaN."""
    x, y = a * c - b * d, a * d + b * c
    bad = (x != x) & (y != y)
    return _each(_muldc3, bad, x, y, a, b, c, d) if bad.any() else (x, y)


def _cdiv(a, b, c, d):
    """(a + ib) / (c + id) for arrays a, b and floats c, d: __divdc3 without scaling (a
    divisor of moderate size) vectorised, _divdc3 element by element otherwise."""
    one = abs(c) < abs(d)  # scaled by d: ratio c / d
    big = abs(d) if one else abs(c)
    if not _RMIN2 <= big < _RBIG:
        return _each(_divdc3, numpy.ones(numpy.shape(a), bool), a, a, a, b, c, d)
    ratio = c / d if one else d / c
    normal = abs(ratio) > _RMIN  # else (a real or imaginary divisor) the other order
    if one:
        denom = (c * ratio) + d
        if normal:
            x, y = ((a * ratio) + b) / denom, ((b * ratio) - a) / denom
        else:
            x, y = ((c * (a / d)) + b) / denom, ((c * (b / d)) - a) / denom
    else:
        denom = (d * ratio) + c
        if normal:
            x, y = ((b * ratio) + a) / denom, (b - (a * ratio)) / denom
        else:
            x, y = (a + (d * (b / c))) / denom, (b - (d * (a / c))) / denom
    aa, ab = numpy.abs(a), numpy.abs(b)
    odd = (x != x) & (y != y)
    if big < _RMAX2:
        odd |= ((aa < _RMIN) & (ab < _RMAX2)) | ((ab < _RMIN) & (aa < _RMAX2))
    return _each(_divdc3, odd, x, y, a, b, c, d) if odd.any() else (x, y)


# ---------------------------------------------------------------- dense linear algebra
# bgc_stiff_lu and bgc_stiff_zlu: partial pivoting on the first largest |a_ik| (|re| + |im|
# for complex), rows whose multiplier is zero left alone, a column without a nonzero pivot
# singular (None); the elimination of row i, a_ij - l a_kj for j > k, is element-wise in C
# and done here for all rows i at once.  The solves: all the row swaps, the column-oriented
# forward substitution (vectorised), the back substitution's row sums in C's order.


def _pivot(size):
    """C's pivot search over a column's sizes from the diagonal: from |a_kk|, the first entry
    larger than the largest so far (a NaN is never larger, and a NaN |a_kk| stays)."""
    if len(size) < 2 or size[0] != size[0]:
        return 0
    rest = numpy.where(size[1:] == size[1:], size[1:], -1.0)
    i = int(numpy.argmax(rest))
    return i + 1 if rest[i] > size[0] else 0


# A small matrix is factored and solved in plain floats, line by line as the C loops read:
# the same operations (Python's float arithmetic is IEEE double, and a pivot is never zero),
# without a numpy call per row, which on a few states costs more than the arithmetic.
_SMALL_LU = 12


def _lu_small(a):
    """bgc_stiff_lu on the rows of a (lists of floats, factored in place)."""
    n = len(a)
    piv = []
    for k in range(n):
        ak = a[k]
        big, p = abs(ak[k]), k
        for i in range(k + 1, n):
            if abs(a[i][k]) > big:
                big, p = abs(a[i][k]), i
        piv.append(p)
        if big == 0.0:
            return None
        if p != k:
            a[k], a[p] = a[p], a[k]
            ak = a[k]
        for i in range(k + 1, n):
            ai = a[i]
            lower = ai[k] / ak[k]
            ai[k] = lower
            if lower != 0.0:
                for j in range(k + 1, n):
                    ai[j] -= lower * ak[j]
    return piv


def _lu_solve_small(lu, piv, b):
    """bgc_stiff_lu_solve on lists."""
    n = len(b)
    for k in range(n):
        p = piv[k]
        b[k], b[p] = b[p], b[k]
    for k in range(n):
        bk = b[k]
        if bk != 0.0:
            for i in range(k + 1, n):
                b[i] -= lu[i][k] * bk
    for k in range(n - 1, -1, -1):
        row = lu[k]
        acc = b[k]
        for i in range(k + 1, n):
            acc -= row[i] * b[i]
        b[k] = acc / row[k]
    return b


def _zlu_small(ar, ai):
    """bgc_stiff_zlu on the rows of ar + i ai (lists of floats, factored in place)."""
    n = len(ar)
    piv = []
    for k in range(n):
        big, p = abs(ar[k][k]) + abs(ai[k][k]), k
        for i in range(k + 1, n):
            size = abs(ar[i][k]) + abs(ai[i][k])
            if size > big:
                big, p = size, i
        piv.append(p)
        if big == 0.0:
            return None
        if p != k:
            ar[k], ar[p] = ar[p], ar[k]
            ai[k], ai[p] = ai[p], ai[k]
        akr, aki = ar[k], ai[k]
        for i in range(k + 1, n):
            rr, ri = ar[i], ai[i]
            lr, li = _divdc3(rr[k], ri[k], akr[k], aki[k])
            rr[k], ri[k] = lr, li
            if lr != 0.0 or li != 0.0:
                for j in range(k + 1, n):
                    pr, pi = _muldc3(lr, li, akr[j], aki[j])
                    rr[j] -= pr
                    ri[j] -= pi
    return piv


def _zlu_solve_small(lur, lui, piv, br, bi):
    """bgc_stiff_zlu_solve on lists."""
    n = len(br)
    for k in range(n):
        p = piv[k]
        br[k], br[p] = br[p], br[k]
        bi[k], bi[p] = bi[p], bi[k]
    for k in range(n):
        xr, xi = br[k], bi[k]
        if xr != 0.0 or xi != 0.0:
            for i in range(k + 1, n):
                pr, pi = _muldc3(lur[i][k], lui[i][k], xr, xi)
                br[i] -= pr
                bi[i] -= pi
    for k in range(n - 1, -1, -1):
        rr, ri = lur[k], lui[k]
        xr, xi = br[k], bi[k]
        for i in range(k + 1, n):
            pr, pi = _muldc3(rr[i], ri[i], br[i], bi[i])
            xr -= pr
            xi -= pi
        br[k], bi[k] = _divdc3(xr, xi, rr[k], ri[k])
    return br, bi


class _SmallLU:
    """The factors of a small matrix as lists (what _lu returns as its "pivots" then carries
    them), so that each solve runs in plain floats too."""

    __slots__ = ("piv", "rows", "imag")

    def __init__(self, piv, rows, imag=None):
        self.piv, self.rows, self.imag = piv, rows, imag

    def __getitem__(self, k):
        return self.piv[k]

    def __len__(self):
        return len(self.piv)


def _lu(a):
    """bgc_stiff_lu on a (n x n, factored in place): the pivots, or None if singular."""
    if isinstance(a, _SparseMatrix):
        return a.piv
    n = a.shape[0]
    if n <= _SMALL_LU:
        rows = a.tolist()
        piv = _lu_small(rows)
        a[:, :] = rows
        return None if piv is None else _SmallLU(piv, rows)
    piv = []
    with numpy.errstate(all="ignore"):
        for k in range(n):
            size = numpy.abs(a[k:, k])
            p = k + _pivot(size)
            piv.append(p)
            if size[p - k] == 0.0:
                return None
            if k + 1 == n:
                break
            if p != k:
                a[[k, p]] = a[[p, k]]
            lower = a[k + 1:, k] / a[k, k]
            a[k + 1:, k] = lower
            rows = numpy.nonzero(lower != 0.0)[0]
            if len(rows) == n - k - 1:
                a[k + 1:, k + 1:] -= lower[:, None] * a[k, k + 1:]
            elif len(rows):
                a[rows + k + 1, k + 1:] -= lower[rows, None] * a[k, k + 1:]
    return piv


def _lu_solve(lu, piv, b):
    """bgc_stiff_lu_solve: A^-1 b (a new vector) from _lu's factors (under the caller's
    numpy.errstate, as _zlu_solve)."""
    if isinstance(lu, _SparseMatrix):
        return lu.solve(b)
    if isinstance(piv, _SmallLU):
        return numpy.array(_lu_solve_small(piv.rows, piv.piv, numpy.asarray(b, dtype=float)
                                           .tolist()))
    b = numpy.array(b, dtype=float)
    n = len(b)
    for k in range(n):
        p = piv[k]
        b[k], b[p] = b[p], b[k]
    for k in range(n - 1):
        bk = b[k]
        if bk != 0.0:
            b[k + 1:] -= lu[k + 1:, k] * bk
    for k in range(n - 1, -1, -1):
        b[k] = _seq_minus(b[k], lu[k, k + 1:] * b[k + 1:]) / lu[k, k]
    return b


def _zlu(ar, ai):
    """bgc_stiff_zlu on ar + i ai (factored in place): the pivots, or None if singular."""
    n = ar.shape[0]
    if n <= _SMALL_LU:
        rows, imag = ar.tolist(), ai.tolist()
        piv = _zlu_small(rows, imag)
        ar[:, :], ai[:, :] = rows, imag
        return None if piv is None else _SmallLU(piv, rows, imag)
    piv = []
    with numpy.errstate(all="ignore"):
        for k in range(n):
            size = numpy.abs(ar[k:, k]) + numpy.abs(ai[k:, k])
            p = k + _pivot(size)
            piv.append(p)
            if size[p - k] == 0.0:
                return None
            if k + 1 == n:
                break
            if p != k:
                ar[[k, p]], ai[[k, p]] = ar[[p, k]], ai[[p, k]]
            lr, li = _cdiv(ar[k + 1:, k], ai[k + 1:, k], float(ar[k, k]), float(ai[k, k]))
            ar[k + 1:, k], ai[k + 1:, k] = lr, li
            rows = numpy.nonzero((lr != 0.0) | (li != 0.0))[0]
            if len(rows):
                pr, pi = _cmul(lr[rows, None], li[rows, None], ar[k, k + 1:], ai[k, k + 1:])
                ar[rows + k + 1, k + 1:] -= pr
                ai[rows + k + 1, k + 1:] -= pi
    return piv


def _zlu_solve(lur, lui, piv, br, bi):
    """bgc_stiff_zlu_solve: A^-1 (br + i bi) (new vectors) from _zlu's factors."""
    if isinstance(lur, _SparseMatrix):
        return lur.zsolve(br, bi)
    if isinstance(piv, _SmallLU):
        xr, xi = _zlu_solve_small(piv.rows, piv.imag, piv.piv,
                                  numpy.asarray(br, dtype=float).tolist(),
                                  numpy.asarray(bi, dtype=float).tolist())
        return numpy.array(xr), numpy.array(xi)
    br, bi = numpy.array(br, dtype=float), numpy.array(bi, dtype=float)
    n = len(br)
    for k in range(n):
        p = piv[k]
        br[k], br[p] = br[p], br[k]
        bi[k], bi[p] = bi[p], bi[k]
    for k in range(n - 1):
        xr, xi = float(br[k]), float(bi[k])
        if xr != 0.0 or xi != 0.0:
            pr, pi = _cmul(lur[k + 1:, k], lui[k + 1:, k], xr, xi)
            br[k + 1:] -= pr
            bi[k + 1:] -= pi
    for k in range(n - 1, -1, -1):
        xr, xi = float(br[k]), float(bi[k])
        if k + 1 < n:
            pr, pi = _cmul(lur[k, k + 1:], lui[k, k + 1:], br[k + 1:], bi[k + 1:])
            xr, xi = float(_seq_minus(xr, pr)), float(_seq_minus(xi, pi))
        br[k], bi[k] = _divdc3(xr, xi, float(lur[k, k]), float(lui[k, k]))
    return br, bi


# A large sparse model's iteration matrices (_JAC_LU, bgc_splu in the C runtime): the values
# of L + U in the plan's positions, factored row by row in the plan's order with the C
# runtime's operations in its order (bgc_splu_factor ... bgc_smat_zsolve), each row's updates
# element-wise; a pivot that fails its test sends the matrix to the dense LU above.


class _SparseLU:
    """The plan (bgc/sparse.py, IterationPlan) as arrays, with each row's parts cut out once."""

    def __init__(self, perm, rowptr, cols, diag, jpos, dpos):
        self.n = len(perm)
        self.perm = numpy.array(perm, dtype=numpy.intp)
        self.cols = numpy.array(cols, dtype=numpy.intp)
        self.jpos = numpy.array(jpos, dtype=numpy.intp)
        self.dpos = numpy.array(dpos, dtype=numpy.intp)
        self.nnz = len(cols)
        self.rowptr, self.diag = list(rowptr), list(diag)
        # per row i: its positions, its L part (positions, columns), its U part after the
        # diagonal (positions, columns)
        self.row = [slice(rowptr[i], rowptr[i + 1]) for i in range(self.n)]
        self.lower = [slice(rowptr[i], diag[i]) for i in range(self.n)]
        self.lcols = [list(cols[rowptr[i]:diag[i]]) for i in range(self.n)]
        self.upper = [slice(diag[i] + 1, rowptr[i + 1]) for i in range(self.n)]
        self.ucols = [self.cols[diag[i] + 1:rowptr[i + 1]] for i in range(self.n)]
        # J's structural entries (the model part binds _JAC_COLUMNS first): where each
        # column starts, and each entry's row and column
        self.colstart, start = [], 0
        for rows in _JAC_COLUMNS:
            self.colstart.append(start)
            start += len(rows)
        self.jrows = numpy.array([i for rows in _JAC_COLUMNS for i in rows], dtype=numpy.intp)
        self.jcols = numpy.array([j for j, rows in enumerate(_JAC_COLUMNS) for _ in rows],
                                 dtype=numpy.intp)


def _splu_factor(pl, a):
    """bgc_splu_factor: a (the values) factored in place; False if a pivot fails its test."""
    w = numpy.zeros(pl.n)
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        row = pl.row[i]
        w[cols[row]] = a[row]
        size = numpy.abs(a[row])
        scale = max(0.0, float(numpy.max(numpy.where(size == size, size, 0.0))))
        for k in pl.lcols[i]:
            lower = float(w[k]) / float(a[diag[k]])
            if not abs(lower) <= 10.0:
                return False
            w[k] = lower
            u = pl.upper[k]
            if u.stop > u.start:
                w[pl.ucols[k]] -= lower * a[u]
        a[row] = w[cols[row]]
        pivot = float(a[diag[i]])
        if not abs(pivot) > 1e-14 * scale or not math.isfinite(pivot):
            return False
    return True


def _splu_solve(pl, a, b):
    """bgc_splu_solve: a new vector (states' order)."""
    w = numpy.empty(pl.n)
    bp = numpy.asarray(b, dtype=float)[pl.perm]
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        lo = pl.lower[i]
        w[i] = _seq_minus(bp[i], a[lo] * w[cols[lo]]) if lo.stop > lo.start else bp[i]
    for i in range(pl.n - 1, -1, -1):
        u = pl.upper[i]
        acc = _seq_minus(w[i], a[u] * w[pl.ucols[i]]) if u.stop > u.start else w[i]
        w[i] = acc / a[diag[i]]
    out = numpy.empty(pl.n)
    out[pl.perm] = w
    return out


def _splu_zfactor(pl, ar, ai):
    """bgc_splu_zfactor on ar + i ai."""
    wr, wi = numpy.zeros(pl.n), numpy.zeros(pl.n)
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        row = pl.row[i]
        wr[cols[row]], wi[cols[row]] = ar[row], ai[row]
        size = numpy.abs(ar[row]) + numpy.abs(ai[row])
        scale = max(0.0, float(numpy.max(numpy.where(size == size, size, 0.0))))
        for k in pl.lcols[i]:
            dk = diag[k]
            lr, li = _divdc3(float(wr[k]), float(wi[k]), float(ar[dk]), float(ai[dk]))
            if not abs(lr) + abs(li) <= 10.0:
                return False
            wr[k], wi[k] = lr, li
            u = pl.upper[k]
            if u.stop > u.start:
                pr, pi = _cmul(lr, li, ar[u], ai[u])
                uc = pl.ucols[k]
                wr[uc] -= pr
                wi[uc] -= pi
        ar[row], ai[row] = wr[cols[row]], wi[cols[row]]
        size = abs(float(ar[diag[i]])) + abs(float(ai[diag[i]]))
        if not size > 1e-14 * scale or not math.isfinite(size):
            return False
    return True


def _splu_zsolve(pl, ar, ai, br, bi):
    """bgc_splu_zsolve: new vectors."""
    wr, wi = numpy.empty(pl.n), numpy.empty(pl.n)
    pr0, pi0 = numpy.asarray(br, dtype=float)[pl.perm], numpy.asarray(bi, dtype=float)[pl.perm]
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        lo = pl.lower[i]
        if lo.stop > lo.start:
            c = cols[lo]
            pr, pi = _cmul(ar[lo], ai[lo], wr[c], wi[c])
            wr[i], wi[i] = _seq_minus(pr0[i], pr), _seq_minus(pi0[i], pi)
        else:
            wr[i], wi[i] = pr0[i], pi0[i]
    for i in range(pl.n - 1, -1, -1):
        u = pl.upper[i]
        xr, xi = float(wr[i]), float(wi[i])
        if u.stop > u.start:
            c = pl.ucols[i]
            pr, pi = _cmul(ar[u], ai[u], wr[c], wi[c])
            xr, xi = float(_seq_minus(xr, pr)), float(_seq_minus(xi, pi))
        wr[i], wi[i] = _divdc3(xr, xi, float(ar[diag[i]]), float(ai[diag[i]]))
    outr, outi = numpy.empty(pl.n), numpy.empty(pl.n)
    outr[pl.perm], outi[pl.perm] = wr, wi
    return outr, outi


class _SparseMatrix:
    """An iteration matrix on the sparse path (bgc_smat): alpha I - J (plus i beta I when
    complex) from J's structural values, factored by factor() (False: singular), sparse or,
    after a failed pivot test, dense."""

    __slots__ = ("re", "im", "piv", "dense")

    def __init__(self, Jv, alpha, beta=None):
        pl = _JAC_LU
        self.re = numpy.zeros(pl.nnz)
        self.re[pl.jpos] = -Jv
        self.re[pl.dpos] += alpha
        self.im = None
        if beta is not None:
            self.im = numpy.zeros(pl.nnz)
            self.im[pl.dpos] += beta
        self.piv, self.dense = None, False
        self._factor(Jv, alpha, beta)

    def _factor(self, Jv, alpha, beta):
        pl = _JAC_LU
        with numpy.errstate(all="ignore"):
            ok = (_splu_factor(pl, self.re) if self.im is None
                  else _splu_zfactor(pl, self.re, self.im))
        if ok:
            self.piv = True
            return
        self.dense = True
        self.re = numpy.zeros((_N, _N))
        self.re[pl.jrows, pl.jcols] = -Jv
        self.re[numpy.diag_indices(_N)] += alpha
        if beta is None:
            self.piv = _lu(self.re)
        else:
            self.im = numpy.zeros((_N, _N))
            self.im[numpy.diag_indices(_N)] += beta
            self.piv = _zlu(self.re, self.im)

    def solve(self, b):
        if self.dense:
            return _lu_solve(self.re, self.piv, b)
        with numpy.errstate(all="ignore"):
            return _splu_solve(_JAC_LU, self.re, b)

    def zsolve(self, br, bi):
        if self.dense:
            return _zlu_solve(self.re, self.im, self.piv, br, bi)
        with numpy.errstate(all="ignore"):
            return _splu_zsolve(_JAC_LU, self.re, self.im, br, bi)


def _real_matrix(J, diagonal):
    """-J with `diagonal` added to its diagonal, as the C runtime forms it (on the sparse path
    factored at once: _lu returns its outcome)."""
    if _JAC_LU is not None:
        return _SparseMatrix(J, diagonal)
    E = -J
    E[numpy.diag_indices(_N)] += diagonal
    return E


def _stiff_fail_singular(name, t, h):
    return _Failure("at t = %.17g: %s: the iteration matrix is singular (h = %.3g)"
                    % (t, name, h), t)


def _stiff_jacobian(run, t, y):
    """J at (t, y): dense, or on the sparse path its structural values (bgc_jacobian_values)."""
    J = numpy.zeros((_N, _N)) if _JAC_LU is None else numpy.zeros(_JAC_LU.jpos.shape[0])
    run.st["jac"] += 1
    try:
        _jacobian_into(t, y.tolist(), run.p, run.w, J, _JAC_LU is not None)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    return J


def _stiff_start(run, t, y):
    """f(t, y) at the start of a run or after an accepted step: a failure ends the run."""
    run.st["rhs"] += 1
    try:
        f0 = run.f(t, y)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    i = _first_nonfinite(f0)
    if i >= 0:
        raise _fail(t, "derivative of state", STATES[i])
    return f0


def _first_step(run, y, f0):
    """The first step of an adaptive run: the earlier run's (bounded by the span), else
    HINIT."""
    hmax = _hmax(run.s)
    return min(run.h, hmax) if run.h > 0.0 else _initial_step(run, run.m["q"], y, f0, hmax)


# ---------------------------------------------------------------- Rosenbrock methods


class _Rosenbrock(_Family):
    """Rosenbrock methods as Hairer's RODAS (bgc_family_rosenbrock in the C runtime)."""

    def __init__(self, run):
        self.run, self.m = run, run.m
        self.accepted_steps, self.nsing = 0, 0
        self.hacc, self.erracc = 0.0, 1.0
        self.ft = numpy.zeros(_N)
        self.f0 = self.J = self.K = self.y = self.y1 = None

    def _point(self, t, y):
        """f, df/dt and J at a new point."""
        run = self.run
        self.f0 = _stiff_start(run, t, y)
        if not _AUTONOMOUS:
            delta = math.sqrt(_EPS * max(1e-5, abs(t)))
            run.st["rhs"] += 1
            try:
                self.ft = (run.f(t + delta, y) - self.f0) / delta
            except _BlockFailure as failure:
                raise _block_failed(failure) from None
        self.J = _stiff_jacobian(run, t, y)

    def start(self, y):
        self._point(self.run.t, y)
        return None if self.run.fixed else _first_step(self.run, y, self.f0)

    def _stages(self, t, h, tph, y, E, piv):
        m, run = self.m, self.run
        c, d, a, C = m["c"], m["d"], m["a"], m["C"]
        K = [None] * m["stages"]
        with numpy.errstate(all="ignore"):
            for i in range(m["stages"]):
                if i == 0:
                    rhs = self.f0.copy()
                else:
                    run.st["rhs"] += 1
                    rhs = run.f(tph if c[i] == 1.0 else t + c[i] * h, y + _combine(a[i], K, i))
                rhs = rhs + _combine(C[i], K, i) / h
                if not _AUTONOMOUS and d[i] != 0.0:
                    rhs = rhs + h * d[i] * self.ft
                K[i] = _lu_solve(E, piv, rhs)
                run.st["solves"] += 1
        return K

    def step(self, t, h, tph, y):
        run, m, st = self.run, self.m, self.run.st
        fixed = run.fixed
        st["lu"] += 1
        E = _real_matrix(self.J, 1.0 / (m["gamma"] * h))
        piv = _lu(E)
        if piv is None:
            if fixed or self.nsing + 1 == 5:
                raise _stiff_fail_singular(run.name, t, h)
            self.nsing += 1
            return _RETRY, None, h * 0.5, (-3, "", None)
        try:
            K = self._stages(t, h, tph, y, E, piv)
        except _BlockFailure as failure:  # an algebraic block failed in a stage
            if fixed:
                raise _block_failed(failure) from None
            return _RETRY, None, h * 0.5, (-2, "", failure)
        stages = m["stages"]
        with numpy.errstate(all="ignore"):
            y1 = y + _combine(m["m"], K, stages)
            err, worst = _stiff_norm(run.s, _combine(m["e"], K, stages), _weights(run.s, y, y1))
        self.worst = worst if worst >= 0 else self.worst
        i = _first_nonfinite(y1)
        if err != err or err == math.inf or i >= 0:
            if fixed:
                raise _fail(tph, "state", STATES[max(i, 0)])
            bad, bad_kind = i, "state"
            for j in range(1, stages):
                if bad >= 0:
                    break
                bad, bad_kind = _first_nonfinite(K[j]), "derivative of state"
            return _RETRY, None, h * 0.5, (bad, bad_kind, None)
        if fixed:
            err = 0.0

        # Gustafsson's predictive controller (rodas.f)
        safe, fac_min, fac_max, expo = m["safe"], m["fac_min"], m["fac_max"], 1.0 / m["q"]
        fac = max(1.0 / fac_max, min(1.0 / fac_min, err ** expo / safe))
        hnew = h / fac
        if err > 1.0:
            return _REJECT, None, hnew, None
        if self.accepted_steps > 0:
            facgus = (self.hacc / h) * (err * err / self.erracc) ** expo / safe
            facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
            fac = max(fac, facgus)
            hnew = h / fac
        self.hacc, self.erracc = h, max(1e-2, err)
        self.accepted_steps += 1
        self.nsing = 0
        self.K, self.y, self.y1 = K, y, y1
        return _ACCEPT, y1, hnew, None

    def dense(self):
        """y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta) (q_1 + theta (q_2 + ...)))."""
        y, y1, K = self.y, self.y1, self.K
        q = []
        for row in self.m["H"]:  # every weight, zeros too, as bgc_ros_prepare
            acc = numpy.zeros(_N)
            for w, k in zip(row, K):
                acc = acc + w * k
            q.append(acc)

        def at(theta):
            s1 = 1.0 - theta
            acc = q[-1]
            for qr in q[-2::-1]:
                acc = qr + theta * acc
            return s1 * y + theta * (y1 + s1 * acc)
        return at

    def after(self, tph, y1, last):
        if not last:
            self._point(tph, y1)
        return False


# ---------------------------------------------------------------- Radau IIA (RADAU5)


def _radau_poly(c, Z):
    """The collocation polynomial through (0, 0) and (c_i, Z_i) in Newton's form:
    u(theta) = theta (b_1 + (theta - c_1) (b_2 + ... + (theta - c_{s-1}) b_s)); b: s x N."""
    x = (0.0,) + tuple(c)
    d = [numpy.zeros(_N)] + [Z[i] for i in range(len(c))]
    s = len(c)
    with numpy.errstate(all="ignore"):
        for j in range(1, s + 1):  # divided differences, in place
            for k in range(s, j - 1, -1):
                d[k] = (d[k] - d[k - 1]) / (x[k] - x[k - j])
    return d[1:]


def _radau_mul(M, V):
    """bgc_radau_mul for every component: M (ns x ns) times the stages V (ns x N), each
    M_i0 V_0 + M_i1 V_1 + ... in this order (all rows i at once)."""
    acc = numpy.multiply.outer(M[:, 0], V[0])
    for j in range(1, len(M)):
        acc += numpy.multiply.outer(M[:, j], V[j])
    return acc


def _radau_u(c, b, theta):
    k = len(b) - 1
    acc = b[k]
    while k > 0:
        k -= 1
        acc = b[k] + (theta - c[k]) * acc
    return theta * acc


class _RadauUse:
    """What follows from a stage set (see bgc_radau_configure in the C runtime)."""

    def __init__(self, m, s, k):
        rd = m["radau"][k]
        self.ns, self.c, self.gamma = rd["s"], rd["c"], rd["gamma"]
        self.alpha, self.beta, self.e = rd["alpha"], rd["beta"], rd["e"]
        self.T, self.Ti = numpy.array(rd["T"]), numpy.array(rd["Ti"])
        self.pairs = (self.ns - 1) // 2
        self.nit = 7 + 5 * ((self.ns - 3) // 2)
        expm = (self.ns + 1) / (2.0 * self.ns)
        en = 1.0 / expm - 1.0
        self.rtol = 0.1 * s.rtol ** expm
        self.atol = self.rtol * (s.atol / s.rtol)
        self.fnewt = max(10.0 * _EPS / self.rtol,
                         min(0.03, math.sqrt(self.rtol) if en == 0.5 else self.rtol ** en))
        self.cfac = m["safe"] * (1 + 2 * self.nit)
        self.expo = 1.0 / (self.ns + 1)


_THET = 0.001  # recompute J when Newton contracted more slowly than this


class _Radau(_Family):
    """Radau IIA after Hairer's RADAU5 and RADAU, fixed or variable order (bgc_family_radau
    in the C runtime)."""

    def __init__(self, run):
        m, s = run.m, run.s
        self.run, self.m = run, m
        self.nsets = len(m["radau"])
        self.variable = self.nsets > 1 and not run.fixed
        self.k_set, self.since = 0, 0
        for k, rd in enumerate(m["radau"]):
            if self.variable and 2 * rd["s"] - 1 == s.order0:
                self.k_set, self.since = k, 10  # going on from an earlier run at its order
        self.change = self.unexp = self.unexn = self.recheck = False
        self.u = _RadauUse(m, s, self.k_set)
        self.hfact = self.hold = self.hacc = 0.0
        self.erracc = 1.0
        self.faccon, self.theta, self.thetat = 1.0, _THET, 0.0
        self.thqold, self.dynold, self.hhfac = 1.0, 1.0, 0.5
        self.reject = self.caljac = False
        self.first = self.needjac = True
        self.accepted_steps, self.nsing, self.newt = 0, 0, 0
        self.J = self.E1 = self.piv1 = self.f0 = self.scal = None
        self.Ec = []  # per complex pair: the factors' real and imaginary parts, the pivots
        self.b = [numpy.zeros(_N)] * self.u.ns
        self.zlast = numpy.zeros(_N)
        self.Z = self.W = self.y = self.dc = None

    def start(self, y):
        run, u = self.run, self.u
        self.f0 = _stiff_start(run, run.t, y)
        self.scal = u.atol + u.rtol * numpy.abs(y)
        return None if run.fixed else _first_step(run, y, self.f0)

    def _order(self, h, y):
        """The order, whenever the matrices are to be factored (variable order only)."""
        hquot = h / self.hold if self.hold > 0.0 else 0.0
        nxt = self.k_set
        self.since += 1
        self.thetat = min(10.0, max(self.theta, 0.5 * self.thetat))
        if (self.newt > 1 and self.thetat <= 0.002 and 0.8 < hquot < 1.2 and self.since > 10
                and self.k_set + 1 < self.nsets):
            nxt = self.k_set + 1
        if (self.thetat >= 0.8 or self.unexp or self.unexn) and self.k_set > 0:
            nxt = self.k_set - 1
        self.unexp = self.unexn = self.recheck = False
        if nxt != self.k_set:
            self.k_set = nxt
            self.u = u = _RadauUse(self.m, self.run.s, nxt)
            self.since, self.change, self.hfact = 1, True, 0.0
            self.scal = u.atol + u.rtol * numpy.abs(y)

    def _factor(self, fac1, alphn, betan):
        """gamma/h I - J and (alpha_k + i beta_k)/h I - J, factored; False if one is singular.
        C adds alpha_k + beta_k _Complex_I, i.e. (alpha_k + beta_k 0) + i (0 + beta_k), to
        -J."""
        st = self.run.st
        st["lu"] += 1
        self.E1 = _real_matrix(self.J, fac1)
        self.piv1 = _lu(self.E1)
        self.Ec = []
        if self.piv1 is None:
            return False
        for k in range(self.u.pairs):
            st["lu"] += 1
            if _JAC_LU is not None:
                E = _SparseMatrix(self.J, alphn[k] + betan[k] * 0.0, betan[k])
                if E.piv is None:
                    return False
                self.Ec.append((E, None, E.piv))
                continue
            Er = _real_matrix(self.J, alphn[k] + betan[k] * 0.0)
            Ei = numpy.zeros((_N, _N))
            Ei[numpy.diag_indices(_N)] += betan[k]
            pv = _zlu(Er, Ei)
            if pv is None:
                return False
            self.Ec.append((Er, Ei, pv))
        return True

    def _newton(self, t, h, tph, y, fac1, alphn, betan):
        """The simplified Newton iteration from the last step's collocation polynomial: 0
        converged (self.Z), else (1, why) a stage failed, 2 no convergence, 3 too slow
        (self.hhfac: the step that would converge)."""
        run, u, st = self.run, self.u, self.run.st
        c, ns, scal = u.c, u.ns, self.scal
        if self.first or self.change:
            Z, W = numpy.zeros((ns, _N)), numpy.zeros((ns, _N))
        else:
            q = h / self.hold
            with numpy.errstate(all="ignore"):
                Z = numpy.array([_radau_u(c, self.b, 1.0 + c[i] * q) - self.zlast
                                 for i in range(ns)])
                W = _radau_mul(u.Ti, Z)
        self.newt = 0
        self.faccon = max(self.faccon, _EPS) ** 0.8
        self.theta = _THET
        while True:
            if self.newt >= u.nit:
                return 2, None
            F = numpy.empty((ns, _N))
            try:
                for i in range(ns):
                    st["rhs"] += 1
                    F[i] = run.f(tph if i == ns - 1 else t + c[i] * h, y + Z[i])
                    j = _first_nonfinite(F[i])
                    if j >= 0:
                        return 1, (j, "derivative of state", None)
            except _BlockFailure as failure:
                return 1, (-2, "", failure)
            with numpy.errstate(all="ignore"):
                G = _radau_mul(u.Ti, F)
                dW = numpy.empty((ns, _N))
                dW[0] = _lu_solve(self.E1, self.piv1, G[0] - fac1 * W[0])
                for k in range(u.pairs):
                    w2, w3 = W[2 * k + 1], W[2 * k + 2]
                    g2 = G[2 * k + 1] - (alphn[k] * w2 - betan[k] * w3)
                    g3 = G[2 * k + 2] - (betan[k] * w2 + alphn[k] * w3)
                    # C's g2 + g3 _Complex_I: (g2 + g3 0) + i g3
                    dW[2 * k + 1], dW[2 * k + 2] = _zlu_solve(*self.Ec[k], g2 + g3 * 0.0, g3)
                st["solves"] += 1 + u.pairs
                self.newt += 1
                # per component dW_0^2 + dW_1^2 + ... (in units of scal), then over them
                part = dW[0] / scal
                part = part * part
                for i in range(1, ns):
                    q = dW[i] / scal
                    part = part + q * q
                dyno = math.sqrt(_seq_sum(part) / (ns * _N)) if _N else 0.0
            if dyno != dyno or dyno == math.inf:
                return 2, None
            newt = self.newt
            if 1 < newt < u.nit:
                thq = dyno / self.dynold
                self.theta = thq if newt == 2 else math.sqrt(thq * self.thqold)
                self.thqold = thq
                theta = self.theta
                if theta < 0.99:
                    self.faccon = theta / (1.0 - theta)
                    dyth = self.faccon * dyno * theta ** (u.nit - 1 - newt) / u.fnewt
                    if dyth >= 1.0 and not run.fixed:  # a smaller step converges sooner
                        qnewt = max(1e-4, min(20.0, dyth))
                        self.hhfac = 0.8 * qnewt ** (-1.0 / (4.0 + u.nit - 1 - newt))
                        return 3, None
                else:
                    return 2, None
            self.dynold = max(dyno, _EPS)
            with numpy.errstate(all="ignore"):
                W = W + dW
                Z = _radau_mul(u.T, W)
            self.Z = Z
            # converged, the contraction measured in this step (never after one iteration)
            if newt > 1 and self.faccon * dyno <= u.fnewt:
                return 0, None

    def _error(self, t, h, y):
        """The error estimate, refined once with f(t, y + err) on the first step and after a
        rejection."""
        run, u, Z = self.run, self.u, self.Z
        ns = u.ns
        with numpy.errstate(all="ignore"):
            f2 = u.e[0] * Z[0]
            for j in range(1, ns):
                f2 = f2 + u.e[j] * Z[j]
            f2 = f2 / h
            cont = _lu_solve(self.E1, self.piv1, f2 + self.f0)
            run.st["solves"] += 1
            wt = u.atol + u.rtol * _c_max(numpy.abs(y), numpy.abs(y + Z[ns - 1]))
            err, worst = _stiff_norm(run.s, cont, wt)
            err = max(err, 1e-10)
            if err >= 1.0 and (self.first or self.reject):  # refined: f at y + err
                run.st["rhs"] += 1
                try:
                    f1 = run.f(t, y + cont)
                except _BlockFailure:
                    f1 = None
                if f1 is not None:
                    cont = _lu_solve(self.E1, self.piv1, f1 + f2)
                    run.st["solves"] += 1
                    err, worst = _stiff_norm(run.s, cont, wt)
                    err = max(err, 1e-10)
        self.worst = worst if worst >= 0 else self.worst
        return err

    def _retry(self, hnew, why):
        """A failed attempt: retried smaller, with a fresh Jacobian unless this one is."""
        self.reject = True
        self.needjac = not self.caljac
        return _RETRY, None, hnew, why

    def _fixed_failure(self, t, h, failed, why):
        """Newton's failure on a fixed step: once more with a fresh Jacobian, else the end."""
        if failed == 1:
            bad, bad_kind, failure = why
            if bad == -2:
                raise _block_failed(failure)
            raise _fail(t, bad_kind, STATES[bad])
        if not self.caljac:
            self.needjac = True
            return _AGAIN, None, h, None
        raise _Failure("at t = %.17g: %s: the Newton iteration does not converge with the "
                       "fixed step h = %.3g" % (t, self.run.name, h), t)

    def _control(self, h, err, y):
        """Step control: Gustafsson's, the safety factor scaled by the Newton iterations."""
        m, u = self.m, self.u
        safe, fac_min, fac_max = m["safe"], m["fac_min"], m["fac_max"]
        fac = min(safe, u.cfac / (self.newt + 2 * u.nit))
        quot = max(1.0 / fac_max, min(1.0 / fac_min, err ** u.expo / fac))
        hnew = h / quot
        if not err < 1.0:
            self.reject = True
            self.needjac = not self.caljac
            return _REJECT, None, 0.1 * h if self.first else hnew, None
        self.first = False
        self.accepted_steps += 1
        if self.accepted_steps > 1 and not self.change:
            facgus = (self.hacc / h) * (err * err / self.erracc) ** u.expo / fac
            facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
            quot = max(quot, facgus)
            hnew = h / quot
        self.change = False
        self.hacc, self.erracc = h, max(1e-2, err)
        Z = self.Z
        y1 = y + Z[u.ns - 1]
        self.b, self.dc, self.y = _radau_poly(u.c, Z), u.c, y
        self.zlast, self.hold = Z[u.ns - 1], h
        self.reject = self.caljac = False
        self.nsing = 0
        return _ACCEPT, y1, hnew, None

    def step(self, t, h, tph, y):
        run = self.run
        if self.needjac:
            self.J = _stiff_jacobian(run, t, y)
            self.needjac, self.caljac, self.hfact = False, True, 0.0
        if self.variable and (h != self.hfact or self.recheck):
            self._order(h, y)
        u = self.u
        fac1 = u.gamma / h
        alphn = [a / h for a in u.alpha]
        betan = [bb / h for bb in u.beta]
        if h != self.hfact:
            if not self._factor(fac1, alphn, betan):
                self.hfact = 0.0
                if run.fixed or self.nsing + 1 == 5:
                    raise _stiff_fail_singular(run.name, t, h)
                self.nsing += 1
                self.unexp = True
                return self._retry(h * 0.5, (-3, "", None))
            self.hfact = h
        failed, why = self._newton(t, h, tph, y, fac1, alphn, betan)
        if failed and run.fixed:
            return self._fixed_failure(t, h, failed, why)
        if failed:
            if failed == 3:
                self.unexn = self.hhfac <= 0.5
            else:
                self.unexp = True
            return self._retry(h * (self.hhfac if failed == 3 else 0.5),
                               why if failed == 1 else (-4, "", None))
        err = 0.0
        if not run.fixed:
            err = self._error(t, h, y)
            if err != err or err == math.inf:
                self.unexp = True
                return self._retry(h * 0.5, (-1, "", None))
        return self._control(h, err, y)

    def dense(self):
        y, c, b = self.y, self.dc, self.b
        return lambda theta: y + _radau_u(c, b, theta)

    def after(self, tph, y1, last):
        """The new point: its weights and f (after the run's last step, the order to go on
        with)."""
        run, u = self.run, self.u
        if last:
            if not run.fixed:
                run.st["order_next"] = 2 * u.ns - 1
            return False
        self.scal = u.atol + u.rtol * numpy.abs(y1)
        run.st["rhs"] += 1
        try:
            self.f0 = run.f(tph, y1)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        return False

    def next_h(self, h, hnew):
        """h is kept (and the factorisations with it) while the controller asks for at most
        20 % more and Newton converged fast; J is recomputed when it converged slowly."""
        if self.theta <= _THET and 1.0 <= hnew / h <= 1.2:
            hnew = h
            if self.variable:
                self.since += 1
                if self.since >= 10 and self.k_set + 1 < self.nsets:
                    self.recheck = True  # ... but look at the order now and then
        self.needjac = self.theta > _THET
        return hnew


# ====================================================================== batch ===
# Batch mode, as the C program's (bgc/runtime/batch.c, which describes it): many runs in one
# process, each from the same state as a new process (fresh parameters, workspace, Newton
# starting values and counters), one result per run; a run that fails is a result too.

METRIC_KINDS = ("final", "max", "min", "maxabs", "rms")
BATCH_COLUMNS = ("run", "status", "steps", "rejected", "rhs", "cpu", "message")  # + metrics


class _LineError(Exception):
    pass


def _metric_spec(spec):
    """KIND:OUTPUT as (kind, output index); ValueError if it is not one."""
    kind, colon, output = spec.partition(":")
    if not colon or kind not in METRIC_KINDS:
        raise ValueError("--metric expects KIND:OUTPUT with KIND one of final, max, min, "
                         "maxabs, rms; got '%s'" % spec)
    if output not in OUTPUTS:
        raise ValueError("--metric %s: '%s' is not an output" % (spec, output))
    return kind, OUTPUTS.index(output)


def _line_overrides(run):
    """A run's parameters {index: value}: from a line of NAME=VALUE words, or a dict."""
    if isinstance(run, dict):
        words = [(str(k), v) for k, v in run.items()]
    else:
        text = run.replace("\t", " ").replace("\r", " ").replace("\n", " ")
        words = []
        for word in text.split(" "):
            if word:
                name, eq, value = word.partition("=")
                if not eq or not name:
                    raise _LineError("expected NAME=VALUE, got '%s'" % word[:200])
                words.append((name, value))
    given = {}
    for name, value in words:
        if name not in _PARAM_NAMES:
            raise _LineError("unknown parameter '%s'" % name[:200])
        if isinstance(value, str):
            try:
                value = _parse_number(name, value)
            except _UsageError:
                raise _LineError("invalid value for %s: '%s'" % (name, value[:200])) from None
        value = float(value)
        if not math.isfinite(value):
            raise _LineError("invalid value for %s: '%r'" % (name, value))
        given[_PARAM_NAMES.index(name)] = value
    return given


def _batch_run(s, base, project, run, specs, trajectory, allow=False):
    """One run: (status, message, metric values, stats)."""
    st = _new_stats()
    nan = [math.nan] * len(specs)
    try:
        given = dict(base)
        given.update(_line_overrides(run))
    except _LineError as error:
        return "invalid", str(error), nan, st
    p = _with_constants(_param_values(given))
    try:
        x0 = _initial_state(s, p, project, allow)
    except SimulationError as error:
        return "failed", str(error), nan, st
    except ConstraintError as error:
        return "constraint", "; ".join(error.messages), nan, st
    acc = [0.0] * len(specs)
    count = 0
    out = None
    if trajectory is not None:
        out = open(trajectory, "w", encoding="utf-8", newline="")
        out.write(",".join(["t"] + OUTPUTS) + "\n")
    try:
        for t, y in _integrate(s, p, x0, st):
            for k, (kind, j) in enumerate(specs):
                v = y[j]
                if kind == "final":
                    acc[k] = v
                elif kind == "max":
                    if count == 0 or v > acc[k]:
                        acc[k] = v
                elif kind == "min":
                    if count == 0 or v < acc[k]:
                        acc[k] = v
                elif kind == "maxabs":
                    if count == 0 or abs(v) > acc[k]:
                        acc[k] = abs(v)
                else:
                    acc[k] = v * v if count == 0 else acc[k] + v * v
            count += 1
            if out is not None:
                out.write(_row_text(t, y))
    except _Failure as failure:
        return "failed", str(failure), nan, st
    finally:
        if out is not None:
            out.close()
    if count == 0:
        return "ok", "", nan, st
    values = [math.sqrt(a / count) if kind == "rms" else a for a, (kind, j) in zip(acc, specs)]
    return "ok", "", values, st


def batch_rows(runs, metrics=(), t_end=None, dt=None, solver=None, rtol=None, atol=None,
               params=None, step=None, project_initial=False, trajectories=None,
               max_steps=None, allow_inconsistent=False, error_states=None):
    """Runs each of `runs` (a line of NAME=VALUE words, or a dict {name: value}) on top of the
    defaults and `params`, yielding one dict per run as it completes: run (its number from 0),
    status (ok, failed, constraint, invalid), each metric ("KIND:OUTPUT", see METRIC_KINDS),
    steps, rejected, rhs, cpu, message.  trajectories: a directory for each run's CSV
    (run-NNNNNN.csv).  error_states: as rows().  ValueError for bad settings or metrics,
    before any run."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")
    s = _settings(t_end, dt, solver, rtol, atol, step, max_steps, error_states=error_states)
    base = _overrides(params)
    specs = [_metric_spec(m) for m in metrics]
    index = 0
    for run in runs:
        if isinstance(run, str) and run.startswith("#"):
            continue
        path = None
        if trajectories is not None:
            path = "%s/run-%06d.csv" % (trajectories, index)
        status, message, values, st = _batch_run(s, base, project_initial, run, specs, path,
                                                 allow_inconsistent)
        row = {"run": index, "status": status}
        row.update(zip(metrics, values))
        row.update(steps=st["steps"], rejected=st["rejected"], rhs=st["rhs"], cpu=st["cpu"],
                   message=message)
        index += 1
        yield row
        if _STOP[0]:
            return


def batch(runs, metrics=(), **options):
    """batch_rows as a list."""
    return list(batch_rows(runs, metrics, **options))


def _quoted(text):
    return '"' + text.replace('"', '""').replace("\n", " ").replace("\r", " ") + '"'


def _batch_main(argv):
    """The program with --batch (see bgc/runtime/batch.c); the exit status."""
    rest, own = [], {"--batch": None, "--trajectories": None}
    metrics = []
    i = 0
    while i < len(argv):
        name, eq, value = argv[i].partition("=")
        if name not in ("--batch", "--metric", "--trajectories"):
            rest.append(argv[i])
            i += 1
            continue
        if not eq:
            if i + 1 >= len(argv):
                sys.stderr.write("error: option '%s' needs a value\n" % argv[i])
                return 2
            i += 1
            value = argv[i]
        if name == "--metric":
            metrics.append(value)
        else:
            own[name] = value
        i += 1
    try:
        parsed = _parse_args(rest)
        for m in metrics:
            _metric_spec(m)
    except _UsageError as error:
        sys.stderr.write(str(error))
        return 2
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    if parsed is None:
        return 0
    options, given, flags = parsed
    try:
        _settings(**options)
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    params = {_PARAM_NAMES[j]: v for j, v in given.items()}
    try:
        source = sys.stdin if own["--batch"] == "-" else open(own["--batch"], encoding="utf-8")
    except OSError:
        sys.stderr.write("error: cannot read '%s'\n" % own["--batch"])
        return 2
    out = sys.stdout
    out.write(",".join(["run", "status"] + metrics + ["steps", "rejected", "rhs", "cpu",
                                                       "message"]) + "\n")
    if source is sys.stdin:
        out.flush()
    handlers = _stop_on_signals()
    try:
        for row in batch_rows((line for line in source), metrics, params=params,
                              project_initial="--project-initial" in flags,
                              allow_inconsistent="--allow-inconsistent" in flags,
                              trajectories=own["--trajectories"], **options):
            out.write("%d,%s%s,%d,%d,%d,%.17g,%s\n" % (
                row["run"], row["status"], "".join(",%.17g" % row[m] for m in metrics),
                row["steps"], row["rejected"], row["rhs"], row["cpu"],
                _quoted(row["message"])))
            if source is sys.stdin:  # (each result as it is known, as the C program's)
                out.flush()
    finally:
        for sig, handler in handlers:
            signal.signal(sig, handler)
        stopped = _STOP[0]
        request_stop(0)
        if source is not sys.stdin:
            source.close()
    out.flush()
    if stopped:
        sys.stderr.write("error: interrupted by signal %d\n" % stopped)
        return 3
    return 0


# ---------------------------------------------------------------- binding


def _bind_model():
    """Derives the runtime's tables from the model part's names (the contract above): call it
    after (re)defining them."""
    global PARAMETERS, _V
    _BLOCK_TABLE[:] = [_Block(row) for row in _BLOCKS]
    PARAMETERS = dict(zip(_PARAM_NAMES, _param_values({})))
    _V = _ListVectors if _N <= _LIST_STATES else _ArrayVectors
    _WORK.clear()  # a workspace of the model's sizes, made when first needed


PARAMETERS = {}
_bind_model()


# ================================================================ solvers ===
# Printed from bgc/solvers.py.
_METHODS = {
    'euler': {
        'family': 'fixed',
        'order': 1,
        'summary': 'explicit Euler, fixed step',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 10.0,
        'beta': 0.0,
        'q': 1,
        'expo_beta': 0.75,
        'stages': 1,
        'fsal': False,
        'c': (0.0,),
        'a': ((),),
        'b': (1.0,),
        'e': (),
        'e2': (),
        'P': (),
    },
    'rk4': {
        'family': 'fixed',
        'order': 4,
        'summary': 'classical Runge-Kutta, fixed step',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 10.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'stages': 4,
        'fsal': False,
        'c': (0.0, 0.5, 0.5, 1.0),
        'a': ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0),),
        'b': (0.16666666666666666, 0.3333333333333333, 0.3333333333333333, 0.16666666666666666),
        'e': (),
        'e2': (),
        'P': (),
    },
    'dopri5': {
        'family': 'erk',
        'order': 5,
        'summary': 'Dormand-Prince 5(4), adaptive, dense output of order 4',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 10.0,
        'beta': 0.04,
        'q': 5,
        'expo_beta': 0.75,
        'stages': 7,
        'fsal': True,
        'c': (0.0, 0.2, 0.3, 0.8, 0.8888888888888888, 1.0, 1.0),
        'a': ((), (0.2,), (0.075, 0.225), (0.9777777777777777, -3.7333333333333334, 3.5555555555555554), (2.9525986892242035, -11.595793324188385, 9.822892851699436, -0.2908093278463649), (2.8462752525252526, -10.757575757575758, 8.906422717743473, 0.2784090909090909, -0.2735313036020583), (0.09114583333333333, 0.0, 0.44923629829290207, 0.6510416666666666, -0.322376179245283, 0.13095238095238096),),
        'b': (0.09114583333333333, 0.0, 0.44923629829290207, 0.6510416666666666, -0.322376179245283, 0.13095238095238096, 0.0),
        'e': (0.0012326388888888888, 0.0, -0.0042527702905061394, 0.03697916666666667, -0.05086379716981132, 0.0419047619047619, -0.025),
        'e2': (),
        'P': ((1.0, -2.8535800653862835, 3.0717434641059005, -1.1270175653862835), (0.0, 0.0, 0.0, 0.0), (0.0, 4.023133379230305, -6.249321565289, 2.675424484351598), (0.0, -3.7324019615885042, 10.068970589843675, -5.685526961588504), (0.0, 2.5548038301849423, -6.399112377351017, 3.5219323679207912), (0.0, -1.3744241142186024, 3.272657752246729, -1.7672812570757455), (0.0, 1.3824689317781436, -3.764937863556287, 2.382468931778144), ),
        'stiffness': (5, 6, 3.25),
    },
    'vern7': {
        'family': 'erk',
        'order': 7,
        'summary': 'Verner 7(6), adaptive, dense output of order 7: moderate to tight tolerances',
        'safe': 0.9,
        'fac_min': 0.333,
        'fac_max': 6.0,
        'beta': 0.04,
        'q': 7,
        'expo_beta': 0.75,
        'stages': 11,
        'fsal': True,
        'c': (0.0, 0.005, 0.10888888888888888, 0.16333333333333333, 0.4555, 0.6095094489978381, 0.884, 0.925, 1.0, 1.0, 1.0, 0.6716626365038747, 0.125, 0.25, 0.53, 0.79),
        'a': ((), (0.005,), (-1.07679012345679, 1.185679012345679), (0.04083333333333333, 0.0, 0.1225), (0.6389139236255726, 0.0, -2.455672638223657, 2.272258714598084), (-2.6615773750187572, 0.0, 10.804513886456137, -8.3539146573962, 0.820487594956657), (6.067741434696771, 0.0, -24.711273635911084, 20.427517930788895, -1.9061579788166472, 1.006172249242068), (12.054670076253203, 0.0, -49.75478495046899, 41.142888638604674, -4.461760149974004, 2.042334822239175, -0.09834843665406108), (10.138146522881808, 0.0, -42.6411360317175, 35.76384003992257, -4.3480228403929075, 2.0098622683770357, 0.3487490460338272, -0.27143900510483127), (-45.030072034298676, 0.0, 187.3272437654589, -154.02882369350186, 18.56465306347536, -7.141809679295079, 1.3088085781613785), (0.04715561848627222, 0.0, 0.0, 0.25750564298434153, 0.2621665397741262, 0.15216092656738558, 0.49399691700324844, -0.29430311714032503, 0.0813174723249511, 0.0), (0.04608828480030098, 0.0, 0.0, 0.26095211559122217, 0.2593539886572149, 0.10712848532313586, -0.07335737007803501, 0.09516817597231149, -0.05557470923733998, 0.0, 0.03190366547506434), (0.05837333975598387, 0.0, 0.0, 0.08577524236694001, -0.03429204581002123, -0.02818259731103036, -0.02078116148802372, -0.0036707401444410195, 0.011406452584364688, 0.0, -0.002750153913374408, 0.05912166395960217), (0.037816201678944845, 0.0, 0.0, 0.031346785326310744, 0.02225110077526238, 0.009958131955421001, 0.015223096043899926, -0.007547047454118317, 0.0013158882065466297, 0.0, -0.002347519033359897, -0.024269839327928092, 0.16625320182902079), (0.05345075085525607, 0.0, 0.0, 0.34301733821384506, 0.20767427262033986, 0.07722675619395836, 0.00013272687985611353, 0.022219958202462402, -0.017410228868402326, 0.0, 0.0071975937699150306, -0.08645504868462665, -0.07705411918260392, 0.0), (0.05681087911635884, 0.0, 0.0, 0.36852219016184323, 0.22940605301030753, 0.08854425014313802, 0.02937879283098644, 0.005463456745004648, -0.01311750049635595, 0.0, 0.005109093689745297, 0.12419640895877533, -0.1043136241598034, 0.0, 0.0),),
        'b': (0.04715561848627222, 0.0, 0.0, 0.25750564298434153, 0.2621665397741262, 0.15216092656738558, 0.49399691700324844, -0.29430311714032503, 0.0813174723249511, 0.0, 0.0),
        'e': (0.0025470118799310456, 0.0, 0.0, -0.00965839487279575, 0.0420647097563969, -0.0666822437469301, 0.26500974646212816, -0.29430311714032503, 0.0813174723249511, -0.020295184663356284, 0.0),
        'e2': (),
        'P': ((1.0, -8.366136708817907, 33.45564674491339, -70.50417466572665, 80.67397907967836, -47.49724826833688, 11.28508943677596), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 13.822881552117133, -112.04150066933103, 378.80182330392614, -626.3590532637976, 497.1667710334457, -151.13341631337596), (0.0, 14.07307810511366, -114.06947125956815, 385.6582019903894, -637.6962607392367, 506.1655757984283, -153.86895735535242), (0.0, 8.16798591450387, -66.20568915797485, 223.8352361965341, -370.11761297318577, 293.7774709021209, -89.3052299554309), (0.0, 26.517713521571906, -214.93958449070786, 726.6906103441299, -1201.602565533699, 953.7610488090023, -289.9332257332943), (0.0, -15.798166912004106, 128.05219533798348, -432.93248289538707, 715.865561966764, -568.2117438592624, 172.7303332447658), (0.0, 4.36511516811192, -35.38148338938862, 119.62148256700969, -197.79735460926827, 156.99984154077703, -47.72628380491679), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, -3.274137494621028, 27.15609115402443, -93.85378772108284, 158.59209585933854, -128.87650569842114, 40.25624390076204), (0.0, 5.921404526401594, -27.552998537066152, 37.272033018740885, 3.387133200887934, -37.98539394174189, 18.957821732777628), (0.0, 8.487477767791544, -39.493242097657294, 53.42407366300933, 4.8549660153948455, -54.44657346814621, 27.17329811960779), (0.0, -19.186819751360847, 167.14983136102234, -537.8357359160404, 827.7451797910091, -614.6483785211819, 176.77592303655177), (0.0, -15.883752349342663, 109.64035230222805, -328.15049709039147, 514.4013813786597, -403.4939189483438, 123.4864347071902), (0.0, -18.84664333946508, 144.22985270152228, -462.026782795111, 728.0525498274546, -552.71094537834, 161.3019689839392), ),
    },
    'dop853': {
        'family': 'erk',
        'order': 8,
        'summary': 'Dormand-Prince 8(5,3), adaptive, dense output of order 7: tight tolerances',
        'safe': 0.9,
        'fac_min': 0.333,
        'fac_max': 6.0,
        'beta': 0.04,
        'q': 8,
        'expo_beta': 0.2,
        'stages': 13,
        'fsal': True,
        'c': (0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0, 1.0, 0.1, 0.2, 0.7777777777777778),
        'a': ((), (0.05260015195876773,), (0.0197250569845379, 0.0591751709536137), (0.02958758547680685, 0.0, 0.08876275643042054), (0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792), (0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242), (0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125), (0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023), (0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996), (0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627), (-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196), (2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636), (0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259), (0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699, -0.008298), (0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325), (-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599, 4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145, 2.9475147891527724, -9.15095847217987),),
        'b': (0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259, 0.0),
        'e': (0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0),
        'e2': (-0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.42268232132379197, -0.1521609496625161, 0.20136540080403034, 0.022651792198360825, 0.0),
        'P': ((1.0, -10.266057073759306, 48.161850968566455, -114.93304874997833, 147.46446875669767, -97.06685363011368, 25.69393346270375), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 13.917653631776604, -154.78787266663716, 522.9219089608218, -456.25918840208783, -75.53193732135753, 154.18974869023643), (0.0, 2.6056037519936095, -21.622822384626506, 2.535182028966755, 292.25417465990404, -505.40999933296894, 231.5293791760455), (0.0, -15.018944223519684, 160.09447708973047, -474.3071826037644, 135.96036916173838, 545.1091945264187, -357.6391179106141), (0.0, 3.050527683318488, -38.54396729189063, 174.47140009219885, -337.0513470238771, 291.78987509083254, -93.40532418362432), (0.0, -1.3278744327655212, 16.661770430049543, -74.44027814126304, 140.75210016191608, -119.2562021040512, 37.45832313645163), (0.0, 2.844533632672879, -36.55829548991012, 170.69007169147514, -345.9748485480496, 313.299553623578, -104.0996495089623), (0.0, 0.7657106259527866, -9.906995535619366, 46.8029919188744, -96.5198694669957, 88.74316650017616, -29.8402934266605), (0.0, -1.0889903364513334, 14.097013042320002, -66.68230591294363, 137.96299063474376, -127.82216401767992, 43.53345659001114), (0.0, 18.148505520854727, -127.63310949253875, 357.3419516129657, -500.7031507909224, 349.17035710882897, -96.32455395918828), (0.0, -9.194632392478356, 93.3567459327894, -282.6272618704363, 361.14007718803333, -201.85219053352347, 39.17726167561544), (0.0, -4.436036387594894, 56.68120539776666, -261.77342902691703, 520.9742236688993, -461.17279991013964, 149.72683625798564), ),
    },
    'ros2': {
        'family': 'rosenbrock',
        'order': 2,
        'summary': 'Rosenbrock 2(1), L-stable, two stages: stiff plants at a fixed step (--step, the embedded target); the Jacobian every step',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 6.0,
        'beta': 0.0,
        'q': 2,
        'expo_beta': 0.75,
        'stages': 2,
        'gamma': 1.7071067811865475,
        'c': (0.0, 1.0),
        'd': (1.7071067811865475, -1.7071067811865475),
        'a': ((), (0.585786437626905,),),
        'C': ((), (-1.17157287525381,),),
        'm': (0.8786796564403574, 0.2928932188134525),
        'e': (0.2928932188134525, 0.2928932188134525),
        'H': ((0.12132034355964258, 0.12132034355964258), (0.0, 0.0),),
    },
    'rodas4': {
        'family': 'rosenbrock',
        'order': 4,
        'summary': 'Rosenbrock 4(3), L-stable, stiff; the Jacobian every step',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 6.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'stages': 6,
        'gamma': 0.25,
        'c': (0.0, 0.386, 0.21, 0.63, 1.0, 1.0),
        'd': (0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0),
        'a': ((), (1.544,), (0.9466785280815826, 0.2557011698983284), (3.314825187068521, 2.896124015972201, 0.9986419139977817), (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895), (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895, 1.0),),
        'C': ((), (-5.6688,), (-2.430093356833875, -0.2063599157091915), (-0.1073529058151375, -9.594562251023355, -20.47028614809616), (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.7089089320616), (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054),),
        'm': (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895, 1.0, 1.0),
        'e': (0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        'H': ((10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662, 0.0), (-0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872, 0.0),),
    },
    'radau5': {
        'family': 'radau',
        'order': 5,
        'summary': 'Radau IIA of order 5, implicit, L-stable, stiff; Jacobian and factorisations reused',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 8.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'radau': ({'s': 3, 'c': (0.1550510257216822, 0.6449489742783178, 1.0), 'gamma': 3.637834252744496, 'alpha': (2.6810828736277523,), 'beta': (3.0504301992474105,), 'T': ((0.09123239487089295, -0.1412552950209542, -0.030029194105147424), (0.241717932707107, 0.20412935229379994, 0.3829421127572619), (0.966048182615093, 1.0, 0.0),), 'Ti': ((4.325579890063155, 0.33919925181580984, 0.5417705399358749), (-4.178718591551905, -0.32768282076106237, 0.47662355450055044), (-0.5028726349457868, 2.571926949855605, -0.5960392048282249),), 'e': (-10.048809399827416, 1.382142733160749, -0.3333333333333333)}, ),
    },
    'rodas5p': {
        'family': 'rosenbrock',
        'order': 5,
        'summary': 'Rosenbrock 5(4), L-stable, stiff; the Jacobian every step',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 6.0,
        'beta': 0.0,
        'q': 5,
        'expo_beta': 0.75,
        'stages': 8,
        'gamma': 0.21193756319429014,
        'c': (0.0, 0.6358126895828704, 0.4095798393397535, 0.9769306725060716, 0.4288403609558664, 1.0, 1.0, 1.0),
        'd': (0.21193756319429014, -0.42387512638858027, -0.3384627126235924, 1.8046452872882734, 2.325825639765069, 0.0, 0.0, 0.0),
        'a': ((), (3.0,), (2.849394379747939, 0.45842242204463923), (-6.954028509809101, 2.489845061869568, -10.358996098473584), (2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641), (-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946), (-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0), (-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0, 1.0),),
        'C': ((), (-14.155112264123755,), (-17.97296035885952, -2.859693295451294), (147.12150275711716, -1.41221402718213, 71.68940251302358), (165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306), (24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471), (30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783, -19.097331116725623, -28.087943162872662), (37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047, -40.06618937091002, -54.66780262877968, -9.48861652309627),),
        'm': (-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0, 1.0, 1.0),
        'e': (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        'H': ((25.948786856663858, -2.5579724845846235, 10.433815404888879, -2.3679251022685204, 0.524948541321073, 1.1241088310450404, 0.4272876194431874, -0.17202221070155493), (-9.91568850695171, -0.9689944594115154, 3.0438037242978453, -24.495224566215796, 20.176138334709044, 15.98066361424651, -6.789040303419874, -6.710236069923372), (11.419903575922262, 2.8879645146136994, 72.92137995996029, 80.12511834622643, -52.072871366152654, -59.78993625266729, -0.15582684282751913, 4.883087185713722),),
    },
    'radau9': {
        'family': 'radau',
        'order': 9,
        'summary': 'Radau IIA of order 9 (5 stages), implicit, L-stable, stiff: tight tolerances',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 8.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'radau': ({'s': 5, 'c': (0.05710419611451768, 0.2768430136381238, 0.5835904323689168, 0.8602401356562195, 1.0), 'gamma': 6.2867047517292765, 'alpha': (3.655694325463572, 5.70095329867179), 'beta': (6.543736899360077, 3.2102656003085497), 'T': ((0.012517586220501045, -0.010242047817908826, 0.04767387729029572, -0.011478515255229515, -0.01401985889287541), (0.0014916701518953824, 0.05017286451737106, -0.09433181918161143, -0.007668830749180163, 0.024708578426518527), (0.07298187638808715, -0.23053953404341795, 0.1027030453801259, 0.01939846399882895, 0.08180035370375117), (0.3800914400035681, 0.37789390224886127, 0.46674413033249434, 0.40760117128019907, 0.19968242788680252), (0.9219789736812105, 1.0, 0.0, 1.0, 0.0),), 'Ti': ((30.0415677215444, 13.865107856271413, 3.4800027747951856, -1.0320087978252634, 0.8043030450739899), (5.344186437834912, 4.593615567759161, -3.0363603234594243, 1.050660190231459, -0.27277861186429625), (3.748059807439805, -3.984965736343885, -1.0444156416080188, 1.1840985681379486, -0.44991777015678036), (-33.041880213519, -17.376953479063566, -0.17212906325400557, -0.09916977798254265, 0.5312281158383066), (-8.611443979875292, 9.699991409528808, 1.9147286396968743, 2.41869200608494, -1.0474634879353375),), 'e': (-27.78093394406464, 3.641478498049213, -1.2525477211691187, 0.5920031671845428, -0.2)}, ),
    },
    'radau13': {
        'family': 'radau',
        'order': 13,
        'summary': 'Radau IIA of order 13 (7 stages), implicit, L-stable, stiff: very tight tolerances',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 8.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'radau': ({'s': 7, 'c': (0.029316427159784893, 0.1480785996684843, 0.3369846902811543, 0.5586715187715501, 0.7692338620300545, 0.9269456713197411, 1.0), 'gamma': 8.936832788405216, 'alpha': (4.378693561506806, 7.14105521918764, 8.511834825102946), 'beta': (10.169693283795011, 6.623045922639276, 3.281013624325059), 'T': ((0.0021537546273105264, 0.021567551351320772, 0.008783567925144144, -0.004055161452331024, 0.004427232753268285, -0.0012386461879528741, -0.0027606174805438525), (-0.0016000250778804286, -0.03813164813441155, -0.021525560594006874, 0.00841556827655959, -0.00403194957022455, -6.666635339396339e-05, 0.00318547482516621), (0.004059107301947683, 0.05739650893938172, 0.05885052920842679, -0.008560431061603433, -0.006923212665023909, -0.0023521809829433384, 0.00041690777252975626), (0.015750488079376845, -0.03821469359696835, -0.16573681127294385, -0.03737124230238446, 0.00823900729850772, 0.0031150711523461752, 0.025116604913438822), (0.11297766102422081, -0.2491742124652637, 0.27356330579866234, 0.0053667613791817705, 0.19321111610126201, 0.10171773248171515, 0.09504502035604623), (0.4583810431839315, 0.5315846490836285, 0.4863228366175729, 0.5265742264584493, 0.27553439498962584, 0.5217519452747653, 0.1280719446355439), (0.8813915783538184, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0),), 'Ti': ((258.13192631998226, 189.0737630813985, 49.08731481793013, 4.110647469661428, 4.053447889315564, -3.112755366607346, 1.6467749135584446), (-3.007390169451292, -11.015866078765772, 1.4877994561316563, 2.1303881595592826, -1.8161410868175656, 1.134325587895161, -0.41469904594330353), (-8.441963188321084, -0.650525274057515, 6.9406707303698765, -3.2050475255978985, 1.0712809435464785, -0.3548507491216222, 0.09198549132786554), (74.6783322350227, 87.40858897990081, 4.024158737379998, -3.714806315158364, -3.4300939859823174, 2.6966048097653124, -0.9386927436075462), (58.356528851906575, -10.06877395780018, -30.36638884256667, -1.020020865184866, -0.11241750037842496, 1.8906408310003777, -0.9716486393831483), (-299.1862480282521, -243.04074536874478, -48.77710407803787, -2.0386719057419342, 1.673560239861085, -1.0873740320571061, 0.9019382492960993), (-93.0765028974353, 23.881631056281144, 39.278880730813846, 14.38891568549108, -3.5104383993993613, 4.8632848855661805, -2.2464827295912397),), 'e': (-54.374436894128614, 7.000024004259187, -2.355661091987557, 1.1322890661061344, -0.6468913267673587, 0.38753338537535237, -0.14285714285714285)}, ),
    },
    'radau': {
        'family': 'radau',
        'order': 13,
        'summary': "Radau IIA of variable order 5, 9, 13 (Hairer's RADAU): the order follows the Newton iteration's convergence; stiff, any tolerance",
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 8.0,
        'beta': 0.0,
        'q': 4,
        'expo_beta': 0.75,
        'radau': ({'s': 3, 'c': (0.1550510257216822, 0.6449489742783178, 1.0), 'gamma': 3.637834252744496, 'alpha': (2.6810828736277523,), 'beta': (3.0504301992474105,), 'T': ((0.09123239487089295, -0.1412552950209542, -0.030029194105147424), (0.241717932707107, 0.20412935229379994, 0.3829421127572619), (0.966048182615093, 1.0, 0.0),), 'Ti': ((4.325579890063155, 0.33919925181580984, 0.5417705399358749), (-4.178718591551905, -0.32768282076106237, 0.47662355450055044), (-0.5028726349457868, 2.571926949855605, -0.5960392048282249),), 'e': (-10.048809399827416, 1.382142733160749, -0.3333333333333333)}, {'s': 5, 'c': (0.05710419611451768, 0.2768430136381238, 0.5835904323689168, 0.8602401356562195, 1.0), 'gamma': 6.2867047517292765, 'alpha': (3.655694325463572, 5.70095329867179), 'beta': (6.543736899360077, 3.2102656003085497), 'T': ((0.012517586220501045, -0.010242047817908826, 0.04767387729029572, -0.011478515255229515, -0.01401985889287541), (0.0014916701518953824, 0.05017286451737106, -0.09433181918161143, -0.007668830749180163, 0.024708578426518527), (0.07298187638808715, -0.23053953404341795, 0.1027030453801259, 0.01939846399882895, 0.08180035370375117), (0.3800914400035681, 0.37789390224886127, 0.46674413033249434, 0.40760117128019907, 0.19968242788680252), (0.9219789736812105, 1.0, 0.0, 1.0, 0.0),), 'Ti': ((30.0415677215444, 13.865107856271413, 3.4800027747951856, -1.0320087978252634, 0.8043030450739899), (5.344186437834912, 4.593615567759161, -3.0363603234594243, 1.050660190231459, -0.27277861186429625), (3.748059807439805, -3.984965736343885, -1.0444156416080188, 1.1840985681379486, -0.44991777015678036), (-33.041880213519, -17.376953479063566, -0.17212906325400557, -0.09916977798254265, 0.5312281158383066), (-8.611443979875292, 9.699991409528808, 1.9147286396968743, 2.41869200608494, -1.0474634879353375),), 'e': (-27.78093394406464, 3.641478498049213, -1.2525477211691187, 0.5920031671845428, -0.2)}, {'s': 7, 'c': (0.029316427159784893, 0.1480785996684843, 0.3369846902811543, 0.5586715187715501, 0.7692338620300545, 0.9269456713197411, 1.0), 'gamma': 8.936832788405216, 'alpha': (4.378693561506806, 7.14105521918764, 8.511834825102946), 'beta': (10.169693283795011, 6.623045922639276, 3.281013624325059), 'T': ((0.0021537546273105264, 0.021567551351320772, 0.008783567925144144, -0.004055161452331024, 0.004427232753268285, -0.0012386461879528741, -0.0027606174805438525), (-0.0016000250778804286, -0.03813164813441155, -0.021525560594006874, 0.00841556827655959, -0.00403194957022455, -6.666635339396339e-05, 0.00318547482516621), (0.004059107301947683, 0.05739650893938172, 0.05885052920842679, -0.008560431061603433, -0.006923212665023909, -0.0023521809829433384, 0.00041690777252975626), (0.015750488079376845, -0.03821469359696835, -0.16573681127294385, -0.03737124230238446, 0.00823900729850772, 0.0031150711523461752, 0.025116604913438822), (0.11297766102422081, -0.2491742124652637, 0.27356330579866234, 0.0053667613791817705, 0.19321111610126201, 0.10171773248171515, 0.09504502035604623), (0.4583810431839315, 0.5315846490836285, 0.4863228366175729, 0.5265742264584493, 0.27553439498962584, 0.5217519452747653, 0.1280719446355439), (0.8813915783538184, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0),), 'Ti': ((258.13192631998226, 189.0737630813985, 49.08731481793013, 4.110647469661428, 4.053447889315564, -3.112755366607346, 1.6467749135584446), (-3.007390169451292, -11.015866078765772, 1.4877994561316563, 2.1303881595592826, -1.8161410868175656, 1.134325587895161, -0.41469904594330353), (-8.441963188321084, -0.650525274057515, 6.9406707303698765, -3.2050475255978985, 1.0712809435464785, -0.3548507491216222, 0.09198549132786554), (74.6783322350227, 87.40858897990081, 4.024158737379998, -3.714806315158364, -3.4300939859823174, 2.6966048097653124, -0.9386927436075462), (58.356528851906575, -10.06877395780018, -30.36638884256667, -1.020020865184866, -0.11241750037842496, 1.8906408310003777, -0.9716486393831483), (-299.1862480282521, -243.04074536874478, -48.77710407803787, -2.0386719057419342, 1.673560239861085, -1.0873740320571061, 0.9019382492960993), (-93.0765028974353, 23.881631056281144, 39.278880730813846, 14.38891568549108, -3.5104383993993613, 4.8632848855661805, -2.2464827295912397),), 'e': (-54.374436894128614, 7.000024004259187, -2.355661091987557, 1.1322890661061344, -0.6468913267673587, 0.38753338537535237, -0.14285714285714285)}, ),
    },
    'auto': {
        'family': 'auto',
        'order': 5,
        'summary': 'dopri5 until its stiffness test fires, then radau (variable order) for the rest of the run',
        'safe': 0.9,
        'fac_min': 0.2,
        'fac_max': 10.0,
        'beta': 0.0,
        'q': 5,
        'expo_beta': 0.75,
        'explicit': 'dopri5',
        'stiff': 'radau',
    },
}
SOLVERS = tuple(_METHODS)
_SOLVER_LIST = 'euler, rk4, dopri5, vern7, dop853, ros2, rodas4, radau5, rodas5p, radau9, radau13, radau or auto'
