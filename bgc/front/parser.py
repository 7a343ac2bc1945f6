"""Stage 1, parse: source text -> AST (bgc.front.ast), syntax errors as located diagnostics."""
from __future__ import annotations

import gc
from functools import lru_cache

from dataclasses import replace

from lark import Lark, Token, Tree
from lark.exceptions import (UnexpectedCharacters, UnexpectedEOF, UnexpectedInput,
                             UnexpectedToken)

from . import ast
from ..base import si
from ..base.diagnostics import ModelError, Note, Origin, Span, fail
from ..base.resources import (MAX_DIMENSION, MAX_INDEX, MAX_NESTING, MAX_OPTION_CHARS, max_source_bytes,
                              resource_dir, set_aside, too_large)

# Reserved: none of these can name anything (docs/semantics.md, "Names").
KEYWORDS = frozenset("""model parameter signal integral init constraint holonomic nonholonomic
    corrector pid pd none phi scene effects outputs time every solver set
    library component port constant for in if elif else and or not import as unit
    then when reinit discrete unilateral restitution input switch""".split())

# Friendly names for terminals in "expected ..." messages.
_TERMINAL_NAMES = {
    "NAME": "a name", "NUMBER": "a number", "INT": "an integer", "STRING": "a string",
    "_NL": "end of line", "SEMICOLON": "';'", "LPAR": "'('", "RPAR": "')'", "LSQB": "'['",
    "RSQB": "']'", "LBRACE": "'{'", "RBRACE": "'}'", "COMMA": "','", "COLON": "':'",
    "EQUAL": "'='", "PLUS": "'+'", "MINUS": "'-'", "STAR": "'*'", "SLASH": "'/'", "POW": "'^'",
    "DOT": "'.'", "AT": "'@'", "$END": "end of file", "CKIND": "'holonomic' or 'nonholonomic'",
    "ANNOT": "'init' or 'phi'",
}


class _BracketPostLex:
    """Drop newlines inside ( ) and [ ]: they do not end a statement there.  Refuse a keyword
    where a name stands (the contextual lexer reads it as a NAME where no keyword fits)."""

    always_accept = ("_NL",)

    def process(self, stream):
        depth = 0
        for tok in stream:
            if tok.type == "NAME" and tok in KEYWORDS:
                _keyword_as_name(tok)
            if tok.type in ("LPAR", "LSQB"):
                depth += 1
            elif tok.type in ("RPAR", "RSQB"):
                depth = max(0, depth - 1)
            elif tok.type == "_NL" and depth > 0:
                continue
            yield tok


_LARK_OPTIONS = dict(parser="lalr", lexer="contextual", propagate_positions=True,
                     maybe_placeholders=True, start=["start", "option_outputs", "option_effects"])


@lru_cache(maxsize=1)
def lark_parser() -> Lark:
    """The parser.  Building its LALR tables takes a tenth of a second or more, every cold
    `bgc simulate`; they are kept in the compile cache (bgc.base.cache.own_cache_dir) under the
    SHA-256 of the grammar, the options and the versions of lark and Python, and read back
    (anything unreadable is built again)."""
    import hashlib
    import pickle
    import sys

    import lark

    from ..base import cache
    text = (resource_dir("grammar") / "bg.lark").read_text(encoding="utf-8")
    key = hashlib.sha256(repr((text, _LARK_OPTIONS, lark.__version__, sys.version_info[:2]))
                         .encode()).hexdigest()[:40]
    name = f"lark-{key}.pickle"
    directory = cache.own_cache_dir()
    if directory is not None:
        parser = _saved(directory / name)
        if parser is not None:
            return parser
    parser = _saved(cache.PREBUILT / name)  # (bgc.execute.prebuild's, at install)
    if parser is None:
        parser = Lark(text, postlex=_BracketPostLex(), **_LARK_OPTIONS)
    if directory is None:
        return parser
    path = directory / name
    try:
        cache.write_cached(path, lambda f: parser.save(f, ("postlex",)))
    except (OSError, pickle.PicklingError):
        pass
    return parser


def _saved(path) -> Lark | None:
    """The parser whose tables were saved at path, or None (missing, damaged, or of another
    lark: built again)."""
    try:
        with open(path, "rb") as f:
            return Lark.__new__(Lark)._load(f, postlex=_BracketPostLex(),
                                            propagate_positions=True)
    except Exception:  # noqa: BLE001
        return None


def _whole(tok: Token, what: str) -> int:
    """An INT token's value, refused above MAX_DIMENSION (before int() reads its digits)."""
    return _integer(str(tok), _tspan(tok), what)


def _integer(text: str, span: Span, what: str, most: int = MAX_DIMENSION) -> int:
    """The value of digits, refused above `most` (before int() reads them)."""
    digits = text.lstrip("0")
    if len(digits) > len(str(most)) or int(digits or 0) > most:
        shown = digits if len(digits) <= 20 else digits[:20] + "..."
        fail(span, f"{what} {shown} is too large (the limit is {most})")
    return int(digits or 0)


def _keyword_as_name(tok: Token):
    fail(_tspan(tok), f"'{tok}' is a keyword: it cannot be a name")


def _span(meta) -> Span:
    return Span(meta.line, meta.column, meta.end_line, meta.end_column)


def _tspan(tok: Token) -> Span:
    return Span(tok.line, tok.column, tok.end_line, tok.end_column)


def _ident(tok: Token) -> ast.Ident:
    return ast.Ident(str(tok), _tspan(tok))


def _doc(tok) -> str | None:
    if tok is None:
        return None
    return str(tok)[1:-1].replace('\\"', '"').replace("\\\\", "\\")


def _statements(items) -> tuple:
    """A body's statements, each port of a `port a, b` list one of them."""
    return tuple(s for x in items for s in (x if type(x) is list else (x,)))


class _ToAst:
    """Builds typed nodes only; no checking beyond the shape of the syntax.  A method per rule,
    called with the rule's meta (its position) and its children already built (_transform)."""

    def start(self, meta, children):
        return _statements(children)

    # declarations
    def model_decl(self, meta, c):
        return ast.ModelDecl(_ident(c[0]), _doc(c[1]), _span(meta))

    def library_decl(self, meta, c):
        return ast.LibraryDecl(_ident(c[0]), _doc(c[1]), _span(meta))

    def param_decl(self, meta, c):
        return ast.ParamDecl(_ident(c[0]), c[1], _doc(c[3]), _span(meta), c[2])

    def unit(self, meta, c):
        text = _doc(c[0])
        try:
            si.parse(text)
        except si.UnitError as e:
            tok = c[0]
            col = tok.column + 1 + e.offset if tok.line == tok.end_line else tok.column
            width = e.length if tok.line == tok.end_line else len(str(tok))
            fail(Span(tok.line, col, tok.line, col + width), str(e))
        return text

    def decl_name(self, meta, c):
        return (_ident(c[0]), c[1])

    def qname(self, meta, c):
        return ast.Ident(".".join(str(t) for t in c), _span(meta))

    def element_decl(self, meta, c):
        (name, index), kind, dim, args, *rest = c
        inits = tuple(x for x in rest if isinstance(x, ast.InitClause))
        effects = tuple(x for x in rest if isinstance(x, ast.Ident))
        return ast.ElementDecl(name, kind, dim, tuple(args or ()), inits,
                               effects, None, _doc(rest[-1]), _span(meta), index)

    def bare_element(self, meta, c):
        """`d : D`: an element without arguments (the ideal diode)."""
        (name, index), kind, *rest = c
        effects = tuple(x for x in rest if isinstance(x, ast.Ident))
        return ast.ElementDecl(name, kind, None, (), (), effects, None, _doc(rest[-1]),
                               _span(meta), index)

    def junction_decl(self, meta, c):
        (name, index), kind, dim, constraint, switch, *rest = c
        effects = tuple(x for x in rest if isinstance(x, ast.Ident))
        return ast.ElementDecl(name, _ident(kind), dim, (), (), effects, constraint,
                               _doc(rest[-1]), _span(meta), index, switch)

    def jswitch(self, meta, c):
        return c[0]

    # components and generation
    def component_decl(self, meta, c):
        name, params, doc, *body = c
        return ast.ComponentDecl(_ident(name), tuple(params or ()), _doc(doc), _statements(body),
                                 _span(meta))

    def cparams(self, meta, c):
        return tuple(c)

    def cparam(self, meta, c):
        return ast.ComponentParam(_ident(c[0]), c[1], c[2], _span(meta), _doc(c[3]))

    def port_decl(self, meta, c):
        """`port a : electrical, b[2]`: a PortDecl per port (a list, which the body holding
        it spreads: _statements), the first one's span from the keyword."""
        first = _span(meta)
        first = Span(first.line, first.col, c[0].span.end_line, c[0].span.end_col)
        return [replace(c[0], span=first), *c[1:]]

    def port_item(self, meta, c):
        return ast.PortDecl(_ident(c[0]), c[1], _ident(c[2]) if c[2] is not None else None,
                            _span(meta), c[3], _doc(c[4]))

    def constant_decl(self, meta, c):
        return ast.ConstantDecl(_ident(c[0]), c[1], _span(meta))

    def for_block(self, meta, c):
        return ast.ForBlock(_ident(c[0]), c[1], c[2], _statements(c[3:]), _span(meta))

    def if_block(self, meta, c):
        cond, *rest = c
        body = _statements(x for x in rest if not isinstance(x, tuple) and x is not None)
        branches = [(cond, body)] + [(x[1], x[2]) for x in rest
                                     if isinstance(x, tuple) and x[0] == "elif"]
        orelse = next((x[1] for x in rest if isinstance(x, tuple) and x[0] == "else"), None)
        return ast.IfBlock(tuple(branches), orelse, _span(meta))

    def elif_part(self, meta, c):
        return ("elif", c[0], _statements(c[1:]))

    def else_part(self, meta, c):
        return ("else", _statements(c))

    def if_expr(self, meta, c):
        cond, value, *rest = c
        branches = ((cond, value),) + tuple(x for x in rest[:-1])
        return ast.IfExpr(branches, rest[-1], _span(meta))

    def elif_expr(self, meta, c):
        return (c[0], c[1])

    def input_decl(self, meta, c):
        return ast.InputDecl(_ident(c[0]), c[1], _doc(c[3]), _span(meta), unit=c[2])

    def discrete_decl(self, meta, c):
        return ast.DiscreteDecl(_ident(c[0]), c[1], _doc(c[2]), _span(meta))

    def when_block(self, meta, c):
        return ast.WhenBlock(c[0], tuple(x for x in c[1:] if x is not None), _span(meta))

    def reinit_stmt(self, meta, c):
        """Its target an expression: a state's name, indexed or not (bgc.front.resolve checks
        it)."""
        return ast.Reinit(c[0], c[1], _span(meta))

    def assign_stmt(self, meta, c):
        return ast.DiscreteAssign(_ident(c[0]), c[1], _span(meta))

    def compare(self, meta, c):
        return ast.Compare(str(c[1]), c[0], c[2], _span(meta))

    def cond_or(self, meta, c):
        return ast.BoolOp("or", tuple(c), _span(meta))

    def cond_and(self, meta, c):
        return ast.BoolOp("and", tuple(c), _span(meta))

    def cond_not(self, meta, c):
        return ast.BoolOp("not", tuple(c), _span(meta))

    def import_name(self, meta, c):
        return ast.ImportDecl(_ident(c[0]), None, _ident(c[1]) if c[1] is not None else None,
                              _span(meta))

    def import_file(self, meta, c):
        return ast.ImportDecl(None, _doc(c[0]), _ident(c[1]), _span(meta))

    def dim(self, meta, c):
        return ast.Dim(_whole(c[0], "dimension"), _whole(c[1], "dimension") if c[1] is not None
                       else None, _span(meta))

    def args(self, meta, c):
        return tuple(c)

    def pos_arg(self, meta, c):
        return ast.Arg(None, c[0], _span(meta))

    def law_arg(self, meta, c):
        return ast.Arg(_ident(c[0]), c[1], _span(meta))

    def init_clause(self, meta, c):
        return ast.InitClause(_ident(c[0]), c[1], _span(meta))

    def effect(self, meta, c):
        return _ident(c[0])

    def constraint(self, meta, c):
        kind = _ident(c[0]) if c[0] is not None else None
        return ast.ConstraintSpec(kind, c[1], c[3], _span(meta), c[2])

    def restitution(self, meta, c):
        return c[0]

    def annotation(self, meta, c):
        return (str(c[0]), c[1], _span(meta))

    def corrector(self, meta, c):
        return c[0]

    def pid(self, meta, c):
        return ast.Corrector("pid", tuple(c), _span(meta))

    def pd(self, meta, c):
        return ast.Corrector("pd", tuple(c), _span(meta))

    def nocorr(self, meta, c):
        return ast.Corrector("none", (), _span(meta))

    def signal_decl(self, meta, c):
        name, dim, expr, unit = c
        return ast.SignalDecl(_ident(name), dim, expr, _span(meta), unit)

    def integral_decl(self, meta, c):
        name, dim, expr, init, unit = c
        return ast.IntegralDecl(_ident(name), dim, expr, init, _span(meta), unit)

    def path(self, meta, c):
        if all(index is None for _, index in c):
            return ast.Ident(".".join(n.name for n, _ in c), _span(meta))
        return ast.PathRef(tuple(c), _span(meta))

    def bond_chain(self, meta, c):
        return ast.BondChain(tuple(c), _span(meta))

    # scenes
    def scene_decl(self, meta, c):
        return ast.SceneDecl(_ident(c[0]), _doc(c[1]), tuple(c[2:]), _span(meta))

    def scene_effects(self, meta, c):
        return ast.SceneEffects(tuple(_ident(t) for t in c), _span(meta))

    def scene_no_effects(self, meta, c):
        return ast.SceneEffects(None, _span(meta))

    def scene_outputs(self, meta, c):
        return ast.SceneOutputs(tuple(c), _span(meta))

    def option_outputs(self, meta, c):
        return tuple(c)

    def outref(self, meta, c):
        """An OutRef (ast.out_ref), or an OutPath while an index is an expression."""
        if all(index is None or type(index) is int for _, index in c):
            return ast.out_ref(c, _span(meta))
        return ast.OutPath(tuple(c), _span(meta))

    def outseg(self, meta, c):
        """(name, index): a whole number written as one is read here, any other expression
        when the constants are known."""
        index = c[1]
        if isinstance(index, ast.Num) and index.text.isdigit():
            index = _integer(index.text, index.span, "index", MAX_INDEX)
        return (str(c[0]), index)

    def scene_time(self, meta, c):
        return ast.SceneTime(c[0], c[1], c[2], _span(meta))

    def scene_solver(self, meta, c):
        opts = tuple(x for x in c[1:] if x is not None)
        return ast.SceneSolver(_ident(c[0]), opts, _span(meta))

    def kwarg(self, meta, c):
        return (_ident(c[0]), c[1])

    def scene_set(self, meta, c):
        return ast.SceneSet(c[0], c[1], _span(meta))

    # expressions
    def number(self, meta, c):
        return ast.Num(str(c[0]), _span(meta))

    def name(self, meta, c):
        return ast.Name(str(c[0]), _span(meta))

    def member(self, meta, c):
        base, name = c
        if isinstance(base, ast.Name):
            return ast.Field(base.name, str(name), _span(meta))
        if isinstance(base, ast.Field):
            return ast.Field(f"{base.owner}.{base.field}", str(name), _span(meta))
        return ast.Member(base, str(name), _span(meta))

    def call(self, meta, c):
        return ast.Call(str(c[0]), tuple(x for x in c[1:] if x is not None), _span(meta))

    def string_arg(self, meta, c):
        return ast.Str(_doc(c[0]), _span(meta))

    def kw_arg(self, meta, c):
        return ast.KwArg(str(c[0]), c[1], _span(meta))

    def vector(self, meta, c):
        return ast.Vector(tuple(c), _span(meta))

    def index(self, meta, c):
        return ast.Index(c[0], c[1], _span(meta))

    def neg(self, meta, c):
        return ast.Neg(c[0], _span(meta))

    def pos(self, meta, c):
        return c[0]

    def _bin(op):
        def build(self, meta, c):
            return ast.BinOp(op, c[0], c[-1], _span(meta))
        return build

    add, sub, mul, div, pow = _bin("+"), _bin("-"), _bin("*"), _bin("/"), _bin("^")


_CHAINS = {"add": "sum", "sub": "sum", "mul": "product", "div": "product"}


def _check_nesting(tree: Tree):
    """Refuse trees nested deeper than MAX_NESTING (chains of + or * count once)."""
    stack = [(tree, 0, None)]
    while stack:
        node, depth, group = stack.pop()
        if not isinstance(node, Tree):
            continue
        g = _CHAINS.get(node.data)
        d = depth if (g is not None and g == group) else depth + 1
        if d > MAX_NESTING + 8:  # statement levels above expressions
            fail(_span(node.meta), f"expression nested too deeply (more than {MAX_NESTING} levels)")
        stack.extend((ch, d, g) for ch in node.children)


def _expected(exc: UnexpectedInput) -> str:
    names = sorted({_TERMINAL_NAMES.get(t, f"'{t.lower()}'" if t.isupper() and not t.startswith("__")
                                        else t) for t in (getattr(exc, "expected", None) or ())})
    names = [n for n in names if not n.startswith("'__") and not n.startswith("__")]
    if not names:
        return ""
    if len(names) > 10:
        return ""
    return ", expected " + (names[0] if len(names) == 1 else "one of " + ", ".join(names))


def _describe(tok: Token) -> str:
    if tok.type == "$END":
        return "end of file"
    if tok.type == "_NL":
        return "end of line"
    return f"'{tok}'"


def _code(source: str):
    """(character, line, column) of each character outside strings and comments."""
    ln, cl = 1, 1
    in_string = in_comment = escaped = False
    for ch in source:
        if in_comment:
            in_comment = ch != "\n"
        elif in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == "#":
            in_comment = True
        elif ch == '"':
            in_string = True
        else:
            yield ch, ln, cl
        ln, cl = (ln + 1, 1) if ch == "\n" else (ln, cl + 1)


def _unclosed_bracket(source: str, line: int, col: int) -> Span | None:
    """The innermost ( or [ still open before (line, col), skipping strings and comments."""
    stack = []
    for ch, ln, cl in _code(source):
        if (ln, cl) >= (line, col):
            break
        if ch in "([":
            stack.append(Span(ln, cl, ln, cl + 1))
        elif ch in ")]" and stack:
            stack.pop()
    return stack[-1] if stack else None


def _unclosed_block(source: str, line: int, col: int) -> Span | None:
    """The innermost { before (line, col) that no } of the whole text closes."""
    stack = []
    for ch, ln, cl in _code(source):
        if ch == "{":
            stack.append(Span(ln, cl, ln, cl + 1))
        elif ch == "}" and stack:
            stack.pop()
    before = [s for s in stack if (s.line, s.col) < (line, col)]
    return before[-1] if before else None


def _block_not_closed(tok: Token, source: str, line: int, col: int):
    """A statement's keyword, or the end of the file, where a block opened before it and
    never closed still holds the parser: the missing '}' is the error (unless a bracket is
    open too: the newlines it holds did not end the statement, _syntax_error's note)."""
    opened = _unclosed_block(source, line, col)
    if opened is None or _unclosed_bracket(source, line, col) is not None:
        return
    width = 1 if tok.type == "$END" else len(str(tok))
    fail(Span(line, col, line, col + width),
         f"syntax error: unexpected {_describe(tok)}: the block opened at "
         f"{opened.line}:{opened.col} is not closed (its '}}' is missing)",
         Note(opened, "the block opened here"))


def _syntax_error(exc: UnexpectedInput, source: str):
    line, col = max(exc.line, 1), max(exc.column, 1)
    if isinstance(exc, UnexpectedToken):
        tok = exc.token
        before = (exc.token_history or [None])[-1]
        if before is not None and str(before) in KEYWORDS and str(tok) in (":", "->"):
            _keyword_as_name(before)  # `scene : 1`, `model -> j`: a keyword declared or bonded
        if tok.type == "$END":
            lines = source.splitlines() or [""]
            line, col = len(lines), len(lines[-1]) + 1
        if tok.type == "$END" or (tok.type != "NAME" and str(tok) in KEYWORDS):
            _block_not_closed(tok, source, line, col)  # `when c { n = 1` then `scene ...`
        if tok.type != "NAME" and str(tok) in KEYWORDS and "NAME" in (exc.expected or ()):
            _keyword_as_name(tok)  # `set : 0`: a keyword where only a name fits
        msg = f"syntax error: unexpected {_describe(tok)}{_expected(exc)}"
        width = max(1, len(str(tok))) if tok.type not in ("$END", "_NL") else 1
    elif isinstance(exc, UnexpectedCharacters):
        ch = source[exc.pos_in_stream] if exc.pos_in_stream < len(source) else "?"
        msg = f"syntax error: unexpected character {ch!r}"
        width = 1
    else:
        msg = "syntax error: unexpected end of file"
        width = 1
    opened = _unclosed_bracket(source, line, col)
    notes = [Note(opened, "this bracket is not closed (a newline inside brackets does not end "
                          "a statement)")] if opened and opened.line < line else []
    fail(Span(line, col, line, col + width), msg, *notes)


def decode(data: bytes) -> str:
    if len(data) > max_source_bytes():  # (read no further than that: its size is not known)
        fail(None, too_large(f"its more than {max_source_bytes()} bytes", len(data), True))
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        fail(Span(line, col, line, col + 1), "input is not valid UTF-8")


def parse(source: str, path: str = "<model>") -> ast.Model:
    """Parse `source` into an ast.Model; raises ModelError with a located diagnostic."""
    size = len(source.encode("utf-8"))
    if size > max_source_bytes():
        fail(None, too_large(f"its {size} bytes", size, True))
    text = source if source.endswith("\n") else source + "\n"
    collecting = gc.isenabled()
    gc.disable()  # (the tree and the AST hold no reference cycles: the collector's walks over
    try:          # their young objects were a third of a large flat model's parse)
        try:
            tree = lark_parser().parse(text, start="start")
        except (UnexpectedEOF, UnexpectedToken, UnexpectedCharacters) as exc:
            _syntax_error(exc, source)
        except UnexpectedInput as exc:  # any other lark input error
            _syntax_error(exc, source)
        _check_nesting(tree)
        return ast.Model(_transform(tree), path, text=source)
    finally:
        if collecting:
            gc.enable()
            set_aside()


@lru_cache(maxsize=64)
def parse_library(source: str, path: str) -> ast.Model:
    """parse() of a library's text, remembered (the AST is immutable): a long-lived process
    (bgc lsp, a notebook) parses each library once, not at every build that imports it."""
    return parse(source, path)


_BUILDERS = {name: f for name, f in vars(_ToAst).items() if not name.startswith("_")}


def _transform(tree):
    """The AST of a parse tree, bottom-up without recursion (a rule without a builder stays a
    Tree); the model errors that building it finds, as they are.  (Lark's own transformer
    does the same walk, but wraps every call of a builder that takes the meta in new objects:
    a third of the parse of a large model.)"""
    order = []  # the tree in reverse postfix order
    queue = [tree]
    while queue:
        t = queue.pop()
        order.append(t)
        if type(t) is Tree:
            queue += t.children
    builder = _ToAst()
    stack: list = []
    for x in reversed(order):
        if type(x) is Tree:
            size = len(x.children)
            if size:
                args = stack[-size:]
                del stack[-size:]
            else:
                args = []
            f = _BUILDERS.get(x.data)
            stack.append(f(builder, x.meta, args) if f is not None else Tree(x.data, args, x.meta))
        else:
            stack.append(x)
    result, = stack
    return result


def _located_at(value, origin: Origin):
    """value (an OutRef, Ident or SceneEffects) with its spans in `origin`."""
    span = replace(value.span, origin=origin)
    if isinstance(value, ast.SceneEffects):
        names = None if value.names is None else tuple(_located_at(n, origin)
                                                       for n in value.names)
        return ast.SceneEffects(names, span)
    return replace(value, span=span)


def parse_option(kind: str, text: str, name: str):
    """A scene's outputs or effects given outside the model (`--outputs x,rod.lambda`,
    `--effects gravity` or `none`), parsed by the model grammar's own rules: a tuple of OutRefs,
    or an ast.SceneEffects.  Errors are located in the option's text, reported as `name`."""
    origin = Origin(name, text)
    if len(text) > MAX_OPTION_CHARS:
        fail(Span(1, 1, 1, 2, origin), f"{name} is too long ({len(text)} characters; the limit "
                                       f"is {MAX_OPTION_CHARS})")
    if "\n" in text or "\r" in text:
        fail(Span(1, 1, 1, 2, origin), f"{name} must be one line")
    start = {"outputs": "option_outputs", "effects": "option_effects"}[kind]
    try:
        try:
            tree = lark_parser().parse(text, start=start)
        except UnexpectedInput as exc:
            _syntax_error(exc, text)
    except ModelError as exc:
        hint = {"outputs": "outputs separated by commas, e.g. x, rod.lambda, q[1]",
                "effects": "effect names separated by commas, or none"}[kind]
        raise ModelError([replace(d, span=d.span and replace(d.span, origin=origin),
                                  message=d.message.split(", expected")[0] + f"; {name} takes "
                                  + hint,
                                  notes=tuple(replace(n, span=n.span and replace(
                                      n.span, origin=origin)) for n in d.notes))
                          for d in exc.diagnostics]) from None
    try:
        value = _transform(tree)
    except ModelError as exc:
        raise ModelError([replace(d, span=replace(d.span, origin=origin))
                          for d in exc.diagnostics]) from None
    if kind == "outputs":
        return tuple(_located_at(r, origin) for r in value)
    return _located_at(value, origin)
