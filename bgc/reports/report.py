"""Stable text dumps of the intermediate values: `bgc check` and `bgc equations`."""
from __future__ import annotations

import itertools
from collections import Counter
from dataclasses import dataclass

import sympy as sp

from ..front import events
from .. import ir
from ..front.graph import model_effects
from ..ir import Table, defines
from ..middle.reduce import BlockInfo, explicit_forms, shown_steps

TWO_PORTS = ("TF", "MTF", "GY", "MGY")

METHODS = {"symbolic": "solved symbolically", "lu": "solved numerically (LU)",
           "newton": "solved numerically (Newton)"}
KINDS = {"I": "I, integral causality", "C": "C, integral causality",
         "integral signal": "integral signal"}


class _Printer(sp.printing.str.StrPrinter):
    """sstr, with floats as the shortest text that reads back as the same double."""

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_Piecewise(self, expr):
        """As the language writes it: if C then A elif C2 then B else D."""
        pairs = list(expr.args)
        text = "if " + " elif ".join(f"{self._print(p.cond)} then {self._print(p.expr)}"
                                     for p in pairs[:-1])
        return f"({text} else {self._print(pairs[-1].expr)})"

    def _print_And(self, expr):
        return "(" + " and ".join(self._print(a) for a in expr.args) + ")"

    def _print_Or(self, expr):
        return "(" + " or ".join(self._print(a) for a in expr.args) + ")"

    def _print_Not(self, expr):
        return f"not {self._print(expr.args[0])}"


def _s(expr) -> str:
    return _Printer({"order": "lex"}).doprint(expr)


def _header(compiled) -> list[str]:
    s = compiled.settings
    line = f"model {compiled.graph.name}" + (f", scene {s.scene}" if s.scene
                                             else ", default scene")
    if s.given:
        line += f" ({' and '.join(s.given)} given ad hoc)"
    return [line]


# ---------------------------------------------------------------- what a scene saves

OP_KINDS = ("add", "neg", "mul", "div", "call", "solve")


@dataclass(frozen=True)
class SceneSummary:
    """A scene against the full model (all effects, every state an output): what it leaves
    out with its effects, what its outputs do not need (pruned), and the operations of the
    generated right side and outputs (counted on the IR, bgc.ir.count_ops) in both."""

    effects_in: tuple[str, ...]
    effects_out: tuple[str, ...]
    left_out: tuple[tuple[str, tuple[str, ...]], ...]  # (why, the declared names) left out
    correctors_off: tuple[tuple[str, tuple[str, ...]], ...]  # (junction, its effects)
    states_kept: tuple[str, ...]
    states_pruned: tuple[str, ...]  # in the scene's physics, needed by no output
    states_out: tuple[str, ...]  # left out with the effects
    full_states: int
    blocks_kept: tuple  # the scene's BlockInfos
    blocks_pruned: tuple  # the full model's BlockInfos the scene's outputs do not need
    blocks_out: tuple  # ... that come from elements left out with the effects
    unknowns: tuple[int, int]  # algebraic unknowns: the scene's, the full model's
    ops: dict  # {("scene" | "full", "rhs" | "outputs"): Counter}


def _base_names(graph) -> set:
    return {el.origin or el.name for el in graph.elements} | {s.name for s in graph.signals}


def scene_summary(compiled, full) -> SceneSummary:
    """compiled: a scene (with its program); full: the same model's default scene."""
    known = model_effects(full.graph.elements)
    chosen = compiled.settings.effects
    effects_in = known if chosen is None else tuple(e for e in known if e in chosen)
    groups: dict[str, list[str]] = {}
    for name, why in compiled.settings.left_out:
        groups.setdefault(why, []).append(name)
    left_out = tuple((why, tuple(names)) for why, names in groups.items())
    by_name = compiled.graph.by_name
    correctors_off = tuple(dict.fromkeys(
        (el.origin or el.name, el.effects) for el in full.graph.elements
        if el.constraint is not None and el.constraint.corrector != "none"
        and el.name in by_name and by_name[el.name].constraint.corrector == "none"))
    in_physics = {st.name for st in compiled.system.states}
    kept = tuple(st.name for st in compiled.reduced.states)
    full_states = [st.name for st in full.reduced.states]
    kept_unknowns = {u for b in compiled.reduced.blocks for u in b.unknowns}
    names = _base_names(compiled.graph)
    pruned, out = [], []
    for b in full.reduced.blocks:
        if kept_unknowns.intersection(b.unknowns):
            continue
        (pruned if all(o in names for o in b.origins) else out).append(b)
    ops = {}
    for key, c in (("scene", compiled), ("full", full)):
        for fn in ("rhs", "outputs"):
            ops[key, fn] = ir.count_ops(c.program, (fn,))
    return SceneSummary(
        effects_in, tuple(e for e in known if e not in effects_in), left_out,
        correctors_off, kept,
        tuple(compiled.reduced.pruned), tuple(n for n in full_states if n not in in_physics),
        len(full_states), tuple(compiled.reduced.blocks), tuple(pruned), tuple(out),
        (sum(len(b.unknowns) for b in compiled.reduced.blocks),
         sum(len(b.unknowns) for b in full.reduced.blocks)), ops)


def _total(c: Counter) -> int:
    return sum(c[k] for k in OP_KINDS)


def _summary_lines(sm: SceneSummary) -> list[str]:
    lines = ["scene against the full model (all effects, every state an output):"]
    lines.append(f"  effects in: {', '.join(sm.effects_in) or 'none'}; left out: "
                 f"{', '.join(sm.effects_out) or 'none'}")
    if sm.left_out:
        lines.append("  left out:")
        lines += [f"    {why}: {', '.join(names)}" for why, names in sm.left_out]
    if sm.correctors_off:
        lines.append("  correctors set to none with their effects: " + ", ".join(
            f"{name} ({' '.join('@' + e for e in effects)})"
            for name, effects in sm.correctors_off))
    lines.append(f"  states: {len(sm.states_kept)} of {sm.full_states} integrated")
    if sm.states_out:
        lines.append(f"    left out with the effects ({len(sm.states_out)}): "
                     + ", ".join(sm.states_out))
    if sm.states_pruned:
        lines.append(f"    pruned, no output needs them ({len(sm.states_pruned)}): "
                     + ", ".join(sm.states_pruned))
    lines.append(f"  algebraic blocks: {len(sm.blocks_kept)} kept; algebraic unknowns "
                 f"{sm.unknowns[0]} of {sm.unknowns[1]}")

    def blocks(bs):
        return "; ".join(f"{', '.join(b.unknowns)} (through {', '.join(b.origins)})" for b in bs)

    if sm.blocks_pruned:
        lines.append(f"    pruned, no output needs them ({len(sm.blocks_pruned)}): "
                     + blocks(sm.blocks_pruned))
    if sm.blocks_out:
        lines.append(f"    left out with the effects ({len(sm.blocks_out)}): "
                     + blocks(sm.blocks_out))
    lines.append("  operations of the generated code (full model -> this scene):")
    lines.append(f"    {'':8}{'right side':^19}{'outputs':^19}".rstrip())
    kinds = [k for k in OP_KINDS if any(sm.ops[key][k] for key in sm.ops)]
    for k in kinds + ["total"]:
        cells = []
        for fn in ("rhs", "outputs"):
            a, b = ((_total(sm.ops[w, fn]) if k == "total" else sm.ops[w, fn][k])
                    for w in ("full", "scene"))
            cells.append(f"{a:>8} -> {b:<7}")
        lines.append(f"    {k:8}{cells[0]}{cells[1]}".rstrip())
    return lines


def _event_lines(sel) -> list[str]:
    """The scene's events (docs/hybrid.md): each condition and what kind of event it is, the
    square waves, the discrete variables and the when-blocks."""
    if sel is None:
        return []
    out = ["events:"]
    out += [f"  {r.text}  (state event: located on the step's dense output)" for r in sel.state]
    out += [f"  {r.text}  (time event at t = {_s(at)})" if not events.never(at) else
            f"  {r.text}  (no event: its time is beyond a double, no run reaches it)"
            for r, at, _ in sel.time]
    out += [f"  {r.text}  (changes at events only)" for r in sel.discrete]
    out += [f"  {q.text}  (time events at its "
            f"{'edges' if q.kind == 'square' else 'breakpoints'})" for q in sel.squares
            if q.kind != "input"]
    out += [f"  input {q.text}  (time events at its data's breakpoints)" for q in sel.squares
            if q.kind == "input" and q.part == 1]
    out += [f"  discrete {d.name} = {_s(d.init)}" for d in sel.discretes]
    for w in sel.whens:
        acts = "; ".join(f"{'reinit ' if a.kind == 'reinit' else ''}{a.name} = {_s(a.expr)}"
                         for a in w.actions)
        out.append(f"  when {w.text} {{ {acts} }}")
    return out


def check_report(compiled, summary: SceneSummary | None = None) -> str:
    g, cg, r = compiled.graph, compiled.causal, compiled.reduced
    lines = _header(compiled)
    if summary is not None:
        lines += _summary_lines(summary)
    if g.instances:
        lines.append(f"instances ({len(g.instances)}):")
        ports: dict = {}
        for p in g.ports:
            owner, _, name = p.name.rpartition(".")
            ports.setdefault(owner, []).append(name + (f"[{p.dim}]" if p.dim > 1 else "")
                                               + (f" : {p.domain}" if p.domain else ""))
        for inst in g.instances:
            listed = ports.get(inst.path)
            lines.append(f"  {inst.path}  {inst.component}"
                         + (f", ports {', '.join(listed)}" if listed else ""))
    lines.append(f"states ({len(r.states)}):")
    units = dict(g.units) if g.units_checked else {}
    lines += [f"  {st.name}  {KINDS[st.kind]}" + (f", in {units[st.name]}" if st.name in units
                                                  else "") for st in r.states]
    if g.inputs:
        lines.append(f"inputs ({len(g.inputs)}; their data from --input, else the default):")
        lines += [f"  {u.name} = {_s(u.default)}" + (f"  \"{u.doc}\"" if u.doc else "")
                  for u in g.inputs]
    if g.tables:
        lines.append(f"tables ({len(g.tables)}):")
        for k, t in enumerate(g.tables):
            lines.append(f"  {k}: {t.name}, {t.rows} rows, x from {t.x[0]!r} to {t.x[-1]!r}, "
                         f"interp = {t.interp}, extrapolate = {t.extrapolate}"
                         + ("; a table of t: its rows are time events" if t.time else
                            "; a law of its abscissa (no events)"))
    if r.pruned:
        lines.append("not integrated (no output needs them): " + ", ".join(r.pruned))
    lines.append("causality (bond: effort set by -> flow set by):")
    lines += _causality_lines(g, cg)
    fields = getattr(compiled.system, "fields", ())
    if fields:
        lines.append("coupled fields (I: M f = p, C: K e = q, solved in the generated code):")
        for name, coords in fields:
            how = (f"Hamiltonian form, dp/dt = e - dT/dq with T = p^T M^-1 p / 2, in "
                   f"{', '.join(coords)}") if coords else \
                "its matrix does not depend on its own coordinates"
            lines.append(f"  {name}: {how}")
    lines += _event_lines(r.events)
    if r.eliminated:
        lines.append("derivative causality (dependent states, eliminated):")
        lines += [f"  {name} = {_s(e) if isinstance(e, sp.Basic) else e}"
                  for name, e in r.eliminated]
    if r.blocks:
        lines.append("algebraic blocks:")
        for b in r.blocks:
            kind = "linear" if b.linear else "nonlinear"
            origins = list(dict.fromkeys(
                (g.by_name[o].origin or o) if o in g.by_name else o for o in b.origins))
            lines.append(f"  {b.index}: {', '.join(b.unknowns)} ({len(b.unknowns)} unknown"
                         f"{'s' * (len(b.unknowns) > 1)}) through {', '.join(origins)}: "
                         f"{kind}, {METHODS[b.method]}" + (f"; {b.note}" if b.note else ""))
    if r.constraints:
        lines.append("constraints:")
        computed = _computed(r)
        for k in r.constraints:
            how = "detected" if k.detected else "declared"
            gains = f"({', '.join(_s(g) for g in k.gains)})" if k.gains and \
                k.corrector != "none" else ""
            pruned = "" if k.multiplier in computed else \
                "; pruned: no output needs it or its states"
            lines.append(f"  {k.junction}: {k.kind} ({how}), corrector {k.corrector}{gains}"
                         f"{pruned}")
            if k.phi is not None:
                lines.append(f"    Phi = {_s(k.phi)}")
            level = "dPhi/dt" if k.kind in ("holonomic", "unilateral") else "Phi"
            lines.append(f"    {level} = {_s(k.balance)}")
    if g.units_checked:
        lines.append(f"units: every law checked; {len(g.units)} quantities' units known "
                     "(declared or inferred: bgc.units, simulate --units)")
    lines.append(f"warnings: {len(r.warnings)}")
    return "\n".join(lines) + "\n"


def _computed(reduced) -> set:
    """Every variable the program's steps define (blocks: their unknowns and body)."""
    out = set()
    for step in reduced.steps:
        out.update(defines(step))
    return out


def _causality_lines(g, cg) -> list[str]:
    """One line per bond as written: a vector bond `v->mass [2]` has one causal stroke (its
    parts', when they agree); the scalar network inside a multiport transformer is not shown."""
    part_of = {label: mb for mb in g.multibonds for label in mb.parts}
    index = {b.label: i for i, b in enumerate(g.bonds)}

    def base(name):
        return g.by_name[name].origin or name

    def inner(name):
        origin = g.by_name[name].origin
        return origin is not None and g.vector_by_name[origin].kind in TWO_PORTS

    lines, shown = [], set()
    for b, by in zip(g.bonds, cg.effort_by):
        mb = part_of.get(b.label)
        if mb is None:
            if not (inner(b.src) and inner(b.dst)):
                lines.append(f"  {b.label}: {base(by)} -> {base(b.other(by))}")
            continue
        if mb.label in shown:
            continue
        shown.add(mb.label)
        setters = [cg.effort_by[index[p]] for p in mb.parts]
        heads = {base(s) for s in setters}
        if len(heads) == 1:
            (head,) = heads
            tail = mb.dst if head == mb.src else mb.src
            lines.append(f"  {mb.label} [{mb.dim}]: {head} -> {tail}")
        else:
            mixed = ", ".join(f"{p}: {s}" for p, s in zip(mb.parts, setters))
            lines.append(f"  {mb.label} [{mb.dim}]: mixed ({mixed})")
    return lines


def _relations(compiled) -> dict:
    """Each relation's symbol -> the relation, for reports (docs/hybrid.md)."""
    g = compiled.graph
    return {r.symbol: r.relation for r in getattr(g, "relations", ())}


MAX_MODE_COMBINATIONS = 8  # beyond, each element's modes are shown with the others as written


def _modes(reduced) -> list:
    """The switched elements' and unilateral junctions' modes: [(discrete's name, its
    symbol)], each taking the values 1 and 0 (docs/hybrid.md)."""
    sel = reduced.events
    if sel is None:
        return []
    kinds = {f"{c.junction}.active" for c in reduced.constraints
             if c.kind == "unilateral" or c.kind in ("diode", "friction", "switch")}
    return [(d.name, d.symbol) for d in sel.discretes if d.symbol.name in kinds]


def _mode_lines(reduced, forms, _s) -> list[str]:
    """The equations in each mode: every combination of the modes' values when there are
    few, else each mode in turn with the others as written.  forms: the explicit forms of the
    rates and multipliers, or None: then the equations of the algebraic blocks that read a
    mode (the rest is the same in every mode)."""
    modes = _modes(reduced)
    if not modes:
        return []
    if forms is not None:
        targets = [(f"d({st.name})/dt", forms[d]) for st, d in
                   zip(reduced.states, reduced.rates)] + \
            [(f"{k.junction}.lambda", forms[k.multiplier]) for k in reduced.constraints]
    else:
        symbols = {sym for _, sym in modes}
        targets = [(f"0 (block {step.index})", e) for step in shown_steps(reduced)
                   if isinstance(step, BlockInfo) for e in step.residuals
                   if e.free_symbols & symbols]
    if 2 ** len(modes) <= MAX_MODE_COMBINATIONS:
        cases = [dict(zip(modes, bits)) for bits in
                 itertools.product((1, 0), repeat=len(modes))]
    else:
        cases = [{m: v} for m in modes for v in (1, 0)]
    lines = ["modes (the equations in each; the event log names the modes):"]
    for case in cases:
        lines.append("  " + ", ".join(f"{name} = {v}" for (name, _), v in case.items()) + ":")
        values = {sym: sp.Integer(v) for (_, sym), v in case.items()}
        for name, expr in targets:
            lines.append(f"    {name} = {_s(_tidy_mode(expr.xreplace(values)))}")
    return lines


def _tidy_mode(expr):
    """A mode's equation, its conditionals decided, in a simpler form where that is cheap."""
    from ..base.resources import fits
    if not fits(expr) or sp.count_ops(expr) > 200:
        return expr
    return sp.simplify(expr)


def _inputs_as_names(graph) -> dict:
    """An input's discrete values (bgc.front.events.InputSlot) -> what the equations show: its
    name (its segment's start and slope are the data's, not the model's)."""
    out = {}
    for j, u in enumerate(graph.inputs):
        out[sp.Symbol(f"input#{j}.0", real=True)] = sp.Integer(0)
        out[sp.Symbol(f"input#{j}.1", real=True)] = sp.Symbol(u.name)
        out[sp.Symbol(f"input#{j}.2", real=True)] = sp.Integer(0)
    return out


def _tables_as_written(expr, tables):
    """Table(k, X, ...) as table(SOURCE, X, options), its derivatives with primes."""
    found = expr.atoms(Table) if tables else ()
    if not found:
        return expr
    out = {}
    for node in found:
        k, X, _, order = node.args
        t = tables[int(k)]
        options = [sp.Symbol(f"interp = {t.interp}")] if t.interp != "linear" else []
        options += [sp.Symbol(f"extrapolate = {t.extrapolate}")] \
            if t.extrapolate != "hold" else []
        out[node] = sp.Function("table" + "'" * int(order))(sp.Symbol(t.name), X, *options)
    return expr.xreplace(out)


def equations_text(compiled) -> str:
    r = compiled.reduced
    shown = _relations(compiled)
    if r.events is not None:  # a mode's value by its name in the event log
        shown = {**shown, **{sym: sp.Symbol(name) for name, sym in _modes(r)}}

    inputs = _inputs_as_names(compiled.graph)

    def _s(expr) -> str:  # (the relations as written, in place of their frozen values)
        expr = expr.xreplace(shown) if shown else expr
        expr = _tables_as_written(expr.xreplace(inputs) if inputs else expr,
                                  compiled.graph.tables)
        return _Printer({"order": "lex"}).doprint(expr)

    lines = _header(compiled)
    lines.append("parameters:")
    lines += [f"  {p.name} = {_s(p.expr)}" for p in r.parameters]
    lines.append("initial values:")
    lines += [f"  {st.name}(t0) = {_s(st.init)}" for st in r.states]
    multipliers = [k.multiplier for k in r.constraints]
    out_syms = [o.expr for o in r.outputs]
    forms = explicit_forms(r, list(r.rates) + multipliers + out_syms)
    if forms is not None:
        lines.append("state equations:")
        lines += [f"  d({st.name})/dt = {_s(forms[d])}" for st, d in zip(r.states, r.rates)]
        if multipliers:
            lines.append("multipliers:")
            lines += [f"  {k.junction}.lambda = {_s(forms[k.multiplier])}"
                      for k in r.constraints]
        lines.append("outputs:")
        lines += [f"  {o.name} = {_s(forms[o.expr])}" for o in r.outputs]
        lines += _mode_lines(r, forms, _s)
        return "\n".join(lines) + "\n"
    lines.append("program (in evaluation order; blocks solved numerically in the generated code):")
    for step in shown_steps(r):
        if isinstance(step, BlockInfo):
            z = ", ".join(step.unknowns)
            how = "A z = b, LU" if step.method == "lu" else "Newton's method"
            lines.append(f"  block {step.index} ({how}) for {z}:")
            lines += [f"    0 = {_s(e)}" for e in step.residuals]
            lines += [f"    where {a.target} = {_s(a.expr)}" for a in step.body]
        else:
            lines.append(f"  {step.target} = {_s(step.expr)}")
    lines.append("state equations:")
    lines += [f"  d({st.name})/dt = {d}" for st, d in zip(r.states, r.rates)]
    lines.append("outputs:")
    lines += [f"  {o.name} = {_s(o.expr)}" for o in r.outputs]
    lines += _mode_lines(r, None, _s)
    return "\n".join(lines) + "\n"


def equations_latex(compiled) -> str:
    """The equations as LaTeX in the paper's notation (bgc/reports/latex.py)."""
    from .latex import latex_system
    return latex_system(compiled, _header(compiled)[0]).text()


# ---------------------------------------------------------------- bgc scenes


def _text_of(expr, lines) -> str:
    """An expression as the model wrote it (one line), else as bgc reads it."""
    sp_ = expr.span
    if sp_ is not None and sp_.origin is None and sp_.line == sp_.end_line \
            and 1 <= sp_.line <= len(lines):
        return lines[sp_.line - 1][sp_.col - 1:sp_.end_col - 1]
    return _s(expr.value)


def scenes_report(graph, source: str) -> str:
    lines = source.splitlines()
    known = model_effects(graph.elements)
    n = len(graph.scenes)
    out = [f"model {graph.name}: {n} scene{'s' * (n != 1)}; effects: "
           f"{', '.join(known) or 'none'}"]
    out.append("default scene (no --scene): every effect, every state an output, "
               "time 0 .. 10 every 0.01")
    for sc in graph.scenes:
        out.append(f"scene {sc.name}" + (f": {sc.doc}" if sc.doc else ""))
        if sc.effects is None:
            out.append("  effects: all")
        else:
            left = [e for e in known if e not in sc.effects]
            out.append(f"  effects: {', '.join(sc.effects) or 'none'}"
                       + (f" (left out: {', '.join(left)})" if left else ""))
        out.append("  outputs: " + (", ".join(r.text for r in sc.outputs) if sc.outputs
                                    else "every state"))
        if sc.time is not None:
            start, stop, every = sc.time
            out.append(f"  time {_text_of(start, lines)} .. {_text_of(stop, lines)}"
                       + (f" every {_text_of(every, lines)}" if every is not None else ""))
        if sc.solver is not None:
            name, opts, _ = sc.solver
            args = ", ".join(f"{k} = {_text_of(v, lines)}" for k, v in opts)
            out.append(f"  solver {name}" + (f"({args})" if args else ""))
        for pname, expr, _ in sc.sets:
            out.append(f"  set {pname} = {_text_of(expr, lines)}")
    return "\n".join(out) + "\n"
