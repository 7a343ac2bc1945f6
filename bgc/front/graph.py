"""The bond graph as the resolve stage hands it on: elements, bonds, signals, scenes.

Plain frozen values in declaration order, with index maps built once (by name, incident bonds),
so that every later question about the graph is a dictionary lookup, never a list search.
The well-formedness checks that more than one stage needs (ports of each element) live here
as public functions.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cached_property

import sympy as sp

from ..base.diagnostics import Collector, Note, Span, did_you_mean
from ..base.resources import compile_memo
from .kinds import KINDS

TIME = sp.Symbol("t", real=True)


_VARS = compile_memo()  # name -> its symbol: SymPy's own constructor checks the assumptions
#                        and consults its cache every time, and the stages ask for the same
#                        names again and again (a bond's effort and flow in every equation)


def var(name: str) -> sp.Symbol:
    """The symbol of a model variable (all model quantities are real)."""
    symbol = _VARS.get(name)
    if symbol is None:
        symbol = _VARS[name] = sp.Symbol(name, real=True)
    return symbol


def written(expr) -> str:
    """expr as the language writes it, for messages (^ for powers)."""
    return str(expr).replace("**", "^")


@dataclass(frozen=True)
class Expr:
    """A resolved expression and the model names it refers to (for later checks)."""

    value: sp.Expr
    refs: tuple[tuple[str, Span], ...]  # (owner name, span) of every name reference
    span: Span


@dataclass(frozen=True)
class Parameter:
    name: str
    expr: Expr
    doc: str | None
    span: Span
    unit: str | None = None  # `unit "kg"`


@dataclass(frozen=True)
class Constraint:
    kind: str | None  # "holonomic" | "nonholonomic" | None (detect)
    annotation: tuple | None  # ("init" | "phi", Expr)
    corrector: str  # pid | pd | none
    gains: tuple[Expr, ...]
    corrector_span: Span | None
    span: Span
    restitution: Expr | None = None  # unilateral (docs/hybrid.md): E of Newton's impact law


@dataclass(frozen=True)
class Element:
    name: str
    kind: str  # Se, MSe, ..., "0", "1"
    value: Expr | None  # the positional argument
    law: tuple[str, Expr] | None  # ("f", EXPR(p)) etc.
    init: tuple[str, Expr] | None
    effects: tuple[str, ...]
    constraint: Constraint | None
    doc: str | None
    span: Span
    name_span: Span
    dim: tuple[int, int] | None = None  # multiport (n in, m out; n == m but for MTF/MGY)
    origin: str | None = None  # after flatten: the multiport this scalar part comes from
    order: int = 0  # its declaration's place in the (instantiated) model, among all declarations

    @property
    def is_junction(self) -> bool:
        return self.kind in ("0", "1")

    @property
    def spec(self):
        return KINDS.get(self.kind)


@dataclass(frozen=True)
class Bond:
    src: str
    dst: str
    label: str  # unique, e.g. "vx->mx"
    span: Span
    # the ports of instances the bond crosses, (domain, unit, span, path) each (its units:
    # bgc.front.units); part: which component of a vector bond it is
    ports: tuple = field(default=(), compare=False)
    part: int | None = field(default=None, compare=False)

    def other(self, node: str) -> str:
        return self.dst if self.src == node else self.src


@dataclass(frozen=True)
class Signal:
    name: str
    expr: Expr
    init: Expr | None  # integral blocks: the state's initial value
    span: Span
    dim: int | None = None  # a vector signal (before flatten)
    unit: str | None = None  # `unit "m"`
    order: int = 0  # its declaration's place in the (instantiated) model, among all declarations

    @property
    def is_integral(self) -> bool:
        return self.init is not None


@dataclass(frozen=True)
class Vector:
    """A multiport element or a vector signal, flattened into scalar parts named NAME[i]."""

    name: str
    what: str  # "element" | "signal"
    dim: int  # its components (a multiport's one-port side, or its output side)
    kind: str  # the element's kind, "signal" for signals
    constraint: bool = False


@dataclass(frozen=True)
class Instance:
    """An instance of a component: its path, the component as the instantiating scope names
    it (`hyd.pipe`), the component's doc string, and the instance's declaration."""

    path: str
    component: str
    doc: str | None
    span: Span


@dataclass(frozen=True)
class Port:
    """A port of an instance, as declared: where a bond crossed its boundary (the bond itself
    is one bond of the flat graph)."""

    name: str  # its path, `p1.a`
    dim: int
    domain: str | None
    unit: str | None
    span: Span


@dataclass(frozen=True)
class Multibond:
    """A vector bond as written, and the scalar bonds flatten made of it."""

    label: str
    src: str
    dst: str
    dim: int
    parts: tuple[str, ...]  # the scalar bonds' labels
    span: Span


def part_name(name: str, i: int) -> str:
    """The scalar part i of a multiport or vector signal."""
    return f"{name}[{i}]"


_PART = re.compile(r"((?:.*\.)?[A-Za-z_][A-Za-z0-9_]*)\[([0-9]+)\]")


def variable_name(element: str, field: str) -> str:
    """The name of an element's variable: `mx.p`, and for part i of a multiport `mass.p[i]`
    (as the modeller indexes it), not `mass[i].p`; the same under an instance's path
    (`k.mass.p[0]`, `link[2].mass.p[0]`) and for an element declared with an index (`c[1]` in
    a `for`: `c.q[1]`), so that every stage and report names a variable alike."""
    m = _PART.fullmatch(element)
    if m:
        return f"{m.group(1)}.{field}[{m.group(2)}]"
    return f"{element}.{field}"


@dataclass(frozen=True)
class Scene:
    name: str
    doc: str | None
    effects: tuple[str, ...] | None  # None: all effects
    effects_span: Span | None
    outputs: tuple | None  # ast.OutRef
    time: tuple[Expr, Expr, Expr | None] | None
    solver: tuple[str, tuple[tuple[str, Expr], ...], Span] | None
    sets: tuple[tuple[str, Expr, Span], ...]
    span: Span
    effect_spans: tuple[Span, ...] = ()  # one per name of `effects`


def model_effects(elements) -> tuple[str, ...]:
    """The effects the model tags its declarations with, in order of first use."""
    return tuple(dict.fromkeys(e for el in elements for e in el.effects))


def check_effect_names(names, spans, known, diags: Collector, where: str) -> None:
    """Each effect a scene names must tag something in the model: a misspelt one would
    otherwise leave out, silently, everything tagged with the one meant."""
    for name, span in zip(names, spans):
        if name not in known:
            listed = ", ".join(known) if known else "none: nothing is tagged with @EFFECT"
            diags.error(span, f"unknown effect '{name}' in {where}{did_you_mean(name, known)}; "
                              f"the model's effects: {listed}")


@dataclass(frozen=True)
class InputInfo:
    """An input (`input NAME = DEFAULT unit "UNIT" "doc"`): a signal whose values come from
    outside."""

    name: str
    default: object  # a SymPy expression of parameters
    doc: str | None
    span: object
    unit: str | None = None


@dataclass(frozen=True)
class Graph:
    name: str
    doc: str | None
    path: str
    parameters: tuple[Parameter, ...]
    elements: tuple[Element, ...]
    bonds: tuple[Bond, ...]
    signals: tuple[Signal, ...]
    scenes: tuple[Scene, ...]
    warnings: tuple = ()
    vectors: tuple = ()  # after flatten: Vector, one per multiport element or vector signal
    multibonds: tuple = ()  # after flatten: Multibond, one per vector bond
    ports: tuple = ()  # Port, one per port of every instance (components, docs/language.md)
    relations: tuple = ()  # bgc.front.events: Relation, Square, Discrete, When (docs/hybrid.md)
    squares: tuple = ()
    discretes: tuple = ()
    whens: tuple = ()
    instances: tuple = ()  # Instance, one per instance of a component, in declaration order
    tables: tuple = ()  # bgc.front.tables.TableData, as Table(k, ...) numbers them
    inputs: tuple = ()  # InputInfo, in declaration order (their values: bgc.front.events.InputSlot)
    constants: tuple = ()  # (name, value) of the model file's constants (`--outputs s[N].q`)
    libraries: tuple = ()  # (path, SHA-256 or None) of the files its imports looked at
    units: tuple = ()  # after the units stage: (name, unit) of each quantity whose unit is known
    units_checked: bool = False  # whether the units stage checked the laws (a unit declared)

    @cached_property
    def vector_by_name(self) -> dict:
        return {v.name: v for v in self.vectors}

    @cached_property
    def by_name(self) -> dict[str, Element]:
        return {el.name: el for el in self.elements}

    @cached_property
    def incident(self) -> dict[str, tuple[int, ...]]:
        """Element name -> indices of its bonds, in bond order."""
        out: dict[str, list[int]] = {el.name: [] for el in self.elements}
        for i, b in enumerate(self.bonds):
            out[b.src].append(i)
            if b.dst != b.src:
                out[b.dst].append(i)
        return {name: tuple(ix) for name, ix in out.items()}

    def element(self, name: str) -> Element:
        return self.by_name[name]


def check_ports(elements, bonds, diags: Collector) -> None:
    """Every one-port has one bond, every two-port one bond in and one out; a passive element
    whose bond points away from it and a junction without bonds are warnings."""
    ins: dict[str, list[Bond]] = {el.name: [] for el in elements}
    outs: dict[str, list[Bond]] = {el.name: [] for el in elements}
    for b in bonds:
        if b.dst in ins:
            ins[b.dst].append(b)
        if b.src in outs:
            outs[b.src].append(b)
    for el in elements:
        i, o = ins[el.name], outs[el.name]
        if el.is_junction:
            if not i and not o:
                diags.warning(el.name_span, f"junction '{el.name}' has no bonds")
            continue
        spec = el.spec
        if spec.ports == 2 and (len(i) != 1 or len(o) != 1):
            diags.error(el.name_span, f"two-port '{el.name}' ({el.kind}) needs exactly one bond in "
                                      f"and one bond out; it has {len(i)} in and {len(o)} out",
                        *[Note(b.span, "bond here") for b in i + o])
        elif spec.ports == 1 and len(i) + len(o) != 1:
            diags.error(el.name_span, f"'{el.name}' ({el.kind}) needs exactly one bond; it has "
                                      f"{len(i) + len(o)}",
                        *[Note(b.span, "bond here") for b in i + o])
        elif spec.ports == 1 and o and spec.role in ("storage", "resistor"):
            diags.warning(o[0].span, f"the bond of '{el.name}' ({el.kind}) points away from "
                                     "it: power flows out of a passive element")
