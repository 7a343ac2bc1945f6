"""What bgc lsp knows of a model's text, without the protocol: its diagnostics (those of
`bgc check`), its outline, and what a name at a place is (hover, definition, completion).

Positions here are (line, character), both from 0, characters counted as Python counts them
(code points); bgc.editor.lsp converts them to the client's units.  A name is looked up as
the compiler looks it up: in the component whose body holds it, then at the file's top;
`alias.comp` through the file's imports (beside the model, $BGC_PATH, bgc's library), whose
files are read once for each change of their size or time (LIBRARIES)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..front import ast
from ..middle.causality import assign_causality
from ..base.diagnostics import Diagnostic, ModelError, Note, Span, instance_notes
from ..front.flatten import flatten
from ..front.instantiate import LIBRARY, instantiate, search_path
from ..front.kinds import KINDS, SWITCHED
from ..front.parser import decode, parse, parse_library
from ..middle.reduce import reduce
from ..front.resolve import resolve
from ..base.resources import read_bounded
from ..middle.scene import apply_scene
from ..middle.system import build_equations

# The reduce stage (SymPy) is the one stage of `bgc check` whose work grows faster than the
# model: the server runs it, after the other stages' diagnostics are out, for systems of at
# most this many equations (every model of the repository but the largest; their reduce takes
# well under half a second).
REDUCE_EQUATIONS = 400


# ---------------------------------------------------------------- diagnostics
@dataclass(frozen=True)
class Checked:
    """A text's diagnostics, as `bgc check` gives them, as far as the stages before reduce go:
    the default scene's errors, or its warnings and each scene's errors (noted `in scene
    NAME` unless inside the scene).  To reduce: the default scene's system, and each scene's
    that passed the stages before reduce (None for one that did not, its errors in `failed`)."""

    diagnostics: tuple[Diagnostic, ...]
    system: object = None  # the default scene's EquationSystem, to reduce (None: failed)
    scenes: tuple = ()  # ((scene, EquationSystem | None, its errors), ...), in order


def check(text: str, path: str) -> Checked:
    """The diagnostics of every stage but reduce: parse, instantiate, resolve, the default
    scene's causality and equations, then each scene's."""
    try:
        graph = flatten(resolve(instantiate(parse(text, path))))
        system = build_equations(assign_causality(apply_scene(graph, None)))
    except ModelError as exc:
        return Checked(exc.diagnostics)
    scenes = []
    for sc in graph.scenes:
        try:
            built = build_equations(assign_causality(apply_scene(graph, sc.name)))
            scenes.append((sc, built, ()))
        except ModelError as exc:
            scenes.append((sc, None, tuple(_in_scene(d, sc) for d in exc.diagnostics)))
    errors = tuple(d for _, _, found in scenes for d in found)
    return Checked(tuple(system.warnings) + errors, system, tuple(scenes))


def reducible(checked: Checked) -> bool:
    """Whether the reduce stage is cheap enough to run for these diagnostics (its size
    estimated before the work: REDUCE_EQUATIONS equations a system at most)."""
    systems = [checked.system] + [s for _, s, _ in checked.scenes if s is not None]
    return checked.system is not None and all(len(s.equations) <= REDUCE_EQUATIONS
                                              for s in systems)


def check_reduced(checked: Checked) -> tuple[Diagnostic, ...]:
    """All of `bgc check`'s diagnostics: the default scene's reduce errors, or its warnings
    (the earlier stages' with the reduce stage's) and each scene's errors, in order."""
    try:
        reduced = reduce(checked.system, False, "auto")
    except ModelError as exc:
        return exc.diagnostics
    found = []
    for sc, system, errors in checked.scenes:
        if system is None:
            found += errors
            continue
        try:
            reduce(system, False, "auto")
        except ModelError as exc:
            found += [_in_scene(d, sc) for d in exc.diagnostics]
    return tuple(reduced.warnings) + tuple(found)


def _in_scene(d: Diagnostic, sc) -> Diagnostic:
    inside = d.span is not None and not d.span.chain and d.span.origin is None \
        and sc.span.line <= d.span.line <= sc.span.end_line
    return d if inside else replace(d, notes=d.notes + (Note(sc.span, f"in scene '{sc.name}'"),))


@dataclass(frozen=True)
class Place:
    """A range of a file: (line, character) from 0, end exclusive; path None: the document."""

    path: str | None
    start: tuple[int, int]
    end: tuple[int, int]


def place(span: Span | None, path: str | None = None) -> Place:
    """A span as a Place (in the file its origin names, if it has one)."""
    if span is None:
        return Place(path, (0, 0), (0, 1))
    if span.origin is not None and span.origin.file:
        path = span.origin.name
    return Place(path, (span.line - 1, span.col - 1), (span.end_line - 1, span.end_col - 1))


@dataclass(frozen=True)
class Located:
    """A diagnostic as the document shows it: where, what, and its notes' places."""

    severity: str
    where: Place  # always in the document
    message: str
    related: tuple[tuple[Place, str], ...]


def locate(d: Diagnostic) -> Located:
    """Where the document shows d: at its span, or (an error in an imported library) at the
    instance or import in the document that leads there, the error's own place the first
    related note.  Notes without a place go into the message."""
    notes = d.notes + instance_notes(d.span)
    related = [(place(n.span), n.message) for n in notes if n.span is not None]
    message = d.message + "".join(f"\nnote: {n.message}" for n in notes if n.span is None)
    if d.span is not None and d.span.origin is not None:
        ours = [p for p, _ in reversed(related) if p.path is None]
        where = ours[0] if ours else Place(None, (0, 0), (0, 1))
        related.insert(0, (place(d.span), "the error is here"))
    else:
        where = place(d.span)
    return Located(d.severity, where, message, tuple(related))


# ---------------------------------------------------------------- files and scopes
@dataclass
class Scope:
    """The names of the model's top level or of one component's body."""

    comp: ast.ComponentDecl | None
    params: dict = field(default_factory=dict)  # name -> ParamDecl | ComponentParam
    elements: dict = field(default_factory=dict)  # name -> ElementDecl
    signals: dict = field(default_factory=dict)  # name -> SignalDecl | IntegralDecl | ...
    ports: dict = field(default_factory=dict)  # name -> PortDecl
    constants: dict = field(default_factory=dict)  # name -> ConstantDecl


@dataclass
class File:
    """A parsed model or library file."""

    path: str
    text: str
    model: ast.Model
    top: Scope
    components: dict  # name -> (ComponentDecl, Scope)
    imports: dict  # alias -> (ImportDecl, File | None)
    scenes: dict  # name -> SceneDecl

    @property
    def doc(self) -> str | None:
        first = self.model.decls[0] if self.model.decls else None
        return getattr(first, "doc", None) if isinstance(first, (ast.ModelDecl,
                                                                  ast.LibraryDecl)) else None


def _fill(scope: Scope, body):
    """Declarations of a body into its scope, `for` and `if` bodies included."""
    stack = list(reversed(body))
    while stack:
        d = stack.pop()
        if isinstance(d, ast.ParamDecl):
            scope.params.setdefault(d.name.name, d)
        elif isinstance(d, ast.ElementDecl):
            scope.elements.setdefault(d.name.name, d)
        elif isinstance(d, (ast.SignalDecl, ast.IntegralDecl, ast.InputDecl, ast.DiscreteDecl)):
            scope.signals.setdefault(d.name.name, d)
        elif isinstance(d, ast.PortDecl):
            scope.ports.setdefault(d.name.name, d)
        elif isinstance(d, ast.ConstantDecl):
            scope.constants.setdefault(d.name.name, d)
        elif isinstance(d, ast.ForBlock):
            stack.extend(reversed(d.body))
        elif isinstance(d, ast.IfBlock):
            for _, branch in reversed(d.branches):
                stack.extend(reversed(branch))
            if d.orelse:
                stack.extend(reversed(d.orelse))


def _file(model: ast.Model, text: str, path: str, depth: int = 0) -> File:
    top = Scope(None)
    _fill(top, model.decls)
    components = {}
    for d in model.decls:
        if isinstance(d, ast.ComponentDecl) and d.name.name not in components:
            scope = Scope(d)
            for p in d.params:
                scope.params.setdefault(p.name.name, p)
            _fill(scope, d.body)
            components[d.name.name] = (d, scope)
    f = File(path, text, model, top, components, {},
             {d.name.name: d for d in model.decls if isinstance(d, ast.SceneDecl)})
    for d in model.decls:
        if isinstance(d, ast.ImportDecl):
            alias = (d.alias or d.name).name
            f.imports.setdefault(alias, (d, _import(f, d, depth)))
    return f


MAX_DEPTH = 8  # libraries importing libraries, followed for names this deep


def _import(f: File, d: ast.ImportDecl, depth: int) -> File | None:
    """The library an import names, found where the compiler looks (None: not found, not
    readable, not parsed)."""
    if depth >= MAX_DEPTH:
        return None
    base = Path(f.path).parent
    if d.file is not None:
        candidates = [base / d.file]
    else:
        candidates = [Path(p) / (d.name.name + ".bg") for p in [base, *search_path(), LIBRARY]]
    path = next((c for c in candidates if c.is_file()), None)
    return library(str(path), depth + 1) if path is not None else None


LIBRARIES: dict = {}  # resolved path -> ((size, mtime), File or None)


def library(path: str, depth: int = 1) -> File | None:
    """A library file, parsed; kept until its size or time changes."""
    key = os.path.realpath(path)
    try:
        st = os.stat(key)
    except OSError:
        return None
    stamp = (st.st_size, st.st_mtime_ns)
    kept = LIBRARIES.get(key)
    if kept is not None and kept[0] == stamp:
        return kept[1]
    LIBRARIES[key] = (stamp, None)  # (being read: an import cycle ends here)
    try:
        text = decode(read_bounded(path))
        found = _file(parse_library(text, path), text, path, depth)
    except (OSError, ModelError):
        found = None
    LIBRARIES[key] = (stamp, found)
    return found


def index(text: str, path: str) -> File | None:
    """The document's File, or None if it does not parse."""
    try:
        return _file(parse(text, path), text, path)
    except ModelError:
        return None
    except RecursionError:  # (bounded by the parser's nesting limit; never the server's end)
        return None


# ---------------------------------------------------------------- what is where
def _contains(span: Span, pos: tuple[int, int]) -> bool:
    start, end = (span.line - 1, span.col - 1), (span.end_line - 1, span.end_col - 1)
    return start <= pos <= end


def scope_at(f: File, pos: tuple[int, int]) -> Scope:
    for comp, scope in f.components.values():
        if _contains(comp.span, pos):
            return scope
    return f.top


def dotted_at(text: str, pos: tuple[int, int]) -> tuple[list[str], int, tuple] | None:
    """The dotted name under pos (`motor.shaft`, indices dropped: `link[2].px` is
    link.px), the index of the part under pos, and the part's range; None in a comment, a
    string or on no name."""
    lines = text.split("\n")
    if not 0 <= pos[0] < len(lines):
        return None
    line = lines[pos[0]]
    col = min(max(pos[1], 0), len(line))
    if _in_comment_or_string(line, col):
        return None
    word = lambda c: c.isalnum() or c == "_"  # noqa: E731
    start = col
    while start > 0 and word(line[start - 1]):
        start -= 1
    end = col
    while end < len(line) and word(line[end]):
        end += 1
    if start == end or line[start].isdigit():
        return None
    parts, at = [line[start:end]], 0
    i = start
    while True:  # parts before: `.name` or `[..].name`
        j = i - 1
        if j >= 0 and line[j] == "]":
            depth = 0
            while j >= 0:
                depth += {"]": 1, "[": -1}.get(line[j], 0)
                if depth == 0:
                    break
                j -= 1
            j -= 1
        if j < 0 or line[j] != ".":
            break
        k = j
        while k > 0 and word(line[k - 1]):
            k -= 1
        if k == j:
            break
        parts.insert(0, line[k:j])
        at += 1
        i = k
    i = end
    while True:  # parts after
        j = i
        if j < len(line) and line[j] == "[":
            close = line.find("]", j)
            j = close + 1 if close > 0 else j
        if j >= len(line) or line[j] != ".":
            break
        k = j + 1
        while k < len(line) and word(line[k]):
            k += 1
        if k == j + 1:
            break
        parts.append(line[j + 1:k])
        i = k
    return parts, at, ((pos[0], start), (pos[0], end))


def _in_comment_or_string(line: str, col: int) -> bool:
    quoted = False
    for i, ch in enumerate(line[:col]):
        if quoted:
            if ch == "\\":
                continue
            quoted = ch != '"'
        elif ch == '"':
            quoted = True
        elif ch == "#":
            return True
    return quoted


@dataclass(frozen=True)
class Target:
    """What a name denotes: kind, the File and node it is declared by, and for an instance
    or component the component (its File and Scope)."""

    what: str  # parameter | element | signal | port | constant | component | library | kind
    #            | scene | variable
    name: str
    file: File | None = None
    node: object = None
    comp: tuple | None = None  # (File, ComponentDecl, Scope) of a component or instance's


def component_of(f: File, kind: str) -> tuple | None:
    """The component a kind names in file f (`resistor`, `el.resistor`): (File, decl, Scope)."""
    if "." in kind:
        alias, name = kind.split(".", 1)
        lib = f.imports.get(alias, (None, None))[1]
        if lib is None or "." in name:
            return None
        found = lib.components.get(name)
        return (lib, *found) if found else None
    found = f.components.get(kind)
    return (f, *found) if found else None


def resolve_name(f: File, scope: Scope, parts: list[str]) -> Target | None:
    """What parts (a dotted name) denote, looked up from scope in file f."""
    if not parts:
        return None
    head, rest = parts[0], parts[1:]
    if head in f.imports and rest:
        lib = f.imports[head][1]
        if lib is None:
            return None
        found = lib.components.get(rest[0])
        if found is None or len(rest) > 1:
            return None
        return Target("component", f"{head}.{rest[0]}", lib, found[0], (lib, *found))
    target = _local(f, scope, head)
    for part in rest:
        if target is None:
            return None
        target = _member(target, part)
    return target


def _local(f: File, scope: Scope, name: str) -> Target | None:
    for what, table in (("parameter", scope.params), ("element", scope.elements),
                        ("signal", scope.signals), ("port", scope.ports),
                        ("constant", scope.constants)):
        if name in table:
            node = table[name]
            comp = component_of(f, node.kind.name) if what == "element" else None
            return Target(what, name, f, node, comp)
    if scope is not f.top:
        found = _local(f, f.top, name)
        if found is not None and found.what == "constant":
            return found
    if name in f.components:
        d, s = f.components[name]
        return Target("component", name, f, d, (f, d, s))
    if name in f.imports:
        return Target("library", name, f.imports[name][1], f.imports[name][0])
    if name in f.scenes:
        return Target("scene", name, f, f.scenes[name])
    if name in KINDS or name in SWITCHED or name in ("0", "1"):
        return Target("kind", name)
    return None


def _member(target: Target, part: str) -> Target | None:
    """`inst.part`: a port, parameter, element or signal of an instance's component, or a
    variable of an element."""
    if target.what == "element" and target.comp is not None:
        lib, _, scope = target.comp
        found = _local(lib, scope, part)
        return found if found is not None and found.what in (
            "port", "parameter", "element", "signal") else None
    if target.what == "element" and part in fields_of(target.node):
        return Target("variable", part, target.file, target.node)
    return None


def fields_of(decl: ast.ElementDecl) -> tuple[str, ...]:
    """The variables of an element (as bgc.front.resolve allows them)."""
    k = decl.kind.name
    if k in SWITCHED:
        base = ("e", "f")
    elif k == "0":
        base = ("e",)
    elif k == "1":
        base = ("f",)
    elif k in KINDS and KINDS[k].ports == 1:
        base = ("e", "f") + ((KINDS[k].state,) if KINDS[k].state else ())
    else:
        base = ()
    if decl.constraint is not None:
        base += ("lambda", "residual")
    return base


def target_at(f: File, pos: tuple[int, int]) -> tuple[Target, tuple] | None:
    """What the name under pos denotes, and the range of the name."""
    found = dotted_at(f.text, pos)
    if found is None:
        return None
    parts, at, span = found
    scope = scope_at(f, pos)
    for d in _elements(scope):  # a component's argument: `motor : el.dc_machine(r = 1)`
        for a in d.args:
            if a.law is not None and _contains(a.law.span, pos):
                comp = component_of(f, d.kind.name)
                if comp is not None and a.law.name in comp[2].params:
                    p = comp[2].params[a.law.name]
                    return Target("parameter", a.law.name, comp[0], p), span
                return Target("kind", d.kind.name), span
    target = resolve_name(f, scope, parts[:at + 1])
    return (target, span) if target is not None else None


def _elements(scope: Scope):
    return scope.elements.values()


# ---------------------------------------------------------------- hover
def law(kind: str) -> str:
    """An element kind's law, from its data (bgc.front.kinds) and docs/semantics.md's conventions."""
    if kind == "0":
        return "0-junction: one effort on all its bonds; the flows in sum to the flows out"
    if kind == "1":
        return "1-junction: one flow on all its bonds; the efforts in sum to the efforts out"
    if kind in SWITCHED:
        return {"D": "ideal diode D: conducting, e = 0 and f > 0; blocking, f = 0 and e < 0",
                "Sw": "ideal switch Sw(COND): closed (e = 0) while COND holds, open (f = 0) "
                      "otherwise",
                "Fr": "dry friction Fr(Fc, Fs): sliding, e = Fc·sign(f); sticking, f = 0 "
                      "while the holding effort stays within Fs"}[kind]
    k = KINDS.get(kind)
    if k is None:
        return ""
    modulated = " (modulated: its argument may read signals, element variables and t)" \
        if k.modulated else ""
    if k.role == "source":
        var = "e" if k.fixed == "effort" else "f"
        return f"{k.fixed} source {kind}(x): {var} = x, whatever the other variable{modulated}"
    if k.role == "storage":
        other = {"p": ("e", "f", "inertia"), "q": ("f", "e", "capacitor")}[k.state]
        return (f"{other[2]} {kind}(x): d{k.state}/dt = {other[0]}, {other[1]} = {k.state}/x, "
                f"or a law `{k.laws[0]} = EXPR({k.state})`; state {k.state}, preferred "
                f"(integral) causality: it imposes the {k.preferred}")
    if k.role == "resistor":
        return f"resistor {kind}(r): e = r·f, or a law `e = EXPR(f)` or `f = EXPR(e)`"
    if k.role == "transformer":
        return f"transformer {kind}(n): e_in = n·e_out, f_out = n·f_in{modulated}"
    return f"gyrator {kind}(r): e_in = r·f_out, e_out = r·f_in{modulated}"


VARIABLES = {"e": "the effort of its bond", "f": "the flow of its bond",
             "p": "its state, the momentum (dp/dt = e)", "q": "its state, the displacement "
             "(dq/dt = f)", "lambda": "the constraint's Lagrange multiplier",
             "residual": "the constraint's residual Φ, its drift (an output only)"}


def source_of(f: File, node) -> str:
    """The text a node was parsed from (one line of it at most)."""
    span = getattr(node, "span", None)
    if span is None:
        return ""
    lines = f.text.split("\n")
    if span.line == span.end_line:
        return lines[span.line - 1][span.col - 1:span.end_col - 1]
    return lines[span.line - 1][span.col - 1:] + " ..."


def hover(f: File, pos: tuple[int, int]) -> tuple[str, tuple] | None:
    """Markdown about the name under pos, and its range."""
    found = target_at(f, pos)
    if found is None:
        return None
    t, span = found
    return describe(t), span


def describe(t: Target) -> str:
    n = t.node
    if t.what == "kind":
        return f"**{t.name}**: {law(t.name)}"
    if t.what == "component":
        return component_text(t.name, *t.comp)
    if t.what == "library":
        lib = t.file
        if lib is None:
            return f"**{t.name}**: a library bgc cannot find or read"
        names = ", ".join(sorted(lib.components))
        return f"**{t.name}**: library `{lib.path}`\n\n{lib.doc or ''}\n\ncomponents: {names}"
    if t.what == "parameter":
        return param_text(t.file, n)
    if t.what == "port":
        return port_text(n)
    if t.what == "element":
        head = f"**{t.name}** : `{source_of(t.file, n.kind)}`"
        if t.comp is not None:
            return head + " (an instance)\n\n" + component_text(n.kind.name, *t.comp)
        text = head + f"\n\n{law(n.kind.name)}"
        return text + (f"\n\n{n.doc}" if n.doc else "")
    if t.what == "variable":
        return f"**{n.name.name}.{t.name}** ({n.kind.name}): {VARIABLES.get(t.name, '')}"
    if t.what == "signal":
        unit = getattr(n, "unit", None)
        doc = getattr(n, "doc", None)
        return (f"**{t.name}**: `{source_of(t.file, n)}`" + (f" unit `{unit}`" if unit else "")
                + (f"\n\n{doc}" if doc else ""))
    if t.what == "scene":
        return f"**scene {t.name}**" + (f"\n\n{n.doc}" if n.doc else "")
    if t.what == "constant":
        return f"**constant {t.name}** = `{source_of(t.file, n.expr)}`"
    return t.name


def _value(p):
    """A parameter's value: a model's, or a component parameter's default (None: none)."""
    return p.expr if isinstance(p, ast.ParamDecl) else p.default


def param_text(f: File, p) -> str:
    value = source_of(f, _value(p)) if _value(p) is not None else None
    unit = getattr(p, "unit", None)
    text = f"**parameter {p.name.name}**" + (f" = `{value}`" if value else "")
    text += f" unit `{unit}`" if unit else ""
    return text + (f"\n\n{p.doc}" if p.doc else "")


def port_text(p) -> str:
    domain = f" : {p.domain.name}" if p.domain is not None else ""
    unit = f" unit `{p.unit}`" if p.unit else ""
    return f"**port {p.name.name}**{domain}{unit}" + (f"\n\n{p.doc}" if p.doc else "")


def component_text(name: str, lib: File, comp: ast.ComponentDecl, scope: Scope) -> str:
    first = lib.model.decls[0] if lib.model.decls else None
    owner = f"library `{first.name.name}`" if isinstance(first, ast.LibraryDecl) else "the file"
    where = f"component of {owner} ({lib.path})"
    out = [f"**{name}**({', '.join(p.name.name for p in comp.params)}): {where}"]
    if comp.doc:
        out.append(comp.doc)
    if scope.ports:
        out.append("ports:\n" + "\n".join(
            f"- `{p.name.name}{' : ' + p.domain.name if p.domain else ''}`"
            + (f" unit `{p.unit}`" if p.unit else "") + (f": {p.doc}" if p.doc else "")
            for p in scope.ports.values()))
    if comp.params:
        out.append("parameters:\n" + "\n".join(
            f"- `{p.name.name}" + (f" = {source_of(lib, p.default)}" if p.default is not None
                                   else "")
            + "`" + (f" unit `{p.unit}`" if p.unit else "") + (f": {p.doc}" if p.doc else "")
            for p in comp.params))
    return "\n\n".join(out)


# ---------------------------------------------------------------- definition
def definition(f: File, pos: tuple[int, int]) -> Place | None:
    """Where the name under pos is declared (its name's range; None: nowhere in a file)."""
    found = target_at(f, pos)
    if found is None:
        return None
    t = found[0]
    if t.what == "library":
        return Place(t.file.path, (0, 0), (0, 0)) if t.file is not None else None
    if t.file is None or t.node is None:
        return None
    where = place(t.node.name.span)
    return replace(where, path=None if t.file is f else t.file.path)


# ---------------------------------------------------------------- completion
@dataclass(frozen=True)
class Item:
    label: str
    what: str  # kind | component | port | parameter | element | signal | variable | library
    detail: str = ""
    doc: str = ""


def complete(f: File, text: str, pos: tuple[int, int]) -> list[Item]:
    """Completions at pos in text (f: the last version of the document that parsed):
    after `alias.` a library's components, after `inst.` an instance's ports, parameters and
    variables (an element's variables), after `name :` the kinds and components, else the
    names in scope."""
    lines = text.split("\n")
    line = lines[pos[0]][:pos[1]] if 0 <= pos[0] < len(lines) else ""
    if _in_comment_or_string(line, len(line)):
        return []
    word = len(line)
    while word > 0 and (line[word - 1].isalnum() or line[word - 1] == "_"):
        word -= 1
    scope = scope_at(f, pos)
    if word > 0 and line[word - 1] == ".":
        found = dotted_at(line + "x", (0, word))  # (the part being written: x)
        if found is None:
            return []
        parts = found[0][:-1]
        if len(parts) == 1 and parts[0] in f.imports:
            lib = f.imports[parts[0]][1]
            return [Item(name, "component", f"{parts[0]}.{name}(...)",
                         component_text(f"{parts[0]}.{name}", lib, d, s))
                    for name, (d, s) in sorted(lib.components.items())] if lib else []
        target = resolve_name(f, scope, parts)
        return _members(target) if target is not None else []
    before = line[:word].rstrip()
    if before.endswith(":") and not before.endswith("::"):
        return _kinds(f)
    items = [Item(n, w) for w, table in (("parameter", scope.params),
                                          ("element", scope.elements),
                                          ("signal", scope.signals), ("port", scope.ports))
             for n in table]
    return items + [Item(a, "library") for a in f.imports]


def _kinds(f: File) -> list[Item]:
    items = [Item(k, "kind", law(k)) for k in [*KINDS, *SWITCHED, "0", "1"]]
    items += [Item(n, "component", "component", component_text(n, f, d, s))
              for n, (d, s) in f.components.items()]
    return items + [Item(a, "library", "library") for a in f.imports]


def _members(t: Target) -> list[Item]:
    if t.what == "element" and t.comp is not None:
        lib, _, scope = t.comp
        items = [Item(n, "port", p.domain.name if p.domain else "port", port_text(p))
                 for n, p in scope.ports.items()]
        items += [Item(n, "parameter", "parameter", param_text(lib, p))
                  for n, p in scope.params.items()]
        items += [Item(n, "element", source_of(lib, e.kind)) for n, e in scope.elements.items()]
        return items + [Item(n, "signal", "signal") for n in scope.signals]
    if t.what == "element":
        return [Item(v, "variable", t.node.kind.name, VARIABLES.get(v, ""))
                for v in fields_of(t.node)]
    return []


# ---------------------------------------------------------------- outline
@dataclass(frozen=True)
class Symbol:
    name: str
    what: str
    where: Place  # the declaration
    name_at: Place  # its name
    detail: str = ""
    children: tuple = ()


def outline(f: File) -> list[Symbol]:
    """The document's declarations, a component's and a scene's inside them."""
    return _symbols(f, f.model.decls)


def _symbols(f: File, decls) -> list[Symbol]:
    out = []
    for d in decls:
        if isinstance(d, (ast.ForBlock, ast.IfBlock)):
            body = d.body if isinstance(d, ast.ForBlock) else [
                s for _, b in d.branches for s in b] + list(d.orelse or ())
            out += _symbols(f, body)
            continue
        name = getattr(d, "alias", None) or getattr(d, "name", None)
        if not isinstance(name, ast.Ident):
            continue
        what, detail, children = _symbol_kind(f, d)
        if what is None:
            continue
        where = place(d.span)
        name_at = place(name.span)
        if not (where.start <= name_at.start and name_at.end <= where.end):
            where = Place(None, min(where.start, name_at.start), max(where.end, name_at.end))
        out.append(Symbol(name.name, what, where, name_at, detail, tuple(children)))
    return out


def _symbol_kind(f: File, d):
    if isinstance(d, ast.ModelDecl):
        return "model", d.doc or "", []
    if isinstance(d, ast.LibraryDecl):
        return "library", d.doc or "", []
    if isinstance(d, ast.ImportDecl):
        return "import", d.file or (d.name.name if d.name else ""), []
    if isinstance(d, ast.ParamDecl):
        return "parameter", source_of(f, d.expr), []
    if isinstance(d, ast.ElementDecl):
        return "element", source_of(f, d.kind), []
    if isinstance(d, (ast.SignalDecl, ast.IntegralDecl, ast.InputDecl, ast.DiscreteDecl)):
        return "signal", "", []
    if isinstance(d, ast.PortDecl):
        return "port", d.domain.name if d.domain else "", []
    if isinstance(d, ast.ConstantDecl):
        return "constant", source_of(f, d.expr), []
    if isinstance(d, ast.ComponentDecl):
        return "component", d.doc or "", _symbols(f, d.body)
    if isinstance(d, ast.SceneDecl):
        return "scene", d.doc or "", []
    return None, "", []
