"""Stage 3, scene: Graph -> Scenario, the graph with one scene's effects applied and the
scene's simulation settings."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import sympy as sp

from ..base import solvers
from ..symbolic.algebra import beyond_double
from ..base.diagnostics import Collector, ModelError, Note, Origin, Span, did_you_mean, fail
from ..front.graph import Expr, Graph, check_effect_names, check_ports, model_effects, var, written
from ..front.instantiate import output_refs
from ..base.resources import MAX_OUTPUT_ROWS
from ..base.run_settings import RunSettings

SOLVER_OPTIONS = ("rtol", "atol", "step", "hmax")
DEFAULT_TIME = (0.0, 10.0, 0.01)
DEFAULT_SOLVER = (solvers.DEFAULT, 1e-6, 1e-9)


def _run_field(name: str) -> property:
    return property(lambda self: getattr(self.run, name), doc=f"the scene's run.{name}")


@dataclass(frozen=True)
class Settings:
    """What a scene chose: its outputs and effects, its parameter values, and its run's
    settings (a bgc.base.run_settings.RunSettings: the one type of those); .t0, .t_end, .dt,
    .solver, .rtol, .atol and .step read the run's."""

    scene: str | None
    outputs: tuple | None  # OutRefs; None: every state
    run: RunSettings
    sets: tuple[tuple[str, Expr], ...]  # parameter default overrides
    given: tuple[str, ...] = ()  # what was given outside the model: "effects", "outputs"
    effects: tuple[str, ...] | None = None  # the effects in (None: all)
    left_out: tuple[tuple[str, str], ...] = ()  # (declared name, why) of what effects left out

    t0, t_end, dt = _run_field("t0"), _run_field("t_end"), _run_field("dt")
    solver, rtol, atol, step = (_run_field("solver"), _run_field("rtol"), _run_field("atol"),
                                _run_field("step"))


@dataclass(frozen=True)
class Override:
    """A scene made on the fly (`--outputs`, `--effects`, or the API's outputs=, effects=):
    what it gives replaces the named scene's (or the default scene's) outputs or effects.
    outputs: OutRefs; effects: an ast.SceneEffects (names None: `none`); None: not given.
    Both come from bgc.front.parser.parse_option, so their spans point into the option's text."""

    outputs: tuple | None = None
    effects: object | None = None


@dataclass(frozen=True)
class Scenario:
    """What the causality stage takes: the graph as the scene sees it, and the settings."""

    graph: Graph
    settings: Settings


def _tagged_out(effects, chosen) -> bool:
    return chosen is not None and any(e not in chosen for e in effects)


def _base(name: str) -> str:
    """The declared name of a part (`mass[1]` -> `mass`)."""
    return name.split("[", 1)[0]


def _apply_effects(graph: Graph, chosen) -> tuple[Graph, dict]:
    """The graph without what the chosen effects leave out, and {declared name: why} of
    everything left out: elements tagged with other effects (a stabilised constraint's tag
    tags its corrector, which falls back to none); then junctions whose bonds are all gone
    (a junction, or a constraint, on nothing); then signals that read what is left out."""
    if chosen is None:
        return graph, {}
    keep, why, notes = [], {}, {}
    for el in graph.elements:
        if not _tagged_out(el.effects, chosen):
            keep.append(el)
        elif el.constraint is not None and el.constraint.corrector != "none":
            c = replace(el.constraint, corrector="none", gains=())
            keep.append(replace(el, constraint=c, effects=()))
        else:
            base = _base(el.name)
            why[base] = "tagged " + " ".join("@" + e for e in el.effects)
            notes[base] = el.name_span
    gone = {el.name for el in graph.elements} - {el.name for el in keep}
    bonds = tuple(b for b in graph.bonds if b.src not in gone and b.dst not in gone)
    had = {n for b in graph.bonds for n in (b.src, b.dst)}
    has = {n for b in bonds for n in (b.src, b.dst)}
    emptied = [el for el in keep if el.is_junction and el.name in had and el.name not in has]
    for el in emptied:
        why.setdefault(_base(el.name), "its bonds are all left out")
        notes.setdefault(_base(el.name), el.name_span)
    keep = [el for el in keep if _base(el.name) not in why]
    signals = _signals_kept(graph.signals, why, notes)
    labels = {b.label for b in bonds}
    multibonds = tuple(mb for mb in graph.multibonds if all(p in labels for p in mb.parts))
    g = replace(graph, elements=tuple(keep), bonds=bonds, signals=signals,
                multibonds=multibonds)
    _check_references(g, why, notes)
    return g, why


def _signals_kept(signals, why: dict, notes: dict) -> tuple:
    """The signals that read nothing left out, directly or through other signals (a worklist
    over who reads whom: linear in the model)."""
    readers: dict[str, list] = {}
    for s in signals:
        for owner, _ in s.expr.refs:
            readers.setdefault(owner, []).append(s)
    todo = list(why)
    while todo:
        owner = todo.pop()
        for s in readers.get(owner, ()):
            base = _base(s.name)
            if base not in why:
                why[base] = f"reads '{owner}', left out"
                notes[base] = s.span
                todo.append(base)
    return tuple(s for s in signals if _base(s.name) not in why)


def _exprs_of(graph: Graph):
    for el in graph.elements:
        for e in (el.value, el.law and el.law[1]):
            if e is not None:
                yield e
        if el.constraint:
            yield from el.constraint.gains
            if el.constraint.annotation:
                yield el.constraint.annotation[1]
    for s in graph.signals:
        yield s.expr


def _check_references(graph: Graph, why: dict, notes: dict):
    diags = Collector()
    for expr in _exprs_of(graph):
        for owner, span in expr.refs:
            if owner in why:
                diags.error(span, f"'{owner}' is left out by this scene's effects but is used here",
                            Note(notes[owner], f"'{owner}' is left out: {why[owner]}"))
    check_ports(graph.elements, graph.bonds, diags)
    diags.raise_if_errors()


def _number(expr: Expr, params: dict) -> float:
    if beyond_double(expr.value, params) is not None:
        fail(expr.span, "value is not finite")
    value = expr.value.xreplace(params)
    try:
        x = float(value)
    except TypeError:
        fail(expr.span, "this must be a number (parameters allowed)")
    if not math.isfinite(x):
        fail(expr.span, "value is not finite")
    return x


def parameter_values(graph: Graph, sets=(), overrides: dict | None = None,
                     given: dict | None = None) -> dict:
    """Every parameter's value, in order: an override (a run's -p) as given, else the scene's
    `set` over the model's default, computed from the ones before it (as the generated code
    does): the one evaluation of parameters outside the generated code.  Without overrides
    the model's own values are checked (a located error if one is not a finite number); with
    them (bgc.analysis.stability, for a run) the values are what the run computes.  given: values
    (a run's -p) that replace the model's as overrides do, the others checked all the same."""
    given = overrides or given or {}
    chosen = dict(sets)
    values = {}
    for p in graph.parameters:
        if p.name in given:
            values[var(p.name)] = sp.Float(float(given[p.name]))
            continue
        expr = chosen.get(p.name, p.expr)
        inside = beyond_double(expr.value, values)
        if inside is not None:
            fail(expr.span,
                 f"parameter '{p.name}' is not finite (inf{_inside(inside, expr.value)})")
        v = expr.value.xreplace(values)
        if overrides is not None:
            values[var(p.name)] = sp.Float(float(v))
            continue
        try:
            x = float(v)
        except TypeError:  # complex (asin(a), a = 2), or not a number: say which
            x = constant_value(expr.value, values, expr.span, f"parameter '{p.name}'")
        if not math.isfinite(x):
            fail(expr.span, f"parameter '{p.name}' is not finite ({x})")
        values[var(p.name)] = sp.Float(x)
    return values


def check_parameters(graph: Graph, name: str | None, override: Override | None,
                     given: dict) -> None:
    """A run's parameter values `given` (name -> float, from -p) in scene `name`: the
    parameters computed from them, and the laws and initial values of parameters only, must
    still be finite real numbers; the located errors of the model's own values otherwise
    (they show the values, so they name the parameters)."""
    scene = next((s for s in graph.scenes if s.name == name), None)
    g, _ = _apply_effects(graph, _effects(graph, scene, override))
    sets = tuple((n, e) for n, e, _ in scene.sets) if scene else ()
    _check_laws(g, parameter_values(g, sets, given=given))


def _solver(scene_solver, params) -> tuple:
    name, rtol, atol = DEFAULT_SOLVER
    step = None
    if scene_solver is None:
        return name, rtol, atol, step, None
    name, opts, span = scene_solver
    if name not in solvers.SOLVERS:
        fail(span, f"unknown solver '{name}' (known: {', '.join(solvers.NAMES)})")
    values = {}
    for key, expr in opts:
        if key not in SOLVER_OPTIONS:
            fail(expr.span, f"unknown solver option '{key}' (known: {', '.join(SOLVER_OPTIONS)})")
        values[key] = _number(expr, params)
        if values[key] <= 0:
            fail(expr.span, f"solver option '{key}' must be positive")
    return name, values.get("rtol", rtol), values.get("atol", atol), values.get("step"), \
        values.get("hmax")


def _check_laws(graph: Graph, params: dict):
    """Laws and initial values that are numbers once the parameters are put in must be real,
    finite doubles (asin(a) with a = 2 is not), and a storage law must not be singular at the
    given parameter values (I(0), C(0))."""
    diags = Collector()
    for el in graph.elements:
        if el.init is not None:
            _guard_value(diags, el.init[1], params, f"the initial value of '{el.name}'")
        if el.value is None or el.is_junction or isinstance(el.value.value, sp.MatrixBase):
            continue  # (a coupled field's matrix: flatten checks it)
        if any(s not in params for s in el.value.value.free_symbols):
            continue  # a law of time or of signals: the generated code checks it as it runs
            # (not `free_symbols - params.keys()`: that walks every parameter, for each law)
        x = _guard_value(diags, el.value, params, f"the law of '{el.name}'")
        if x == 0.0 and el.spec.role == "storage":
            diags.error(el.value.span, f"{el.kind}({el.value.value}) of '{el.name}' is singular: "
                                       "its value is 0 at the given parameters")
    for sig in graph.signals:
        if sig.init is not None:
            _guard_value(diags, sig.init, params, f"the initial value of '{sig.name}'")
    diags.raise_if_errors()


def _guard_value(diags: Collector, expr: Expr, params: dict, what: str) -> float | None:
    try:
        return constant_value(expr.value, params, expr.span, what)
    except ModelError as exc:
        diags.items.extend(exc.diagnostics)
        return None


def constant_value(value, params: dict, span, what: str) -> float:
    """The double that value (parameters only) takes at these parameter values; a located
    error naming the parameters when it is a complex number or not finite."""
    inside = beyond_double(value, params)
    if inside is not None:
        fail(span, f"{what} is not finite: {written(value)}{_at(value, params)} (inf"
                   f"{_inside(inside, value)})")
    try:
        v = value.xreplace(params)
    except TypeError:  # SymPy refused to build it: atan2(0, 1/a) at a = 0 compares a NaN
        v = sp.nan
    try:
        x = float(v)
    except TypeError:  # a complex number, or not a number at all
        if _is_complex(v):
            fail(span, f"{what} evaluates to a complex number: {written(value)}"
                       f"{_at(value, params)}{_why_complex(value, params)}")
        x = math.nan
    except (OverflowError, ValueError):
        x = math.inf
    if not math.isfinite(x):
        fail(span, f"{what} is not finite: {written(value)}{_at(value, params)} "
                   "(a division by zero, or a number beyond a double?)")
    return x


def _inside(node, whole) -> str:
    """': exp(b) is beyond a double' when a part of the expression is, not all of it."""
    return "" if node == whole else f": {written(node)} is beyond a double"


def _is_complex(v) -> bool:
    try:
        z = complex(v.evalf(20))
    except (TypeError, ValueError, OverflowError):
        return False
    return z.imag != 0 and math.isfinite(z.real) and math.isfinite(z.imag)


def _why_complex(value, params: dict) -> str:
    """' (|a| > 1)': where value leaves the reals, the innermost function that does."""
    for sub in sp.postorder_traversal(value):
        if isinstance(sub, (sp.asin, sp.acos)):
            inside, why = sub.args[0], f"|{written(sub.args[0])}| > 1"
        elif isinstance(sub, sp.log):
            inside, why = sub.args[0], f"{written(sub.args[0])} < 0"
        elif sub.is_Pow and not sub.exp.is_Integer:
            root = "a square root" if sub.exp == sp.Rational(1, 2) else "a fractional power"
            inside, why = sub.base, f"{written(sub.base)} < 0 under {root}"
        else:
            continue
        try:
            x = float(inside.xreplace(params))
        except (TypeError, OverflowError):
            continue
        if (abs(x) > 1) if isinstance(sub, (sp.asin, sp.acos)) else (x < 0):
            return f" ({why})"
    return ""


def _at(value, params: dict) -> str:
    """' with a = 2, b = -1': the parameters value reads, as they are here."""
    used = sorted(value.free_symbols & params.keys(), key=lambda s: s.name)
    return " with " + ", ".join(f"{s.name} = {float(params[s]):.17g}" for s in used) if used \
        else ""


def _effects(graph: Graph, scene, override) -> tuple[str, ...] | None:
    effects = scene.effects if scene is not None else None
    if override is not None and override.effects is not None:
        given = override.effects
        names = () if given.names is None else tuple(n.name for n in given.names)
        diags = Collector()
        check_effect_names(names, [n.span for n in given.names or ()],
                           model_effects(graph.elements), diags, given.span.origin.name
                           if given.span.origin else "the given effects")
        diags.raise_if_errors()
        effects = names
    return effects


def _square_apart(t, period, t0) -> bool:
    """Whether the periods of square(period, duty, t0) around t are apart in doubles, as the
    runtimes compute them (bgc_square_period: k + 1 > k, t0 + k period < t0 + (k + 1) period)."""
    q = (t - t0) / period
    k = float(math.floor(q)) if math.isfinite(q) else math.nan
    return k + 1.0 > k and t0 + (k + 1.0) * period > t0 + k * period


def _check_squares(graph: Graph, t0: float, t1: float) -> None:
    """A square wave of numbers whose edges are not apart in doubles within the scene's time
    span (a period of 1e-300, or of 1e-6 at t = 1e10) can be followed by no run: a located
    error at the square() call (one of parameters, whose -p may give another period, stops
    the run that reaches such a time with the value not finite)."""
    for q in graph.squares:
        if getattr(q, "kind", None) != "square" or (q.period.free_symbols | q.t0.free_symbols):
            continue  # (of parameters: -p may give others; the run stops where it must)
        try:
            period, start = float(q.period), float(q.t0)
        except (TypeError, ValueError):
            continue
        if not (period > 0 and math.isfinite(period) and math.isfinite(start)) or start > t1:
            continue
        for t in (max(t0, start), t1):
            if not _square_apart(t, period, start):
                fail(q.span, f"the edges of '{q.text}' are not apart in doubles at t = {t:.6g} "
                             f"(its period {period:.6g} is finer than the time's resolution "
                             "there): no run can follow it")


def apply_scene(graph: Graph, name: str | None, override: Override | None = None,
                option: str = "scene") -> Scenario:
    """The graph as scene `name` sees it (None: the default scene, all effects, every state),
    with the outputs and effects of `override` in place of the scene's when it gives them.
    An unknown name is an error located in the name itself, which errors call `option`."""
    scene = None
    if name is not None:
        scene = next((s for s in graph.scenes if s.name == name), None)
        if scene is None:
            known = ", ".join(s.name for s in graph.scenes) or "none"
            fail(Span(1, 1, 1, len(name) + 1, Origin(option, name)),
                 f"no scene named '{name}' in model '{graph.name}'"
                 f"{did_you_mean(name, [s.name for s in graph.scenes])} (scenes: {known})")
    given = tuple(k for k in ("effects", "outputs")
                  if override is not None and getattr(override, k) is not None)
    effects = _effects(graph, scene, override)
    outputs = output_refs(override.outputs, dict(graph.constants)) if "outputs" in given \
        else (scene.outputs if scene else None)
    g, left_out = _apply_effects(graph, effects)
    sets = tuple((n, e) for n, e, _ in scene.sets) if scene else ()
    params = parameter_values(g, sets)
    _check_laws(g, params)
    t0, t1, dt = DEFAULT_TIME
    if scene is not None and scene.time is not None:
        t0, t1 = _number(scene.time[0], params), _number(scene.time[1], params)
        if scene.time[2] is not None:
            dt = _number(scene.time[2], params)
        if not t1 > t0:
            fail(scene.time[1].span, "the end time must be after the start time")
        if not dt > 0:
            fail(scene.time[2].span, "the output interval must be positive")
        if scene.time[2] is None:
            dt = (t1 - t0) / 1000
        elif not (t1 - t0) / dt <= MAX_OUTPUT_ROWS:
            fail(scene.time[2].span, f"more than {MAX_OUTPUT_ROWS:.0e} output rows: the output "
                                     "interval is too small for the time span")
    _check_squares(g, t0, t1)
    solver, rtol, atol, step, hmax = _solver(scene.solver if scene else None, params)
    run = RunSettings(t0, t1, dt, solver, rtol, atol, step, scene=name, max_step=hmax)
    return Scenario(g, Settings(name, outputs, run, sets, given, effects,
                                tuple(left_out.items())))
