"""AST of a .bg model: frozen nodes, each with the source span it came from."""
from __future__ import annotations

from dataclasses import dataclass

from ..base.diagnostics import Span


# ---------------------------------------------------------------- expressions
@dataclass(frozen=True)
class Num:
    text: str
    span: Span


@dataclass(frozen=True)
class Name:
    name: str
    span: Span


@dataclass(frozen=True)
class Field:
    """X.e, X.f, X.p, X.q, X.lambda, X.residual."""

    owner: str
    field: str
    span: Span


@dataclass(frozen=True)
class Call:
    func: str
    args: tuple
    span: Span


@dataclass(frozen=True)
class Str:
    """A string argument of a call: table("road.csv", t)."""

    text: str
    span: Span


@dataclass(frozen=True)
class KwArg:
    """A named argument of a call: interp = step."""

    name: str
    value: object  # an expression or a Str
    span: Span


@dataclass(frozen=True)
class BinOp:
    op: str  # + - * / ^
    left: object
    right: object
    span: Span


@dataclass(frozen=True)
class Neg:
    operand: object
    span: Span


@dataclass(frozen=True)
class Index:
    base: object
    index: object
    span: Span


@dataclass(frozen=True)
class Member:
    """BASE.NAME where BASE is not a plain path (`link[i].tip`): resolved to a Field or a
    Name by the instantiate stage, once the index is a constant."""

    base: object
    name: str
    span: Span


@dataclass(frozen=True)
class Compare:
    """A relation of compile-time constants (`if i > 1`)."""

    op: str
    left: object
    right: object
    span: Span


@dataclass(frozen=True)
class BoolOp:
    op: str  # and | or | not
    items: tuple
    span: Span


@dataclass(frozen=True)
class IfExpr:
    """`if C1 then A elif C2 then B else D`: ((condition, value), ...) and the else value."""

    branches: tuple
    orelse: object
    span: Span


@dataclass(frozen=True)
class Vector:
    items: tuple
    span: Span


# ---------------------------------------------------------------- declarations
@dataclass(frozen=True)
class Ident:
    name: str
    span: Span


@dataclass(frozen=True)
class Dim:
    n: int
    m: int | None  # two-ports map n -> m
    span: Span


@dataclass(frozen=True)
class Arg:
    law: Ident | None  # `e = EXPR(f)` style law arguments name their left side
    expr: object
    span: Span


@dataclass(frozen=True)
class InitClause:
    var: Ident
    expr: object
    span: Span


@dataclass(frozen=True)
class Corrector:
    kind: str  # pid | pd | none
    args: tuple
    span: Span


@dataclass(frozen=True)
class ConstraintSpec:
    kind: Ident | None  # holonomic | nonholonomic | unilateral | None (detect)
    annotation: tuple | None  # ("init" | "phi", expr, span)
    corrector: Corrector | None
    span: Span
    restitution: object = None  # unilateral: restitution(E)


@dataclass(frozen=True)
class ModelDecl:
    name: Ident
    doc: str | None
    span: Span


@dataclass(frozen=True)
class ParamDecl:
    name: Ident
    expr: object
    doc: str | None
    span: Span
    unit: str | None = None


@dataclass(frozen=True)
class ElementDecl:
    name: Ident
    kind: Ident  # Se, I, MTF, ... or "0"/"1" for junctions
    dim: Dim | None
    args: tuple[Arg, ...]
    inits: tuple[InitClause, ...]
    effects: tuple[Ident, ...]
    constraint: ConstraintSpec | None
    doc: str | None
    span: Span
    index: object = None  # `link[i] : ...`: the index expression (instantiate resolves it)
    switch: object = None  # `J : 1 switch(COND)`: a controlled junction's condition

    @property
    def is_junction(self) -> bool:
        return self.kind.name in ("0", "1")


@dataclass(frozen=True)
class SignalDecl:
    name: Ident
    dim: Dim | None
    expr: object
    span: Span
    unit: str | None = None
    index: object = None


@dataclass(frozen=True)
class IntegralDecl:
    name: Ident
    dim: Dim | None
    expr: object
    init: object
    span: Span
    unit: str | None = None
    index: object = None


@dataclass(frozen=True)
class PathRef:
    """A bond's end with indexed segments (`link[i-1].tip`): ((name Ident, index expr or
    None), ...); the instantiate stage makes it an Ident naming the path."""

    parts: tuple
    span: Span


@dataclass(frozen=True)
class BondChain:
    nodes: tuple  # Ident (a plain path `a` or `p1.a`) or PathRef
    span: Span
    ports: tuple = ()  # after instantiate: the ports it crosses, (domain, unit, span, path)


# ---------------------------------------------------------------- components and generation
@dataclass(frozen=True)
class LibraryDecl:
    name: Ident
    doc: str | None
    span: Span


@dataclass(frozen=True)
class ComponentParam:
    name: Ident
    default: object | None
    unit: str | None
    span: Span
    doc: str | None = None


@dataclass(frozen=True)
class ComponentDecl:
    name: Ident
    params: tuple[ComponentParam, ...]
    doc: str | None
    body: tuple
    span: Span


@dataclass(frozen=True)
class PortDecl:
    name: Ident
    dim: Dim | None
    domain: Ident | None
    span: Span
    unit: str | None = None
    doc: str | None = None


@dataclass(frozen=True)
class ConstantDecl:
    name: Ident
    expr: object
    span: Span


@dataclass(frozen=True)
class ForBlock:
    var: Ident
    start: object
    stop: object
    body: tuple
    span: Span


@dataclass(frozen=True)
class IfBlock:
    branches: tuple  # ((condition, body), ...): if, then each elif
    orelse: tuple | None
    span: Span


@dataclass(frozen=True)
class ImportDecl:
    name: Ident | None  # import NAME
    file: str | None  # import "file.bg"
    alias: Ident | None
    span: Span


@dataclass(frozen=True)
class InputDecl:
    """`input NAME [= DEFAULT] [unit "UNIT"] ["doc"]`: a signal whose values come from
    outside."""

    name: Ident
    expr: object  # the default (parameters only), or None: 0
    doc: str | None
    span: Span
    dim: object = None  # a scalar signal
    unit: str | None = None
    index: object = None


# ---------------------------------------------------------------- events
@dataclass(frozen=True)
class DiscreteDecl:
    """`discrete NAME = EXPR`: piecewise constant, changed only by when-blocks."""

    name: Ident
    expr: object
    doc: str | None
    span: Span


@dataclass(frozen=True)
class Reinit:
    """`reinit X = EXPR` in a when-block: a state's value after the event.  X is written as an
    expression naming the state (a Name, Field, or an Index of one: `link[i].mass.p[0]`)."""

    target: object
    expr: object
    span: Span


@dataclass(frozen=True)
class DiscreteAssign:
    """`NAME = EXPR` in a when-block: a discrete variable's value after the event."""

    name: Ident
    expr: object
    span: Span


@dataclass(frozen=True)
class WhenBlock:
    condition: object
    stmts: tuple  # Reinit | DiscreteAssign
    span: Span


# ---------------------------------------------------------------- scenes
@dataclass(frozen=True)
class OutRef:
    owner: str
    field: str | None
    index: int | None
    span: Span

    @property
    def text(self) -> str:
        s = self.owner + (f".{self.field}" if self.field else "")
        return s + (f"[{self.index}]" if self.index is not None else "")


def out_ref(segments, span: Span) -> OutRef:
    """The output that ((name, index or None), ...) names: a, a[1], a.f, a.f[1], p1.res.e,
    arm.link[2].rod.lambda: the last name a field when there is more than one, the last index
    the output's."""
    *head, (last, index) = segments
    if not head:
        return OutRef(last, None, index, span)
    owner = ".".join(n + (f"[{i}]" if i is not None else "") for n, i in head)
    return OutRef(owner, last, index, span)


@dataclass(frozen=True)
class OutPath:
    """An output whose indices are not all numbers yet (`s[N].cap.q`, `q[2*k]`):
    ((name, index: an int, a compile-time integer expression, or None), ...); made an OutRef
    once the constants are known (bgc.front.instantiate.output_refs)."""

    parts: tuple
    span: Span


@dataclass(frozen=True)
class SceneEffects:
    names: tuple[Ident, ...] | None  # None: `effects none`
    span: Span


@dataclass(frozen=True)
class SceneOutputs:
    refs: tuple[OutRef, ...]
    span: Span


@dataclass(frozen=True)
class SceneTime:
    start: object
    stop: object
    every: object | None
    span: Span


@dataclass(frozen=True)
class SceneSolver:
    name: Ident
    options: tuple[tuple[Ident, object], ...]
    span: Span


@dataclass(frozen=True)
class SceneSet:
    name: Ident  # or a PathRef (`set s[N].r = 2`) until the constants are known
    expr: object
    span: Span


@dataclass(frozen=True)
class SceneDecl:
    name: Ident
    doc: str | None
    stmts: tuple
    span: Span


@dataclass(frozen=True)
class Model:
    decls: tuple
    path: str
    ports: tuple = ()  # after instantiate: graph.Port, one per port of every instance
    instances: tuple = ()  # after instantiate: graph.Instance, in declaration order
    constants: tuple = ()  # after instantiate: (name, value) of the file's constants
    text: str = ""  # the model file's text (a span without an origin is in it)
    libraries: tuple = ()  # after instantiate: (path, SHA-256) of each file its imports read,
    #                        in order, and (path, None) of each place they looked at before
