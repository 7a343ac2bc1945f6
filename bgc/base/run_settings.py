"""A run's settings (RunSettings: the one type for them, from the scene's defaults to what a
generated program is started with), the checks on them, and the choices the command line
offers.  Light on purpose (the standard library and bgc.base.solvers only, no SymPy, no numpy): the
command line's help, its warm path (bgc.execute.warm) and the API all read it, and a warm
`bgc simulate` must not pay for the compiler's imports."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields, replace

from . import solvers
from .resources import MAX_OUTPUT_ROWS

ALGEBRA = ("auto", "symbolic", "numeric")  # how algebraic blocks are solved (bgc.middle.reduce)
BACKENDS = ("c", "vm", "python")  # what runs a simulation (vm: bgc/codegen/vm.py, the interpreter)
SWEEP_BACKENDS = ("c", "python")  # what runs a sweep's batches
TARGETS = ("c", "python", "fmu", "embedded")  # what `compile` writes (fmu: bgc/codegen/fmu.py;
#                                               embedded: bgc/codegen/embedded.py)
FORMATS = ("text", "latex")  # what `equations` prints
SIMULATE_OPTIONS = ("t_end", "dt", "solver", "rtol", "atol", "step", "params", "project_initial",
                    "max_steps", "allow_inconsistent", "max_step", "event_rows", "events")


def choice(name: str, value, allowed):
    """ValueError, naming the allowed values, for an argument that is not one of them."""
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, allowed))}, "
                         f"not {value!r}")


def exclusive(project_initial, allow_inconsistent):
    """ValueError if both ways of treating inconsistent initial values are asked for."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")


@dataclass(frozen=True)
class RunSettings:
    """Everything that decides a run, in one value: the scene's numbers (a scene's defaults are
    a RunSettings, compiled into its program; bgc.ir.Program.scene is one), and the options a
    run gives over them (`with_options`, by dataclasses.replace).  The first seven fields are
    the scene's, in the order the IR has always built them."""

    t0: float
    t_end: float
    dt: float
    solver: str
    rtol: float
    atol: float
    step: float | None = None  # the fixed step; None: dt
    max_steps: int | None = None  # between two output times; None: the program's (100000)
    params: tuple[tuple[str, float], ...] = ()  # parameter overrides, in the order given
    project_initial: bool = False
    allow_inconsistent: bool = False
    scene: str | None = None  # the scene's name (reports; not a run option)
    max_step: float | None = None  # every solver's largest step (a scene's hmax)
    event_rows: bool = False  # two rows at each event: its left and right limits
    events: str | None = None  # the event log's file (t,event,change)
    input_files: tuple[str, ...] = ()  # CSV files of the inputs' data (--input)
    input_data: tuple = ()  # ((name, (t, ...), (u, ...)), ...): the inputs' data given as
    #                         numbers (the API's inputs=)
    error_states: int | None = None  # the adaptive solvers' error control weighs the first
    #   error_states states only (bgc periodic's Newton runs: the states, not their
    #   sensitivities); None: all.  Not a simulate option.

    def with_options(self, **options) -> RunSettings:
        """These settings with the options given (None: keep this one's); params a dict."""
        given = {k: v for k, v in options.items() if v is not None}
        if "params" in given:
            given["params"] = tuple(dict(given["params"]).items())
        for flag in ("project_initial", "allow_inconsistent", "event_rows"):
            if flag in given:
                given[flag] = bool(given[flag])
        return replace(self, **given)

    def options(self, defaults: RunSettings) -> dict:
        """What these settings change against a program's own (`defaults`, the scene it was
        compiled with), as the keyword arguments of the generated module's simulate().  Only
        the changes, so that a run with the scene's settings starts the program exactly as it
        always has."""
        changed = [f.name for f in fields(self) if f.name not in ("t0", "scene")
                   and getattr(self, f.name) != getattr(defaults, f.name)]
        out = {name: getattr(self, name) for name in changed}
        if "params" in out:
            out["params"] = dict(self.params)
        if "input_files" in out:
            out["input"] = list(out.pop("input_files"))
        if "input_data" in out:
            out["inputs"] = {name: (t, u) for name, t, u in out.pop("input_data")}
        return out

    def args(self, defaults: RunSettings) -> list[str]:
        """The generated program's command line for these settings (see options)."""
        return run_args(**self.options(defaults))


def parameter_overrides(given, names) -> tuple[tuple[str, float], ...]:
    """Parameter overrides ({name: value}) checked against the program's parameters, `names`
    (in the order the message lists them): the one check of -p and params=."""
    for name in given or {}:
        if name not in names:
            raise ValueError(f"unknown parameter {name!r} (parameters: "
                             f"{', '.join(names) or 'none'})")
    return tuple((given or {}).items())


def run_args(t_end=None, dt=None, solver=None, rtol=None, atol=None, step=None, params=None,
             project_initial=False, max_steps=None, allow_inconsistent=False, max_step=None,
             event_rows=False, events=None, input=None, inputs=None,
             error_states=None) -> list[str]:
    """The generated program's command line for these options (None: the program's own)."""
    args = []
    for flag, value in (("--t-end", t_end), ("--dt", dt), ("--solver", solver),
                        ("--rtol", rtol), ("--atol", atol), ("--step", step),
                        ("--max-steps", max_steps), ("--max-step", max_step),
                        ("--error-states", error_states),
                        ("--events", None if events is None else os.fspath(events))):
        if value is not None:
            args += [flag, repr(value) if isinstance(value, float) else str(value)]
    for name, value in (params or {}).items():
        args += ["-p", f"{name}={float(value)!r}"]
    if project_initial:
        args.append("--project-initial")
    if allow_inconsistent:
        args.append("--allow-inconsistent")
    if event_rows:
        args.append("--event-rows")
    if inputs:
        raise ValueError("inputs given as numbers are written to files first (bgc.execute.runner)")
    for path in input or ():
        args += ["--input", os.fspath(path)]
    return args


def input_data(inputs) -> tuple:
    """The API's inputs= ({name: (t, values)}) as RunSettings.input_data, checked (ValueError,
    TypeError for people): t non-decreasing (a repeated t is a jump: input_order), as many
    values, finite numbers."""
    if not isinstance(inputs, dict):
        raise TypeError("inputs must be a dict of input names to (t, values)")
    out = []
    for name, data in inputs.items():
        try:
            t, u = data
            t = tuple(float(v) for v in t)
            u = tuple(float(v) for v in u)
        except (TypeError, ValueError):
            raise TypeError(f"the data of input {name!r} is a pair (t, values) of sequences "
                            "of numbers") from None
        if not t or len(t) != len(u):
            raise ValueError(f"input {name!r}: t and the values must be as many, at least one")
        if not all(math.isfinite(v) for v in t + u):
            raise ValueError(f"input {name!r}: the data must be finite numbers")
        k = input_order(t)
        if k is not None:
            raise ValueError(f"input {name!r}: {input_order_problem(t, k, f'at t[{k}]')}")
        out.append((str(name), t, u))
    return tuple(out)


def input_order(ts, k: int | None = None) -> int | None:
    """The first index from k on (else from 1) where an input's times break their order (None:
    none): t does not decrease, and a repeated t is a jump, two samples, never three (as
    the runtimes check it: runtime.py's _input_order, main.c's bgc_input_rows)."""
    for k in range(1, len(ts)) if k is None else (k,) if k >= 1 else ():
        if ts[k] < ts[k - 1] or (k >= 2 and ts[k] == ts[k - 1] == ts[k - 2]):
            return k
    return None


def input_order_problem(ts, k: int, at: str) -> str:
    """What is wrong at index k (input_order), there being `at` ("here": in a file's row)."""
    if ts[k] < ts[k - 1]:
        return f"t decreases {at} (t does not decrease from row to row; a repeated t is a jump)"
    return f"the same t a third time {at} (a jump is two rows of the same t)"


def input_file_problem(path: str, names) -> str | None:
    """What is wrong with an --input file for a model whose inputs are `names` (None: it
    is fine): a header with a column t and one per input given, rows of finite numbers, t
    non-decreasing (input_order)."""
    import csv
    try:
        with open(path, encoding="utf-8", newline="") as f:
            rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        return f"cannot read the input file '{path}': {getattr(error, 'strerror', None) or error}"
    if not rows:
        return f"{path}: the file is empty (a header t,NAME,... then rows of numbers)"
    head = [h.strip() for h in rows[0]]
    if "t" not in head:
        return f"{path}: the header has no column 't'"
    for name in head:
        if name != "t" and name not in names:
            return (f"{path}: '{name}' is not an input of the model (its inputs: "
                    f"{', '.join(names) or 'none'})")
    if len(set(head)) != len(head):
        return f"{path}: a column is named twice in the header"
    k, times = head.index("t"), []
    for n, row in enumerate(rows[1:], 2):
        if len(row) != len(head):
            return f"{path}: row {n} has {len(row)} fields, the header {len(head)}"
        for cell in row:
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                return f"{path}: row {n}: '{cell.strip()}' is not a finite number"
        times.append(float(row[k]))
        if input_order(times, len(times) - 1) is not None:
            return f"{path}: row {n}: {input_order_problem(times, len(times) - 1, 'here')}"
    if len(rows) < 2:
        return f"{path}: no rows of data"
    return None


def input_file_columns(path: str) -> list[str]:
    """The columns an --input file's header names ([] if it cannot be read)."""
    import csv
    try:
        with open(path, encoding="utf-8", newline="") as f:
            return [h.strip() for h in next(csv.reader(f), [])]
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def input_file_data(path: str) -> dict:
    """An --input file that input_file_problem passed, as the API's inputs=: {name: (t,
    values)}, one per column besides t."""
    import csv
    with open(path, encoding="utf-8", newline="") as f:
        rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    head = [h.strip() for h in rows[0]]
    k = head.index("t")
    t = tuple(float(r[k]) for r in rows[1:])
    return {name: (t, tuple(float(r[j]) for r in rows[1:]))
            for j, name in enumerate(head) if j != k}


def check_run_options(options: dict):
    """ValueError for a run setting that is wrong whatever the model: an unknown solver, a
    tolerance, interval or step that is not a positive finite number, a non-finite end time
    or parameter value.  What depends on the model (the end time against the start, the
    parameters' names) is checked once it is built."""
    if options.get("solver") is not None:
        choice("solver", options["solver"], solvers.NAMES)
    events = options.get("events")
    if events is not None and not isinstance(events, (str, os.PathLike)):
        raise TypeError("events must be a file name (the event log's CSV)")
    for key in ("rtol", "atol", "dt", "step", "t_end", "max_step"):
        value = options.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or (key != "t_end" and not value > 0):
            what = "a finite number" if key == "t_end" else "a positive finite number"
            raise ValueError(f"{key} must be {what}, not {value!r}")
    steps = options.get("max_steps")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int)
                              or not 0 <= steps <= 10**15):
        raise ValueError(f"max_steps must be a whole number from 0 (no limit) to 1e15, "
                         f"not {steps!r}")
    exclusive(options.get("project_initial"), options.get("allow_inconsistent"))
    params = options.get("params") or {}
    if not isinstance(params, dict):
        raise TypeError("params must be a dict of parameter names to numbers")
    for name, value in params.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ValueError(f"parameter {name!r} must be a finite number, not {value!r}")


def run_span_problem(settings, t_end=None, dt=None) -> str | None:
    """What is wrong with a run to t_end every dt (None: the scene's) from the scene's start
    (settings: anything with t0, t_end and dt), or None."""
    t_end = settings.t_end if t_end is None else t_end
    dt = settings.dt if dt is None else dt
    if not t_end > settings.t0:
        return f"the end time {t_end!r} is not after the start time {settings.t0!r}"
    if not (t_end - settings.t0) / dt <= MAX_OUTPUT_ROWS:
        return f"more than {MAX_OUTPUT_ROWS:.0e} output rows: the output interval is too small"
    return None
