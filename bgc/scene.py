"""Stage 3, scene: Graph -> Scenario, the graph with one scene's effects applied and the
scene's simulation settings."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import sympy as sp

from . import solvers
from .diagnostics import Collector, Note, fail
from .graph import Expr, Graph, check_ports, var

SOLVER_OPTIONS = ("rtol", "atol", "step")
DEFAULT_TIME = (0.0, 10.0, 0.01)
DEFAULT_SOLVER = (solvers.DEFAULT, 1e-6, 1e-9)


@dataclass(frozen=True)
class Settings:
    scene: str | None
    outputs: tuple | None  # OutRefs; None: every state
    t0: float
    t_end: float
    dt: float
    solver: str
    rtol: float
    atol: float
    step: float | None
    sets: tuple[tuple[str, Expr], ...]  # parameter default overrides


@dataclass(frozen=True)
class Scenario:
    """What the causality stage takes: the graph as the scene sees it, and the settings."""

    graph: Graph
    settings: Settings


def _tagged_out(effects, chosen) -> bool:
    return chosen is not None and any(e not in chosen for e in effects)


def _apply_effects(graph: Graph, chosen) -> Graph:
    keep, dropped = [], {}
    for el in graph.elements:
        if not _tagged_out(el.effects, chosen):
            keep.append(el)
        elif el.constraint is not None and el.constraint.corrector != "none":
            # An effect on a stabilised constraint tags its corrector, which falls back to none.
            c = replace(el.constraint, corrector="none", gains=())
            keep.append(replace(el, constraint=c, effects=()))
        else:
            dropped[el.name] = el
    bonds = tuple(b for b in graph.bonds if b.src not in dropped and b.dst not in dropped)
    g = replace(graph, elements=tuple(keep), bonds=bonds)
    _check_references(g, dropped)
    return g


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


def _check_references(graph: Graph, dropped):
    diags = Collector()
    for expr in _exprs_of(graph):
        for owner, span in expr.refs:
            if owner in dropped:
                diags.error(span, f"'{owner}' is left out by this scene's effects but is used here",
                            Note(dropped[owner].name_span, f"'{owner}' is tagged "
                                 + " ".join("@" + e for e in dropped[owner].effects)))
    check_ports(graph.elements, graph.bonds, diags)
    diags.raise_if_errors()


def _number(expr: Expr, params: dict) -> float:
    value = expr.value.xreplace(params)
    try:
        x = float(value)
    except TypeError:
        fail(expr.span, "this must be a number (parameters allowed)")
    if not math.isfinite(x):
        fail(expr.span, "value is not finite")
    return x


def parameter_values(graph: Graph, sets=()) -> dict:
    """Numeric default value of every parameter (with scene overrides), in order."""
    overrides = dict(sets)
    values = {}
    for p in graph.parameters:
        expr = overrides.get(p.name, p.expr)
        v = expr.value.xreplace(values)
        try:
            x = float(v)
        except TypeError:
            fail(expr.span, f"parameter '{p.name}' does not evaluate to a number")
        if not math.isfinite(x):
            fail(expr.span, f"parameter '{p.name}' is not finite ({x})")
        values[var(p.name)] = sp.Float(x)
    return values


def _solver(scene_solver, params) -> tuple:
    name, rtol, atol = DEFAULT_SOLVER
    step = None
    if scene_solver is None:
        return name, rtol, atol, step
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
    return name, values.get("rtol", rtol), values.get("atol", atol), values.get("step")


def _check_laws(graph: Graph, params: dict):
    """A storage law singular at the given parameter values (I(0), C(0)) is a model error."""
    diags = Collector()
    for el in graph.elements:
        if el.value is None or el.is_junction or el.spec.role != "storage":
            continue
        v = el.value.value.xreplace(params)
        if v.is_number and float(v) == 0.0:
            diags.error(el.value.span, f"{el.kind}({el.value.value}) of '{el.name}' is singular: "
                                       "its value is 0 at the given parameters")
    diags.raise_if_errors()


def apply_scene(graph: Graph, name: str | None) -> Scenario:
    """The graph as scene `name` sees it (None: the default scene, all effects, every state)."""
    if name is None:
        t0, t1, dt = DEFAULT_TIME
        solver, rtol, atol = DEFAULT_SOLVER
        _check_laws(graph, parameter_values(graph))
        return Scenario(graph, Settings(None, None, t0, t1, dt, solver, rtol, atol, None, ()))
    scene = next((s for s in graph.scenes if s.name == name), None)
    if scene is None:
        known = ", ".join(s.name for s in graph.scenes) or "none"
        fail(None, f"no scene named '{name}' in model '{graph.name}' (scenes: {known})")
    g = _apply_effects(graph, scene.effects)
    params = parameter_values(g, tuple((n, e) for n, e, _ in scene.sets))
    _check_laws(g, params)
    t0, t1, dt = DEFAULT_TIME
    if scene.time is not None:
        t0, t1 = _number(scene.time[0], params), _number(scene.time[1], params)
        if scene.time[2] is not None:
            dt = _number(scene.time[2], params)
        if not t1 > t0:
            fail(scene.time[1].span, "the end time must be after the start time")
        if not dt > 0:
            fail(scene.time[2].span, "the output interval must be positive")
        if scene.time[2] is None:
            dt = (t1 - t0) / 1000
    solver, rtol, atol, step = _solver(scene.solver, params)
    sets = tuple((n, e) for n, e, _ in scene.sets)
    return Scenario(g, Settings(scene.name, scene.outputs, t0, t1, dt, solver, rtol, atol, step,
                                sets))
