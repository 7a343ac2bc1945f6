"""Stage 8, emit: Program -> {filename: text}, through the templates in templates/ and the
runtime files in bgc/runtime/ (inlined verbatim: a generated program stays one file).

Pure functions: the same Program gives the same bytes (no version, date or time stamp, no
set or dict-of-symbols order).  Names from the model reach the output only as escaped string
literals; C identifiers derived from parameter names are sanitised and prefixed.

Each IR function becomes one function of the target language, or several when it is long
(bgc.ir.layout: chunks of bounded size, so that a C compiler's time grows linearly with the
model); the values that cross chunks, and those a Newton block reads or sets, live in the
workspace, the rest are locals.  The workspace's layout is decided here, once per program.
"""
from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass

import sympy as sp

from .. import ir
from ..base import solvers
from ..base.resources import quiet_collector, resource_dir
from ..ir import Assign, Newton, Program, Resolve, Solve, Store, as_expr
from ..ir.printers import CPrinter, PythonPrinter, float_literal

POW10_RANGE = (-24, 56)  # powers of ten for the C number formatter: |v| in about 1e-40..1e40
C_RUNTIME = ("runtime.c", "drive.c", "erk.c", "stiff.c", "main.c", "batch.c")  # bgc/runtime/, in this order
PY_RUNTIME = ("runtime.py", "main.py", "drive.py", "erk.py", "stiff.py", "batch.py")  # the same:
#   the parts of the Python runtime, one module (python_runtime), each named after its C twin
COPY_RUN = 64  # C: at least this many copies in a row (out[i] = x[j], ...) become one loop
PARAMETER_CHUNK = 256  # C: lines of the parameters' defaults or constants in one function
FUNCTION_LINES = 500  # C: lines of a model function's chunk in one function (emit._line_chunks)
PLAN_ARRAYS = ("diag", "lptr", "lpos", "lrow", "uptr", "upos", "ucol", "upd", "prow", "pcol")
ITERATION_ARRAYS = ("perm", "rowptr", "cols", "diag", "jpos", "dpos")  # sparse.IterationPlan
MODEL_FUNCTIONS = ("rhs", "outputs", "jvp")  # take the workspace, may solve blocks; so do
#                                               a program's extra functions
# (bgc.codegen.lower.with_tangent)
PLAIN_FUNCTIONS = ("residual", "scale", "position_jac", "velocity_jac", "velocity_metric")
SPARSE_FUNCTIONS = ("position_jac", "velocity_jac", "velocity_metric")  # store their nonzero
#                                                                         entries only


class EmitError(ValueError):
    """A Program the emitters cannot print (a bug in the stage that built it)."""


# ---------------------------------------------------------------- the workspace


@dataclass(frozen=True)
class BlockArea:
    save: int
    lu: int
    dense: int
    b: int
    scale: int
    z: int
    r: int
    zt: int
    rt: int
    piv: int
    how: int


@dataclass(frozen=True)
class Workspace:
    """Offsets of everything in the workspace's double and int arrays."""

    y0: int
    stages: int
    y: int
    jac: int
    slots: int
    blocks: tuple[BlockArea, ...]
    doubles: int
    ints: int
    layouts: dict  # function name -> ir.Layout


def workspace(program: Program, chunk_ops: int, layouts: bool = True) -> Workspace:
    """layouts=False: no slots for the values that cross chunks (bgc.codegen.vm keeps them in its
    registers)."""
    n = max(len(program.states), 1)
    y0, stages = 0, n
    y = stages + 15 * n
    jac = y + max(len(program.outputs), 1)
    slots = jac + 2 * n
    layouts = {name: ir.layout(program.function(name).body, slots, chunk_ops)
               for name in model_functions(program)} if layouts else {}
    top = slots + max((len(lay.slot) for lay in layouts.values()), default=0)
    areas, ints = [], 0
    for bp in program.blocks:
        m, nnz = bp.lu.m, bp.lu.nnz
        save = top
        lu = save + nnz
        dense = lu + (0 if bp.lu.dense else nnz)
        b = dense + m * m
        areas.append(BlockArea(save, lu, dense, b, b + m, b + 2 * m, b + 3 * m, b + 4 * m,
                                b + 5 * m, ints, ints + m))
        top = b + 6 * m
        ints += m + 1
    return Workspace(y0, stages, y, jac, slots, tuple(areas), top, ints, layouts)


# ---------------------------------------------------------------- statements to lines


class Writer:
    """Lines of one target language for the statements of one function."""

    def __init__(self, program: Program, ws: Workspace, printer, lang: str):
        self.program = program
        self.ws = ws
        self.printer = printer
        self.c = lang == "c"
        self.function = ""  # the IR function being written (names its Newton functions)
        self.used: set = set()  # the symbols the function reads
        self.on_failure = "return 1;"  # C: what a failed block solve does

    def newton_name(self, block: int) -> str:
        return (f"bgc_{self.function}_block{block}" if self.c
                else f"_{self.function}_block{block}")

    def storage(self, layout: ir.Layout):
        """Where each program variable of a function lives: its slot, its Newton area, or a
        local of its own name."""
        names = {w: f"wv[{s}]" for w, s in layout.slot.items()}
        for chunk in layout.chunks:
            for s in chunk:
                if isinstance(s, Newton):
                    area = self.ws.blocks[s.block]
                    for k, z in enumerate(s.unknowns):
                        names[z] = f"wv[{area.z + k}]"
        return names

    def code(self, e) -> str:
        return self.printer.doprint(e)

    def assign(self, target: str, value: str, local: bool) -> str:
        if local:
            return f"const double {target} = {value};" if self.c else f"{target} = {value}"
        return f"{target} = {value};" if self.c else f"{target} = {value}"

    def statement(self, s, out_name: str, t_name="t") -> list[str]:
        names = self.printer.names
        if isinstance(s, Assign):
            text = names.get(s.target)
            return [self.assign(text or s.target.name, self.code(s.expr), text is None)]
        if isinstance(s, Store):
            return [self.assign(f"{out_name}[{s.index}]", self.code(s.expr), False)]
        semi = ";" if self.c else ""
        if isinstance(s, (Solve, Resolve)):
            bp = self.program.blocks[s.block]
            area = self.ws.blocks[s.block]
            lines = []
            if isinstance(s, Solve):
                for pos, e in zip(bp.lu.entries, s.matrix):
                    lines.append(f"wv[{area.save + pos}] = {self.code(e)}{semi}")
            for r, e in enumerate(s.rhs):
                lines.append(f"wv[{area.b + r}] = {self.code(e)}{semi}")
            call = "bgc_block_solve" if isinstance(s, Solve) else "bgc_block_resolve"
            if self.c:
                lines.append(f"if ({call}(w, {s.block}, {t_name}))")
                lines.append(f"    {self.on_failure}")
            else:
                lines.append(f"_{call[4:]}(w, {s.block}, {t_name})")
            targets = s.unknowns if isinstance(s, Solve) else s.targets
            for k, z in enumerate(targets):
                if z not in self.used:
                    continue  # an unknown that nothing reads stays in the workspace
                text = names.get(z)
                lines.append(self.assign(text or z.name, f"wv[{area.b + k}]", text is None))
            return lines
        if isinstance(s, Newton):
            newton_name = self.newton_name(s.block)
            final = int(s.final_factor) if self.c else bool(s.final_factor)
            if self.c:
                return [f"if (bgc_newton(w, {s.block}, {newton_name}, {t_name}, x, p, {final}))",
                        "    return 1;"]
            return [f"_newton(w, {s.block}, {newton_name}, {t_name}, x, p, {final})"]
        raise EmitError(f"unknown statement {s!r}")

    def newton_function(self, s: Newton, layout_names: dict) -> dict:
        """The lines of a Newton block's residual/Jacobian function (unknowns as z[k])."""
        bp = self.program.blocks[s.block]
        names = dict(layout_names)
        # C passes pointers; Python the workspace list and an offset into it
        z, r, J = ("z[{}]", "r[{}]", "J[{}]") if self.c else ("z[zo + {}]", "r[ro + {}]",
                                                              "J[jo + {}]")
        for k, u in enumerate(s.unknowns):
            names[u] = z.format(k)
        self.printer.names = names
        body = []
        for a in s.body:
            body += self.statement(a, "r")
        residuals = [self.assign(r.format(i), self.code(e), False)
                     for i, e in enumerate(s.residuals)]
        tangents = []
        for a in s.tangents:
            tangents += self.statement(a, "J")
        jacobian = [self.assign(J.format(pos), self.code(e), False)
                    for pos, e in zip(bp.lu.entries, s.jacobian)]
        return {"name": self.newton_name(s.block), "body": body, "residuals": residuals,
                "tangents": tangents, "jacobian": jacobian}


def function_context(writer: Writer, name: str, out_name: str) -> dict:
    f = writer.program.function(name)
    writer.function = name
    writer.used = set().union(*[ir.uses(s) for s in f.body]) if f.body else set()
    layout = writer.ws.layouts[name]
    names = writer.storage(layout)
    chunks = []
    newtons = {}
    for chunk in layout.chunks:
        writer.printer.names = names
        lines = []
        for s in chunk:
            lines += writer.statement(s, out_name)
        if writer.c:  # (a long run of stores as loops, a long chunk as functions)
            chunks += _line_chunks(_copy_loops(lines), FUNCTION_LINES)
        else:
            chunks.append(lines)
        for s in chunk:
            if isinstance(s, Newton) and s.block not in newtons:
                newtons[s.block] = s
    evals = [writer.newton_function(s, names) for _, s in sorted(newtons.items())]
    writer.printer.names = {}
    return {"name": name, "args": f.args, "chunks": chunks, "evals": evals}


_COPY = re.compile(r"^(out|wv|x0)\[(\d+)\] = (?:(x|v|wv)\[(\d+)\]|(-?\d+(?:\.\d*)?(?:e[-+]?\d+)?));$")


def _copy_loops(lines: list[str]) -> list[str]:
    """C: a run of COPY_RUN or more stores in a row of copies from one array to one array
    (the outputs that are states, the right side's entries read from the workspace), or of
    numbers to one array (the initial states), as one loop over index tables, the stores in
    the same order and the same values.  A C optimiser's alias walks over a run of stores
    grow as its square (gcc -O1: a third of a second for 1500 copies); the loop costs it
    nothing.  Shorter runs stay as they are."""
    out: list[str] = []
    run: list[tuple] = []

    def flush():
        if len(run) < COPY_RUN:
            out.extend(line for *_, line in run)
        else:
            out.extend(_copy_loop(run))
        run.clear()

    for line in lines:
        m = _COPY.match(line)
        kind = m and (m.group(1), m.group(3))  # destination, source array (None: numbers)
        if run and kind != run[0][0]:
            flush()
        if m:
            dest, i, src, j, number = m.groups()
            run.append((kind, int(i), int(j) if src else number, line))
        else:
            out.append(line)
    flush()
    return out


def _copy_loop(run: list[tuple]) -> list[str]:
    """One loop for a run of stores `dest[i] = src[j];` or `dest[i] = number;`: an index that
    steps by one from its first value is written as first + bgc_k, any other index, and the
    numbers, as a table."""
    (dest, src), n = run[0][0], len(run)
    lines, index = ["{"], []
    for position, name, table in ((1, dest, "bgc_to"), (2, src, "bgc_from")):
        values = [r[position] for r in run]
        if name is None:
            lines.append(f"    static const double bgc_value[{n}] = {{ {', '.join(values)} }};")
            index.append("bgc_value[bgc_k]")
        elif values == list(range(values[0], values[0] + n)):
            index.append(f"{name}[{values[0]} + bgc_k]" if values[0] else f"{name}[bgc_k]")
        else:
            lines.append(f"    static const int {table}[{n}] = {{ {', '.join(map(str, values))} }};")
            index.append(f"{name}[{table}[bgc_k]]")
    lines += ["    int bgc_k;", f"    for (bgc_k = 0; bgc_k < {n}; ++bgc_k)",
              f"        {index[0]} = {index[1]};", "}"]
    return lines


_TEMPORARY = re.compile(r"^const double (w\d+) = ")
_NAME = re.compile(r"\bw\d+\b")


def _line_chunks(lines: list[str], size: int | None = None) -> list[list[str]]:
    """C: a function's lines (the parameters' defaults, the constants, a chunk of a model
    function) as consecutive chunks of about `size` lines, each ending between two
    statements outside any braces where no temporary (`const double wK = ...;`) is read
    after it, so that each can be a function of its own, run in order.  A C optimiser's
    alias walks over a function's stores grow as their number squared: 2 000 defaults and
    1 000 constants of a model with a parameter per section cost gcc -O1 half its compile
    in one function each, as do the 2 000 stores that assemble one block of the 64-section
    ladder with symbolic resistances.  One chunk (the lines as they were) when there are at
    most size (default PARAMETER_CHUNK)."""
    size = PARAMETER_CHUNK if size is None else size
    if len(lines) <= size:
        return [lines]
    last = {}
    for k, line in enumerate(lines):
        for name in _NAME.findall(line):
            last[name] = k
    chunks, start, reach, depth = [], 0, -1, 0
    for k, line in enumerate(lines):
        m = _TEMPORARY.match(line)
        if m:
            reach = max(reach, last.get(m.group(1), k))
        depth += line.count("{") - line.count("}")
        if k + 1 - start >= size and reach <= k and depth == 0 and k + 1 < len(lines) \
                and line.endswith((";", "}")) and not lines[k + 1].startswith(" "):
            chunks.append(lines[start:k + 1])
            start = k + 1
    chunks.append(lines[start:])
    return chunks


def plain_lines(writer: Writer, name: str, out_name: str) -> list[str]:
    """A function without the workspace argument.  The constraint rows of a field whose flows
    solve M(q) f = p read a linear block: such a function makes a workspace of its own for the
    block's storage (it runs at the start of a run, not per step), and its results are NaN if
    the block is singular."""
    writer.printer.names = {}
    f = writer.program.function(name)
    writer.used = set().union(*[ir.uses(s) for s in f.body]) if f.body else set()
    solves = any(isinstance(s, (Solve, Resolve)) for s in f.body)
    writer.on_failure = "goto fail;"
    lines = []
    if solves:
        lines += ["bgc_work *w = bgc_work_new(); /* its algebraic blocks' storage */",
                  "double *wv;", "int k;", "if (!w)", "    goto fail;", "wv = w->v;"] \
            if writer.c else ["w = _Work()", "wv = w.v"]
    for s in f.body:
        lines += writer.statement(s, out_name)
    if solves and writer.c:
        lines += ["bgc_work_free(w);", "return;", "fail:",
                  f"for (k = 0; k < {max(f.size, 1)}; k++)", f"    {out_name}[k] = NAN;",
                  "bgc_work_free(w);"]
    writer.on_failure = "return 1;"
    return lines


# ---------------------------------------------------------------- C


@quiet_collector()
def emit_c(program: Program, chunk_ops: int = ir.CHUNK_OPS, linked: bool = False) \
        -> dict[str, str]:
    """The standalone C99 program: {"<name>.c": text}.  linked: the model part alone, to be
    linked with the runtime built once (c_runtime_unit; see linkable)."""
    validate(program)
    fields = c_param_fields(tuple(p.name for p in program.params))
    printer = CPrinter(len(program.states), fields, program.n_consts)
    ws = workspace(program, chunk_ops)
    writer = Writer(program, ws, printer, "c")
    context = common_context(program, ws, c_string_literal, True)
    context.update(
        param_fields=fields,
        param_defaults=[printer.doprint(p.default) for p in program.params],
        default_chunks=_line_chunks(
            [f"if (!given || !given[{j}]) p->{fields[j]} = {printer.doprint(p.default)};"
             for j, p in enumerate(program.params)]),
        model={name: function_context(writer, name, "out")
               for name in model_functions(program)},
        plain={name: plain_lines(writer, name, "out") for name in PLAIN_FUNCTIONS},
        plain_sizes={name: program.function(name).size for name in PLAIN_FUNCTIONS},
        sparse=SPARSE_FUNCTIONS,
        consts=_line_chunks(plain_lines(writer, "consts", "p->c")),
        init=_copy_loops(plain_lines(writer, "init", "x0")),
        scene=_scene_context(program, c_string_literal, step_none="0.0"),
        **c_runtime_parts(),
    )
    if linked:
        context["runtime"] = _link_definitions()
    return {f"{context['ident']}.c": render("c_program.c.j2", context)}


@quiet_collector()
def emit_python(program: Program, chunk_ops: int = ir.CHUNK_OPS) -> dict[str, str]:
    """The standalone Python module (numpy only): {"<name>.py": text}."""
    validate(program)
    if not program.has_jacobian:  # (its jvp and jacobian are part of the module's API)
        raise EmitError("the Python module needs a program with its Jacobian (jvp)")
    n, m, k = len(program.states), len(program.params), program.n_consts
    fast, ieee = PythonPrinter(n, m, n_consts=k), PythonPrinter(n, m, ieee=True, n_consts=k)
    ws = workspace(program, chunk_ops)
    context = common_context(program, ws, py_string_literal, False)
    variants = {}
    for label, printer in (("fast", fast), ("ieee", ieee)):
        writer = Writer(program, ws, printer, "python")
        variants[label] = {
            "model": {name: function_context(writer, name, "out")
                      for name in model_functions(program)},
            "plain": {name: plain_lines(writer, name, "out") for name in PLAIN_FUNCTIONS},
            "consts": plain_lines(writer, "consts", "out"),
            "init": plain_lines(writer, "init", "out"),
            "param_defaults": [printer.doprint(p.default) for p in program.params],
        }
    context.update(
        fast=variants["fast"], ieee=variants["ieee"],
        jac_colors=list(program.jacobian.colors), jac_columns=list(program.jacobian.columns),
        plain_sizes={name: program.function(name).size for name in PLAIN_FUNCTIONS},
        scene=_scene_context(program, py_string_literal, step_none="None"),
        velocity_movable=["True" if v else "False" for v in program.velocity_movable],
        runtime=python_runtime(),
    )
    return {f"{context['ident']}.py": render("python_module.py.j2", context)}


def model_functions(program: Program) -> tuple[str, ...]:
    """rhs, outputs, jvp, the event functions of a program with events, then the program's
    extra functions (bgc.codegen.lower.with_tangent: an FMU's outputs_jvp;
    bgc.analysis.operating's, in the
    Python module)."""
    out = tuple(k for k in MODEL_FUNCTIONS if k in program.functions) + (
        ir.EVENT_FUNCTIONS if program.events is not None else ())
    return out + tuple(k for k in program.functions if k not in ir.FUNCTION_NAMES
                       and k not in ir.EVENT_FUNCTIONS)


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
    2^127 <= hi * 2^64 + lo < 2^128: hi and lo as 16 hex digits (exact integer arithmetic).
    The C runtime carries this table for POW10_RANGE (a test checks that it is this)."""
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


def _list(values) -> str:
    return ", ".join(str(v) for v in values) if values else "0"


def block_names(program: Program, limit: int = 6) -> list[str]:
    out = []
    for bp in program.blocks:
        names = list(bp.unknowns[:limit])
        if len(bp.unknowns) > limit:
            names.append(f"and {len(bp.unknowns) - limit} more")
        out.append(", ".join(names))
    return out


# ---------------------------------------------------------------- small blocks, unrolled

UNROLL_MAX = 400  # a static plan of at most this many entries + updates is unrolled


def _unrolled_lu(k: int, lu, area: BlockArea, c: bool) -> dict | None:
    """Block k's static LU and its solve as straight-line code (C or Python), or None when the
    plan is dense or long (the runtime's loops over the plan then do it).  The same floating-
    point operations in the same order as the runtime's bgc_lu_static and _solve (so the
    results are the same to the bit), without the loops' index lookups: for the small blocks
    of constrained mechanisms those cost more than the arithmetic.  factor(v): 0 / True, or
    1 / False when a pivot fails its test (the runtime then factors densely); lsolve(v, b):
    b := A^-1 b with the factors at v."""
    if lu.dense or lu.m == 0 or lu.nnz + len(lu.upd) + len(lu.lpos) > UNROLL_MAX:
        return None
    semi = ";" if c else ""
    L, S = area.lu, area.save

    def at(q):
        return f"v[{L + q}]"

    def fabs(e):
        return f"fabs({e})" if c else f"abs({e})"

    def largest(terms):  # the runtime's fold: bgc_max(...bgc_max(start, t0)..., tn)
        if len(terms) == 1:
            return terms[0]
        if c:
            text = terms[0]
            for t in terms[1:]:
                text = f"bgc_max({text}, {t})"
            return text
        return f"max({', '.join(terms)})"

    factor = []
    rows: list[list[int]] = [[] for _ in range(lu.m)]
    for q, i in enumerate(lu.prow):
        rows[i].append(q)
    for i, qs in enumerate(rows):
        factor.append(_decl(c, f"s{i}", largest(["0.0"] + [fabs(f"v[{S + q}]") for q in qs])))
    if c:
        factor += [f"v[{L + q}] = v[{S + q}];" for q in range(lu.nnz)]
    else:
        factor.append(f"v[{L}:{L + lu.nnz}] = v[{S}:{S + lu.nnz}]")
    fail = "return 1;" if c else "return False"
    finite = "isfinite" if c else "math.isfinite"
    if lu.symmetric:
        factor.append(_decl(c, "sign", f"-1.0 if {at(lu.diag[0])} < 0.0 else 1.0" if not c
                            else f"{at(lu.diag[0])} < 0.0 ? -1.0 : 1.0"))
    q = 0
    for kk in range(lu.m):
        pivot = at(lu.diag[kk])
        below = range(lu.lptr[kk], lu.lptr[kk + 1])
        if lu.symmetric:
            test = f"sign * {pivot} > 1e-14 * s{kk}"
        elif below:  # (with nothing below, the threshold test holds for every finite pivot)
            big = largest([fabs(pivot)] + [fabs(at(lu.lpos[l])) for l in below])
            test = (f"{fabs(pivot)} >= 0.1 * {big} {'&&' if c else 'and'} "
                    f"{fabs(pivot)} > 1e-14 * s{kk}")
        else:
            test = f"{fabs(pivot)} > 1e-14 * s{kk}"
        if c:
            factor += [f"if (!({test}) || !isfinite({pivot}))", f"    {fail}"]
        else:
            factor += [f"if not ({test}) or not {finite}({pivot}):", f"    {fail}"]
        for l in below:
            target = at(lu.lpos[l])
            factor.append(f"{target} = {target} / {pivot}{semi}")
            for u in range(lu.uptr[kk], lu.uptr[kk + 1]):
                factor.append(f"{at(lu.upd[q])} -= {target} * {at(lu.upos[u])}{semi}")
                q += 1
    factor.append("return 0;" if c else "return True")
    solve = []
    x = (lambda i: f"b[{i}]") if c else (lambda i: f"v[xb + {i}]")
    for kk in range(lu.m):
        for l in range(lu.lptr[kk], lu.lptr[kk + 1]):
            solve.append(f"{x(lu.lrow[l])} -= {at(lu.lpos[l])} * {x(kk)}{semi}")
    for kk in reversed(range(lu.m)):
        terms = "".join(f" - {at(lu.upos[u])} * {x(lu.ucol[u])}"
                        for u in range(lu.uptr[kk], lu.uptr[kk + 1]))
        value = f"({x(kk)}{terms}) / {at(lu.diag[kk])}" if terms else f"{x(kk)} / {at(lu.diag[kk])}"
        solve.append(f"{x(kk)} = {value}{semi}")
    prefix = "bgc_" if c else "_"
    return {"factor": f"{prefix}block{k}_factor", "lsolve": f"{prefix}block{k}_lsolve",
            "factor_lines": factor, "lsolve_lines": solve}


def _decl(c: bool, name: str, value: str) -> str:
    return f"const double {name} = {value};" if c else f"{name} = {value}"


# ---------------------------------------------------------------- context


def common_context(program: Program, ws: Workspace, literal, c: bool) -> dict:
    jac = program.jacobian
    color_ptr, color_cols, col_ptr, col_rows = [0], [], [0], []
    for cols in jac.colors:
        color_cols += cols
        color_ptr.append(len(color_cols))
    for rows in jac.columns:
        col_rows += rows
        col_ptr.append(len(col_rows))
    blocks = []
    for k, (bp, area) in enumerate(zip(program.blocks, ws.blocks)):
        lu = bp.lu
        flat, pointers = [], []
        for key in PLAN_ARRAYS:
            values = getattr(lu, key)
            pointers.append(f"bgc_block{k}_plan + {len(flat)}" if values else "NULL")
            flat += values
        fields = [str(lu.m), str(int(lu.dense)), str(int(lu.symmetric)), str(lu.nnz)] + pointers
        offsets = [area.save, area.lu, area.dense, area.b, area.scale, area.z, area.r, area.zt,
                   area.rt, area.piv, area.how]
        unrolled = _unrolled_lu(k, lu, area, c)
        functions = [unrolled["factor"], unrolled["lsolve"]] if unrolled else \
            (["NULL", "NULL"] if c else ["None", "None"])
        blocks.append({
            "flat": _list(flat),
            "init": "{ { " + ", ".join(fields) + " }, " + ", ".join(map(str, offsets))
                    + ", " + ", ".join(functions) + " }",
            "unrolled": unrolled, "functions": functions,
            "m": lu.m, "dense": lu.dense, "symmetric": lu.symmetric, "nnz": lu.nnz,
            "offsets": offsets,
            "arrays": {key: list(getattr(lu, key)) for key in PLAN_ARRAYS},
        })
    return {
        "events": events_context(program, literal),
        "tables": _tables_context(program, c),
        "inputs": [literal(u.name) for u in program.inputs],
        "ident": identifier(program.name),
        "model_name": literal(program.name),
        "ident_literal": literal(identifier(program.name)),
        "states": [literal(s) for s in program.states],
        "params": [literal(p.name) for p in program.params],
        "outputs": [literal(o) for o in program.outputs],
        "constraints": [{"junction": literal(c.junction), "level": literal(c.level)}
                        for c in program.constraints],
        "block_names": [literal(b) for b in block_names(program)],
        "blocks": blocks,
        "n_states": len(program.states),
        "n_params": len(program.params),
        "n_consts": program.n_consts,
        "n_outputs": len(program.outputs),
        "n_constraints": len(program.constraints),
        "n_blocks": len(program.blocks),
        "autonomous": int(not reads_time(program.function("rhs"))),
        "position_rows": list(program.position_rows),
        "velocity_rows": list(program.velocity_rows),
        "velocity_movable": [1 if v else 0 for v in program.velocity_movable],
        "jac": {"colors": len(jac.colors), "color_ptr": _list(color_ptr),
                "color_cols": _list(color_cols), "col_ptr": _list(col_ptr),
                "col_rows": _list(col_rows), "nnz": len(col_rows)},
        "jac_lu": None if jac.lu is None else
        {key: _list(getattr(jac.lu, key)) for key in ITERATION_ARRAYS} | {"nnz": jac.lu.nnz},
        "has_jacobian": program.has_jacobian,
        "ws": ws,
        "list": _list,
    }


def _scene_context(program: Program, literal, step_none: str) -> dict:
    sc = program.scene
    return {
        "t0": float_literal(sc.t0),
        "t_end": float_literal(sc.t_end),
        "dt": float_literal(sc.dt),
        "solver": literal(sc.solver),
        "solver_enum": solvers.index(sc.solver),
        "rtol": float_literal(sc.rtol),
        "atol": float_literal(sc.atol),
        "step": step_none if sc.step is None else float_literal(sc.step),
        "hmax": None if sc.max_step is None else float_literal(sc.max_step),
    }


def _tables_context(program: Program, c: bool) -> list:
    """The lookup tables' data as C initialisers or Python tuples (bgc/front/tables.py)."""
    out = []
    for tab in program.tables:
        def seq(values):
            text = ", ".join(_number(v) for v in values)
            return "{ " + text + " }" if c else "(" + text + ("," if len(values) == 1 else "") + ")"
        out.append({"n": tab.rows, "error": int(tab.extrapolate == "error"), "x": seq(tab.x),
                    "origin": seq(tab.origins), "coef": seq(tab.coefficients)})
    return out


def discrete_log(ev) -> list[int]:
    """ir.Events.log, two ints per discrete value (LOG_PLAIN, 0 for each where it is empty)."""
    return list(ev.log) if ev.log else [0] * (2 * ev.discrete)


def events_context(program: Program, literal) -> dict | None:
    """The sizes and tables of a program's events (None: it has none, nor their code)."""
    ev = program.events
    if ev is None:
        return None
    return {"indicators": ev.indicators, "timers": ev.timers, "discrete": ev.discrete,
            "strict": [int(x) for x in ev.strict], "names": [literal(n) for n in ev.names],
            "jumps": ev.jumps,
            "log": [str(v) for v in discrete_log(ev)],
            "kinds": "".join(k[0] for k in ev.kinds)}


# ---------------------------------------------------------------- validation


def validate(program: Program) -> None:
    n = len(program.states)
    sizes = {"init": n, "rhs": n, "outputs": len(program.outputs),
             "residual": len(program.constraints), "scale": len(program.constraints),
             "position_jac": len(program.position_rows) * n,
             "velocity_jac": len(program.velocity_rows) * n,
             "velocity_metric": len(program.velocity_rows) * n}
    if program.has_jacobian:
        sizes["jvp"] = n
    sizes.update((k, f.size) for k, f in program.functions.items() if k not in sizes)
    for name, size in sizes.items():
        f = program.function(name)
        if f.size != size:
            raise EmitError(f"function {name} has {f.size} results, expected {size}")
        stores = sorted(s.index for s in f.body if isinstance(s, Store))
        if name in SPARSE_FUNCTIONS:  # the nonzero entries, each once
            if len(set(stores)) != len(stores) or any(not 0 <= k < size for k in stores):
                raise EmitError(f"function {name} stores an entry twice or out of range")
        elif stores != list(range(size)):
            raise EmitError(f"function {name} does not store each of its {size} results once")
    if len(program.velocity_movable) != n:
        raise EmitError(f"velocity_movable has {len(program.velocity_movable)} entries, "
                        f"expected {n}")
    if program.scene.solver not in solvers.SOLVERS:
        raise EmitError(f"unknown solver {program.scene.solver!r}")
    if any(c.level not in ("position", "velocity") for c in program.constraints):
        raise EmitError("constraint levels must be 'position' or 'velocity'")
    for name in ("init", "consts"):
        if _uses_more_than_parameters(program.function(name)):
            raise EmitError(f"the {name} function may use parameters only")
    for name in PLAIN_FUNCTIONS:
        if any(isinstance(s, Newton) for s in program.function(name).body):
            raise EmitError(f"the {name} function cannot solve nonlinear blocks")
    for name in ("init", "consts"):
        if any(not isinstance(s, (Assign, Store)) for s in program.function(name).body):
            raise EmitError(f"the {name} function cannot solve algebraic blocks")
    for j, param in enumerate(program.params):
        _check_default(j, param.default)


def reads_time(f: ir.Function) -> bool:
    return any(ir.T in e.free_symbols for s in f.body for e in ir.expressions(s))


def _uses_more_than_parameters(f: ir.Function) -> bool:
    exprs = [e for s in f.body for e in ir.expressions(s)]
    return any(ir.T in e.free_symbols or e.has(ir.X) or e.has(ir.C) or e.has(ir.V)
               for e in exprs)


def _check_default(j: int, default: sp.Expr) -> None:
    default = as_expr(default)
    if ir.T in default.free_symbols or default.has(ir.X) or default.has(ir.C):
        raise EmitError(f"the default of parameter {j} uses time, states or constants")
    for ref in default.atoms(sp.Indexed):
        if ref.base == ir.P and not (ref.indices[0].is_Integer and int(ref.indices[0]) < j):
            raise EmitError(f"the default of parameter {j} uses {ref}, not an earlier parameter")


# ---------------------------------------------------------------- templates


@functools.lru_cache(maxsize=None)
def environment():
    import jinja2  # (here: the interpreter backend and a warm run do without)

    class CompiledTemplates(jinja2.BytecodeCache):
        """The templates as Jinja compiles them (Python code objects), kept in the compile
        cache (bgc.base.cache.own_cache_dir) as the parser keeps its tables: a cold `bgc
        simulate` reads them in a millisecond instead of compiling them (40 ms).  Jinja keys
        them by the template's name and checks its source's checksum and its own and
        Python's versions; anything unreadable is compiled again, and a cache that cannot
        be written is none."""

        def _path(self, bucket):
            from ..base import cache
            directory = cache.own_cache_dir()
            return None if directory is None else directory / f"jinja-{bucket.key[:40]}.cache"

        def load_bytecode(self, bucket) -> None:
            path = self._path(bucket)
            try:
                if path is not None:
                    with open(path, "rb") as f:
                        bucket.load_bytecode(f)
            except Exception:  # noqa: BLE001  (a damaged file: compiled again)
                bucket.reset()

        def dump_bytecode(self, bucket) -> None:
            from ..base import cache
            path = self._path(bucket)
            try:
                if path is not None:
                    cache.write_cached(path, bucket.write_bytecode)
            except OSError:
                pass

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(resource_dir("templates"))),
        bytecode_cache=CompiledTemplates(),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        autoescape=False,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["indent_line"] = lambda line: "    " + line
    return env


@functools.lru_cache(maxsize=None)
def c_runtime_parts() -> dict[str, str]:
    """The model-independent parts of a generated C program, as the template places them:
    the solvers' numbers (before the API), the API (bgc/runtime/api.h), and the solver tables
    followed by the runtime files (after the model part)."""
    return {"solver_enum": solver_enum_c(), "api": runtime_text("api.h"),
            "runtime": "\n".join([solver_tables_c()] + [runtime_text(f) for f in C_RUNTIME])}


def python_runtime() -> str:
    """The model-independent start of a generated Python module, after its docstring: the
    runtime (the parts PY_RUNTIME lists, each less its header, joined by two blank lines: one
    module, whose contract with the model part heads it) and the solver tables; the model part
    follows and replaces the runtime's neutral model names."""
    return "\n\n".join([runtime_body(runtime_text(f)) for f in PY_RUNTIME]
                       + [solver_tables_python()])


def runtime_body(text: str) -> str:
    """A part of the Python runtime (bgc/runtime/*.py) less its header: the comment lines up to
    the first blank line, which say what the part is and name its C twin."""
    header, blank, body = text.partition("\n\n")
    if not blank or not all(line.startswith("#") for line in header.split("\n")):
        raise ValueError("a part of the Python runtime starts with a header of comment lines, "
                         "then a blank line")
    return body


def runtime_text(name: str) -> str:
    return (resource_dir("runtime") / name).read_text(encoding="utf-8")


def render(template: str, context: dict) -> str:
    return environment().get_template(template).render(**context)


# ---------------------------------------------------------------- the runtime built once
#
# `bgc simulate` does not compile the runtime with every model: it compiles it once into the
# cache (bgc.base.cache.compile_c_linked) and links each model's part with it.  The runtime's
# files are the ones a standalone program inlines, unchanged; what they read of the model at
# compile time there (its sizes and scene as macros, its tables and model functions as static
# names, the parameter struct) the runtime unit reads from the model's object at run time:
#   - the model part exports each of them under a bgc_link_ name (_link_definitions, in place
#     of the runtime a standalone program carries);
#   - the runtime unit declares those and maps the model's names onto them with macros
#     (_link_declarations), and is the runtime's text with three mechanical rewrites
#     (unit_text): a local enum of model sizes becomes const ints, a zero-initialised
#     array of a model size a variable-length array set with memset, and the API's arrays of
#     a model size extern arrays of unknown size;
#   - the parameter struct, which the runtime copies and keeps by value, is an array of
#     LINK_PARAMS doubles in the runtime (the model's struct is all doubles, so its fields
#     are the first ones); a model with more is built standalone (linkable).
# The same compiler and flags build both units, so the arithmetic is the same instructions as
# in a standalone program (tools/csv_digests.py --c-build compares the CSV bytes).

LINK_PARAMS = 16384  # the most doubles (parameters and constants) a linked model may have
LINK_INTS = ("NUM_STATES", "NUM_PARAMS", "NUM_CONSTANTS", "NUM_OUTPUTS", "NUM_CONSTRAINTS",
             "NUM_POSITION_ROWS", "NUM_VELOCITY_ROWS", "NUM_BLOCKS", "AUTONOMOUS",
             "WORK_DOUBLES", "WORK_INTS", "WORK_Y0", "WORK_STAGES", "WORK_Y", "WORK_JAC",
             "JAC_COLORS", "JAC_SPARSE", "SCENE_SOLVER", "NUM_INDICATORS", "NUM_TIMERS",
             "NUM_DISCRETE", "DISCRETE_OFFSET", "NUM_INPUTS", "HAS_JACOBIAN", "NUM_TABLES",
             "NUM_JUMPS", "PARAM_DOUBLES")
LINK_DOUBLES = ("SCENE_T0", "SCENE_T_END", "SCENE_DT", "SCENE_RTOL", "SCENE_ATOL", "SCENE_STEP",
                "SCENE_HMAX")
LINK_TABLES = (("bgc_block", "blocks"), ("int", "jac_color_ptr"), ("int", "jac_color_cols"),
               ("int", "jac_col_ptr"), ("int", "jac_col_rows"), ("bgc_splu", "jac_lu"),
               ("int", "position_rows"),
               ("int", "velocity_rows"), ("int", "velocity_movable"),
               ("int", "indicator_strict"), ("char *const", "discrete_names"),
               ("int", "discrete_log"), ("bgc_table_data", "tables"))
LINK_FUNCTIONS = (("rhs", ""), ("outputs", ""), ("jvp", "const double *v, "), ("events", ""),
                  ("next_time", ""), ("update", "const double *r, "))
_MODEL_ARGS = "double t, const double *x, const bgc_params *p, bgc_work *w, "
_MODEL_SIZE = r"\bBGC_(?:" + "|".join(LINK_INTS + LINK_DOUBLES) + r")\b"


def linkable(program: Program) -> bool:
    """Whether the program's parameter struct fits the runtime built once (LINK_PARAMS)."""
    discrete = program.events.discrete if program.events is not None else 0
    return max(len(program.params), 1) + max(program.n_consts, 1) + discrete <= LINK_PARAMS


def _link_function(name: str, extra: str) -> tuple[str, str]:
    """The prototype of a model function as the runtime unit calls it, and its call."""
    call = "t, x, p, w, " + (extra.split("*")[1].rstrip(", ") + ", " if extra else "") + "out"
    return f"int bgc_link_{name}({_MODEL_ARGS}{extra}double *out)", call


@functools.lru_cache(maxsize=None)
def _link_definitions() -> str:
    """What a linked model part ends with instead of the runtime: its sizes, scene, tables and
    model functions under the names the runtime unit reads."""
    out = ["/* ===================================================================== link === */",
           "/* The runtime is built once and linked with this part (bgc/emit.py, c_runtime_unit):",
           "   what it reads of the model, under the names it reads. */",
           f"typedef char bgc_link_params_fit[sizeof(bgc_params) <= {LINK_PARAMS} * sizeof(double)"
           " ? 1 : -1];", "#ifndef BGC_SCENE_HMAX", "#define BGC_SCENE_HMAX 0.0", "#endif"]
    out += [f"const int bgc_link_{m.lower()} = BGC_{m};" for m in LINK_INTS]
    out += [f"const double bgc_link_{m.lower()} = BGC_{m};" for m in LINK_DOUBLES]
    out += [f"const {t} *const bgc_link_{name} = bgc_{name};" for t, name in LINK_TABLES]
    for name, extra in LINK_FUNCTIONS:
        proto, call = _link_function(name, extra)
        out += [proto, "{", f"    return bgc_model_{name}({call});", "}"]
    out += ["const char *bgc_link_input_name(int j)", "{", "    return bgc_input_name(j);", "}"]
    out += ["#ifndef BGC_NO_MAIN", "const char *const bgc_link_ident = bgc_ident;", "#endif"]
    return "\n".join(out) + "\n"


def link_declarations() -> tuple[str, str]:
    """The runtime unit's view of a linked model part: before the API, its sizes and the
    parameter struct; after it, its tables and model functions."""
    sizes = ["/* ==================================================================== model === */",
             "/* The model part this runtime is linked with (bgc/emit.py, _link_definitions). */"]
    for kind, names in (("int", LINK_INTS), ("double", LINK_DOUBLES)):
        for m in names:
            sizes += [f"extern const {kind} bgc_link_{m.lower()};",
                      f"#define BGC_{m} bgc_link_{m.lower()}"]
    sizes += ["/* The model's parameter struct is its parameters' and constants' doubles. */",
              f"typedef struct bgc_params {{ double v[{LINK_PARAMS}]; }} bgc_params;"]
    tables = []
    for t, name in LINK_TABLES:
        tables += [f"extern const {t} *const bgc_link_{name};",
                   f"#define bgc_{name} bgc_link_{name}"]
    for name, extra in LINK_FUNCTIONS:
        tables += [_link_function(name, extra)[0] + ";",
                   f"#define bgc_model_{name} bgc_link_{name}"]
    tables += ["const char *bgc_link_input_name(int j);",
               "#define bgc_input_name bgc_link_input_name"]
    tables += ["extern const char *const bgc_link_ident;", "#define bgc_ident bgc_link_ident"]
    return "\n".join(sizes) + "\n", "\n".join(tables) + "\n"


@functools.lru_cache(maxsize=None)
def c_runtime_unit() -> str:
    """The runtime built once: one C99 translation unit, the same for every model (its
    SHA-256 is part of its cache key), linked with a model part emit_c(..., linked=True)."""
    sizes, tables = link_declarations()
    return "".join([
        "/* bgc's runtime, built once and linked with each model's part (bgc/emit.py). */\n",
        environment().get_template("c_prelude.c.j2").render(), sizes, solver_enum_c(),
        unit_text(runtime_text("api.h")), tables, "\n", solver_tables_c(), "\n",
        "\n".join(unit_text(runtime_text(f)) for f in C_RUNTIME)])


def unit_text(text: str) -> str:
    """A runtime file as the runtime unit compiles it, where the model's sizes are variables
    (see above): each line rewritten by _unit_line; `names`, the enum constants made variables
    so far (N, D, M: a zeroed array of such a size is rewritten too)."""
    names: set = set()
    return "".join(_unit_line(line, names) for line in text.splitlines(keepends=True))


_ENUM = re.compile(r"^(\s*)enum \{ (.*) \};(.*\n?)$")
_ZEROED = re.compile(r"^(\s*)(double|int) ((?:\w+\[[^\]=]+\] = \{ 0(?:\.0)? \}(?:, )?)+);(\n?)$")
_EXTERN_ARRAY = re.compile(r"^(extern .*)\[BGC_DIM\(BGC_NUM_\w+\)\];")


def _unit_line(line: str, names: set) -> str:
    m = _EXTERN_ARRAY.match(line)
    if m:
        return _EXTERN_ARRAY.sub(r"\1[];", line)
    m = _ENUM.match(line)
    if m and _model_sized(m.group(2), names):
        indent, body, rest = m.groups()
        items = body.split(", ")
        sized = [i for i in items if _model_sized(i, names)]
        names.update(i.split(" = ")[0] for i in sized)
        fixed = [i for i in items if i not in sized]
        return (f"{indent}const int {', '.join(sized)};"
                + (f" enum {{ {', '.join(fixed)} }};" if fixed else "") + rest)
    m = _ZEROED.match(line)
    if m and _model_sized(m.group(3), names):
        indent, kind, decls, end = m.groups()
        arrays = [d.split(" = ")[0] for d in decls.split("}, ")]
        zero = " ".join(f"memset({a.split('[')[0]}, 0, sizeof {a.split('[')[0]});" for a in arrays)
        return f"{indent}{kind} {', '.join(arrays)};{end}{indent}{zero}{end}"
    return line


def _model_sized(text: str, names: set) -> bool:
    """Whether a C expression reads one of the model's sizes (a macro, or an enum constant
    made from one)."""
    return bool(re.search(_MODEL_SIZE, text)) or any(
        re.search(rf"\b{re.escape(n)}\b", text) for n in names)


# ---------------------------------------------------------------- the solver tables


def _number(value) -> str:
    """A coefficient as the shortest literal that reads back as the same double (C and
    Python)."""
    text = repr(float(value))
    return text if any(c in text for c in ".en") else text + ".0"


def _c_array(name: str, values) -> str:
    values = list(values)
    if not values:
        return ""
    body = ", ".join(_number(v) for v in values)
    return f"static const double {name}[{len(values)}] = {{ {body} }};\n"


def square(rows, width: int) -> list:
    """Strictly lower triangular rows as a width x width row-major list."""
    out = []
    for row in rows:
        out += list(row) + [0] * (width - len(row))
    return out


def solver_enum_c() -> str:
    """The solvers' numbers, before the API section of a generated C program."""
    lines = ["/* ============================================================ solvers === */",
             "/* The solvers (bgc/solvers.py); their tables follow the API section. */",
             f"#define BGC_NUM_SOLVERS {len(solvers.NAMES)}",
             f"#define BGC_SOLVER_LIST {c_string_literal(solvers.names_text())}",
             "enum {"]
    lines += [f"    BGC_SOLVER_{name.upper()} = {k}," for k, name in enumerate(solvers.NAMES)]
    lines.append("};")
    return "\n".join(lines) + "\n"


def solver_tables_c() -> str:
    """The solvers' coefficients and descriptions as C data (the same in every program)."""
    out = ["/* ====================================================== solver tables === */",
           "/* Printed from bgc/solvers.py. */"]
    radau_sets: dict = {}
    for s in solvers.SOLVER_LIST:
        tab, ident = s.tableau, f"bgc_{s.name}"
        if isinstance(tab, solvers.ERKTableau):
            width = tab.all_stages
            out.append(_c_array(f"{ident}_c", tab.c + tab.extra_c)
                       + _c_array(f"{ident}_a", square(tab.a + tab.extra_a, width))
                       + _c_array(f"{ident}_b", tab.b) + _c_array(f"{ident}_e", tab.error)
                       + _c_array(f"{ident}_e2", tab.error2)
                       + _c_array(f"{ident}_P", [v for row in tab.dense for v in row]))
            degree = len(tab.dense[0]) if tab.dense else 0
            ptr = lambda part, present: f"{ident}_{part}" if present else "NULL"  # noqa: E731
            out.append(f"static const bgc_erk {ident}_erk = {{ {tab.stages}, {width}, "
                       f"{int(tab.fsal)}, {degree}, {ident}_c, {ident}_a, {ident}_b, "
                       f"{ptr('e', tab.error)}, {ptr('e2', tab.error2)}, "
                       f"{ptr('P', tab.dense)} }};")
        elif isinstance(tab, solvers.RosenbrockTableau):
            st = tab.stages
            out.append(_c_array(f"{ident}_c", tab.c) + _c_array(f"{ident}_d", tab.d)
                       + _c_array(f"{ident}_a", square(tab.a, st))
                       + _c_array(f"{ident}_C", square(tab.C, st))
                       + _c_array(f"{ident}_m", tab.m) + _c_array(f"{ident}_e", tab.e)
                       + _c_array(f"{ident}_H", [v for row in tab.dense for v in row]))
            out.append(f"static const bgc_rosenbrock {ident}_ros = {{ {st}, {len(tab.dense)}, "
                       f"{_number(tab.gamma)}, {ident}_c, {ident}_d, {ident}_a, {ident}_C, "
                       f"{ident}_m, {ident}_e, {ident}_H }};")
        elif s.family == "radau":  # the stage sets' arrays once, then the solver's sets
            for set_ in tab:
                sid = f"bgc_radau_s{set_.stages}"
                if sid in radau_sets:
                    assert radau_sets[sid] is set_, "one tableau per stage count"
                    continue
                radau_sets[sid] = set_
                out.append(_c_array(f"{sid}_c", set_.c) + _c_array(f"{sid}_alpha", set_.alpha)
                           + _c_array(f"{sid}_beta", set_.beta)
                           + _c_array(f"{sid}_T", [v for row in set_.T for v in row])
                           + _c_array(f"{sid}_Ti", [v for row in set_.Ti for v in row])
                           + _c_array(f"{sid}_e", set_.e))
            out.append(f"static const bgc_radau {ident}_radau[{len(tab)}] = {{")
            for set_ in tab:
                sid = f"bgc_radau_s{set_.stages}"
                out.append(f"    {{ {set_.stages}, {_number(set_.gamma)}, {sid}_c, {sid}_alpha, "
                           f"{sid}_beta, {sid}_T, {sid}_Ti, {sid}_e }},")
            out.append("};")
    out.append("const char *const bgc_solver_names[BGC_NUM_SOLVERS] = {")
    out += [f"    {c_string_literal(s.name)}," for s in solvers.SOLVER_LIST]
    out.append("};")
    out.append("static const bgc_method bgc_methods[BGC_NUM_SOLVERS] = {")
    for k, s in enumerate(solvers.SOLVER_LIST):
        ctl = s.control or solvers.Control(0.9, 0.2, 10.0, 0.0, s.order)
        stiff = s.stiffness
        erk = f"&bgc_{s.name}_erk" if isinstance(s.tableau, solvers.ERKTableau) else "NULL"
        ros = (f"&bgc_{s.name}_ros" if isinstance(s.tableau, solvers.RosenbrockTableau)
               else "NULL")
        radau = (f"bgc_{s.name}_radau, {len(s.tableau)}" if s.family == "radau"
                 else "NULL, 0")
        phases = ((solvers.index(s.explicit), solvers.index(s.stiff)) if s.family == "auto"
                  else (-1, -1))
        out.append(
            f"    {{ {c_string_literal(s.name)}, {c_string_literal(s.summary)}, "
            f"BGC_FAMILY_{s.family.upper()}, {s.order}, {erk}, {ros}, {_number(ctl.safe)}, "
            f"{_number(ctl.fac_min)}, {_number(ctl.fac_max)}, {_number(ctl.beta)}, {ctl.q}, "
            f"{_number(ctl.expo_beta)}, "
            f"{stiff.stage_i if stiff else -1}, {stiff.stage_j if stiff else -1}, "
            f"{_number(stiff.bound) if stiff else '0.0'}, {phases[0]}, {phases[1]}, {radau} }},")
    out.append("};")
    return "\n".join(out) + "\n"


def _py_tuple(values) -> str:
    values = [_number(v) for v in values]
    return "(" + ", ".join(values) + ("," if len(values) == 1 else "") + ")"


def solver_tables_python() -> str:
    """The solvers' coefficients and descriptions as Python data (the same in every module):
    _METHODS maps a name to a dict of its family, control and tableau."""
    lines = ["# ================================================================ solvers ===",
             "# Printed from bgc/solvers.py.", "_METHODS = {"]
    for s in solvers.SOLVER_LIST:
        ctl = s.control or solvers.Control(0.9, 0.2, 10.0, 0.0, s.order)
        fields = {"family": repr(s.family), "order": str(s.order), "summary": repr(s.summary),
                  "safe": _number(ctl.safe), "fac_min": _number(ctl.fac_min),
                  "fac_max": _number(ctl.fac_max), "beta": _number(ctl.beta), "q": str(ctl.q),
                  "expo_beta": _number(ctl.expo_beta)}
        tab = s.tableau
        if isinstance(tab, solvers.ERKTableau):
            fields.update(
                stages=str(tab.stages), fsal=str(tab.fsal),
                c=_py_tuple(tab.c + tab.extra_c),
                a="(" + ", ".join(_py_tuple(r) for r in tab.a + tab.extra_a) + ",)",
                b=_py_tuple(tab.b), e=_py_tuple(tab.error), e2=_py_tuple(tab.error2),
                P="(" + "".join(_py_tuple(r) + ", " for r in tab.dense) + ")")
        elif isinstance(tab, solvers.RosenbrockTableau):
            fields.update(
                stages=str(tab.stages), gamma=_number(tab.gamma), c=_py_tuple(tab.c),
                d=_py_tuple(tab.d), a="(" + ", ".join(_py_tuple(r) for r in tab.a) + ",)",
                C="(" + ", ".join(_py_tuple(r) for r in tab.C) + ",)", m=_py_tuple(tab.m),
                e=_py_tuple(tab.e), H="(" + ", ".join(_py_tuple(r) for r in tab.dense) + ",)")
        elif s.family == "radau":  # dicts of their own: 'beta' is taken
            fields["radau"] = "(" + "".join(
                "{" + ", ".join(f"{k!r}: {v}" for k, v in {
                    "s": str(t.stages), "c": _py_tuple(t.c), "gamma": _number(t.gamma),
                    "alpha": _py_tuple(t.alpha), "beta": _py_tuple(t.beta),
                    "T": "(" + ", ".join(_py_tuple(r) for r in t.T) + ",)",
                    "Ti": "(" + ", ".join(_py_tuple(r) for r in t.Ti) + ",)",
                    "e": _py_tuple(t.e)}.items()) + "}, " for t in tab) + ")"
        if s.stiffness:
            fields["stiffness"] = (f"({s.stiffness.stage_i}, {s.stiffness.stage_j}, "
                                   f"{_number(s.stiffness.bound)})")
        if s.family == "auto":
            fields.update(explicit=repr(s.explicit), stiff=repr(s.stiff))
        lines.append(f"    {s.name!r}: {{")
        lines += [f"        {key!r}: {value}," for key, value in fields.items()]
        lines.append("    },")
    lines.append("}")
    lines.append("SOLVERS = tuple(_METHODS)")
    lines.append(f"_SOLVER_LIST = {solvers.names_text()!r}")
    return "\n".join(lines) + "\n"
