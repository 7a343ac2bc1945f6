"""Stage 1b, instantiate: an AST with components, constants, `for` and `if` -> a flat AST.

The model's instances form a tree; this stage builds it once and flattens it into the
declarations of one flat model, so that resolve and every later stage see what a modeller
could have written out by hand: every name a path (`p1.res`, `arm.link[2].rod`), every port
fused with the bonds on its two sides into one bond, every constant and `for` variable a
number, every `if` decided.

- Names.  A declaration inside an instance is named by the instance's path and its own name;
  an indexed name `link[i]` takes the value of i (`link[2]`).  A name in an expression is
  looked up in its own scope (the component's parameters, signals, elements and instances;
  then its file's constants); `p1.res.e` walks down the instances.
- Parameters.  A component's parameter becomes a parameter of the model under the instance's
  path (`p1.r`), its value the argument (an expression of the instantiating scope) or the
  default; an argument that reads a signal, an element variable, t or a time source makes it
  a signal instead (it then modulates what uses it).
- Ports.  Inside, one bond joins a port to an inner node; outside, one bond joins the
  instance's port to an outer node; the two make one bond (checked: both present, the same
  way, declared domains equal).
- Spans.  Every span inside an instance carries the chain of instances that led there
  (diagnostics.Span.chain), so that any later stage's error there gets a note per level.

Nothing here recurses with the model's size: instances and generated statements are handled
with explicit work lists, and their number and depth are bounded (bgc.base.resources) before the
work they would cause.  Expressions are walked recursively; their depth is the parser's bound.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path

from . import ast
from ..base.diagnostics import Collector, ModelError, Note, Origin, Span, did_you_mean, error, fail
from .graph import Instance, Port
from .kinds import KINDS, SWITCHED, TIME_SOURCES
from ..base.resources import (MAX_INDEX, MAX_INSTANCE_DEPTH, max_statements, read_bounded,
                              too_large)

LIBRARY = Path(__file__).resolve().parent.parent / "library"  # bgc's standard library

MAX_CONSTANT = 2 ** 53  # the magnitude of a compile-time integer
MAX_LIBRARIES = 100  # files one model imports, directly or not
STRUCTURE = (ast.ComponentDecl, ast.ConstantDecl, ast.ForBlock, ast.IfBlock, ast.ImportDecl,
             ast.PortDecl, ast.LibraryDecl)


class _TooLarge(ModelError):
    """The model makes more statements than a compile can take: the stage stops at once."""


# ---------------------------------------------------------------- files and components
@dataclass
class _File:
    """A model or library file: its components, constants and imports."""

    path: str
    origin: Origin | None  # None: the model file itself
    decls: tuple
    components: dict = field(default_factory=dict)  # name (or alias.name) -> ComponentDecl
    owner: dict = field(default_factory=dict)  # component name -> the _File declaring it
    constants: dict = field(default_factory=dict)  # name -> int (the file's top level)
    sha256: str = ""  # of a library's bytes, as read (bgc.execute.warm checks them again)


@dataclass
class _Scope:
    """The model or one instance: where its names live and how its text is reported."""

    prefix: str  # "" for the model, "p1." for instance p1
    file: _File
    comp: ast.ComponentDecl | None
    chain: tuple  # ((path, span of the instance's declaration), ...), innermost first
    effects: tuple  # the effects of the instances that enclose it (Idents)
    decl: ast.ElementDecl | None = None  # the instance's declaration (in the parent)
    parent: "_Scope | None" = None
    parent_env: dict | None = None
    items: list = field(default_factory=list)  # (statement, env) after generation
    table: dict = field(default_factory=dict)  # local name -> kind
    children: dict = field(default_factory=dict)  # local instance name -> _Scope
    signal_params: set = field(default_factory=set)  # parameters bound to signals
    first: dict = field(default_factory=dict)  # local name -> span of its first declaration

    @property
    def path(self) -> str:
        return self.prefix[:-1]

    def sp(self, span: Span | None) -> Span | None:
        if span is None or (not self.chain and self.file.origin is None):
            return span
        return Span(span.line, span.col, span.end_line, span.end_col, self.file.origin,
                    self.chain)


# ---------------------------------------------------------------- compile-time integers
_OPS = {"+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b}
_RELATIONS = {"<": lambda a, b: a < b, "<=": lambda a, b: a <= b, ">": lambda a, b: a > b,
              ">=": lambda a, b: a >= b, "==": lambda a, b: a == b, "!=": lambda a, b: a != b}


def _respan(node, sp):
    """A table's file or option with its spans in this scope, its names as written."""
    if isinstance(node, ast.KwArg):
        return ast.KwArg(node.name, _respan(node.value, sp), sp(node.span))
    if isinstance(node, (ast.Str, ast.Field, ast.Name)):
        return replace(node, span=sp(node.span))
    return node


def _const(node, env: dict, scope: _Scope, what: str) -> int:
    """The value of a compile-time integer expression: numbers, constants, `for` variables,
    + - * / ^, min, max, abs."""
    if isinstance(node, ast.Num):
        text = node.text
        if not text.isdigit():
            try:
                value = float(text)
            except ValueError:
                value = None
            if value is None or value != value or abs(value) == float("inf") \
                    or value != int(value):
                fail(scope.sp(node.span), f"{what} must be a whole number, not {text}")
            return _bounded(int(value), node, scope)
        if len(text.lstrip("0")) > 16:
            fail(scope.sp(node.span), f"{what} is too large")
        return _bounded(int(text), node, scope)
    if isinstance(node, ast.Name):
        if node.name in env:
            return env[node.name]
        fail(scope.sp(node.span), f"'{node.name}' is not a compile-time constant: {what} must be "
                                  "one (a number, a 'constant' or a 'for' variable)")
    if isinstance(node, ast.Neg):
        return -_const(node.operand, env, scope, what)
    if isinstance(node, ast.BinOp):
        # a chain of + and - (or * and /) as long as the text is, left to right without
        # recursing down it; other nesting is bounded by the parser (MAX_NESTING)
        group = "+-" if node.op in ("+", "-") else ("*/" if node.op in ("*", "/") else node.op)
        spine = []
        while isinstance(node, ast.BinOp) and node.op in group:
            spine.append(node)
            node = node.left
        a = _const(node, env, scope, what)
        for n in reversed(spine):
            a = _const_op(n, a, _const(n.right, env, scope, what), scope, what)
        return a
    if isinstance(node, ast.Call) and node.func in ("min", "max", "abs") and node.args:
        values = [_const(a, env, scope, what) for a in node.args]
        if node.func == "abs":
            if len(values) != 1:
                fail(scope.sp(node.span), "abs() takes 1 argument")
            return abs(values[0])
        return (min if node.func == "min" else max)(values)
    fail(scope.sp(node.span), f"{what} must be a compile-time constant (a number, a 'constant' "
                              "or a 'for' variable)")


def _const_op(node, a: int, b: int, scope: _Scope, what: str) -> int:
    """a OP b for _const, OP node's."""
    if node.op in _OPS:
        return _bounded(_OPS[node.op](a, b), node, scope)
    if node.op == "/":
        if b == 0 or a % b:
            fail(scope.sp(node.span), f"{what} must be a whole number: {a}/{b} is not")
        return a // b
    if b < 0 or b > 64:
        fail(scope.sp(node.span), f"{what}: the exponent must be a whole number from 0 to 64")
    return _bounded(a ** b, node, scope)


def _bounded(value: int, node, scope: _Scope) -> int:
    if abs(value) > MAX_CONSTANT:
        fail(scope.sp(node.span), f"a compile-time integer is at most 2^53 in magnitude; this "
                                  f"one is {value}")
    return value


def _condition(node, env: dict, scope: _Scope) -> bool:
    if isinstance(node, ast.Compare):
        return _RELATIONS[node.op](_const(node.left, env, scope, "a condition of 'if'"),
                                   _const(node.right, env, scope, "a condition of 'if'"))
    if isinstance(node, ast.BoolOp):
        if node.op == "not":
            return not _condition(node.items[0], env, scope)
        values = (_condition(n, env, scope) for n in node.items)
        return all(values) if node.op == "and" else any(values)
    fail(scope.sp(node.span), "'if' takes a relation of compile-time constants (i > 1)")


def _reads(body, var: str) -> bool:
    """Whether what a body makes can depend on `var`: the name occurs in a constant, a bound
    or a condition of the body (at any depth of its `for` and `if`)."""
    todo = list(body)
    while todo:
        stmt = todo.pop()
        if isinstance(stmt, ast.ConstantDecl):
            exprs = [stmt.expr]
        elif isinstance(stmt, ast.ForBlock):
            exprs = [stmt.start, stmt.stop]
            todo += stmt.body
        elif isinstance(stmt, ast.IfBlock):
            exprs = [cond for cond, _ in stmt.branches]
            for _, branch in stmt.branches:
                todo += branch
            todo += stmt.orelse or ()
        else:
            continue
        while exprs:
            node = exprs.pop()
            if isinstance(node, ast.Name):
                if node.name == var:
                    return True
            elif isinstance(node, tuple):
                exprs += node
            elif hasattr(node, "__dataclass_fields__") and not isinstance(node, Span):
                exprs += [getattr(node, f) for f in node.__dataclass_fields__]
    return False


# ---------------------------------------------------------------- the stage
class _Instantiate:
    def __init__(self, model: ast.Model, consts: dict, search: list):
        self.model = model
        self.consts = dict(consts)
        self.search = search
        self.diags = Collector()
        self.generated = 0
        self.most = max_statements()
        self.out: list = []  # the flat declarations
        self.edges: list = []  # (src end, dst end, src span, dst span, depth of its scope)
        self.ports: dict = {}  # flat port name -> graph.Port
        self.instances: list = []  # graph.Instance, in pre-order
        self.files: dict = {}  # resolved library path -> _File
        self.looked: dict = {}  # each path an import looked at -> its SHA-256, None: no file
        self.top = {id(d) for d in model.decls}  # the model file's top-level statements
        self.dims: dict = {}  # flat element name -> (dimension of its in side, of its out side)

    # ------------------------------------------------------------ counting
    def charge(self, n: int, span):
        """Count what the expansion makes, against what estimate() allowed (a backstop: the
        estimate counts the same before the work)."""
        self.generated += n
        if self.generated > self.most:
            self.refuse(span)

    def refuse(self, span):
        raise _TooLarge([error(span, too_large(
            f"the more than {self.most} declarations and bonds its components and 'for' "
            "loops make", self.most))])

    # ------------------------------------------------------------ the size, before the work
    def estimate(self, main: _File):
        """Refuse, before anything is expanded, a model whose components and `for` loops make
        more declarations and bonds than a compile can take (max_statements: the memory bgc
        may use): the same count as the expansion's (a `for` charges its passes over its
        body, each statement one, an instance its component's), made without making them.  A
        component's size does not depend on its instance (its body sees its file's constants
        only): each is counted once; a loop whose body's constants, bounds and conditions do
        not read its variable is counted once and multiplied.  Whatever the count cannot
        evaluate (a bound that is not a constant) counts nothing: the expansion reports it."""
        self.sizes: dict = {}
        self.estimated = self._count(main.decls, dict(main.constants), main,
                                     _Scope("", main, None, (), ()), True)

    def _count(self, body, env: dict, file: _File, scope: _Scope, top: bool) -> int:
        total = 0
        stack = [[iter(body), env, None]]
        while stack:
            frame = stack[-1]
            stmt = next(frame[0], None)
            if stmt is None:
                loop = frame[2]  # (a loop's passes are made one after another, not stacked)
                if loop is None or loop[1] > loop[2]:
                    stack.pop()
                else:
                    frame[0], frame[1] = iter(loop[4]), {**loop[3], loop[0]: loop[1]}
                    loop[1] += 1
                continue
            try:
                total += self._one(stmt, frame, stack, file, scope, top)
            except _TooLarge:
                raise
            except ModelError:
                continue
            if top and total > self.most:
                self.refuse(scope.sp(getattr(stmt, "span", None)))
        return total

    def _one(self, stmt, frame: list, stack: list, file: _File, scope: _Scope,
             top: bool) -> int:
        """What one statement of a body makes (its passes, its statements), pushing the bodies
        it repeats or chooses."""
        env = frame[1]
        if isinstance(stmt, ast.ConstantDecl):
            if not (scope.comp is None and top and id(stmt) in self.top):
                frame[1] = {**env, stmt.name.name: _const(stmt.expr, env, scope, "")}
            return 0
        if isinstance(stmt, ast.ForBlock):
            a = _const(stmt.start, env, scope, "")
            b = _const(stmt.stop, env, scope, "")
            count = max(0, b - a + 1)
            passes = count * max(1, len(stmt.body))
            if count == 0 or passes > self.most:
                return passes
            if _reads(stmt.body, stmt.var.name):
                stack.append([iter(()), env, [stmt.var.name, a, b, env, stmt.body]])
                return passes
            once = self._count(stmt.body, {**env, stmt.var.name: a}, file, scope, False)
            return passes + count * once
        if isinstance(stmt, ast.IfBlock):
            chosen = next((body for cond, body in stmt.branches
                           if _condition(cond, env, scope)), stmt.orelse)
            if chosen:
                stack.append([iter(chosen), env, None])
            return 0
        if isinstance(stmt, (ast.ImportDecl, ast.ComponentDecl, ast.LibraryDecl)):
            return 0
        if isinstance(stmt, ast.ElementDecl) and not stmt.is_junction \
                and stmt.kind.name in file.components:
            return 1 + self._component(file, stmt.kind.name)
        return 1

    def _component(self, file: _File, name: str) -> int:
        """The declarations and bonds one instance of component `name` makes (its nested
        instances' included); a component reached again while it is counted (it instantiates
        itself: the expansion says so) counts nothing."""
        comp = file.components[name]
        key = id(comp)
        if key not in self.sizes:
            self.sizes[key] = 0
            cfile = file.owner[name]
            size = self._count(comp.body, dict(cfile.constants), cfile,
                               _Scope("", cfile, comp, (), ()), False)
            self.sizes[key] = min(size, self.most + 1)
        return self.sizes[key]

    # ------------------------------------------------------------ files
    def main_file(self) -> _File:
        f = _File(self.model.path, None, self.model.decls)
        self.load_file(f, library=False)
        return f

    def load_file(self, f: _File, library: bool):
        top = _Scope("", f, None, (), ())
        for d in f.decls:
            if isinstance(d, ast.ImportDecl):
                self.guard(self.do_import, f, d, top)
        for d in f.decls:
            if isinstance(d, ast.ComponentDecl):
                name = d.name.name
                if name in KINDS:
                    self.diags.error(top.sp(d.name.span), f"'{name}' is an element kind: a "
                                                          "component needs another name")
                    continue
                if name in f.components:
                    self.diags.error(top.sp(d.name.span), f"component '{name}' is declared twice")
                    continue
                f.components[name] = d
                f.owner[name] = f
                for p in d.params:
                    if p.name.name == "t":
                        self.diags.error(top.sp(p.name.span), "'t' is time and cannot be "
                                                              "declared")
            elif library and not isinstance(d, (ast.ConstantDecl, ast.ImportDecl,
                                                ast.LibraryDecl)):
                self.diags.error(top.sp(d.span), "a library holds only components, constants "
                                                 "and imports")
        env = {}
        for d in f.decls:
            if isinstance(d, ast.ConstantDecl):
                self.guard(self.constant, d, env, top, not library)
        f.constants = env

    def constant(self, d: ast.ConstantDecl, env: dict, scope: _Scope, overridable: bool):
        name = d.name.name
        if name in env:
            fail(scope.sp(d.name.span), f"constant '{name}' is declared twice")
        if overridable and scope.comp is None and name in self.consts:
            env[name] = self.consts.pop(name)
        else:
            env[name] = _const(d.expr, env, scope, f"constant '{name}'")

    def do_import(self, f: _File, d: ast.ImportDecl, top: _Scope):
        alias = (d.alias or d.name).name
        if d.file is not None:
            base = Path(f.path).parent
            candidates = [base / d.file]
            shown = d.file
        else:
            name = d.name.name + ".bg"
            dirs = [Path(f.path).parent] + self.search + [LIBRARY]
            candidates = [Path(p) / name for p in dirs]
            shown = name
        path = next((c for c in candidates if c.is_file()), None)
        for c in candidates[:candidates.index(path) if path is not None else len(candidates)]:
            self.looked.setdefault(str(c), None)  # (a file made there later would be found)
        if path is None and d.file is not None:
            fail(top.sp(d.span), f"cannot find the library file '{d.file}' (a path relative to "
                                 "the file that imports it)")
        if path is None:
            beside = "the model" if f.origin is None else "the library"
            fail(top.sp(d.span), f"cannot find the library '{d.name.name}': there is no {shown} "
                                 f"beside {beside}, in the directories of $BGC_PATH, or in bgc's "
                                 "standard library")
        key = str(path.resolve())
        if key not in self.files:
            if len(self.files) >= MAX_LIBRARIES:
                fail(top.sp(d.span), f"too many libraries imported (at most {MAX_LIBRARIES})")
            self.files[key] = None  # being read: an import cycle ends here
            self.files[key] = self.parse_library(path, d, top)
        lib = self.files[key]
        if lib is not None:
            self.looked.setdefault(str(path), lib.sha256)
        if lib is None:
            fail(top.sp(d.span), f"library {shown} imports itself (through its imports)")
        if any(k.startswith(alias + ".") for k in f.components):
            fail(top.sp(d.span), f"'{alias}' names two imports")
        for name, comp in lib.components.items():
            if "." not in name:
                f.components[f"{alias}.{name}"] = comp
                f.owner[f"{alias}.{name}"] = lib.owner[name]

    def parse_library(self, path: Path, d: ast.ImportDecl, top: _Scope) -> _File:
        from .parser import decode, parse_library
        text = None
        try:
            data = read_bounded(str(path))
            text = decode(data)
            model = parse_library(text, str(path))
        except OSError as exc:
            fail(top.sp(d.span), f"cannot read {path}: {exc.strerror}")
        except ModelError as exc:
            origin = Origin(str(path), text if text is not None else "", file=True)
            raise ModelError([replace(e, span=e.span and replace(e.span, origin=origin),
                                      notes=tuple(replace(n, span=n.span and replace(
                                          n.span, origin=origin)) for n in e.notes)
                                      + (Note(top.sp(d.span), "imported here"),))
                              for e in exc.diagnostics]) from None
        lib = _File(str(path), Origin(str(path), text, file=True), model.decls,
                    sha256=hashlib.sha256(data).hexdigest())
        first = model.decls[0] if model.decls else None
        if not isinstance(first, ast.LibraryDecl):
            fail(top.sp(d.span), f"{path} is not a library: a library file starts with "
                                 "'library NAME'")
        self.load_file(lib, library=True)
        return lib

    def guard(self, fn, *args):
        try:
            return fn(*args)
        except _TooLarge:
            raise  # (the one error: nothing more is looked at)
        except ModelError as exc:
            self.diags.items.extend(exc.diagnostics)
            return None

    # ------------------------------------------------------------ generation
    def expand(self, scope: _Scope, body, env: dict):
        """The statements of a body after `constant`, `for` and `if`, each with its
        constants: scope.items; scope.table from them."""
        stack = [[iter(body), env]]
        while stack:
            top = stack[-1]
            stmt = next(top[0], None)
            if stmt is None:
                stack.pop()
                continue
            self.guard(self.generate, scope, stmt, top, stack)
        for stmt, env in scope.items:
            self.guard(self.declare, scope, stmt, env)

    def generate(self, scope: _Scope, stmt, top: list, stack: list):
        """One statement of a body: kept (with its constants), or what it generates pushed
        on the stack of bodies to read."""
        env = top[1]
        if isinstance(stmt, ast.ConstantDecl):
            if scope.comp is None and id(stmt) in self.top:
                return  # the file's constants: already in env
            env = dict(env)
            self.guard(self.constant, stmt, env, scope, False)
            top[1] = env
        elif isinstance(stmt, ast.ForBlock):
            what = f"a bound of 'for {stmt.var.name}'"
            a = _const(stmt.start, env, scope, what)
            b = _const(stmt.stop, env, scope, what)
            count = max(0, b - a + 1)
            self.charge(count * max(1, len(stmt.body)), scope.sp(stmt.span))
            for i in range(b, a - 1, -1):
                stack.append([iter(stmt.body), {**env, stmt.var.name: i}])
        elif isinstance(stmt, ast.IfBlock):
            chosen = next((body for cond, body in stmt.branches
                           if _condition(cond, env, scope)), stmt.orelse)
            if chosen:
                stack.append([iter(chosen), env])
        elif isinstance(stmt, ast.ImportDecl):
            if scope.comp is not None or id(stmt) not in self.top:
                fail(scope.sp(stmt.span), "'import' belongs at the top of a file")
        elif isinstance(stmt, ast.ComponentDecl):
            return
        elif isinstance(stmt, ast.LibraryDecl):
            fail(scope.sp(stmt.span), f"'{stmt.name.name}' is a library: it holds "
                                      "components for models to import, and cannot be "
                                      "built itself")
        elif isinstance(stmt, ast.PortDecl) and scope.comp is None:
            fail(scope.sp(stmt.span), "'port' declares where bonds cross a component's "
                                      "boundary; a model has no ports")
        else:
            self.charge(1, scope.sp(getattr(stmt, "span", None)))
            scope.items.append((stmt, env))

    def declare(self, scope: _Scope, stmt, env):
        if isinstance(stmt, (ast.ParamDecl, ast.SignalDecl, ast.IntegralDecl, ast.ElementDecl,
                             ast.PortDecl, ast.DiscreteDecl, ast.InputDecl)):
            name = self.local_name(scope, stmt, env)
            if isinstance(stmt, ast.ElementDecl) and self.is_instance(scope, stmt):
                kind = "instance"
            else:
                kind = {ast.ParamDecl: "parameter", ast.SignalDecl: "signal",
                        ast.IntegralDecl: "signal", ast.ElementDecl: "element",
                        ast.PortDecl: "port", ast.DiscreteDecl: "signal",
                        ast.InputDecl: "signal"}[type(stmt)]
            old = scope.table.get(name)
            if old is not None and ("instance" in (old, kind) or "port" in (old, kind)):
                first = scope.first.get(name)
                fail(scope.sp(stmt.name.span), f"'{scope.prefix + name}' is declared twice",
                     *([Note(first, f"first declaration of '{scope.prefix + name}'")]
                       if first else []))
            scope.table.setdefault(name, kind)
            scope.first.setdefault(name, scope.sp(stmt.name.span))

    def local_name(self, scope: _Scope, stmt, env) -> str:
        index = getattr(stmt, "index", None)
        if index is None:
            return stmt.name.name
        k = _const(index, env, scope, f"the index of '{stmt.name.name}'")
        if not 0 <= k <= MAX_INDEX:
            fail(scope.sp(index.span), f"an index of a name is from 0 to {MAX_INDEX}; this "
                                       f"one is {k}")
        return f"{stmt.name.name}[{k}]"

    def is_instance(self, scope: _Scope, stmt: ast.ElementDecl) -> bool:
        return not stmt.is_junction and stmt.kind.name in scope.file.components

    # ------------------------------------------------------------ the instance tree
    def build(self):
        main = self.main_file()
        unknown = sorted(set(self.consts) - set(main.constants))
        root = _Scope("", main, None, (), ())
        if unknown:
            self.diags.raise_if_errors()
            names = ", ".join(main.constants) or "none"
            text = f"{unknown[0]}={self.consts[unknown[0]]}"
            fail(Span(1, 1, 1, len(unknown[0]) + 1, Origin("--const", text)),
                 f"the model has no constant '{unknown[0]}'"
                 f"{did_you_mean(unknown[0], main.constants)} (its constants: {names})")
        self.diags.raise_if_errors()
        self.estimate(main)
        self.guard(self.expand, root, main.decls, dict(main.constants))
        self.diags.raise_if_errors()
        # the instances, depth first: each one's body expanded once
        todo = [root]
        while todo:
            scope = todo.pop()
            for stmt, env in scope.items:
                if isinstance(stmt, ast.ElementDecl) and self.is_instance(scope, stmt):
                    child = self.guard(self.child, scope, stmt, env)
                    if child is not None:
                        todo.append(child)
        self.diags.raise_if_errors()
        self.emit(root)
        self.fuse()
        self.diags.raise_if_errors()
        return ast.Model(tuple(self.out), self.model.path, tuple(self.ports.values()),
                         tuple(self.instances), tuple(main.constants.items()),
                         self.model.text, tuple(self.looked.items()))

    def child(self, parent: _Scope, stmt: ast.ElementDecl, env) -> _Scope:
        name = self.local_name(parent, stmt, env)
        comp = parent.file.components[stmt.kind.name]
        cfile = parent.file.owner[stmt.kind.name]
        path = parent.prefix + name
        span = parent.sp(stmt.span)
        chain = ((path, span),) + parent.chain
        if len(chain) > MAX_INSTANCE_DEPTH:
            fail(span, f"instances nested more than {MAX_INSTANCE_DEPTH} levels deep")
        s = parent
        while s is not None:
            if s.comp is comp:
                fail(span, f"component '{comp.name.name}' instantiates itself (through "
                           f"instance '{s.path}')" if s.path != parent.path else
                           f"component '{comp.name.name}' instantiates itself")
            s = s.parent
        if stmt.dim is not None:
            fail(parent.sp(stmt.dim.span), f"'{name}' is an instance of component "
                                           f"'{stmt.kind.name}': it takes no dimension")
        if stmt.inits:
            fail(parent.sp(stmt.inits[0].span), f"'{name}' is an instance of component "
                                                f"'{stmt.kind.name}': give initial values "
                                                "as its parameters")
        effects = parent.effects + tuple(replace(e, span=parent.sp(e.span))
                                         for e in stmt.effects)
        child = _Scope(path + ".", cfile, comp, chain, effects, stmt, parent, env)
        parent.children[name] = child
        for p in comp.params:
            child.table[p.name.name] = "parameter"
        self.expand(child, comp.body, dict(cfile.constants))
        return child

    # ------------------------------------------------------------ emitting
    def emit(self, root: _Scope):
        """The flat declarations, in pre-order: an instance's where it is declared."""
        stack = [(root, iter(root.items))]
        while stack:
            scope, it = stack[-1]
            item = next(it, None)
            if item is None:
                stack.pop()
                continue
            stmt, env = item
            if isinstance(stmt, ast.ElementDecl) and self.is_instance(scope, stmt):
                child = scope.children.get(self.guard(self.local_name, scope, stmt, env))
                if child is not None and self.guard(self.arguments, child) is not None:
                    self.instances.append(Instance(child.path, stmt.kind.name,
                                                   child.comp.doc, child.chain[0][1]))
                    stack.append((child, iter(child.items)))
                continue
            self.guard(self.statement, scope, stmt, env)

    def arguments(self, child: _Scope) -> bool:
        """The component's parameters of one instance: parameters (or signals, when the
        argument reads one) named by the instance's path."""
        decl, parent, comp = child.decl, child.parent, child.comp
        given, positional, named = {}, 0, False
        names = [p.name.name for p in comp.params]
        for arg in decl.args:
            if arg.law is None:
                if named:
                    fail(parent.sp(arg.span), "positional arguments come before named ones")
                if positional >= len(names):
                    fail(parent.sp(arg.span), f"component '{comp.name.name}' takes "
                                              f"{len(names)} parameters; this is one more")
                key = names[positional]
                positional += 1
            else:
                named = True
                key = arg.law.name
                if key not in names:
                    listed = ", ".join(names) or "none"
                    fail(parent.sp(arg.law.span), f"component '{comp.name.name}' has no parameter "
                                                  f"'{key}'{did_you_mean(key, names)} (its "
                                                  f"parameters: {listed})")
            if key in given:
                fail(parent.sp(arg.span), f"parameter '{key}' is given twice")
            given[key] = arg
        env = child.file.constants
        for p in comp.params:
            name = p.name.name
            if name in given:
                rw = _Rewriter(self, parent, child.parent_env)
                expr = rw.expr(given[name].expr)
            elif p.default is not None:
                rw = _Rewriter(self, child, env)
                expr = rw.expr(p.default)
            else:
                fail(parent.sp(decl.span), f"instance '{child.path}' of '{comp.name.name}' "
                                           f"needs a value for its parameter '{name}' (it has "
                                           "no default)")
            ident = ast.Ident(child.prefix + name, child.sp(p.name.span))
            if rw.dynamic:
                child.signal_params.add(name)
                self.out.append(ast.SignalDecl(ident, None, expr, child.sp(p.span), p.unit))
            else:
                self.out.append(ast.ParamDecl(ident, expr, p.doc, child.sp(p.span), p.unit))
        return True

    def statement(self, scope: _Scope, stmt, env):
        rw = _Rewriter(self, scope, env)
        if isinstance(stmt, ast.BondChain):
            ends = [self.end(scope, n, env) for n in stmt.nodes]
            depth = len(scope.chain)
            for (a, sa), (b, sb) in zip(ends, ends[1:]):
                self.edges.append((a, b, sa, sb, depth))
            return
        if isinstance(stmt, ast.PortDecl):
            name = scope.prefix + stmt.name.name
            self.ports[name] = Port(name, stmt.dim.n if stmt.dim else 1,
                                    stmt.domain.name if stmt.domain else None, stmt.unit,
                                    scope.sp(stmt.span))
            return
        name = None
        if isinstance(stmt, (ast.ParamDecl, ast.SignalDecl, ast.IntegralDecl, ast.ElementDecl,
                             ast.DiscreteDecl, ast.InputDecl)):
            name = ast.Ident(scope.prefix + self.local_name(scope, stmt, env),
                             scope.sp(stmt.name.span))
        if isinstance(stmt, ast.ElementDecl):
            if not stmt.is_junction and stmt.kind.name not in KINDS and "." in stmt.kind.name:
                fail(scope.sp(stmt.kind.span), f"unknown component '{stmt.kind.name}'")
            self.check_unqualified(scope, stmt)
            own = {"e", "f"}
            spec = KINDS.get(stmt.kind.name)
            if spec is not None and spec.state:
                own.add(spec.state)
            args = tuple(ast.Arg(rw.map(a.law), rw.expr(a.expr, own if a.law else ()),
                                 scope.sp(a.span)) for a in stmt.args)
            effects = rw.map(stmt.effects) + scope.effects
            n = stmt.dim.n if stmt.dim else 1
            m = stmt.dim.m if stmt.dim and stmt.dim.m is not None else n
            self.dims[name.name] = (n, m)
            out = replace(rw.map(replace(stmt, args=())), name=name, args=args,
                          effects=effects, index=None)
        elif isinstance(stmt, ast.SceneDecl):
            out = rw.map(stmt)
        elif isinstance(stmt, (ast.ParamDecl, ast.SignalDecl, ast.IntegralDecl,
                               ast.DiscreteDecl, ast.InputDecl)):
            out = replace(rw.map(stmt), name=name)
            if hasattr(out, "index"):
                out = replace(out, index=None)
        elif isinstance(stmt, ast.WhenBlock):  # its targets are names of this scope
            out = replace(rw.map(stmt), stmts=tuple(
                rw.map(st) if isinstance(st, ast.Reinit)  # (its target an expression)
                else replace(rw.map(st), name=rw.target(st.name)) for st in stmt.stmts))
        else:
            out = rw.map(stmt)
        self.out.append(out)

    def check_unqualified(self, scope: _Scope, stmt: ast.ElementDecl):
        """A kind that is a component of an imported library named without the library's
        alias (`cap2` for `F.cap2`): an error saying how to write it, with a note at each
        import that has it."""
        kind = stmt.kind.name
        if stmt.is_junction or kind in KINDS or kind in SWITCHED or "." in kind:
            return
        qualified = [k for k in scope.file.components if k.partition(".")[2] == kind]
        if not qualified:
            return
        imports = {(d.alias or d.name).name: d.span for d in scope.file.decls
                   if isinstance(d, ast.ImportDecl)}
        notes = [Note(replace(imports[q.partition(".")[0]], origin=scope.file.origin),
                      f"imported here as '{q.partition('.')[0]}'") for q in qualified]
        fail(scope.sp(stmt.kind.span), f"unknown kind '{kind}': a component of an imported "
                                       "library is used qualified: write "
                                       + " or ".join(f"'{q}'" for q in qualified), *notes)

    def end(self, scope: _Scope, node, env):
        """A bond's end: ("node", flat name) or ("port", flat port name, inner?)."""
        if isinstance(node, ast.PathRef):
            segs = [n.name if i is None else
                    f"{n.name}[{_const(i, env, scope, 'an index in a bond')}]"
                    for n, i in node.parts]
        else:
            segs = node.name.split(".")
        span = scope.sp(node.span)
        first = scope.table.get(segs[0])
        if len(segs) == 1:
            if first == "port":
                return ("port", scope.prefix + segs[0], True), span
            if first == "instance":
                child = scope.children.get(segs[0])
                ports = [n for n, k in child.table.items() if k == "port"] if child else []
                fail(span, f"bond to instance '{scope.prefix + segs[0]}': bond to one of its "
                           f"ports ({', '.join(f'{segs[0]}.{p}' for p in ports) or 'it has none'})")
            return ("node", scope.prefix + segs[0]), span
        if first == "instance":
            child = scope.children.get(segs[0])
            if child is None:  # (its instantiation failed, reported)
                raise ModelError([])
            if len(segs) == 2 and child.table.get(segs[1]) == "port":
                return ("port", child.prefix + segs[1], False), span
            ports = [f"{segs[0]}.{n}" for n, k in child.table.items() if k == "port"]
            fail(span, f"bond to '{scope.prefix + '.'.join(segs)}': a bond reaches into an "
                       f"instance through its ports only ({', '.join(ports) or 'it has none'})")
        return ("node", scope.prefix + ".".join(segs)), span

    # ------------------------------------------------------------ ports
    def check_dimensions(self, src: str, dst: str, ports, span: Span):
        """A vector port `a[n]` carries a bond of n; a scalar port a scalar bond."""
        if not ports:
            return
        n = self.dims.get(src, (None, None))[1]
        m = self.dims.get(dst, (None, None))[0]
        if n is None or n != m:
            return  # (unknown ends are reported by resolve, unequal ones by flatten)
        for port in ports:
            if port.dim != n:
                self.diags.error(span, f"port '{port.name}' has dimension {port.dim}, but the "
                                       f"bond through it joins '{src}' and '{dst}', of "
                                       f"dimension {n}",
                                 Note(port.span, f"'{port.name}' is declared here"))
                return

    def _span(self, k: int) -> Span:
        _, _, sa, sb, _ = self.edges[k]
        return sa.join(sb)

    def check_port(self, name: str, port: Port, sides: dict) -> bool:
        """Whether a port has one bond inside and one outside, pointing the same way (each
        error reported)."""
        ok = True
        for inner in (True, False):
            ks = sides[inner]
            where = "inside its component" if inner else "outside, where it is used"
            if not ks:
                self.diags.error(port.span, f"port '{name}' is not bonded {where} (bond a "
                                            "free end to a zero source)")
                ok = False
            elif len(ks) > 1:
                self.diags.error(self._span(ks[1]), f"port '{name}' is bonded more than "
                                                    f"once {where}",
                                 Note(self._span(ks[0]), "the first bond"))
                ok = False
        if not ok:
            return False
        (ki,), (ko,) = sides[True], sides[False]
        into_inner = self.edges[ki][1] == ("port", name, True)
        into_outer = self.edges[ko][1] == ("port", name, False)
        if into_inner != into_outer:
            return True
        self.diags.error(self._span(ko), f"the bonds of port '{name}' point opposite ways: the "
                                         "bond outside and the bond inside are one bond, and "
                                         "point the same way", Note(self._span(ki),
                                                                    "the bond inside"))
        return False

    def fuse(self):
        """Each port joins its inner and outer bond into one; the bonds that result, in the
        order of their first part."""
        if self.diags.errors:  # (an instance left out: its ports would be reported unbonded)
            return
        at: dict = {}
        for k, (a, b, _, _, _) in enumerate(self.edges):
            for end in (a, b):
                if end[0] == "port":
                    at.setdefault(end[1], {True: [], False: []})[end[2]].append(k)
        ok = True
        for name, port in self.ports.items():
            ok = self.check_port(name, port, at.get(name, {True: [], False: []})) and ok
        if not ok:
            return
        other = {}
        for name, sides in at.items():
            (ki,), (ko,) = sides[True], sides[False]
            other[(name, ki)], other[(name, ko)] = ko, ki
        seen = set()
        for k, (a, b, sa, sb, depth) in enumerate(self.edges):
            if a[0] == "port":
                continue
            seen.add(k)
            best, cur, domain, through = (depth, sa, sb), k, None, []
            while True:
                _, b, sb_k, _, _ = self.edges[cur]
                if b[0] != "port":
                    break
                port = self.ports.get(b[1])
                if port is None:
                    break
                if port.domain is not None:
                    if domain is not None and domain.domain != port.domain:
                        self.diags.error(self.edges[cur][2].join(self.edges[cur][3]),
                                         f"this bond joins ports of different domains: "
                                         f"'{domain.name}' ({domain.domain}) and '{port.name}' "
                                         f"({port.domain})",
                                         Note(domain.span, f"'{domain.name}' is declared here"),
                                         Note(port.span, f"'{port.name}' is declared here"))
                    domain = port
                through.append(port)
                cur = other[(b[1], cur)]
                seen.add(cur)
                d = self.edges[cur][4]
                if d < best[0]:
                    best = (d, self.edges[cur][2], self.edges[cur][3])
            end = self.edges[cur][1]
            self.check_dimensions(a[1], end[1], through, best[1].join(best[2]))
            if cur == k:
                self.out.append(ast.BondChain((ast.Ident(a[1], sa), ast.Ident(b[1], sb)),
                                              sa.join(sb)))
            else:
                span = best[1].join(best[2])
                self.out.append(ast.BondChain((ast.Ident(a[1], span), ast.Ident(end[1], span)),
                                              span, tuple((p.domain, p.unit, p.span, p.name)
                                                          for p in through)))
        for k, (a, b, sa, sb, _) in enumerate(self.edges):
            if k not in seen:
                self.diags.error(sa.join(sb), "this bond joins ports only: no element at either "
                                              "end of the bonds it is part of")
                break


_FIELDS: dict = {}  # a node type -> its fields' names, in order


class _Rewriter:
    """One scope's expressions made flat: names to paths, constants to numbers."""

    def __init__(self, stage: _Instantiate, scope: _Scope, env: dict):
        self.stage, self.scope, self.env = stage, scope, env
        self.dynamic = False  # reads a signal, an element variable or t

    def map(self, node, own=()):
        """Any node with its spans in this scope, its expressions rewritten (own: the names an
        element's law reads as its own variables, e and f, inside conditionals too)."""
        if isinstance(node, Span):
            return self.scope.sp(node)
        if isinstance(node, tuple):
            return tuple(self.map(x, own) for x in node)
        if isinstance(node, (ast.Num, ast.Name, ast.Field, ast.Member, ast.Index, ast.Call,
                             ast.BinOp, ast.Neg, ast.Vector)):
            return self.expr(node, own)
        if is_dataclass(node) and not isinstance(node, type):
            names = _FIELDS.get(type(node))
            if names is None:
                names = _FIELDS[type(node)] = tuple(f.name for f in fields(node))
            return type(node)(*[self.map(getattr(node, n), own) for n in names])
        return node

    def expr(self, node, own=()):
        sp = self.scope.sp
        if isinstance(node, ast.Num):
            return replace(node, span=sp(node.span))
        if isinstance(node, ast.Name):
            n = node.name
            if n in own:
                return replace(node, span=sp(node.span))
            if n in self.env and n not in self.scope.table:
                return ast.Num(str(self.env[n]), sp(node.span))
            if n == "t":
                self.dynamic = True
                return replace(node, span=sp(node.span))
            return self.path([n], node)
        if isinstance(node, ast.Field):
            return self.path(node.owner.split(".") + [node.field], node)
        if isinstance(node, ast.Member):
            return self.path(self.try_segments(node, strict=True), node)
        if isinstance(node, ast.Index):
            if self.names_indexed(node):
                return self.path(self.try_segments(node), node)
            return ast.Index(self.expr(node.base, own), self.expr(node.index, own), sp(node.span))
        if isinstance(node, ast.Call) and node.func == "table":  # a file and named options
            keep = (ast.Str, ast.Field, ast.KwArg)  # are not names in this scope
            args = tuple(_respan(a, sp) if isinstance(a, keep) else self.expr(a, own)
                         for a in node.args)
            return ast.Call(node.func, args, sp(node.span))
        if isinstance(node, ast.Call):
            if node.func in TIME_SOURCES:  # (square(1/f, d): it varies in time, as t does)
                self.dynamic = True
            return ast.Call(node.func, tuple(self.expr(a, own) for a in node.args), sp(node.span))
        if isinstance(node, ast.BinOp):  # (a chain `a + b + c ...` by a loop, not as deep)
            spine = []
            while isinstance(node, ast.BinOp):
                spine.append(node)
                node = node.left
            acc = self.expr(node, own)
            for b in reversed(spine):
                acc = ast.BinOp(b.op, acc, self.expr(b.right, own), sp(b.span))
            return acc
        if isinstance(node, ast.Neg):
            negs = []
            while isinstance(node, ast.Neg):
                negs.append(node)
                node = node.operand
            acc = self.expr(node, own)
            for n in reversed(negs):
                acc = ast.Neg(acc, sp(n.span))
            return acc
        if isinstance(node, ast.Vector):
            return ast.Vector(tuple(self.expr(a, own) for a in node.items), sp(node.span))
        return self.map(node, own)

    def target(self, ident: ast.Ident) -> ast.Ident:
        """A when-block's assigned discrete variable by its path."""
        node = self.path(ident.name.split("."), ident)
        text = node.name if isinstance(node, ast.Name) else f"{node.owner}.{node.field}"
        return ast.Ident(text, node.span)

    def names_indexed(self, node: ast.Index) -> bool:
        """Whether `node` is a name declared with an index (`r[2]`, a `for`'s `x[i]`), not a
        component of a vector: `k.mass.p[0]` indexes the variable p of element k.mass, so
        its path is k.mass.p and the index stays an index."""
        segs = self.try_segments(node)
        if segs is None:
            return False
        found = self.lookup(segs)
        return (found is not None and found[1] in ("signal", "parameter", "element")
                and len(found[2]) == 1)

    def try_segments(self, node, strict=False):
        """The path a node names (`link[2].rod` -> ["link[2]", "rod"]), or None."""
        if isinstance(node, ast.Name):
            return [node.name]
        if isinstance(node, ast.Field):
            return node.owner.split(".") + [node.field]
        if isinstance(node, ast.Member):
            base = self.try_segments(node.base, strict)
            return None if base is None else base + [node.name]
        if isinstance(node, ast.Index):
            base = self.try_segments(node.base, strict)
            if base is None:
                return None
            if not strict:
                try:
                    k = _const(node.index, self.env, self.scope, "an index")
                except ModelError:
                    return None
            else:
                k = _const(node.index, self.env, self.scope, "the index of a name")
            return base[:-1] + [f"{base[-1]}[{k}]"]
        if strict:
            fail(self.scope.sp(node.span), "only a name, or an indexed name, is followed by "
                                           "'.NAME'")
        return None

    def lookup(self, segs):
        """(scope, kind, rest) where segs lead: down the instances, then a local name."""
        s, i = self.scope, 0
        while i < len(segs) - 1 and s.table.get(segs[i]) == "instance" and segs[i] in s.children:
            s = s.children[segs[i]]
            i += 1
        kind = s.table.get(segs[i])
        return (s, kind, segs[i:]) if kind is not None else None

    def path(self, segs, node):
        sp = self.scope.sp(node.span)
        found = self.lookup(segs)
        if found is None:
            s, rest = self.scope, segs
            kind = None
        else:
            s, kind, rest = found
        if len(rest) == 1:
            if kind == "signal" or (kind == "parameter" and rest[0] in s.signal_params):
                self.dynamic = True
            if kind == "instance":
                fail(sp, f"'{s.prefix + rest[0]}' is an instance of component "
                         f"'{s.children[rest[0]].comp.name.name}': name one of its variables")
            return ast.Name(s.prefix + rest[0], sp)
        self.dynamic = True
        owner = ".".join(rest[:-1])
        if kind in ("signal", "parameter") and len(rest) == 2:
            what = "a signal" if kind == "signal" else "a parameter"
            fail(sp, f"'{s.prefix + rest[0]}' is {what} and has no field '{rest[1]}'")
        return ast.Field(s.prefix + owner, rest[-1], sp)


def output_refs(refs, constants: dict) -> tuple:
    """Outputs (OutRefs, OutPaths) as OutRefs, each index an expression of `constants` made a
    number (`s[N].cap.q` -> `s[8].cap.q`); ModelError with an error for each output that
    cannot be, located where it is written."""
    out, diags = [], Collector()
    for r in refs:
        try:
            out.append(_output_ref(r, constants) if isinstance(r, ast.OutPath) else r)
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    diags.raise_if_errors()
    return tuple(out)


def _output_ref(path: ast.OutPath, constants: dict) -> ast.OutRef:
    scope = _text_scope(path.span)
    segments = [(name, index if index is None or type(index) is int else
                 _index_value(index, constants, scope, "an index in outputs"))
                for name, index in path.parts]
    return ast.out_ref(segments, path.span)


def path_name(node, constants: dict) -> ast.Ident:
    """A scene's `set` target as an Ident: a PathRef's indices (`s[N].r`) made numbers."""
    if not isinstance(node, ast.PathRef):
        return node
    scope = _text_scope(node.span)
    segs = [n.name if i is None else
            f"{n.name}[{_index_value(i, constants, scope, 'an index in a scene')}]"
            for n, i in node.parts]
    return ast.Ident(".".join(segs), node.span)


def _text_scope(span: Span) -> _Scope:
    """The scope of a scene's or an option's text (`--outputs`): where its spans point."""
    origin = span.origin
    return _Scope("", _File(origin.name if origin else "", origin, ()), None, (), ())


def _index_value(node, constants: dict, scope: _Scope, what: str) -> int:
    k = _const(node, constants, scope, what)
    if not 0 <= k <= MAX_INDEX:
        fail(scope.sp(node.span), f"an index is from 0 to {MAX_INDEX}; this one is {k}")
    return k


def needs_instantiation(model: ast.Model) -> bool:
    """Whether the model uses components, constants, generation or indexed names."""
    for d in model.decls:
        if isinstance(d, STRUCTURE):
            return True
        if getattr(d, "index", None) is not None:
            return True
        if isinstance(d, ast.BondChain) and any(isinstance(n, ast.PathRef) for n in d.nodes):
            return True
    return False


def search_path() -> list:
    """The directories of $BGC_PATH, in order."""
    return [p for p in os.environ.get("BGC_PATH", "").split(os.pathsep) if p]


def instantiate(model: ast.Model, consts: dict | None = None) -> ast.Model:
    """The flat model of `model` (itself when it has nothing to flatten); consts: values for
    the model's `constant`s (`--const N=16`).  Raises ModelError with every error found (a
    --const the model does not have located in the option's text)."""
    consts = dict(consts or {})
    if not consts and not needs_instantiation(model):
        return model
    return _Instantiate(model, consts, search_path()).build()


__all__ = ["instantiate", "output_refs", "path_name"]


def front(src):
    """The parse and instantiate stages: the model's text as a flat AST (components
    instantiated, `for` and `if` expanded, constants replaced by their values); src: a
    bgc.api.Source)."""
    from .parser import parse
    return instantiate(parse(src.text, src.path), dict(src.consts))
