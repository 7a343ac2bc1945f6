"""Stage 4, causality: Scenario -> CausalGraph, by the Sequential Causality Assignment Procedure.

For every bond we decide which end sets its effort (the other end sets its flow).  Order:
sources and constraint junctions (their causality is fixed), storage elements in preferred
integral causality, resistors, then any bond still free; each choice is propagated through
junctions and two-ports before the next.  A choice that contradicts an earlier one is a causal
conflict and names both.  Storage elements left in derivative causality are reported, not refused.

Propagation runs on an explicit stack (a chain of junctions as long as the model is does not
recurse), and every lookup is an index map built once.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from ..base.diagnostics import Collector, ModelError, Note
from ..front.graph import Element, Graph
from .scene import Scenario, Settings


@dataclass(frozen=True)
class CausalGraph:
    """The scene's graph with a causal stroke on every bond."""

    graph: Graph
    settings: Settings
    effort_by: tuple[str, ...]  # per bond (graph order): the node that sets the bond's effort
    derivative: tuple[str, ...]  # storage elements in derivative causality
    arbitrary: tuple[str, ...]  # resistors / bonds whose causality was chosen freely

    def sets_effort(self, bond_index: int, node: str) -> bool:
        return self.effort_by[bond_index] == node


class _Assigner:
    def __init__(self, graph: Graph, diags: Collector):
        self.g = graph
        self.diags = diags
        self.by: list[str | None] = [None] * len(graph.bonds)
        self.origin: list[str | None] = [None] * len(graph.bonds)
        self.incident = graph.incident
        self.elements = graph.by_name
        self.failed = False
        self._pending: list[tuple[str, str]] = []  # (node, origin) still to propagate from

    def assign(self, i: int, setter: str, origin: str, at: str):
        """Bond i's effort is set by `setter`, because of `origin`; propagate from both ends
        (before the caller's next choice: run() drains the stack)."""
        if self.by[i] is not None:
            if self.by[i] != setter and not self.failed:
                self._conflict(i, origin, at)
            return
        self.by[i] = setter
        self.origin[i] = origin
        b = self.g.bonds[i]
        self._pending.append((b.dst, origin))
        self._pending.append((b.src, origin))

    def choose(self, i: int, setter: str, origin: str):
        """A free choice (or a fixed one): assign it and propagate all its consequences."""
        self.assign(i, setter, origin, origin)
        while self._pending:
            node, why = self._pending.pop()
            self.propagate(node, why)

    def _conflict(self, i, origin, at):
        self.failed = True
        first = self.origin[i]
        b = self.g.bonds[i]
        junction = next((n for n in (b.dst, b.src) if self.elements[n].is_junction), at)
        el = self.elements[junction]
        where = f"junction '{junction}'" if el.is_junction else f"'{junction}'"
        what = "its effort" if el.kind == "0" else "its flow" if el.kind == "1" else "causality"
        self.diags.error(self.elements[origin].name_span,
                         f"causal conflict at {where}: '{origin}' and '{first}' both impose {what}"
                         if first != origin else
                         f"causal conflict at {where}: '{origin}' imposes contradictory causality",
                         Note(self.elements[first].name_span, f"'{first}' is declared here"),
                         Note(b.span, "on this bond"))

    def propagate(self, node: str, origin: str):
        el = self.elements[node]
        bonds = self.incident[node]
        if el.is_junction:
            self._junction(el, bonds, origin)
        elif el.spec.ports == 2:
            self._two_port(el, bonds, origin)

    def _junction(self, el: Element, bonds, origin):
        if el.constraint is not None:
            return  # all its bonds were fixed when it was seeded
        bond = self.g.bonds
        # effort "in" at a 0-junction: set by the other end; at a 1-junction, the one bond whose
        # effort the junction computes is the odd one out.
        if el.kind == "0":
            odd = [i for i in bonds if self.by[i] is not None and self.by[i] != el.name]
        else:
            odd = [i for i in bonds if self.by[i] == el.name]
        free = [i for i in bonds if self.by[i] is None]
        if len(odd) > 1 and not self.failed:
            i, j = odd[0], odd[1]
            self.failed = True
            kind = "effort" if el.kind == "0" else "flow"
            a, b = self.origin[j], self.origin[i]
            self.diags.error(self.elements[a].name_span,
                             f"causal conflict at junction '{el.name}': '{a}' and '{b}' both "
                             f"impose its {kind}",
                             Note(self.elements[b].name_span, f"'{b}' is declared here"),
                             Note(el.name_span, f"junction '{el.name}'"))
            return
        if len(odd) == 1:
            for i in free:
                usual = el.name if el.kind == "0" else bond[i].other(el.name)
                self.assign(i, usual, origin, el.name)
        elif len(free) == 1 and not odd:
            i = free[0]
            setter = bond[i].other(el.name) if el.kind == "0" else el.name
            self.assign(i, setter, origin, el.name)

    def _two_port(self, el: Element, bonds, origin):
        known = [i for i in bonds if self.by[i] is not None]
        free = [i for i in bonds if self.by[i] is None]
        if len(known) != 1 or len(free) != 1:
            return
        k, f = known[0], free[0]
        sets_k = self.by[k] == el.name
        # TF passes causality through (sets exactly one effort); GY sets both efforts or none.
        sets_f = (not sets_k) if el.spec.role == "transformer" else sets_k
        self.assign(f, el.name if sets_f else self.g.bonds[f].other(el.name), origin, el.name)


def _seed_fixed(a: _Assigner, defer=frozenset()):
    for el in a.g.elements:
        if el.name in defer:
            continue
        if el.constraint is not None:
            # The multiplier is an unknown effort (0) / flow (1) imposed on every bond.
            for i in a.incident[el.name]:
                setter = el.name if el.kind == "0" else a.g.bonds[i].other(el.name)
                a.choose(i, setter, el.name)
        elif not el.is_junction and el.spec.role == "source":
            (i,) = a.incident[el.name]
            setter = el.name if el.spec.fixed == "effort" else a.g.bonds[i].other(el.name)
            a.choose(i, setter, el.name)


def _preferred_setter(a: _Assigner, el: Element, i: int) -> str:
    sets_effort = el.spec.preferred == "effort"
    return el.name if sets_effort else a.g.bonds[i].other(el.name)


DUAL_SWITCHED = ("switch", "diode")  # switched one-ports that may take either causality


def _dual_switched(el: Element) -> bool:
    return el.constraint is not None and el.constraint.kind in DUAL_SWITCHED and el.kind == "0"


def assign_causality(scenario: Scenario) -> CausalGraph:
    """The causal strokes.  A switch or a diode (bgc.middle.contact) is first the constraint
    junction that imposes its effort (the multiplier; its flow the constrained balance).  Where
    two of them, or one and a source, would impose one junction's effort (a switch and its
    freewheeling diode), their strokes are chosen after the storages' instead (_switched_strokes).
    Where the first form leaves storages in derivative causality (a switch that closes a loop of
    capacitors, a diode across a capacitor), each is tried as the dual junction that imposes its
    flow, and kept so where that leaves fewer (one element at a time, in declaration order)."""
    try:
        causal = _assign(scenario.graph, scenario.settings)
    except ModelError as err:
        causal = _switched_strokes(scenario, err)
    if not causal.derivative:
        return causal
    for el in scenario.graph.elements:
        if not _dual_switched(el):
            continue
        graph = causal.graph
        dual = replace(graph, elements=tuple(replace(e, kind="1") if e.name == el.name else e
                                             for e in graph.elements))
        try:
            trial = _assign(dual, scenario.settings)
        except ModelError:
            continue
        if len(trial.derivative) < len(causal.derivative):
            causal = trial
    return causal


def _switched_strokes(scenario: Scenario, err: ModelError) -> CausalGraph:
    """A causal conflict where switched one-ports meet (coupled switched elements, docs/hybrid.md
    section 13): the procedure again with their strokes left free until the storages' preferred
    ones are propagated, each then imposing its effort where the bond is still free and its
    flow (the dual junction) where the rest of the model already imposes its effort.  So a
    switch in series with a voltage source and a freewheeling diode on the node after it
    become one switch that imposes its current and one diode that imposes the node's voltage.
    The conflict stands (err) where that does not resolve it."""
    graph = scenario.graph
    switched = [el for el in graph.elements if _dual_switched(el)]
    if not switched or any(len(graph.incident[el.name]) != 1 for el in switched):
        raise err  # (a one-port without its one bond is refused where the conflict is)
    a = _strokes(graph, Collector(), frozenset(el.name for el in switched))
    if a.failed:
        raise err
    dual = {el.name for el in switched if a.by[a.incident[el.name][0]] != el.name}
    graph = replace(graph, elements=tuple(replace(e, kind="1") if e.name in dual else e
                                          for e in graph.elements))
    try:
        return _assign(graph, scenario.settings)
    except ModelError:
        raise err from None


def _strokes(graph: Graph, diags: Collector, defer=frozenset()) -> _Assigner:
    """The procedure's choices, in its order: sources and constraint junctions (but those in
    defer), storages in preferred causality, the deferred one-ports in their preferred form
    (imposing their effort) where still free, resistors, then any bond still free."""
    a = _Assigner(graph, diags)
    _seed_fixed(a, defer)
    storage = [el for el in graph.elements if not el.is_junction and el.spec.role == "storage"]
    for el in storage:
        (i,) = a.incident[el.name]
        if a.by[i] is None:
            a.choose(i, _preferred_setter(a, el, i), el.name)
    for el in graph.elements:
        if el.name in defer:
            (i,) = a.incident[el.name]
            if a.by[i] is None:
                a.choose(i, el.name, el.name)
    a.arbitrary = []
    for el in graph.elements:
        if not el.is_junction and el.spec.role == "resistor":
            (i,) = a.incident[el.name]
            if a.by[i] is None:
                a.arbitrary.append(el.name)
                # resistance form e = r f unless the law is written f = EXPR(e)
                sets_effort = not (el.law is not None and el.law[0] == "f")
                a.choose(i, el.name if sets_effort else graph.bonds[i].other(el.name), el.name)
    for i, b in enumerate(graph.bonds):
        if a.by[i] is None:
            a.arbitrary.append(b.label)
            a.choose(i, b.src, b.src)
    return a


def _assign(graph: Graph, settings: Settings) -> CausalGraph:
    diags = Collector()
    a = _strokes(graph, diags)
    _check_junctions(a, diags)
    _check_multibonds(a, diags)
    diags.raise_if_errors()
    storage = [el for el in graph.elements if not el.is_junction and el.spec.role == "storage"]
    derivative = tuple(el.name for el in storage
                       if a.by[a.incident[el.name][0]] != _preferred_setter(
                           a, el, a.incident[el.name][0]))
    return CausalGraph(graph, settings, tuple(a.by), derivative, tuple(a.arbitrary))


def _check_multibonds(a: _Assigner, diags: Collector):
    """A vector bond has one causal stroke: its components must agree on which end sets the
    effort (a multiport transformer then passes flow from its input side, f_out = T f_in, or
    from its output side when T is square: never part one way and part the other)."""
    if a.failed or not a.g.multibonds:
        return
    index = {b.label: i for i, b in enumerate(a.g.bonds)}

    def base(name):
        return a.elements[name].origin or name

    for mb in a.g.multibonds:
        heads = [base(a.by[index[p]]) for p in mb.parts]
        if len(set(heads)) == 1:
            continue
        comps = ", ".join(f"[{k}] by '{h}'" for k, h in enumerate(heads))
        why = ""
        for end in (mb.src, mb.dst):
            v = a.g.vector_by_name.get(end)
            el = a.g.by_name.get(f"{end}.in[0]")
            if v is not None and el is not None and el.origin == end:
                n = sum(1 for p in a.g.elements if p.origin == end and ".in[" in p.name)
                why = (f"; '{end}' ({v.kind}[{n}->{v.dim}]) passes flow from its input side "
                       f"(f_out = T f_in), or from its output side only as a whole and only when "
                       f"T is square")
                if n != v.dim:
                    why += f" (this one is {v.dim}x{n})"
        diags.error(mb.span, f"the vector bond '{mb.src} -> {mb.dst}' gets a different causal "
                             f"stroke in its components (the effort set {comps}): a multibond "
                             f"has one causal stroke{why}. Write the components as scalar bonds "
                             "if they are meant to differ")


def _check_junctions(a: _Assigner, diags: Collector):
    """Every plain junction must have its common variable set by exactly one bond."""
    if a.failed:
        return
    for el in a.g.elements:
        if not el.is_junction or el.constraint is not None or not a.incident[el.name]:
            continue
        bonds = a.incident[el.name]
        if el.kind == "0":
            odd = [i for i in bonds if a.by[i] != el.name]
        else:
            odd = [i for i in bonds if a.by[i] == el.name]
        if len(odd) != 1:
            what = "effort" if el.kind == "0" else "flow"
            diags.error(el.name_span, f"junction '{el.name}': its common {what} is set by "
                                      f"{len(odd)} bonds, it must be set by exactly one")
