"""Stable text dumps of the intermediate values: `bgc check` and `bgc equations`."""
from __future__ import annotations

import sympy as sp

from .reduce import Block, explicit_forms

TWO_PORTS = ("TF", "MTF", "GY", "MGY")

METHODS = {"symbolic": "solved symbolically", "lu": "solved numerically (LU)",
           "newton": "solved numerically (Newton)"}
KINDS = {"I": "I, integral causality", "C": "C, integral causality",
         "integral signal": "integral signal"}


class _Printer(sp.printing.str.StrPrinter):
    """sstr, with floats as the shortest text that reads back as the same double."""

    def _print_Float(self, expr):
        return repr(float(expr))


def _s(expr) -> str:
    return _Printer({"order": "lex"}).doprint(expr)


def _header(compiled) -> list[str]:
    s = compiled.settings
    return [f"model {compiled.graph.name}" + (f", scene {s.scene}" if s.scene
                                              else ", default scene")]


def check_report(compiled) -> str:
    g, cg, r = compiled.graph, compiled.causal, compiled.reduced
    lines = _header(compiled)
    lines.append(f"states ({len(r.states)}):")
    lines += [f"  {st.name}  {KINDS[st.kind]}" for st in r.states]
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
    if r.eliminated:
        lines.append("derivative causality (dependent states, eliminated):")
        lines += [f"  {name} = {_s(e) if e is not None else '(solved with its block)'}"
                  for name, e in r.eliminated]
    if r.blocks:
        lines.append("algebraic blocks:")
        for b in r.blocks:
            kind = "linear" if b.linear else "nonlinear"
            origins = list(dict.fromkeys(
                (g.by_name[o].origin or o) if o in g.by_name else o for o in b.origins))
            lines.append(f"  {b.index}: {', '.join(b.unknowns)} ({len(b.unknowns)} unknown"
                         f"{'s' * (len(b.unknowns) > 1)}) through {', '.join(origins)}: "
                         f"{kind}, {METHODS[b.method]}")
    if r.constraints:
        lines.append("constraints:")
        for k in r.constraints:
            how = "detected" if k.detected else "declared"
            gains = f"({', '.join(_s(g) for g in k.gains)})" if k.gains else ""
            lines.append(f"  {k.junction}: {k.kind} ({how}), corrector {k.corrector}{gains}")
            if k.phi is not None:
                lines.append(f"    Phi = {_s(k.phi)}")
            lines.append(f"    {'dPhi/dt' if k.kind == 'holonomic' else 'Phi'} = {_s(k.balance)}")
    lines.append(f"warnings: {len(r.warnings)}")
    return "\n".join(lines) + "\n"


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


def equations_text(compiled) -> str:
    r = compiled.reduced
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
        return "\n".join(lines) + "\n"
    lines.append("program (in evaluation order; blocks solved numerically in the generated code):")
    for step in r.steps:
        if isinstance(step, Block):
            z = ", ".join(u.name for u in step.unknowns)
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
    return "\n".join(lines) + "\n"


def equations_latex(compiled) -> str:
    r = compiled.reduced
    multipliers = [k.multiplier for k in r.constraints]
    forms = explicit_forms(r, list(r.rates) + multipliers) or {}
    rows = [rf"\frac{{d}}{{dt}} {_tex_name(st.name)} &= {sp.latex(forms.get(d, d))}"
            for st, d in zip(r.states, r.rates)]
    rows += [rf"\lambda_{{\mathrm{{{k.junction}}}}} &= "
             rf"{sp.latex(forms.get(k.multiplier, k.multiplier))}" for k in r.constraints]
    return "\\begin{aligned}\n" + " \\\\\n".join(rows) + "\n\\end{aligned}\n"


def _tex_name(name: str) -> str:
    return r"\mathrm{" + name.replace("_", r"\_") + "}"
