"""Lookup tables: `table(FILE.csv | [[x, y], ...], X, interp = ..., extrapolate = ...,
column = "name")` (docs/language.md, "Tables").

The resolve stage reads a table's data here, at compile time, and registers it: the model's
expression becomes `Table(k, X, seg, 0)` (bgc.ir), k the table's number, seg -1 for a table
of anything but t (the runtime searches X's interval at every call) or, for a table of t, a
discrete value (bgc.front.events) holding the interval, set at events: each breakpoint is a time
event, so the solver steps onto it and never integrates across a jump or a kink.

A table of n rows has n + 1 pieces, each a cubic polynomial in dx = X - origin:

    piece 0          X < x[0]                origin x[0]     the left extrapolation
    piece i          x[i-1] <= X < x[i]      origin x[i-1]   the interpolation (0 < i < n)
    piece n          X >= x[n-1]             origin x[n-1]   the right extrapolation

with coefficients (a, b, c, d): value a + dx (b + dx (c + dx d)).  The coefficients are
computed here, once, in exact rational arithmetic from the doubles of the data (each rounded
to the nearest double at the end), so that they do not depend on the order of operations,
and embedded in the generated code; both runtimes evaluate the same Horner form.

  linear  a = y[i-1], b = (y[i] - y[i-1]) / (x[i] - x[i-1])
  step    a = y[i-1] (the interval's left row), b = c = d = 0
  cubic   the monotone piecewise cubic Hermite interpolant of Fritsch and Carlson, with
          Fritsch and Butland's slopes (SciPy's PchipInterpolator): C1, no overshoot
          between rows (a monotone table stays monotone), each slope from its neighbours only
  hold    extrapolation: the end row's value
  linear  extrapolation: the end's tangent (an end interval's slope; step: 0)
  error   extrapolation: the run stops where X leaves [x[0], x[n-1]]: an event indicator
          (bgc.ir.TableGuard, how far X is inside) located like any other, and the event
          there fails (bgc.front.events.update_stores); the value itself is held

A repeated x is a jump: the interval between the two rows is empty, the row before it gives
the value on the left, the row after it on the right (and a cubic table is two independent
curves, one each side).
"""
from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from fractions import Fraction

from ..base.diagnostics import Note, Origin, Span, fail

INTERP = ("linear", "step", "cubic")
EXTRAPOLATE = ("hold", "linear", "error")
MAX_TABLE_BYTES = 8 << 20  # 8 MiB: a larger table file is refused, not read
MAX_TABLE_ROWS = 100_000  # rows of one table (a file's, or a literal's)
MAX_TABLES = 1_000  # tables of one model


@dataclass(frozen=True)
class TableData:
    name: str  # what reports call it: the file, or the signal
    x: tuple[float, ...]  # the breakpoints, non-decreasing
    y: tuple[float, ...]
    interp: str
    extrapolate: str
    origins: tuple[float, ...]  # per piece (n + 1)
    coefficients: tuple[float, ...]  # per piece a, b, c, d (4 (n + 1))
    time: bool  # a table of t: its breakpoints are time events
    file: str = ""  # the file its rows were read from, as opened ("" for rows in the model):
    #                 a warm run checks it is unchanged (bgc.execute.warm)

    @property
    def rows(self) -> int:
        return len(self.x)

    @property
    def text(self) -> str:
        return f"table({self.name}, {'t' if self.time else 'X'}, interp = {self.interp}, " \
               f"extrapolate = {self.extrapolate})"


# ---------------------------------------------------------------- reading


def read_csv(path: str, shown: str, column: str | None, span: Span,
             column_span: Span | None) -> tuple[list[float], list[float], list[int], str]:
    """x, y, the line of each row and the file's text, from a CSV file with a header row;
    located errors (at the file's row, with a note at the model's table)."""
    here = Note(span, "the table is read here")
    try:
        size = os.stat(path).st_size
    except OSError as e:
        fail(span, f"cannot read the table file '{shown}': {e.strerror or e}")
    if size > MAX_TABLE_BYTES:
        fail(span, f"the table file '{shown}' is too large ({size} bytes; the limit is "
                   f"{MAX_TABLE_BYTES})")
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_TABLE_BYTES + 1)
        text = data.decode("utf-8-sig")
    except OSError as e:
        fail(span, f"cannot read the table file '{shown}': {e.strerror or e}")
    except UnicodeDecodeError:
        fail(span, f"the table file '{shown}' is not UTF-8 text")
    origin = Origin(shown, text, file=True)

    def at(line: int, message: str):
        fail(Span(line, 1, line, 2, origin), message, here)

    lines = text.splitlines()
    rows = [(k + 1, line) for k, line in enumerate(lines) if line.strip()]
    if not rows:
        fail(span, f"the table file '{shown}' is empty (a header row, then rows of x, y)")
    if len(rows) - 1 > MAX_TABLE_ROWS:
        fail(span, f"the table file '{shown}' has {len(rows) - 1} rows; the limit is "
                   f"{MAX_TABLE_ROWS}")
    try:
        parsed = [(k, next(csv.reader(io.StringIO(line)))) for k, line in rows]
    except csv.Error as e:
        fail(span, f"the table file '{shown}' is not CSV: {e}")
    (head_line, header), body = parsed[0], parsed[1:]
    header = [h.strip() for h in header]
    if len(header) < 2:
        at(head_line, f"a table file has a header row of at least two columns (x, then y), "
                      f"not {', '.join(header) or 'an empty one'}")
    col = 1
    if column is not None:
        if column not in header[1:]:
            fail(column_span or span, f"the table file '{shown}' has no column '{column}' (its "
                                      f"columns: {', '.join(header)})")
        col = header.index(column, 1)
    xs, ys, where = [], [], []
    for line, cells in body:
        if len(cells) != len(header):
            at(line, f"this row has {len(cells)} fields, the header {len(header)}")
        values = []
        for k in (0, col):
            try:
                v = float(cells[k])
            except ValueError:
                at(line, f"'{cells[k].strip()}' is not a number (column '{header[k]}')")
            if not math.isfinite(v):
                at(line, f"'{cells[k].strip()}' is not a finite number (column '{header[k]}')")
            values.append(v)
        xs.append(values[0])
        ys.append(values[1])
        where.append(line)
    if len(xs) < 2:
        fail(span, f"the table file '{shown}' has {len(xs)} row{'s' * (len(xs) != 1)}; a table "
                   "needs at least two")
    for k in range(1, len(xs)):
        if xs[k] < xs[k - 1]:
            at(where[k], f"x decreases here ({xs[k]!r} after {xs[k - 1]!r}): a table's x is "
                         "non-decreasing (a repeated x is a jump)")
        if k >= 2 and xs[k] == xs[k - 1] == xs[k - 2]:
            at(where[k], f"x = {xs[k]!r} a third time: a jump is two rows of the same x")
    return xs, ys, where, text


def check_rows(xs, ys, spans, span: Span):
    """The same checks of a literal table's rows (spans: each row's)."""
    if len(xs) < 2:
        fail(span, "a table needs at least two rows [x, y]")
    for k in range(1, len(xs)):
        if xs[k] < xs[k - 1]:
            fail(spans[k], f"x decreases here ({xs[k]!r} after {xs[k - 1]!r}): a table's x is "
                           "non-decreasing (a repeated x is a jump)")
        if k >= 2 and xs[k] == xs[k - 1] == xs[k - 2]:
            fail(spans[k], f"x = {xs[k]!r} a third time: a jump is two rows of the same x")


# ---------------------------------------------------------------- coefficients


def _pchip_slopes(x: list, y: list) -> list:
    """Fritsch-Butland slopes of one strictly increasing run of rows (Fractions), as SciPy's
    PchipInterpolator computes them (its end slopes too)."""
    n = len(x)
    h = [x[k + 1] - x[k] for k in range(n - 1)]
    m = [(y[k + 1] - y[k]) / h[k] for k in range(n - 1)]
    if n == 2:
        return [m[0], m[0]]
    d = [Fraction(0)] * n
    for k in range(1, n - 1):
        if m[k - 1] == 0 or m[k] == 0 or _sign(m[k - 1]) != _sign(m[k]):
            continue
        w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
        d[k] = (w1 + w2) / (w1 / m[k - 1] + w2 / m[k])
    d[0] = _edge(h[0], h[1], m[0], m[1])
    d[n - 1] = _edge(h[n - 2], h[n - 3], m[n - 2], m[n - 3])
    return d


def _edge(h0, h1, m0, m1):
    """SciPy's one-sided three-point end slope, made shape-preserving."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if _sign(d) != _sign(m0):
        return Fraction(0)
    if _sign(m0) != _sign(m1) and abs(d) > abs(3 * m0):
        return 3 * m0
    return d


def _sign(v) -> int:
    return (v > 0) - (v < 0)


def build(name: str, xs, ys, interp: str, extrapolate: str, time: bool,
          file: str = "") -> TableData:
    """The table's pieces: origins and coefficients (module doc)."""
    n = len(xs)
    X = [Fraction(v) for v in xs]
    Y = [Fraction(v) for v in ys]
    zero = Fraction(0)
    pieces: list = [None] * (n + 1)  # interior pieces 1..n-1: (a, b, c, d)
    slope_at = [zero] * n  # the interpolant's derivative at each row (for the ends)
    runs, start = [], 0
    for k in range(1, n + 1):
        if k == n or X[k] == X[k - 1]:
            runs.append((start, k))
            start = k
    for lo, hi in runs:
        if hi - lo < 2:
            continue
        if interp == "cubic":
            d = _pchip_slopes(X[lo:hi], Y[lo:hi])
        for k in range(lo, hi - 1):
            h = X[k + 1] - X[k]
            s = (Y[k + 1] - Y[k]) / h
            if interp == "linear":
                pieces[k + 1] = (Y[k], s, zero, zero)
                slope_at[k] = slope_at[k + 1] = s
            elif interp == "step":
                pieces[k + 1] = (Y[k], zero, zero, zero)
            else:
                d0, d1 = d[k - lo], d[k + 1 - lo]
                pieces[k + 1] = (Y[k], d0, (3 * s - 2 * d0 - d1) / h, (d0 + d1 - 2 * s) / (h * h))
                slope_at[k], slope_at[k + 1] = d0, d1
    for k in range(1, n):  # the empty interval of a jump: never evaluated
        if pieces[k] is None:
            pieces[k] = (Y[k - 1], zero, zero, zero)
    linear = extrapolate == "linear"
    pieces[0] = (Y[0], slope_at[0] if linear else zero, zero, zero)
    pieces[n] = (Y[n - 1], slope_at[n - 1] if linear else zero, zero, zero)
    origins = (xs[0],) + tuple(xs[:n - 1]) + (xs[n - 1],)
    coefficients = tuple(float(c) for p in pieces for c in p)
    return TableData(name, tuple(float(v) for v in xs), tuple(float(v) for v in ys), interp,
                     extrapolate, tuple(float(v) for v in origins), coefficients, time, file)


# ---------------------------------------------------------------- evaluation (as the runtimes)


def piece(t: TableData, X: float) -> int:
    """The piece holding X: the number of breakpoints <= X (binary search, as bgc_table)."""
    lo, hi = 0, len(t.x)
    while lo < hi:
        mid = (lo + hi) // 2
        if t.x[mid] <= X:
            lo = mid + 1
        else:
            hi = mid
    return lo


def evaluate(t: TableData, X: float, order: int = 0) -> float:
    """The table's value (or its derivative of that order) at X, as the runtimes compute it."""
    if X != X:
        return math.nan
    s = piece(t, X)
    a, b, c, d = t.coefficients[4 * s:4 * s + 4]
    dx = X - t.origins[s]
    if order == 0:
        return a + dx * (b + dx * (c + dx * d))
    if order == 1:
        return b + dx * (2.0 * c + dx * (3.0 * d))
    if order == 2:
        return 2.0 * c + dx * (6.0 * d)
    return 6.0 * d if order == 3 else 0.0
