"""Emitters: a CodeModel to source text, {filename: text}, through the templates in templates/.

Pure functions: the same CodeModel gives the same bytes (no version, date or time stamp, no
set or dict-of-symbols order).  Names from the model reach the output only as escaped string
literals; C identifiers derived from parameter names are sanitised and prefixed.
"""
from __future__ import annotations

import functools
import json
import re

import jinja2
import sympy as sp

from bgc.codemodel import Block, C, CodeModel, P, T, X, as_expr
from bgc.printers import CPrinter, PythonPrinter, float_literal
from bgc.resources import resource_dir

SOLVERS = ("euler", "rk4", "dopri5")
POW10_RANGE = (-24, 56)  # powers of ten for the C number formatter: |v| in about 1e-40..1e40


class EmitError(ValueError):
    """A CodeModel the emitters cannot print (a bug in the stage that built it)."""


def emit_c(cm: CodeModel) -> dict[str, str]:
    """The standalone C99 program: {"<name>.c": text}."""
    _validate(cm)
    fields = c_param_fields(tuple(p.name for p in cm.params))
    printer = CPrinter(len(cm.states), fields, len(cm.consts.results))
    context = _common_context(cm, c_string_literal)
    context.update(
        param_fields=fields,
        param_defaults=[printer.doprint(p.default) for p in cm.params],
        blocks=_print_blocks(cm, printer),
        scene=_scene_context(cm, c_string_literal, step_none="0.0"),
        pow10_table=pow10_table(*POW10_RANGE),
    )
    return {f"{context['ident']}.c": _render("c_program.c.j2", context)}


def emit_python(cm: CodeModel) -> dict[str, str]:
    """The standalone Python module (numpy only): {"<name>.py": text}."""
    _validate(cm)
    n, m, k = len(cm.states), len(cm.params), len(cm.consts.results)
    fast, ieee = PythonPrinter(n, m, n_consts=k), PythonPrinter(n, m, ieee=True, n_consts=k)
    context = _common_context(cm, py_string_literal)
    context.update(
        param_defaults={"fast": [fast.doprint(p.default) for p in cm.params],
                        "ieee": [ieee.doprint(p.default) for p in cm.params]},
        blocks={"fast": _print_blocks(cm, fast), "ieee": _print_blocks(cm, ieee)},
        scene=_scene_context(cm, py_string_literal, step_none="None"),
        velocity_movable=["True" if v else "False" for v in cm.velocity_movable],
    )
    return {f"{context['ident']}.py": _render("python_module.py.j2", context)}


# ---------------------------------------------------------------- literals and names


def c_string_literal(text: str) -> str:
    """A C string literal of text's UTF-8 bytes: \\ " ? escaped, all else outside ASCII
    32..126 as three-digit octal (so no following character can extend an escape)."""
    out = []
    for byte in text.encode("utf-8", "surrogatepass"):
        char = chr(byte)
        if char in '\\"?':
            out.append("\\" + char)
        elif 32 <= byte <= 126:
            out.append(char)
        else:
            out.append("\\%03o" % byte)
    return '"' + "".join(out) + '"'


def py_string_literal(text: str) -> str:
    """A Python string literal in pure ASCII (JSON's escapes are Python's)."""
    return json.dumps(text, ensure_ascii=True)


def identifier(name: str) -> str:
    """name reduced to [A-Za-z0-9_], never empty, never starting with a digit (for file
    names and comments, not for anything that must be unique)."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name)[:64]
    return ident if ident and not ident[0].isdigit() else "m_" + ident


def c_param_fields(names: tuple[str, ...]) -> tuple[str, ...]:
    """Struct field names for the parameters: p_<name> when those are distinct, otherwise
    p<j>_<name> (unique by the index); never a keyword, never one of bgc's own names."""
    bases = [re.sub(r"[^A-Za-z0-9_]", "_", name)[:40] for name in names]
    fields = tuple(f"p_{b}" for b in bases)
    if len(set(fields)) == len(fields):
        return fields
    return tuple(f"p{j}_{b}" for j, b in enumerate(bases))


def pow10_table(low: int, high: int) -> list[dict]:
    """10^m for low <= m <= high as (hi * 2^64 + lo) * 2^e2 rounded down, with
    2^127 <= hi * 2^64 + lo < 2^128: hi and lo as 16 hex digits (exact integer arithmetic)."""
    rows = []
    for m in range(low, high + 1):
        num, den = (10 ** m, 1) if m >= 0 else (1, 10 ** -m)
        e2 = num.bit_length() - den.bit_length() - 128
        while True:
            mant = (num << -e2) // den if e2 < 0 else num // (den << e2)
            if mant >> 128:
                e2 += 1
            elif not mant >> 127:
                e2 -= 1
            else:
                break
        rows.append({"m": m, "hi": "%016x" % (mant >> 64), "lo": "%016x" % (mant & (2**64 - 1)),
                     "e2": e2})
    return rows


# ---------------------------------------------------------------- context


def _common_context(cm: CodeModel, literal) -> dict:
    return {
        "ident": identifier(cm.name),
        "model_name": literal(cm.name),
        "states": [literal(s) for s in cm.states],
        "params": [literal(p.name) for p in cm.params],
        "outputs": [literal(o) for o in cm.outputs],
        "constraints": [{"junction": literal(c.junction), "level": literal(c.level)}
                        for c in cm.constraints],
        "n_states": len(cm.states),
        "n_params": len(cm.params),
        "n_consts": len(cm.consts.results),
        "n_outputs": len(cm.outputs),
        "n_constraints": len(cm.constraints),
        "position_rows": list(cm.position_rows),
        "velocity_rows": list(cm.velocity_rows),
        "velocity_movable": [1 if v else 0 for v in cm.velocity_movable],
    }


def _scene_context(cm: CodeModel, literal, step_none: str) -> dict:
    sc = cm.scene
    return {
        "t0": float_literal(sc.t0),
        "t_end": float_literal(sc.t_end),
        "dt": float_literal(sc.dt),
        "solver": literal(sc.solver),
        "solver_enum": SOLVERS.index(sc.solver),
        "rtol": float_literal(sc.rtol),
        "atol": float_literal(sc.atol),
        "step": step_none if sc.step is None else float_literal(sc.step),
    }


_BLOCKS = ("consts", "init", "rhs", "out", "residual", "scale", "position_jac", "velocity_jac")


def _print_blocks(cm: CodeModel, printer) -> dict:
    return {name: _print_block(getattr(cm, name), printer) for name in _BLOCKS}


def _print_block(block: Block, printer) -> dict:
    block = _renumber_temps(block)
    return {
        "temps": [(sym.name, printer.doprint(expr)) for sym, expr in block.temps],
        "results": [printer.doprint(expr) for expr in block.results],
    }


def _renumber_temps(block: Block) -> Block:
    """Temporaries renamed w0, w1, ... in order, whatever prefix the block was made with."""
    mapping = {sym: sp.Symbol(f"w{k}") for k, (sym, _) in enumerate(block.temps)}
    if all(old == new for old, new in mapping.items()):
        return block
    return Block(tuple((mapping[sym], as_expr(expr).xreplace(mapping))
                       for sym, expr in block.temps),
                 tuple(as_expr(expr).xreplace(mapping) for expr in block.results))


# ---------------------------------------------------------------- validation


def _validate(cm: CodeModel) -> None:
    n, n_pos, n_vel = len(cm.states), len(cm.position_rows), len(cm.velocity_rows)
    sizes = {"init": n, "rhs": n, "out": len(cm.outputs), "residual": len(cm.constraints),
             "scale": len(cm.constraints), "position_jac": n_pos * n, "velocity_jac": n_vel * n}
    for name, size in sizes.items():
        got = len(getattr(cm, name).results)
        if got != size:
            raise EmitError(f"block {name} has {got} results, expected {size}")
    if len(cm.velocity_movable) != n:
        raise EmitError(f"velocity_movable has {len(cm.velocity_movable)} entries, expected {n}")
    if cm.scene.solver not in SOLVERS:
        raise EmitError(f"unknown solver {cm.scene.solver!r}")
    if any(c.level not in ("position", "velocity") for c in cm.constraints):
        raise EmitError("constraint levels must be 'position' or 'velocity'")
    for name in ("init", "consts"):
        if _uses_more_than_parameters(getattr(cm, name)):
            raise EmitError(f"the {name} block may use parameters only")
    for j, param in enumerate(cm.params):
        _check_default(j, param.default)


def _uses_more_than_parameters(block: Block) -> bool:
    exprs = [as_expr(e) for _, e in block.temps] + [as_expr(e) for e in block.results]
    return any(T in e.free_symbols or e.has(X) or e.has(C) for e in exprs)


def _check_default(j: int, default: sp.Expr) -> None:
    default = as_expr(default)
    if T in default.free_symbols or default.has(X) or default.has(C):
        raise EmitError(f"the default of parameter {j} uses time, states or constants")
    for ref in default.atoms(sp.Indexed):
        if ref.base == P and not (ref.indices[0].is_Integer and int(ref.indices[0]) < j):
            raise EmitError(f"the default of parameter {j} uses {ref}, not an earlier parameter")


# ---------------------------------------------------------------- templates


@functools.lru_cache(maxsize=None)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(resource_dir("templates"))),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        autoescape=False,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def _render(template: str, context: dict) -> str:
    return _environment().get_template(template).render(**context)
