"""The embedded C target: Program -> {"NAME.h": ..., "NAME.c": ...} (docs/embedded.md).

One fixed step per call of NAME_step, no heap, no stdio, no mutable global: the caller owns the
state, parameter, input and output structs, every array is sized at compile time, and the only
work area of a step is a local array of a size fixed here.  The model part is the C emitter's
(bgc.codegen.emit: the same statements, printed by the same printer, in the same order), the
step is the fixed-step driver's (bgc/runtime/erk.c, bgc_fixed_step, on the grid t0 + k H of
drive.c with one step per output interval), so that in double the states and outputs after k
steps are the bytes `bgc simulate --solver S --step H --dt H` writes at t0 + k H.  With
--real float every value, coefficient and function is the float one (sinf, 2.0f, ...): the
same operations in the same order, rounded to float.  A model with events adds its event
functions and the fixed-step driver's event handling (drive.c's bgc_find_event, bgc_hidden,
the Hermite interpolant, the event iteration), the rest of an output interval stepped from an
event inside the same call, so that its rows are again simulate's bytes.  A Rosenbrock
method (ros2; rodas4, rodas5p) is the runtime's on fixed steps (bgc/runtime/stiff.c: f, df/dt
and the Jacobian from jvp at the step's start, I/(gamma h) - J factored with partial pivoting
in a local n x n array, one solve per stage), on simulate's grid t0 + k H over the run.
Inputs are the caller's samples at each step's end, held from there (the runtime's input
segments with slope 0, each sample a time event), as simulate reads an --input file whose
rows are those samples held between them.

What the target cannot run yet is refused before anything is written, with the place in the
model and what to change (check_supported)."""
from __future__ import annotations

import re

import sympy as sp

from .. import ir
from ..base import solvers
from ..base.diagnostics import ModelError, error
from ..ir import (FUNCTIONS, D, InputNext, InputPart, PeriodicNext, Program, SquareNext,
                  SquareWave, T, Table)
from ..ir.printers import CPrinter, float_literal
from . import emit

REALS = ("double", "float")
HELPERS = ("bgc_opaque", "bgc_sq", "bgc_min", "bgc_max", "bgc_sign", "bgc_heaviside",
           "bgc_square", "bgc_square_next", "bgc_periodic_next")  # emitted where used
EXPLICIT = ("euler", "rk4")  # the explicit fixed-step methods the target steps with
ROSENBROCK = tuple(s.name for s in solvers.SOLVER_LIST if s.family == "rosenbrock")
SOLVERS = EXPLICIT + ROSENBROCK  # the Rosenbrock methods always on fixed steps here
FLOAT_NEWTON_RTOL = 1e-5  # float: Newton's relative tolerance at least this
FLOAT_BAND_ULPS = 16  # float: a changed relation's band, in float's epsilons of |g|'s largest
MAX_TABLE_ROWS = 1024  # the most rows of a lookup table the target would carry (flash)
FAULTS = (("OK", 0, "the step was taken"),
          ("FAULT_NONFINITE", 1, "a derivative, state or output is not finite: the state is "
                                 "left as it was before the step"),
          ("FAULT_NEWTON", 2, "an algebraic block is singular, or its Newton iteration does "
                              "not converge within 50 iterations: the state is left as it was"))
ROSENBROCK_FAULTS = (("FAULT_SINGULAR", 5, "the Rosenbrock step's iteration matrix I/(gamma H) "
                                           "- J is singular: the state is left as it was"),)


EVENT_FAULTS = (("FAULT_EVENTS", 3, "the events do not settle: an event iteration of more than "
                                   "100 passes, 100 events in a row each within the time's "
                                   "resolution of the one before (Zeno), 1000 steps in a row "
                                   "cut short by an event (a sliding mode), or more than 1000 "
                                   "events in one step: the state is left as it was"),
                ("FAULT_TIME", 4, "the time no longer resolves the step (t / H beyond about "
                                  "1e14): the state is left as it was"))


class _EmbeddedPrinter(CPrinter):
    """CPrinter with the discrete values d in the step's work area (w->d: the state's copy
    that the step works on) rather than in the parameter struct, which the caller owns."""

    def _print_index(self, base, index):
        if base.name == D.name:
            return f"w->d[{index}]"
        return super()._print_index(base, index)


class _FloatPrinter(_EmbeddedPrinter):
    """CPrinter in single precision: float literals (2.0f) and libm's float functions (sinf);
    the layout, and so the operations and their order, are CPrinter's."""

    FUNCTION_NAMES = {**CPrinter.FUNCTION_NAMES,
                      **{f: f + "f" for f in FUNCTIONS
                         if CPrinter.FUNCTION_NAMES.get(f, f) == f},  # libm's, not bgc_max
                      "Abs": "fabsf"}

    _raw_time = False  # inside a time event's helper: t as the driver's double

    def _print(self, expr, **kwargs):
        if isinstance(expr, (sp.Rational, sp.Float)) or expr in (sp.pi, sp.E):
            return super()._print(expr, **kwargs) + "f"
        if expr == T and not self._raw_time:
            return "(bgc_real)t"
        if type(expr) in (SquareWave, SquareNext, PeriodicNext, InputPart, InputNext) \
                and not self._raw_time:
            self._raw_time = True  # (an edge in float is off by float's resolution at t)
            try:
                return super()._print(expr, **kwargs)
            finally:
                self._raw_time = False
        return super()._print(expr, **kwargs)

    def _print_power(self, expr):
        text = super()._print_power(expr)
        if expr.exp.is_Rational and expr.exp.is_negative and text.startswith("1.0/"):
            return "1.0f/" + text[4:]
        return text

    def _quotient(self, numer, denom):
        text = super()._quotient(numer, denom)
        return text if numer else "1.0f" + text[3:]

    def _print_call(self, expr):
        if type(expr).__name__ == "Heaviside" and len(expr.args) == 1:
            return f"bgc_heaviside({self._print(expr.args[0])}, 0.5f)"
        return super()._print_call(expr)

    def _print_pow_call(self, base, exp):
        return f"powf({base}, {exp})"


_DOUBLE_DECL = re.compile(r"^const double ")


def _typed(lines: list[str], name: str = "") -> list[str]:
    """The C emitter's temporaries (`const double wK = ...`) in the target's real type; those
    of next_time stay double (times: the driver's clock is a double whatever the real type)."""
    if name == "next_time":
        return lines
    return [_DOUBLE_DECL.sub("const bgc_real ", line) for line in lines]


def _functions(program: Program, solver: str = "rk4") -> tuple[str, ...]:
    """The model functions the target emits: rhs and outputs, a Rosenbrock method's jvp (the
    Jacobian's directional derivatives), and a model with events its indicators (events), its
    next time events (next_time) and one pass of its event iteration (update)."""
    return (("rhs", "outputs") + (("jvp",) if solver in ROSENBROCK else ())
            + (ir.EVENT_FUNCTIONS if program.events is not None else ()))


def workspace(program: Program, chunk_ops: int, solver: str = "rk4"):
    """The work area (in the state: a Newton block's last solution is its next start): the
    values that cross the chunks of a long model function (each chunk a function of its own),
    then each algebraic block's storage, as the C emitter lays them out, from offset 0."""
    layouts = {name: ir.layout(program.function(name).body, 0, chunk_ops)
               for name in _functions(program, solver)}
    top = max((len(lay.slot) for lay in layouts.values()), default=0)
    areas, ints = [], 0
    for bp in program.blocks:
        m, nnz = bp.lu.m, bp.lu.nnz
        save = top
        lu = save + nnz
        dense = lu + (0 if bp.lu.dense else nnz)
        b = dense + m * m
        areas.append(emit.BlockArea(save, lu, dense, b, b + m, b + 2 * m, b + 3 * m,
                                     b + 4 * m, b + 5 * m, ints, ints + m))
        top = b + 6 * m
        ints += m + 1
    return emit.Workspace(0, 0, 0, 0, 0, tuple(areas), top, ints, layouts)


_FLOAT_LITERAL = re.compile(r"(?<![\w.\[])(\d+\.\d*(?:e[-+]?\d+)?|\d+e[-+]?\d+)(?![\w.])")


def _single(lines: list[str]) -> list[str]:
    """The C emitter's unrolled LU lines in float: float literals and fabsf."""
    return [_FLOAT_LITERAL.sub(r"\1f", line).replace("fabs(", "fabsf(") for line in lines]


# ---------------------------------------------------------------- refusals


def _refuse(span, message: str):
    raise ModelError([error(span, f"embedded target: {message}")])


def check_supported(program: Program, graph, scene, solver: str, real: str = "double",
                    step: float | None = None) -> None:
    """ModelError, located, for what the embedded target does not run (yet): an adaptive
    solver, Newton blocks in float, a scene's max_step below the step, lookup tables (one of
    more than MAX_TABLE_ROWS rows named so), and what its Rosenbrock step does not run."""
    sc = program.scene
    span = scene.solver[2] if scene is not None and scene.solver else None
    # a Rosenbrock method named by the scene without a step is an adaptive run in simulate
    if solver not in SOLVERS or (solver in ROSENBROCK and scene is not None and step is None
                                 and sc.step is None):
        family = "adaptive" if solvers.get(solver).adaptive else "not a fixed-step method"
        _refuse(span, f"the solver '{solver}' is {family}; the target takes one fixed step "
                      f"per call: give --solver rk4 or --solver euler (or --solver ros2 for a "
                      f"stiff model), and --step H")
    h = step if step is not None else (sc.step if sc.step is not None else sc.dt)
    if sc.max_step is not None and h > sc.max_step:
        span = scene.solver[2] if scene is not None and scene.solver else None
        _refuse(span, f"the scene's max_step {sc.max_step:g} is below the step {h:g}, "
                      f"which bgc simulate would split: give --step {sc.max_step:g} or less")
    newton = [bp for bp in program.blocks if bp.method == "newton"]
    if newton and real == "float":
        _refuse(None, f"algebraic block {newton[0].index} ({', '.join(newton[0].unknowns[:4])}) "
                      f"is solved by Newton's method, which the target does not run in float "
                      f"yet: use --real double")
    for k, tab in enumerate(program.tables):
        span = _table_span(graph, k)
        if tab.rows > MAX_TABLE_ROWS:
            _refuse(span, f"the table '{tab.name}' has {tab.rows} rows, more than the "
                          f"{MAX_TABLE_ROWS} the target carries in flash: resample it to "
                          f"{MAX_TABLE_ROWS} rows or fewer")
        _refuse(span, f"lookup tables ('{tab.name}') are not supported yet")
    if solver in ROSENBROCK:
        _check_rosenbrock(program, solver, real, span)


def _check_rosenbrock(program: Program, solver: str, real: str, span) -> None:
    """What the target's Rosenbrock step does not run (yet): events (simulate locates them on
    the method's own dense output and restarts it), a large model's sparse iteration matrix,
    and in float a right side that reads t (its df/dt is a forward difference over double's
    sqrt(eps) of t, below float's resolution)."""
    if not program.has_jacobian:
        raise ValueError("a Rosenbrock method needs the program's jvp (build it with jacobian)")
    if program.events is not None:
        _refuse(span, f"the solver '{solver}' with events (when-blocks, switched elements, "
                      f"impacts, time events, an input's samples) is not supported yet: give "
                      f"--solver rk4 or --solver euler")
    if program.jacobian.lu is not None:
        _refuse(span, f"the solver '{solver}' on a model of {len(program.states)} states, "
                      f"whose iteration matrix bgc simulate factors by its sparse plan, is not "
                      f"supported yet: give --solver rk4 or --solver euler")
    if real == "float" and emit.reads_time(program.function("rhs")):
        _refuse(span, f"the solver '{solver}' in float on a model whose laws read the time "
                      f"t: its df/dt, a forward difference over sqrt(DBL_EPSILON t), is below "
                      f"float's resolution: use --real double")


def _table_span(graph, k: int):
    """The place of the first signal or element that reads table k (Table(k, ...)), or
    None."""
    for item in (*graph.signals, *graph.elements):
        for ex in (getattr(item, "expr", None), getattr(item, "value", None)):
            v = getattr(ex, "value", None)
            if isinstance(v, sp.Basic) and any(int(f.args[0]) == k for f in v.atoms(Table)):
                return ex.span
    return None


# ---------------------------------------------------------------- emission


def emit_embedded(program: Program, real: str = "double", solver: str = "rk4",
                  step: float | None = None, chunk_ops: int = ir.CHUNK_OPS) -> dict[str, str]:
    """{"NAME.h": the API, "NAME.c": the model and its step} for a program check_supported
    accepted; step: H (default: the scene's step, else its output interval)."""
    if real not in REALS:
        raise ValueError(f"real must be one of {', '.join(REALS)}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(SOLVERS)}")
    sc = program.scene
    h = step if step is not None else (sc.step if sc.step is not None else sc.dt)
    if not (h > 0.0 and h != float("inf")):
        raise ValueError("the step must be positive and finite")
    fields = emit.c_param_fields(tuple(p.name for p in program.params))
    printer = (_FloatPrinter if real == "float" else _EmbeddedPrinter)(
        len(program.states), fields, program.n_consts)
    ws = workspace(program, chunk_ops, solver)
    writer = emit.Writer(program, ws, printer, "c")
    model = {}
    for name in _functions(program, solver):
        f = emit.function_context(writer, name, "out")
        f["chunks"] = [_typed(lines, name) for lines in f["chunks"]]
        for e in f["evals"]:
            for key in ("body", "residuals", "tangents", "jacobian"):
                e[key] = _typed(e[key])
        model[name] = f
    blocks = emit.common_context(program, ws, emit.c_string_literal, True)["blocks"]
    for b in blocks:
        if b["unrolled"]:
            for key in ("factor_lines", "lsolve_lines"):
                lines = _typed(b["unrolled"][key])
                b["unrolled"][key] = _single(lines) if real == "float" else lines
    defaults = [printer.doprint(p.default) for p in program.params]
    consts = _typed(emit.plain_lines(writer, "consts", "p->c"))
    init = _typed(emit.plain_lines(writer, "init", "x0"))
    code = "\n".join([*defaults, *consts, *init] + [line for f in model.values()
                                                   for lines in f["chunks"] for line in lines]
                     + [line for f in model.values() for e in f["evals"] for key in
                        ("body", "residuals", "tangents", "jacobian") for line in e[key]])
    if blocks:
        code += "\nbgc_max("
    tab = solvers.get(solver).tableau
    lit = (lambda v: float_literal(v) + "f") if real == "float" else float_literal
    ident = emit.identifier(program.name)
    context = {
        "ident": ident, "NAME": ident, "guard": f"BGC_EMBEDDED_{ident.upper()}_H",
        "model_name": emit.c_string_literal(program.name),
        "real": real, "solver": solver, "step": float_literal(h),
        "t0": float_literal(sc.t0),
        "n_states": len(program.states), "n_outputs": len(program.outputs),
        "n_params": len(program.params), "n_consts": program.n_consts,
        "n_inputs": len(program.inputs), "inputs": bool(program.inputs),
        "input_names": [i.name for i in program.inputs],
        "work": max(ws.doubles, 1), "ints": max(ws.ints, 1),
        "blocks": blocks,
        # Newton's relative tolerance: the scene's, at least float's resolution in float; atol
        # the scene's in both (the model's own decisions read it: a contact's rest, a switch's
        # dead band, which float would otherwise take differently from double)
        "rtol": lit(max(sc.rtol, FLOAT_NEWTON_RTOL) if real == "float" else sc.rtol),
        "atol": lit(sc.atol),
        "eps": "FLT_EPSILON" if real == "float" else "DBL_EPSILON",
        # a changed relation's band, relative to its indicator's largest magnitude: simulate's
        # 1e-12 in double; in float what float resolves of the indicator
        "band": lit(1e-12) if real == "double" else f"({FLOAT_BAND_ULPS:g}.0f * FLT_EPSILON)",
        "fabs": "fabsf" if real == "float" else "fabs",
        "sqrt": "sqrtf" if real == "float" else "sqrt",
        "floor": "floorf" if real == "float" else "floor",
        "states": [emit.c_string_literal(s) for s in program.states],
        "outputs": [emit.c_string_literal(o) for o in program.outputs],
        "params": [emit.c_string_literal(p.name) for p in program.params],
        "param_fields": fields,
        "param_defaults": defaults, "consts": consts, "init": init,
        "model": model,
        "autonomous": not emit.reads_time(program.function("rhs")),
        "stages": tab.stages,
        "tab_c": ", ".join(lit(v) for v in tab.c),
        "tab_a": ", ".join(lit(v) for v in emit.square(tab.a, tab.stages)) or lit(0.0),
        "tab_b": ", ".join(lit(v) for v in getattr(tab, "b", ())),
        "faults": FAULTS + (EVENT_FAULTS if program.events is not None else ())
                  + (ROSENBROCK_FAULTS if solver in ROSENBROCK else ()),
        "family": "rosenbrock" if solver in ROSENBROCK else "erk",
        "ros": _rosenbrock_context(tab, lit) if solver in ROSENBROCK else None,
        "jac": _jacobian_context(program) if solver in ROSENBROCK else None,
        "code": code, "events": emit.events_context(program, emit.c_string_literal),
        "helpers": [name for name in HELPERS if f"{name}(" in code],
        "flit": lit,
    }
    return {f"{ident}.h": emit.render("embedded/model.h.j2", context),
            f"{ident}.c": emit.render("embedded/model.c.j2", context)}


def _rosenbrock_context(tab, lit) -> dict:
    """A Rosenbrock tableau's arrays as C initialisers (the nodes c in double: times)."""
    square = lambda rows: ", ".join(lit(v) for v in emit.square(rows, tab.stages))  # noqa: E731
    return {"c": ", ".join(float_literal(v) for v in tab.c),
            "d": ", ".join(lit(v) for v in tab.d), "a": square(tab.a), "C": square(tab.C),
            "m": ", ".join(lit(v) for v in tab.m), "gamma": float_literal(tab.gamma)}


def _jacobian_context(program: Program) -> dict:
    """The Jacobian's colours and columns as the C emitter flattens them (bgc_jac_*)."""
    jac = program.jacobian
    color_ptr, color_cols, col_ptr, col_rows = [0], [], [0], []
    for cols in jac.colors:
        color_cols += cols
        color_ptr.append(len(color_cols))
    for rows in jac.columns:
        col_rows += rows
        col_ptr.append(len(col_rows))
    text = lambda v: ", ".join(map(str, v)) or "0"  # noqa: E731
    return {"ncolors": len(jac.colors), "color_ptr": text(color_ptr),
            "ncolor_cols": len(color_cols), "color_cols": text(color_cols),
            "col_ptr": text(col_ptr), "ncol_rows": len(col_rows), "col_rows": text(col_rows)}


def _struct_bytes(fields) -> int:
    """The bytes of a struct of (size, count) fields in order, each aligned to its size (the
    host's natural alignment), padded to its largest."""
    offset, align = 0, 1
    for size, count in fields:
        offset = -(-offset // size) * size + size * count
        align = max(align, size)
    return -(-offset // align) * align


def memory(program: Program, real: str = "double", solver: str = "rk4",
           chunk_ops: int = ir.CHUNK_OPS) -> dict:
    """The bytes of the caller's structs (natural alignment, 8-byte long) and of one step's
    local arrays (the stages, their argument, the outputs, and the state's copy that the step
    works on; a Rosenbrock method also f, df/dt, the iteration matrix and its pivots, and the
    Jacobian's direction and product; with events also the step's end, the located state, the
    interpolant's two derivatives and the indicators), for --report."""
    size = 8 if real == "double" else 4
    n, m = max(len(program.states), 1), max(len(program.outputs), 1)
    ws = workspace(program, chunk_ops, solver)
    fields = [(8, 1), (size, n)] + ([(size, n)] if real == "float" else []) + [
        (size, max(ws.doubles, 1)), (4, max(ws.ints, 1))]  # (float: x's compensation)
    ev = program.events
    if ev is not None:
        g = max(ev.indicators, 1)
        fields += [(8, 3), (8, 2), (4, 1), (size, max(ev.discrete, 1)), (size, 3 * g)]
    if program.inputs:  # the held samples: their times, values, and whether there are any
        fields += [(8, len(program.inputs)), (size, len(program.inputs)), (4, 1)]
    state = _struct_bytes(fields)
    stages = solvers.get(solver).tableau.stages
    locals_ = stages * n + 2 * n + m + (4 * n + max(ev.indicators, 1) if ev is not None else 0)
    pivots = 0
    if solver in ROSENBROCK:  # the stages, ys, f0, df/dt, E (n x n), jvp's v and jv; pivots
        locals_ = stages * n + 5 * n + n * n + m
        pivots = 4 * n
    return {"state": state,
            "params": (max(len(program.params), 1) + max(program.n_consts, 1)) * size,
            "outputs": m * size, "inputs": max(len(program.inputs), 1) * size,
            "step_locals": locals_ * size + pivots + state}
