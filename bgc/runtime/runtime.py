# bgc/runtime/runtime.py -- the Python runtime's first part; its C twin is runtime.c (with api.h,
# whose contract the part's head states in Python): the contract with the model part and the
# neutral model, errors, the model functions' helpers (waves, inputs, tables, libm), the
# workspace, the algebraic blocks' solves, the public functions, constraints and settings.
# The Python runtime is one module made of the parts bgc.codegen.emit.PY_RUNTIME lists, in its
# order, each less its header (its lines up to the first blank line, as these), joined by two
# blank lines (python_runtime()); the tests load that text (tests/helpers.py, pyruntime()).

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
