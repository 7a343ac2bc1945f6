"""The interpreter backend: a Program (bgc.ir) as a compact instruction list for the
interpreter built once per machine (bgc/runtime/vm.c), so a model runs without a C build.

The interpreter is the runtime built once (the step driver, the solvers, the CSV writer, the
command line: bgc.codegen.emit.c_runtime_unit) with bgc/runtime/vm.c in place of a model's part: at
its start it reads the file this module writes and implements the model part's contract
(bgc/runtime/api.h) by interpreting it.  So a run goes through the same driver and solvers as
the C backend, and only the model's functions are interpreted.

Same bytes as the C backend: each expression is printed by the C printer (bgc.ir.printers, the
text the C backend compiles, with only the names of its operands changed), and that text is
read back with C's precedence and associativity into register instructions, one per operation
of the text, in its order.  The interpreter does each with the same C operation or libm call,
in a translation unit compiled with the same flags, so it computes the same bits as the
generated C (and therefore as the Python module).

The program file (little-endian): the model part's sizes, scene, names and tables (the
bgc_link_* values of bgc.codegen.emit, in their order), the blocks' plans and workspace offsets, a
table of constants, and code segments: each a frame size and instructions of four int32
(opcode, then operands: registers, indices into x, p, the constants, out, or a block).  The
functions of a model part are segments (ENTRIES; a parameter's default is a segment of its
own); a Newton block's residuals and Jacobian are a segment that its NEWTON instruction names.
The registers of the model functions live in the workspace (bgc_work.v) above the program's
own storage, so the interpreter allocates nothing per call.

A new IR function (a new name in bgc.ir's FUNCTIONS, a new statement kind) is one entry in
OPS (and in _CALLS for a function printed as a call) and one case in vm.c.
"""
from __future__ import annotations

import functools
import hashlib
import re
import struct
from pathlib import Path


from . import emit
from .. import ir
from ..base import cache, toolchain
from ..base.resources import resource_dir
from ..ir import Assign, Newton, Program, Resolve, Solve, Store
from ..ir.printers import CPrinter

FORMAT = 7  # of the program file; vm.c refuses any other
MAGIC = b"BGCVM\0\0\0"

# The instruction set: name and the kinds of its three operands (r: a register; i: an index,
# into x, p, the input vector, the constants, out or J, or a block; -: unused).  The order is
# the opcodes' numbers; vm.c's cases are named the same (BGC_VM_<NAME>).
OPS = (
    ("END", "---"),       # return 0
    ("LDX", "ri-"),       # r = x[i]
    ("LDP", "ri-"),       # r = p->v[i]  (parameters, then constants c, then discrete d)
    ("LDIN", "ri-"),      # r = in[i]  (jvp's v, update's r, a Newton block's unknowns z)
    ("LDT", "r--"),       # r = t
    ("LDATOL", "r--"),    # r = w->atol
    ("LDK", "ri-"),       # r = constant i
    ("MOV", "rr-"),
    ("STO", "ir-"),       # out[i] = r
    ("STJ", "ir-"),       # J[i] = r (a Newton block's Jacobian entries)
    ("JEND", "---"),      # return 0 if J is NULL (a Newton block's residuals only)
    ("ADD", "rrr"), ("SUB", "rrr"), ("MUL", "rrr"), ("DIV", "rrr"), ("NEG", "rr-"),
    ("LT", "rrr"), ("LE", "rrr"), ("GT", "rrr"), ("GE", "rrr"), ("EQ", "rrr"), ("NE", "rrr"),
    ("AND", "rrr"), ("OR", "rrr"), ("NOT", "rr-"),
    ("SEL", "rrr"),       # r0 = r0 != 0 ? r1 : r2
    ("SIN", "rr-"), ("COS", "rr-"), ("TAN", "rr-"), ("ASIN", "rr-"), ("ACOS", "rr-"),
    ("ATAN", "rr-"), ("SINH", "rr-"), ("COSH", "rr-"), ("TANH", "rr-"), ("ASINH", "rr-"),
    ("ACOSH", "rr-"), ("ATANH", "rr-"), ("EXP", "rr-"), ("LOG", "rr-"), ("SQRT", "rr-"),
    ("FABS", "rr-"), ("SIGN", "rr-"),
    ("ATAN2", "rrr"), ("POW", "rrr"), ("MIN", "rrr"), ("MAX", "rrr"), ("HEAVISIDE", "rrr"),
    ("SQUARE", "rrr"),    # r0 = bgc_square(r1, r2, the next instruction's r1, r2)
    ("SQUARENEXT", "rrr"),
    ("PERIODICNEXT", "rrr"),  # r0 = bgc_periodic_next(r1, r2, the next instruction's r1)
    ("ARGS", "-rr"),      # the last arguments of SQUARE, SQUARENEXT, PERIODICNEXT
    ("SOLVE", "i--"),     # bgc_block_solve(w, i, t); return 1 if it fails
    ("RESOLVE", "i--"),
    ("NEWTON", "iii"),    # bgc_newton(w, block, the segment's residuals, ..., final)
    ("TABLE", "rrr"),     # r0 = bgc_table(&bgc_tables[k], r1, r2, order): k, order the IARGS'
    ("TABLEGUARD", "rri"),  # r0 = bgc_table_guard(&bgc_tables[i], r1)
    ("TABLEPIECE", "rri"),  # r0 = bgc_table_piece(&bgc_tables[i], r1)
    ("TABLENEXT", "rri"),   # r0 = bgc_table_next(&bgc_tables[i], r1)
    ("INPUT", "rrr"),     # r0 = bgc_input(w, j, r1, part, r2): j, part the IARGS'
    ("INPUTNEXT", "rri"),   # r0 = bgc_input_next(w, i, r1)
    ("IARGS", "-ii"),     # the indices of TABLE and INPUT
)
OPCODE = {name: k for k, (name, _) in enumerate(OPS)}
KINDS = {name: kinds for name, kinds in OPS}

# the functions the C printer calls, as instructions
_CALLS = {"sin": "SIN", "cos": "COS", "tan": "TAN", "asin": "ASIN", "acos": "ACOS",
          "atan": "ATAN", "sinh": "SINH", "cosh": "COSH", "tanh": "TANH", "asinh": "ASINH",
          "acosh": "ACOSH", "atanh": "ATANH", "exp": "EXP", "log": "LOG", "sqrt": "SQRT",
          "fabs": "FABS", "bgc_sign": "SIGN", "atan2": "ATAN2", "pow": "POW",
          "bgc_min": "MIN", "bgc_max": "MAX", "bgc_heaviside": "HEAVISIDE",
          "bgc_square": "SQUARE", "bgc_square_next": "SQUARENEXT",
          "bgc_periodic_next": "PERIODICNEXT"}
# the runtime's calls that name a table or an input (their first arguments are indices)
_INDEXED = {"bgc_table": "TABLE", "bgc_table_guard": "TABLEGUARD",
            "bgc_table_piece": "TABLEPIECE", "bgc_table_next": "TABLENEXT",
            "bgc_input": "INPUT", "bgc_input_next": "INPUTNEXT"}

# the model part's entry points, in the file's order (-1: the program has none)
ENTRIES = ("consts", "init", "rhs", "outputs", "jvp", "events", "next_time", "update",
           "residual", "scale", "position_jac", "velocity_jac", "velocity_metric")
MODEL_FUNCTIONS = ("rhs", "outputs", "jvp", "events", "next_time", "update")
INT_TABLES = ("jac_color_ptr", "jac_color_cols", "jac_col_ptr", "jac_col_rows",
              "position_rows", "velocity_rows", "velocity_movable", "indicator_strict",
              "discrete_log")


class VMError(toolchain.BackendError):
    """A program the interpreter cannot run (too many parameters for the runtime built once:
    bgc.codegen.emit.linkable; functions of an FMU), or a bug in bgc: the command line says it in
    one
    line, as it says a C toolchain's failure."""


# ---------------------------------------------------------------- C text to instructions


class _Printer(CPrinter):
    """The C printer, its operands named plainly: x[i], v[i], r[i], p[j], c[k], d[k], t,
    atol and program variables by name (or as `names` says), table k as tab[k]."""

    ATOL = "atol"

    def _print_index(self, base, index):
        return f"{base.name}[{index}]"

    def _table_ref(self, k):
        return f"tab[{k}]"


_TOKEN = re.compile(r"\s*(?:(\d+\.\d*(?:e[-+]?\d+)?|\d+e[-+]?\d+|\d+)"
                    r"|([A-Za-z_]\w*)(?:\[(\d+)\])?"
                    r"|(<=|>=|==|!=|&&|\|\||[-+*/()<>!?:,]))")
_BINARY = {"||": (2, "OR"), "&&": (3, "AND"), "==": (4, "EQ"), "!=": (4, "NE"),
           "<": (5, "LT"), "<=": (5, "LE"), ">": (5, "GT"), ">=": (5, "GE"),
           "+": (6, "ADD"), "-": (6, "SUB"), "*": (7, "MUL"), "/": (7, "DIV")}
_UNARY = 8


def _tokens(text: str) -> list:
    out, pos = [], 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            raise VMError(f"cannot read the printed expression at {text[pos:pos + 20]!r}")
        pos = m.end()
        number, name, index, op = m.groups()
        if number is not None:
            out.append(("num", float(number)))
        elif name is not None:
            out.append(("name", name, None if index is None else int(index)))
        else:
            out.append(("op", op))
    out.append(("op", "$"))
    return out


class _Segment:
    """The instructions of one segment being written: operands are registers of the function
    (fixed: >= 0) or temporaries (< 0, numbered from -1 down, a stack), placed above the
    function's fixed registers at the end (_Function.finish)."""

    def __init__(self):
        self.code: list[list] = []  # [op, a, b, c]
        self.prologue: list[list] = []  # loads of the segment's own inputs (a Newton's z)


class _Function:
    """The registers and segments of one IR function (and its Newton blocks)."""

    def __init__(self, unit: "_Unit", base: int):
        self.unit = unit
        self.base = base
        self.fixed = 0  # registers base .. base + fixed - 1
        self.temps = 0  # the temporaries in use (a stack) ...
        self.most = 0  # ... and the most at once
        self.reg: dict = {}  # symbol, ("x", i), ("k", value), ... -> register
        self.prologue: list[list] = []  # the function's input loads
        self.segments: list[_Segment] = []

    def fixed_reg(self) -> int:
        self.fixed += 1
        return self.base + self.fixed - 1

    def alloc(self) -> int:
        self.temps += 1
        self.most = max(self.most, self.temps)
        return -self.temps

    def free(self, r: int) -> None:
        if r < 0:
            assert r == -self.temps, "temporaries freed out of order"
            self.temps -= 1

    def input(self, key, seg: _Segment | None = None) -> int:
        """The register an input is loaded into, once (in the function's prologue, or a Newton
        segment's own for its unknowns)."""
        if key in self.reg:
            return self.reg[key]
        r = self.fixed_reg()
        self.reg[key] = r
        kind = key[0]
        if kind == "x":
            load = ["LDX", r, key[1], 0]
        elif kind == "p":
            load = ["LDP", r, key[1], 0]
        elif kind in ("in", "z"):  # (a Newton segment's z: keyed by the segment too)
            load = ["LDIN", r, key[1], 0]
        elif kind == "t":
            load = ["LDT", r, 0, 0]
        elif kind == "atol":
            load = ["LDATOL", r, 0, 0]
        else:  # a number
            load = ["LDK", r, self.unit.constant(key[1]), 0]
        (seg.prologue if kind == "z" else self.prologue).append(load)
        return r

    def finish(self) -> tuple[int, list]:
        """The frame size and each segment's code (prologue first, the function's own prologue
        before its first segment), temporaries placed after the fixed registers."""
        top = self.base + self.fixed
        out = []
        for k, seg in enumerate(self.segments):
            code = (self.prologue if k == 0 else []) + seg.prologue + seg.code + [["END", 0, 0, 0]]
            words = []
            for op, *args in code:
                kinds = KINDS[op]
                words.append(OPCODE[op])
                for kind, a in zip(kinds, args):
                    words.append(top - a - 1 if kind == "r" and a < 0 else a)
            out.append(words)
        return top + self.most, out


class _Unit:
    """The whole program being written: its constants and segments."""

    def __init__(self, program: Program):
        self.program = program
        self.constants: dict = {}
        self.segments: list = []  # (frame, words)
        n = len(program.states)
        self.printer = _Printer(n, tuple(f"p{j}" for j in range(len(program.params))),
                                program.n_consts)
        self.n_params = max(len(program.params), 1)
        self.c_base = self.n_params
        self.d_base = self.n_params + max(program.n_consts, 1)

    def constant(self, value: float) -> int:
        key = struct.pack("<d", value)  # (-0.0 and 0.0 apart)
        if key not in self.constants:
            self.constants[key] = len(self.constants)
        return self.constants[key]


class _Compiler:
    """One segment's statements into instructions."""

    def __init__(self, fn: _Function, seg: _Segment, names: dict):
        self.fn = fn
        self.seg = seg
        self.names = names  # symbol name -> register (program variables, unknowns, ...)

    def emit(self, op, a=0, b=0, c=0):
        self.seg.code.append([op, a, b, c])

    # -- expressions

    def expression(self, e) -> int:
        """A register holding e's value (a temporary, or a fixed register)."""
        text = self.fn.unit.printer.doprint(e)
        self.toks = _tokens(text)
        self.pos = 0
        r, _ = self.parse(0)
        if self.toks[self.pos] != ("op", "$"):
            raise VMError(f"cannot read the printed expression {text!r}")
        return r

    def into(self, target: int, e) -> None:
        """e computed into the register target."""
        r = self.expression(e)
        code = self.seg.code
        if r < 0 and code and code[-1][1] == r and KINDS[code[-1][0]][0] == "r" and \
                code[-1][0] != "SEL":  # (SEL reads its condition where it writes)
            code[-1][1] = target
        else:
            self.emit("MOV", target, r)
        self.fn.free(r)

    def peek(self):
        return self.toks[self.pos]

    def take(self):
        tok = self.toks[self.pos]
        self.pos += 1
        return tok

    def expect(self, op):
        tok = self.take()
        if tok != ("op", op):
            raise VMError(f"expected {op!r} in a printed expression, got {tok!r}")

    def parse(self, rbp: int) -> tuple[int, float | None]:
        """Pratt parsing of C's expression grammar (as much of it as the printer writes):
        (register, its constant value if a literal)."""
        left = self.nud()
        while True:
            tok = self.peek()
            if tok[0] != "op":
                raise VMError(f"unexpected {tok!r} in a printed expression")
            op = tok[1]
            if op == "?":
                if rbp >= 1:
                    return left
                self.take()
                cond = left[0]
                if cond >= 0:  # (SEL writes its result over the condition)
                    t = self.fn.alloc()
                    self.emit("MOV", t, cond)
                    cond = t
                a, _ = self.parse(0)
                self.expect(":")
                b, _ = self.parse(0)
                self.fn.free(b)
                self.fn.free(a)
                self.emit("SEL", cond, a, b)
                left = (cond, None)
                continue
            if op not in _BINARY or _BINARY[op][0] <= rbp:
                return left
            self.take()
            bp, name = _BINARY[op]
            right = self.parse(bp)
            left = (self.binary(name, left[0], right[0]), None)

    def binary(self, name: str, a: int, b: int) -> int:
        self.fn.free(b)
        dst = a if a < 0 else self.fn.alloc()
        self.emit(name, dst, a, b)
        return dst

    def nud(self) -> tuple[int, float | None]:
        tok = self.take()
        if tok[0] == "num":
            return self.fn.input(("k", tok[1])), tok[1]
        if tok[0] == "name":
            _, name, index = tok
            if self.peek() == ("op", "(") and index is None:
                return self.call(name), None
            return self.operand(name, index), None
        op = tok[1]
        if op == "(":
            inner = self.parse(0)
            self.expect(")")
            return inner
        if op == "-":
            if self.peek()[0] == "num":  # a negative literal
                value = -self.take()[1]
                return self.fn.input(("k", value)), value
            r, value = self.parse(_UNARY)
            if value is not None:  # a negative literal
                return self.fn.input(("k", -value)), -value
            return self.unary("NEG", r), None
        if op == "!":
            r, _ = self.parse(_UNARY)
            return self.unary("NOT", r), None
        raise VMError(f"unexpected {op!r} in a printed expression")

    def unary(self, name: str, r: int) -> int:
        dst = r if r < 0 else self.fn.alloc()
        self.emit(name, dst, r)
        return dst

    def index(self, expect: str) -> int:
        """A table's number (tab[k]) or an integer literal (an input's number, a part, an
        order) of a call in _INDEXED."""
        tok = self.take()
        if expect == "tab" and tok[0] == "name" and tok[1] == "tab" and tok[2] is not None:
            return tok[2]
        if expect == "int" and tok[0] == "num" and tok[1] == int(tok[1]) and tok[1] >= 0:
            return int(tok[1])
        raise VMError(f"expected {'a table' if expect == 'tab' else 'an index'} in a printed "
                      f"call, got {tok!r}")

    def indexed(self, name: str) -> int:
        """A call of _INDEXED: bgc_table(tab[k], X, piece, order), bgc_table_guard(tab[k], X),
        ..., bgc_input(w, j, t, part, default), bgc_input_next(w, j, t); its registers'
        arguments evaluated in their order, as C evaluates them (they have no effects)."""
        op = _INDEXED[name]
        if op.startswith("INPUT"):
            if self.take() != ("name", "w", None):
                raise VMError(f"expected the workspace as {name}'s first argument")
            self.expect(",")
            first = self.index("int")
        else:
            first = self.index("tab")
        self.expect(",")
        a = self.parse(0)[0]
        regs, ints = [a], [first]
        if op == "TABLE":
            self.expect(",")
            regs.append(self.parse(0)[0])
            self.expect(",")
            ints.append(self.index("int"))
        elif op == "INPUT":
            self.expect(",")
            ints.append(self.index("int"))
            self.expect(",")
            regs.append(self.parse(0)[0])
        self.expect(")")
        for r in reversed(regs):
            self.fn.free(r)
        dst = self.fn.alloc()
        if op in ("TABLE", "INPUT"):
            self.emit(op, dst, regs[0], regs[1])
            self.emit("IARGS", 0, ints[0], ints[1])
        else:
            self.emit(op, dst, regs[0], ints[0])
        return dst

    def call(self, name: str) -> int:
        self.expect("(")
        if name in _INDEXED:
            return self.indexed(name)
        args = [self.parse(0)[0]]
        while self.peek() == ("op", ","):
            self.take()
            args.append(self.parse(0)[0])
        self.expect(")")
        if name == "bgc_opaque":  # (the interpreter folds nothing: the number as it is)
            (a,) = args
            return a
        if name == "bgc_sq":
            (a,) = args
            dst = a if a < 0 else self.fn.alloc()
            self.emit("MUL", dst, a, a)
            return dst
        op = _CALLS.get(name)
        if op is None:
            raise VMError(f"the interpreter has no function {name!r}")
        for a in reversed(args):
            self.fn.free(a)
        dst = self.fn.alloc()
        if op in ("SQUARE", "SQUARENEXT", "PERIODICNEXT"):
            self.emit(op, dst, args[0], args[1])
            self.emit("ARGS", 0, args[2], args[3] if len(args) > 3 else args[2])
        elif KINDS[op][2] == "r":
            self.emit(op, dst, args[0], args[1])
        else:
            self.emit(op, dst, args[0])
        return dst

    def operand(self, name: str, index: int | None) -> int:
        fn = self.fn
        if index is None:
            if name == "t":
                return fn.input(("t",))
            if name == "atol":
                return fn.input(("atol",))
            if name in self.names:
                return self.names[name]
            raise VMError(f"unknown variable {name!r} in a printed expression")
        if name == "x":
            return fn.input(("x", index))
        if name == "p":
            return fn.input(("p", index))
        if name == "c":
            return fn.input(("p", fn.unit.c_base + index))
        if name == "d":
            return fn.input(("p", fn.unit.d_base + index))
        if name in ("v", "r"):
            return fn.input(("in", index))
        if name == "wv":
            return index
        raise VMError(f"unknown operand {name}[{index}] in a printed expression")

    # -- statements

    def var(self, sym) -> int:
        r = self.names.get(sym.name)
        if r is None:
            r = self.names[sym.name] = self.fn.fixed_reg()
        return r

    def statement(self, s, ws) -> None:
        program = self.fn.unit.program
        if isinstance(s, Assign):
            self.into(self.var(s.target), s.expr)
        elif isinstance(s, Store):
            r = self.expression(s.expr)
            self.emit("STO", s.index, r)
            self.fn.free(r)
        elif isinstance(s, (Solve, Resolve)):
            bp, area = program.blocks[s.block], ws.blocks[s.block]
            if isinstance(s, Solve):
                for pos, e in zip(bp.lu.entries, s.matrix):
                    self.into(area.save + pos, e)
            for row, e in enumerate(s.rhs):
                self.into(area.b + row, e)
            self.emit("SOLVE" if isinstance(s, Solve) else "RESOLVE", s.block)
            targets = s.unknowns if isinstance(s, Solve) else s.targets
            for k, z in enumerate(targets):
                self.emit("MOV", self.var(z), area.b + k)
        elif isinstance(s, Newton):
            area = ws.blocks[s.block]
            for k, z in enumerate(s.unknowns):
                self.names[z.name] = area.z + k  # (the outer code reads them there)
            seg = _Segment()
            self.fn.segments.append(seg)
            index = len(self.fn.segments) - 1  # (made absolute by _write)
            inner = _Compiler(self.fn, seg, dict(self.names))
            for k, z in enumerate(s.unknowns):
                inner.names[z.name] = None
            inner.newton(s, program.blocks[s.block])
            for a in s.body:  # (the body's variables, set by the last evaluation)
                self.names[a.target.name] = inner.names[a.target.name]
            self.emit("NEWTON", s.block, index, int(s.final_factor))
        else:
            raise VMError(f"unknown statement {s!r}")

    def newton(self, s: Newton, bp) -> None:
        for k, z in enumerate(s.unknowns):
            self.names[z.name] = self.fn.input(("z", k, id(self.seg)), self.seg)
        for a in s.body:
            self.statement(a, None)
        for i, e in enumerate(s.residuals):
            r = self.expression(e)
            self.emit("STO", i, r)
            self.fn.free(r)
        self.emit("JEND")
        for a in s.tangents:
            self.statement(a, None)
        for pos, e in zip(bp.lu.entries, s.jacobian):
            r = self.expression(e)
            self.emit("STJ", pos, r)
            self.fn.free(r)


def _function(unit: _Unit, body, ws, base: int) -> tuple[int, list]:
    fn = _Function(unit, base)
    seg = _Segment()
    fn.segments.append(seg)
    compiler = _Compiler(fn, seg, {})
    for s in body:
        compiler.statement(s, ws)
    return fn.finish()


# ---------------------------------------------------------------- the file


def _ints(values) -> bytes:
    values = list(values)
    return struct.pack(f"<i{len(values)}i", len(values), *values)


def _strings(texts) -> bytes:
    out = [struct.pack("<i", len(texts))]
    for text in texts:
        data = text.encode("utf-8", "surrogatepass")
        out.append(struct.pack("<i", len(data)) + data)
    return b"".join(out)


def _declined(program: Program) -> bool:
    """Parts the interpreter does not run yet: a sparse Jacobian (bgc.symbolic.sparse's iteration
    plan); such a model is built in C."""
    return program.jacobian.lu is not None


def supports(program: Program) -> bool:
    """Whether the interpreter runs the program (else program_bytes raises VMError): its
    parameters and constants fit the runtime built once, nothing of it is _declined, and its
    functions are a model part's (MODEL_FUNCTIONS and the constraint rows', not an FMU's
    outputs_jvp)."""
    return emit.linkable(program) and not _declined(program) and all(
        k in MODEL_FUNCTIONS for k in emit.model_functions(program))


def program_bytes(program: Program) -> bytes:
    """The program file the interpreter runs (see the module's docstring)."""
    if not emit.linkable(program):
        raise VMError("the model has more parameters and constants than the interpreter "
                      f"holds ({emit.LINK_PARAMS}); use --backend c")
    if _declined(program):
        raise VMError("the interpreter does not run models with a sparse Jacobian yet; use "
                      "--backend c")
    emit.validate(program)
    unit = _Unit(program)
    ws = emit.workspace(program, ir.CHUNK_OPS, layouts=False)
    base = ws.doubles  # the interpreter's registers: above the program's own storage
    entries = {}
    frames = [0]
    names = emit.model_functions(program)
    extra = [k for k in names if k not in MODEL_FUNCTIONS]
    if extra:
        raise VMError(f"the interpreter does not run the functions {', '.join(extra)}")

    def add(name, body, b):
        frame, segs = _function(unit, body, ws, b)
        first = len(unit.segments)
        for words in segs:  # a NEWTON's segment index made absolute
            k = 0
            while k < len(words):
                op = OPS[words[k]][0]
                if op == "NEWTON":
                    words[k + 2] += first
                k += 4
            unit.segments.append((frame, words))
        if name is not None:
            entries[name] = first
        return frame

    for name in MODEL_FUNCTIONS + ("residual", "scale", "position_jac", "velocity_jac",
                                   "velocity_metric"):
        if name in program.functions:
            frames.append(add(name, program.function(name).body, base))
    defaults = []
    for j, param in enumerate(program.params):
        defaults.append(len(unit.segments))
        add(None, (Store(0, ir.as_expr(param.default)),), 0)
    add("consts", program.function("consts").body, 0)
    add("init", program.function("init").body, 0)
    work_doubles = max(frames)
    if work_doubles < ws.doubles:
        work_doubles = ws.doubles

    ev = program.events
    jac = program.jacobian
    color_ptr, color_cols, col_ptr, col_rows = [0], [], [0], []
    for cols in jac.colors:
        color_cols += cols
        color_ptr.append(len(color_cols))
    for rows in jac.columns:
        col_rows += rows
        col_ptr.append(len(col_rows))
    sc = program.scene
    ints = {
        "NUM_STATES": len(program.states), "NUM_PARAMS": len(program.params),
        "NUM_CONSTANTS": program.n_consts, "NUM_OUTPUTS": len(program.outputs),
        "NUM_CONSTRAINTS": len(program.constraints),
        "NUM_POSITION_ROWS": len(program.position_rows),
        "NUM_VELOCITY_ROWS": len(program.velocity_rows), "NUM_BLOCKS": len(program.blocks),
        "AUTONOMOUS": int(not emit.reads_time(program.function("rhs"))),
        "WORK_DOUBLES": work_doubles, "WORK_INTS": ws.ints, "WORK_Y0": ws.y0,
        "WORK_STAGES": ws.stages, "WORK_Y": ws.y, "WORK_JAC": ws.jac,
        "JAC_COLORS": len(jac.colors), "JAC_SPARSE": 0, "SCENE_SOLVER": emit.solvers.index(sc.solver),
        "NUM_INDICATORS": ev.indicators if ev else 0, "NUM_TIMERS": ev.timers if ev else 0,
        "NUM_DISCRETE": ev.discrete if ev else 0,
        "DISCRETE_OFFSET": unit.d_base if ev else 0, "NUM_INPUTS": len(program.inputs),
        "HAS_JACOBIAN": int(program.has_jacobian), "NUM_TABLES": len(program.tables),
        "NUM_JUMPS": ev.jumps if ev else 0,
        "PARAM_DOUBLES": emit.LINK_PARAMS}  # (the interpreter's parameters: a copy copies all)
    doubles = {"SCENE_T0": sc.t0, "SCENE_T_END": sc.t_end, "SCENE_DT": sc.dt,
               "SCENE_RTOL": sc.rtol, "SCENE_ATOL": sc.atol,
               "SCENE_STEP": 0.0 if sc.step is None else sc.step,
               "SCENE_HMAX": 0.0 if sc.max_step is None else sc.max_step}
    tables = {"jac_color_ptr": color_ptr, "jac_color_cols": color_cols, "jac_col_ptr": col_ptr,
              "jac_col_rows": col_rows, "position_rows": list(program.position_rows),
              "velocity_rows": list(program.velocity_rows),
              "velocity_movable": [int(v) for v in program.velocity_movable],
              "indicator_strict": [int(v) for v in ev.strict] if ev else [],
              "discrete_log": emit.discrete_log(ev) if ev else []}
    out = [MAGIC, struct.pack("<i", FORMAT)]
    out.append(struct.pack(f"<{len(emit.LINK_INTS)}i", *(ints[m] for m in emit.LINK_INTS)))
    out.append(struct.pack(f"<{len(emit.LINK_DOUBLES)}d",
                           *(float(doubles[m]) for m in emit.LINK_DOUBLES)))
    out.append(_strings([program.name, emit.identifier(program.name)]))
    for texts in (program.states, [p.name for p in program.params], program.outputs,
                  [c.junction for c in program.constraints],
                  [c.level for c in program.constraints], emit.block_names(program),
                  list(ev.names) if ev else [], [u.name for u in program.inputs]):
        out.append(_strings(list(texts)))
    for name in INT_TABLES:
        out.append(_ints(tables[name]))
    out.append(struct.pack("<i", len(program.blocks)))
    for bp, area in zip(program.blocks, ws.blocks):
        lu = bp.lu
        out.append(struct.pack("<4i", lu.m, int(lu.dense), int(lu.symmetric), lu.nnz))
        for key in emit.PLAN_ARRAYS:
            out.append(_ints(getattr(lu, key)))
        out.append(struct.pack("<11i", area.save, area.lu, area.dense, area.b, area.scale,
                               area.z, area.r, area.zt, area.rt, area.piv, area.how))
    out.append(struct.pack("<i", len(program.tables)))
    for tab in program.tables:  # (bgc.front.tables: rows, then each piece's origin and a, b, c, d)
        out.append(struct.pack("<2i", tab.rows, int(tab.extrapolate == "error")))
        for values in (tab.x, tab.origins, tab.coefficients):
            out.append(struct.pack(f"<{len(values)}d", *values))
    consts = list(unit.constants)
    out.append(struct.pack("<i", len(consts)) + b"".join(consts))
    out.append(struct.pack("<i", len(unit.segments)))
    for frame, words in unit.segments:
        out.append(struct.pack(f"<2i{len(words)}i", frame, len(words) // 4, *words))
    out.append(struct.pack(f"<{len(ENTRIES)}i", *(entries.get(n, -1) for n in ENTRIES)))
    out.append(_ints(defaults))
    return b"".join(out)


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# ---------------------------------------------------------------- the interpreter's source


def c_opcodes() -> str:
    """The opcodes as vm.c names them, before it (the numbers are OPS's order)."""
    lines = ["/* The interpreter's opcodes (bgc/vm.py, OPS). */", "enum {"]
    lines += [f"    BGC_VM_{name} = {k}," for k, (name, _) in enumerate(OPS)]
    lines += ["};", f"#define BGC_VM_NUM_OPS {len(OPS)}", f"#define BGC_VM_FORMAT {FORMAT}",
              f"#define BGC_VM_ENTRIES {len(ENTRIES)}",
              "enum { " + ", ".join(f"BGC_VM_ENTRY_{n.upper()} = {k}"
                                    for k, n in enumerate(ENTRIES)) + " };",
              "#define BGC_VM_LABELS " + ", ".join(f"&&bgc_vm_op_{n}" for n, _ in OPS),
              "static const char *const bgc_vm_kinds[BGC_VM_NUM_OPS] = { "
              + ", ".join(f'"{k}"' for _, k in OPS) + " };"]
    return "\n".join(lines) + "\n"


def c_link_definitions() -> str:
    """What the interpreter defines of a model part's bgc_link_ names (set when it reads a
    program), and the tables that say where each value of the file goes."""
    out = ["/* The model part's values, read from the program file (bgc/vm.py). */"]
    out += [f"int bgc_link_{m.lower()};" for m in emit.LINK_INTS]
    out += [f"double bgc_link_{m.lower()};" for m in emit.LINK_DOUBLES]
    out += ["const bgc_block *bgc_link_blocks;",
            "static const bgc_splu bgc_vm_no_lu; /* (the interpreter's Jacobians are dense: "
            "supports) */", "const bgc_splu *bgc_link_jac_lu = &bgc_vm_no_lu;"]
    out += [f"const int *bgc_link_{n};" for n in INT_TABLES]
    out += ["const char *const *bgc_link_discrete_names;", "const char *bgc_link_ident;",
            "const bgc_table_data *bgc_link_tables;"]
    out += ["static int *const bgc_vm_link_ints[] = { "
            + ", ".join(f"&bgc_link_{m.lower()}" for m in emit.LINK_INTS) + " };",
            "static double *const bgc_vm_link_doubles[] = { "
            + ", ".join(f"&bgc_link_{m.lower()}" for m in emit.LINK_DOUBLES) + " };",
            "static const int **const bgc_vm_link_tables[] = { "
            + ", ".join(f"&bgc_link_{n}" for n in INT_TABLES) + " };"]
    return "\n".join(out) + "\n"


_LINK_CONST = re.compile(r"extern const (int|double) bgc_link_")
_ARRAY = re.compile(r"^extern const char \*const (\w+)\[\];", re.MULTILINE)


def _mutable(text: str) -> str:
    """The runtime unit's declarations of a model part's values as the interpreter defines
    them: set when it reads a program, not at compile time."""
    text = _LINK_CONST.sub(r"extern \1 bgc_link_", text)
    return text.replace("*const bgc_link_", "*bgc_link_")


@functools.lru_cache(maxsize=None)
def c_unit() -> str:
    """The interpreter's source: the runtime unit (bgc.codegen.emit.c_runtime_unit: the same files,
    the same rewrites), its declarations of the model part's values made variables, its main
    renamed bgc_program_main, then vm.c (the model part, interpreted, and the main that reads
    the program first).  Built once per machine (bgc.base.cache.compile_vm)."""
    sizes, tables = emit.link_declarations()
    api = _ARRAY.sub(r"extern const char *const *\1;", emit.unit_text(emit.runtime_text("api.h")))
    api = api.replace("extern const char *const bgc_model_name;",
                      "extern const char *bgc_model_name;")
    files = []
    for name in emit.C_RUNTIME:
        text = emit.unit_text(emit.runtime_text(name))
        if name == "main.c":
            text = "#define main bgc_program_main\n" + text + "#undef main\n"
        files.append(text)
    return "".join([
        "/* bgc's interpreter: the runtime built once, with the model part read from a file "
        "(bgc/codegen/vm.py). */\n",
        emit.environment().get_template("c_prelude.c.j2").render(), _mutable(sizes),
        emit.solver_enum_c(), api, _mutable(tables), "\n", emit.solver_tables_c(), "\n",
        "\n".join(files), "\n", c_opcodes(), f"#define LINK_PARAMS_MAX {emit.LINK_PARAMS}\n",
        c_link_definitions(), emit.runtime_text("vm.c")])


def interpreter() -> Path:
    """The interpreter's executable: from the cache, else built into it (once per machine:
    bgc.base.cache.compile_vm)."""
    return cache.compile_vm(sources_digest(), c_unit)


@functools.lru_cache(maxsize=None)
def sources_digest() -> str:
    """The SHA-256 of what the interpreter's text is made of: the runtime's files, the C
    prelude, and the modules that write the rest (this one, bgc.codegen.emit, bgc.base.solvers)."""
    h = hashlib.sha256()
    runtime = resource_dir("runtime")
    files = [runtime / name for name in ("api.h", *emit.C_RUNTIME, "vm.c")]
    files += [resource_dir("templates") / "c_prelude.c.j2", Path(__file__),
              Path(emit.__file__), Path(emit.solvers.__file__)]
    for path in files:
        data = path.read_bytes()
        h.update(f"{path.name} {len(data)}\n".encode())
        h.update(data)
    return h.hexdigest()
