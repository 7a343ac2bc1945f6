"""Stable text dumps of the intermediate values: `bgc check` and `bgc equations`."""
from __future__ import annotations

import sympy as sp


class _Printer(sp.printing.str.StrPrinter):
    """sstr, with floats as the shortest text that reads back as the same double."""

    def _print_Float(self, expr):
        return repr(float(expr))


def _s(expr) -> str:
    return _Printer({"order": "lex"}).doprint(expr)


def _header(compiled) -> list[str]:
    g, s = compiled.graph, compiled.settings
    return [f"model {g.name}" + (f", scene {s.scene}" if s.scene else ", default scene")]


def check_report(compiled) -> str:
    g, c, r = compiled.graph, compiled.causality, compiled.reduced
    es = r.system
    kinds = {st.symbol: _state_kind(es, st) for st in es.states}
    lines = _header(compiled)
    lines.append(f"states ({len(r.states)}):")
    lines += [f"  {st.name}  {kinds[st.symbol]}" for st in r.states]
    if r.pruned:
        lines.append("not integrated (no output needs them): " + ", ".join(r.pruned))
    lines.append("causality (bond: effort set by -> flow set by):")
    for b, by in zip(g.bonds, c.effort_by):
        other = b.dst if by == b.src else b.src
        lines.append(f"  {b.label}: {by} -> {other}")
    if r.eliminated:
        lines.append("derivative causality (dependent states, eliminated):")
        lines += [f"  {name} = {_s(e)}" for name, e in r.eliminated]
    if r.loops:
        lines.append("algebraic loops:")
        lines += [f"  through {', '.join(lp.elements)}: "
                  f"{'linear, solved symbolically' if lp.linear else 'nonlinear, solved symbolically'}"
                  for lp in r.loops]
    if r.constraints:
        lines.append("constraints:")
        for k in r.constraints:
            how = "detected" if k.detected else "declared"
            gains = f"({', '.join(_s(g) for g in k.gains)})" if k.gains else ""
            lines.append(f"  {k.junction}: {k.kind} ({how}), corrector {k.corrector}{gains}")
            if k.phi is not None:
                lines.append(f"    Phi = {_s(k.phi)}")
            lines.append(f"    {'dPhi/dt' if k.kind == 'holonomic' else 'Phi'} = {_s(k.balance)}")
    warnings = list(g.warnings) + list(r.warnings)
    lines.append(f"warnings: {len(warnings)}")
    return "\n".join(lines) + "\n"


def _state_kind(es, st) -> str:
    if st.origin in {s.name for s in es.graph.signals}:
        return "integral signal"
    el = es.graph.element(st.origin)
    return f"{el.kind}, integral causality"


def equations_text(compiled) -> str:
    r = compiled.reduced
    lines = _header(compiled)
    lines.append("parameters:")
    sets = dict(compiled.settings.sets)
    for p in compiled.graph.parameters:
        lines.append(f"  {p.name} = {_s(sets.get(p.name, p.expr).value)}")
    lines.append("initial values:")
    lines += [f"  {st.name}(t0) = {_s(st.init)}" for st in r.states]
    lines.append("state equations:")
    lines += [f"  d({st.name})/dt = {_s(st.rhs)}" for st in r.states]
    if r.constraints:
        lines.append("multipliers:")
        lines += [f"  {k.junction}.lambda = {_s(k.multiplier)}" for k in r.constraints]
    lines.append("outputs:")
    lines += [f"  {o.name} = {_s(o.expr)}" for o in r.outputs]
    return "\n".join(lines) + "\n"


def equations_latex(compiled) -> str:
    r = compiled.reduced
    rows = [rf"\frac{{d}}{{dt}} {_tex_name(st.name)} &= {sp.latex(st.rhs)}" for st in r.states]
    rows += [rf"\lambda_{{\mathrm{{{k.junction}}}}} &= {sp.latex(k.multiplier)}"
             for k in r.constraints]
    return "\\begin{aligned}\n" + " \\\\\n".join(rows) + "\n\\end{aligned}\n"


def _tex_name(name: str) -> str:
    return r"\mathrm{" + name.replace("_", r"\_") + "}"
