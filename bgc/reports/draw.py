"""`bgc draw`: the bond graph as Graphviz DOT, with the causal strokes the compiler assigned.

Not a stage: a report on a compiled model (`bgc.api.Compiled`), drawn as the model was written
(multiports and vector bonds as such, not their scalar parts) and in the scene it was compiled
for.  The conventions (docs/cli.md, "bgc draw"):

- a bond is an edge in the direction of power, with a half-arrow at its head;
- its causal stroke (a `tee`) sits at the end where the effort is *received*: the element at
  that end has the bond's effort as its input and sets its flow; the other end sets the effort
  (`bgc check`'s `effort set by -> flow set by`: the stroke is at the second name).  A source of
  effort has it at the far end (Se --| ), an I in integral causality at its own end (--| I);
- a vector bond (multibond) is a double line labelled with its dimension, and has one stroke;
  junction arrays and multiport elements carry their dimension, `0[2]`, `I[2] : m`;
- signals (integrators, modulations) are thin arrows with a full head; an integrator's initial
  value is an arrow into it;
- a constraint junction carries its Baumgarte corrector as a block diagram (the paper's figures
  3, 4, 7 and 8): the balance B, d/dt, the gains 2 alpha and beta^2 (pid) or gamma (pd), the
  integral
  Phi of B, summed to 0, which determines the multiplier lambda; a holonomic constraint's
  initial-condition annotation is an arrow into the junction (figure 9);
- what the scene leaves out is drawn dashed and grey, not omitted.

Every text from the model (names, doc strings, expressions as written) goes through `_quoted`
or `_html`, so no text can end a DOT string or an HTML label early.  The output depends only on
the model and the scene, in declaration order: the same bytes every run.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the compiler's modules import SymPy: imported when a drawing is made
    from ..front.graph import Element, Graph

FORMATS = ("dot", "svg", "png")
GREY = "gray60"
SIGNAL = "#1f4e9a"
FONT = "Helvetica"
MAX_TEXT = 28  # an expression longer than this is shortened in a label

GRAPHVIZ_HELP = ("Graphviz's `dot` program is not on the PATH: install Graphviz "
                 "(Debian/Ubuntu: apt install graphviz; macOS: brew install graphviz; "
                 "conda: conda install graphviz; https://graphviz.org/download/), or write "
                 "the drawing as DOT with -o FILE.dot, which needs nothing")


class GraphvizMissing(RuntimeError):
    """`dot` is not installed; the message says how to get it."""


class GraphvizFailed(RuntimeError):
    """`dot` refused the drawing (a bug in bgc: the DOT it writes is always valid)."""


# ---------------------------------------------------------------- escaping

_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\ud800-\udfff\ufffe\uffff]")
BACKSLASH = "\u29f5"  # ⧵, shown for a backslash


def _clean(text: str) -> str:
    """Text without the characters XML and DOT cannot hold (line breaks become spaces), and
    without backslashes, shown as ⧵: Graphviz expands \\N, \\G, \\n, ... in labels and
    tooltips, and how a doubled backslash reads differs between its versions and attributes."""
    text = text.replace("\r\n", " ").replace("\r", " ").replace("\n", " ").replace("\t", " ")
    return _CONTROL.sub("", text).replace("\\", BACKSLASH)


def _quoted(text: str) -> str:
    """A DOT double-quoted string showing `text`: quotes escaped, & as &amp; (Graphviz reads
    entities in labels), no backslash left (_clean)."""
    return '"' + _clean(text).replace("&", "&amp;").replace('"', '\\"') + '"'


def _html(text: str) -> str:
    """Text for inside a DOT HTML label (an XML fragment)."""
    text = _clean(text)
    for a, b in (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ('"', "&quot;"),
                 ("'", "&#39;")):
        text = text.replace(a, b)
    return text


def _attrs(**attrs) -> str:
    """[key=value, ...] in the order given (None: left out); an _Html value is an HTML label,
    any other a quoted string."""
    items = []
    for key, value in attrs.items():
        if value is None:
            continue
        if isinstance(value, _Html):
            items.append(f"{key}=<{value.text}>")
        else:
            items.append(f"{key}={_quoted(str(value))}")
    return "[" + ", ".join(items) + "]"


@dataclass(frozen=True)
class _Html:
    text: str  # already escaped


def _label(main: str, sub: str | None = None, grey: bool = False) -> _Html:
    """A node label: `main` as a modeller writes it, `sub` (the element's name) small under it."""
    colour = f' COLOR="{GREY}"' if grey else ""
    text = f"<FONT{colour}>{_html(main)}</FONT>"
    if sub:
        subcolour = GREY if grey else "gray35"
        text += f'<BR/><FONT POINT-SIZE="9" COLOR="{subcolour}">{_html(sub)}</FONT>'
    return _Html(text)


# ---------------------------------------------------------------- the model as written


def _written(compiled) -> Graph:
    """The graph as the model text writes it: multiports whole, every effect in."""
    from ..front.instantiate import front
    from ..front.resolve import resolve
    return resolve(front(compiled.source))


def _text(expr, lines: list[str]) -> str:
    """An expression as the model writes it (shortened), else as bgc reads it."""
    span = expr.span
    text = None
    if span is not None and span.origin is None and 1 <= span.line <= span.end_line <= len(lines):
        if span.line == span.end_line:
            text = lines[span.line - 1][span.col - 1:span.end_col - 1]
        else:
            parts = [lines[span.line - 1][span.col - 1:]]
            parts += lines[span.line:span.end_line - 1]
            parts.append(lines[span.end_line - 1][:span.end_col - 1])
            text = " ".join(parts)
        if "#" in text:
            text = None
    if text is None:
        text = str(expr.value)
    text = " ".join(text.split())
    return text if len(text) <= MAX_TEXT else text[:MAX_TEXT - 1] + "…"


def _kind_text(el: Element) -> str:
    if el.dim is None:
        return el.kind
    n, m = el.dim
    return f"{el.kind}[{n}→{m}]" if n != m else f"{el.kind}[{n}]"


SWITCHED = {"diode": ("D", "ideal diode"), "friction": ("Fr", "dry friction"),
            "switch": ("Sw", "ideal switch"), "unilateral": (None, "unilateral constraint")}


def _element_label(el: Element, lines, grey: bool) -> _Html:
    kind = _kind_text(el)
    if el.is_junction:
        sub = el.name
        switched = SWITCHED.get(el.constraint.kind) if el.constraint is not None else None
        if switched:  # a switched element, or a gap: a constraint junction in one mode
            kind = switched[0] or kind
            if el.constraint.gains and switched[0]:  # Fr(Fc, Fs), Sw(COND)
                kind += "(" + ", ".join(_text(g, lines) for g in el.constraint.gains) + ")"
            sub += f" ({switched[1]})"
        elif el.constraint is not None:
            sub += " (constraint)"
        return _label(kind, sub, grey)
    if el.law is not None:
        main = f"{kind} : {el.law[0]} = {_text(el.law[1], lines)}"
    elif el.value is not None:
        main = f"{kind} : {_text(el.value, lines)}"
    else:
        main = kind
    return _label(main, el.name, grey)


# ---------------------------------------------------------------- causality per written bond


@dataclass(frozen=True)
class DrawnBond:
    """A bond as written, with where its causal stroke is (the node that receives its
    effort, None when the scene left the bond out)."""

    label: str
    src: str
    dst: str
    dim: int
    stroke: str | None
    left_out: bool
    mixed: bool = False


def _port_dim(el: Element) -> int:
    """The dimension of the port a bond leaves element el by."""
    if el.dim is None:
        return 1
    n, m = el.dim
    return m if not el.is_junction and el.spec.ports == 2 else n


def drawn_bonds(compiled, written: Graph | None = None) -> tuple[DrawnBond, ...]:
    """Every bond of the model as written, in order, with its causal stroke: at the end that
    receives the effort, the other end being the one the causality stage says sets it (for a
    vector bond, its parts' setter, all the same)."""
    written = written or _written(compiled)
    g, effort_by = compiled.graph, compiled.causal.effort_by
    index = {b.label: i for i, b in enumerate(g.bonds)}
    vector = {mb.label: mb for mb in g.multibonds}

    def base(name: str) -> str:
        el = g.by_name.get(name)
        return (el.origin or name) if el is not None else name

    out = []
    for b in written.bonds:
        mb = vector.get(b.label)  # (not there when the scene left the bond out)
        parts = mb.parts if mb is not None else (b.label,)
        dim = _port_dim(written.by_name[b.src])
        if not all(p in index for p in parts):
            out.append(DrawnBond(b.label, b.src, b.dst, dim, None, True))
            continue
        setters = list(dict.fromkeys(base(effort_by[index[p]]) for p in parts))
        if len(setters) != 1 or setters[0] not in (b.src, b.dst):
            out.append(DrawnBond(b.label, b.src, b.dst, dim, None, False, mixed=True))
            continue
        stroke = b.dst if setters[0] == b.src else b.src
        out.append(DrawnBond(b.label, b.src, b.dst, dim, stroke, False))
    return tuple(out)


# ---------------------------------------------------------------- the drawing


class _Dot:
    def __init__(self, boxes: dict | None = None):
        self.lines: list[str] = []
        self.depth = 1
        self.boxes = boxes or {}  # collapsed instance path -> its box (with --depth)
        self.seen: set = set()  # edges drawn to or from a box

    def add(self, text: str):
        self.lines.append("  " * self.depth + text)

    def box(self, id_: str) -> str | None:
        """The box of the collapsed instance a node is inside, if it is."""
        return _owner(id_, self.boxes)

    def node(self, id_: str, **attrs):
        if self.box(id_) is None:
            self.add(f"{_quoted(id_)} {_attrs(**attrs)};")

    def edge(self, a: str, b: str, **attrs):
        ba, bb = self.box(a), self.box(b)
        if ba is not None or bb is not None:
            a, b = ba or a, bb or b
            attrs.pop("id", None)
            key = (a, b, _attrs(**attrs))
            if a == b or key in self.seen:
                return  # (inside one box, or drawn already)
            self.seen.add(key)
        self.add(f"{_quoted(a)} -> {_quoted(b)} {_attrs(**attrs)};")


def _owner(name: str, paths) -> str | None:
    """The innermost of the instance paths `paths` that `name` is inside of."""
    k = len(name)
    while True:
        k = max(name.rfind(".", 0, k), -1)
        if k <= 0:
            return None
        if name[:k] in paths:
            return name[:k]


def _instances(dot: _Dot, written: Graph, depth: int | None):
    """One cluster per instance, holding the nodes of its elements and signals (a node first
    named in a cluster is drawn in it); below `depth` levels, an instance is one box with its
    ports instead."""
    paths = {i.path: i for i in written.instances}
    children: dict = {}
    for inst in written.instances:
        children.setdefault(_owner(inst.path, paths), []).append(inst)
    nodes: dict = {}
    for name in [el.name for el in written.elements] + [s.name for s in written.signals]:
        nodes.setdefault(_owner(name, paths), []).append(name)
    ports: dict = {}
    for p in written.ports:
        owner, _, local = p.name.rpartition(".")
        ports.setdefault(owner, []).append(local + (f"[{p.dim}]" if p.dim > 1 else "")
                                           + (f" : {p.domain}" if p.domain else ""))
    stack = [(inst, 1) for inst in reversed(children.get(None, []))]
    while stack:
        inst, level = stack.pop()
        if inst is None:
            dot.depth -= 1
            dot.add("}")
            continue
        title = f"{inst.path} : {inst.component}"
        if depth is not None and level > depth:
            listed = ports.get(inst.path)
            sub = "ports " + ", ".join(listed) if listed else "no ports"
            dot.node(inst.path, shape="box", style="rounded,filled", fillcolor="gray95",
                     label=_label(title, sub), tooltip=inst.doc or title)
            continue
        dot.add(f"subgraph {_quoted('cluster ' + inst.path)} {{")
        dot.depth += 1
        dot.add(f"label={_quoted(title)}; tooltip={_quoted(inst.doc or title)}; fontsize=11; "
                f"style=rounded; color=gray50;")
        for name in nodes.get(inst.path, ()):
            dot.add(f"{_quoted(name)};")
        stack.append((None, level))
        stack += [(c, level + 1) for c in reversed(children.get(inst.path, []))]


def _bond_edge(dot: _Dot, b: DrawnBond):
    """A bond: dir=both, the half-arrow (lvee) at its head, the stroke (tee) at the end that
    receives the effort, nearest the node; a multibond as a double line with its dimension."""
    left_out = b.left_out
    head = "tee" if b.stroke == b.dst else ""
    tail = "tee" if b.stroke == b.src else "none"
    attrs = dict(dir="both", arrowhead=head + "lvee", arrowtail=tail, arrowsize="1.0",
                 id=f"bond {b.label}")
    if b.dim > 1:
        colour = GREY if left_out else "black"
        attrs.update(color=f"{colour}:{colour}", label=f"{b.dim}", penwidth="1.0")
    else:
        attrs.update(penwidth="1.3")
    if left_out:
        attrs.update(style="dashed", fontcolor=GREY)
        if b.dim == 1:
            attrs.update(color=GREY)
    if b.mixed:
        attrs.update(xlabel="mixed causality")
    dot.edge(b.src, b.dst, **attrs)


def _signal_edge(dot: _Dot, a: str, b: str, grey: bool, **attrs):
    colour = GREY if grey else SIGNAL
    base = dict(color=colour, fontcolor=colour, arrowsize="0.6", penwidth="0.8")
    if grey:
        base["style"] = "dashed"
    base.update(attrs)
    dot.edge(a, b, **base)


def _init_arrow(dot: _Dot, target: str, text: str, grey: bool, tooltip: str):
    """An initial value drawn as the paper draws it for integrators: an arrow into the block."""
    node = f"{target}:init"
    dot.node(node, shape="plaintext", label=_label(text, None, grey), fontsize="10",
             tooltip=tooltip)
    _signal_edge(dot, node, target, grey, arrowhead="normal", style="dotted")


def _gain(text: str, square: bool = False, factor: str = "") -> str:
    simple = re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*|[0-9.eE+-]+", text) is not None
    inner = text if simple else f"({text})"
    return f"{factor}{inner}²" if square else f"{factor}{inner}"


def _corrector(dot: _Dot, el: Element, kind: str, off: str | None, lines, grey: bool):
    """The block diagram of a constraint junction's corrector (figures 3, 4, 7, 8): the
    junction's balance B, d/dt B, the gains on B and on its integral, summed to 0, which the
    multiplier is found to satisfy, drawn back into the junction.  off: why the scene turned
    the corrector off (its gains are then grey)."""
    c, name = el.constraint, el.name
    holonomic = kind == "holonomic"
    b_text = "dΦ/dt" if holonomic else "Φ"
    what = "effort" if el.kind == "1" else "flow"
    gains = [_text(g, lines) for g in c.gains]
    title = f"corrector {c.corrector}" + (f"({', '.join(gains)})" if gains else "")
    if off:
        title += f": left out ({off})"
    colour = GREY if grey else SIGNAL
    dot.add(f"subgraph {_quoted('cluster corrector ' + name)} {{")
    dot.depth += 1
    dot.add(f"label={_quoted(title)}; fontsize=10; fontname={_quoted(FONT)}; "
            f"style=\"rounded,dashed\"; color={_quoted(colour)}; fontcolor={_quoted(colour)};")
    ids = {k: f"{name}:{k}" for k in ("B", "d", "k1", "int", "k2", "sum")}
    dot.node(ids["B"], shape="plaintext", label=_label(b_text, f"{what} balance of {name}", grey),
             tooltip=f"the {what} balance of {name}: {b_text} ({kind})")
    dot.node(ids["d"], label=_label("d/dt", None, grey), shape="box", fontsize="11",
             height="0.3", color=colour)
    dot.node(ids["sum"], shape="circle", label=_label("Σ = 0", None, grey), fontsize="10",
             width="0.5", fixedsize="true", color=colour,
             tooltip=f"the multiplier {name}.lambda makes this sum 0")
    _signal_edge(dot, ids["B"], ids["d"], grey)
    _signal_edge(dot, ids["d"], ids["sum"], grey, label="d²Φ/dt²" if holonomic else "dΦ/dt",
                 fontsize="9")
    gone = grey or off is not None
    box = dict(shape="box", fontsize="11", height="0.3", color=GREY if gone else SIGNAL)
    if c.corrector == "pid":
        dot.node(ids["k1"], label=_label(_gain(gains[0], factor="2·"), None, gone), **box)
        dot.node(ids["int"], label=_label("∫", None, gone), **box)
        dot.node(ids["k2"], label=_label(_gain(gains[1], square=True), None, gone), **box)
        for a, b, extra in (("B", "k1", {}), ("k1", "sum", {}), ("B", "int", {}),
                            ("int", "k2", dict(label="Φ", fontsize="9")), ("k2", "sum", {})):
            _signal_edge(dot, ids[a], ids[b], gone, **extra)
        _init_arrow(dot, ids["int"], _annotation(c, lines) or "Φ(0) = 0", gone,
                    "the integrator's initial condition: the constant term of the geometric "
                    "constraint")
    elif c.corrector == "pd":
        dot.node(ids["k1"], label=_label(_gain(gains[0]), None, gone), **box)
        _signal_edge(dot, ids["B"], ids["k1"], gone)
        _signal_edge(dot, ids["k1"], ids["sum"], gone)
    dot.depth -= 1
    dot.add("}")
    _signal_edge(dot, name, ids["B"], grey)  # outside the cluster: the junction is not in it
    _signal_edge(dot, ids["sum"], name, grey, label="λ (flow)" if what == "effort" else "λ",
                 fontsize="10", constraint="false", tooltip=f"{name}.lambda, the multiplier")


def _annotation(c, lines) -> str | None:
    """A holonomic constraint's initial-condition annotation as the drawing shows it."""
    if c.annotation is None:
        return None
    which, expr = c.annotation
    return _text(expr, lines) if which == "init" else "Φ = " + _text(expr, lines)


@dataclass(frozen=True)
class _Scene:
    """What the drawing needs of the compiled scene, by declared name."""

    kept: frozenset  # elements the scene keeps
    why: dict  # left out -> why
    kinds: dict  # constraint junction -> holonomic | nonholonomic, as the compiler found
    correctors: dict  # constraint junction -> its corrector in this scene


def _scene(compiled) -> _Scene:
    g = compiled.graph

    def base(name):
        el = g.by_name.get(name)
        return (el.origin or name) if el is not None else name

    kinds = {}
    for k in compiled.reduced.constraints:
        kinds.setdefault(base(k.junction), k.kind)
    correctors = {base(el.name): el.constraint.corrector for el in g.elements
                  if el.constraint is not None}
    return _Scene(frozenset(base(el.name) for el in g.elements),
                  dict(compiled.settings.left_out), kinds, correctors)


def _title(written: Graph, settings) -> str:
    where = f"scene {settings.scene}" if settings.scene else "default scene"
    if "effects" in settings.given:
        where += ", effects " + (", ".join(settings.effects) or "none")
    return written.name + (f": {written.doc}" if written.doc else "") + f"  ({where})"


def _elements(dot: _Dot, written: Graph, sc: _Scene, lines):
    for el in written.elements:
        grey = el.name not in sc.kept
        tip = el.doc or ""
        if grey:
            tip = (tip + "; " if tip else "") + f"left out by the scene: {sc.why.get(el.name, '')}"
        dot.node(el.name, tooltip=tip or el.name, shape="plaintext",
                 label=_element_label(el, lines, grey))


def _signals(dot: _Dot, written: Graph, sc: _Scene, lines):
    """Signals as blocks (an integrator with its initial value), with an arrow from what each
    reads; then an arrow from each signal or element an element's value reads (modulation)."""
    names = {s.name for s in written.signals} | set(written.by_name)
    for s in written.signals:
        grey = s.name in sc.why
        tip = f"signal {s.name}" + (f": left out by the scene: {sc.why[s.name]}" if grey else "")
        box = dict(shape="box", fontsize="12", height="0.3", color=GREY if grey else SIGNAL,
                   style="dashed" if grey else None, tooltip=tip)
        if s.is_integral:
            dim = f" [{s.dim}]" if s.dim else ""
            dot.node(s.name, label=_label("∫", s.name + dim, grey), **box)
            _init_arrow(dot, s.name, _text(s.init, lines), grey, f"the initial value of {s.name}")
        else:
            dot.node(s.name, label=_label(f"{s.name} = {_text(s.expr, lines)}", None, grey),
                     **box)
        for owner in dict.fromkeys(o for o, _ in s.expr.refs):
            if owner in names:
                _signal_edge(dot, owner, s.name, grey or owner in sc.why)
    for el in written.elements:
        refs = [o for e in (el.value, el.law and el.law[1]) if e is not None for o, _ in e.refs]
        for owner in dict.fromkeys(refs):
            if owner in names and owner != el.name:
                _signal_edge(dot, owner, el.name, el.name not in sc.kept or owner in sc.why)


def _constraints(dot: _Dot, written: Graph, sc: _Scene, lines):
    for el in written.elements:
        c = el.constraint
        if c is None or dot.box(el.name) is not None:
            continue
        grey = el.name not in sc.kept
        kind = sc.kinds.get(el.name) or c.kind or (
            "nonholonomic" if c.corrector == "pd" else "holonomic")
        off = None
        if c.corrector != "none" and sc.correctors.get(el.name, c.corrector) == "none":
            off = "tagged " + " ".join("@" + e for e in el.effects)
        _corrector(dot, el, kind, off, lines, grey)
        text = _annotation(c, lines)
        if text is not None:
            _init_arrow(dot, el.name, text, grey, "the geometric constraint's initial "
                                                  "condition (the paper's figure 9)")


def draw_dot(compiled, depth: int | None = None) -> str:
    """The bond graph of `compiled` (a bgc.api.Compiled) as Graphviz DOT text: the model as
    written, in the compiled scene, with the causal strokes its causality stage assigned;
    each instance of a component a cluster, those more than `depth` levels down (0: every
    instance) collapsed into boxes."""
    written = _written(compiled)
    lines = compiled.source.text.splitlines()
    sc = _scene(compiled)
    boxes = {}
    if depth is not None:
        paths = {i.path for i in written.instances}
        for inst in written.instances:
            level, up = 1, _owner(inst.path, paths)
            while up is not None:
                level, up = level + 1, _owner(up, paths)
            if level == depth + 1:
                boxes[inst.path] = inst.path
    dot = _Dot(boxes)
    dot.lines = ["// bgc draw: the bond graph with its causal strokes (docs/cli.md)",
                 f"digraph {_quoted(written.name)} {{"]
    dot.add(f"graph [rankdir=LR, nodesep=0.45, ranksep=0.6, fontname={_quoted(FONT)}, "
            f"fontsize=12, labelloc=t, label={_quoted(_title(written, compiled.settings))}];")
    dot.add(f"node [fontname={_quoted(FONT)}, fontsize=13, margin=\"0.04,0.02\"];")
    dot.add(f"edge [fontname={_quoted(FONT)}, fontsize=10];")
    _instances(dot, written, depth)
    _elements(dot, written, sc, lines)
    for b in drawn_bonds(compiled, written):
        _bond_edge(dot, b)
    _signals(dot, written, sc, lines)
    _constraints(dot, written, sc, lines)
    dot.lines.append("}")
    return "\n".join(dot.lines) + "\n"


# ---------------------------------------------------------------- rendering


def format_of(path: str) -> str | None:
    """The drawing format a file name asks for (its extension), or None."""
    m = re.search(r"\.([A-Za-z]+)$", str(path))
    fmt = m.group(1).lower() if m else None
    return fmt if fmt in FORMATS else None


def have_graphviz() -> bool:
    return shutil.which("dot") is not None


def render(dot_text: str, fmt: str) -> bytes:
    """The drawing in format fmt ("dot", "svg" or "png"); svg and png run Graphviz's `dot`
    (GraphvizMissing when it is not installed)."""
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {', '.join(map(repr, FORMATS))}, not {fmt!r}")
    if fmt == "dot":
        return dot_text.encode("utf-8")
    exe = shutil.which("dot")
    if exe is None:
        raise GraphvizMissing(GRAPHVIZ_HELP)
    done = subprocess.run([exe, f"-T{fmt}"], input=dot_text.encode("utf-8"),
                          capture_output=True, timeout=120)
    if done.returncode != 0:
        raise GraphvizFailed(f"dot -T{fmt} failed: "
                             + done.stderr.decode("utf-8", "replace").strip())
    return done.stdout


__all__ = ["draw_dot", "render", "drawn_bonds", "format_of", "have_graphviz",
           "GraphvizMissing", "GraphvizFailed", "FORMATS"]
