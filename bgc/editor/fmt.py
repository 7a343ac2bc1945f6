"""bgc fmt: a model's text in the canonical layout.

The model's own grammar (grammar/bg.lark) parses the text once more into a concrete tree that
keeps every token (keep_all_tokens: brackets, commas, keywords, statement ends); the comments,
which the grammar ignores, are read from the gaps between the tokens (a gap holds only what
the lexer skips: blanks, line continuations, newlines inside brackets and comments), and each
is attached to a token: after the code on its line to the token before it, on a line of its
own to the token after it.  A layout document (bgc.editor.doc) is built from the tree, the
tokens as they are written, and printed in WIDTH columns.

The layout (docs/editors.md): one statement a line (`a; b` becomes two), blocks indented by 2,
continuation lines by 4; one space around `->`, `=`, `:`, `+`, `-`, relations and keywords,
none around `*`, `/`, `^`, `.`, inside brackets and before a comma; consecutive one-line
declarations of one kind (elements, parameters, ports, signals ...) aligned at their `:` or
`=`, and the comments after consecutive lines in one column; at most one blank line kept
between statements, none at a block's ends.  A statement wider than WIDTH breaks inside its
brackets (as many items a line as fit; a matrix a row a line, a component's parameters one a
line; a last argument that is a vector or a call hugged: `f(a, [`), or at its clauses and
operators with a line continuation `\\`.  A doc string is never broken: a line is wider only
where nothing can break.

Meaning never changes: the tokens are printed as written, only the white space between them
changes (and condition names, which the event log takes from the text, are spaced as here:
bgc.front.spelling); the result is parsed again and its tokens and comments compared with the
input's (FormatBug if they differ: a bug of bgc fmt, never written).  The layout depends on the
tokens, the comments and the blank lines only, so formatting twice gives what formatting once
gives."""
from __future__ import annotations

import bisect
import hashlib
import sys
from dataclasses import dataclass
from functools import lru_cache

from lark import Lark, Token, Tree

from ..base import cache
from ..base.diagnostics import ModelError
from ..front.parser import parse
from ..base.resources import resource_dir
from .doc import (BREAK_PARENT, HARDLINE, SOFTLINE, Comment, Fill, Group, Indent, Line,
                  LineSuffix, flat_width, propagate_breaks, render)

WIDTH = 100  # columns
BLOCK = 2  # a block's statements, indented
CONTINUATION = 4  # a statement's continuation lines and a bracket's items, indented

SEPARATORS = ("_NL", "SEMICOLON")
BLOCKS = frozenset({"component_decl", "for_block", "if_block", "elif_part", "else_part",
                    "when_block", "scene_decl"})
# keywords written against their opening bracket, as a call: `holonomic(init = 1)`, `pid(a, b)`
CALL_KEYWORDS = frozenset({"constraint", "holonomic", "nonholonomic", "unilateral", "pid", "pd",
                           "switch", "restitution", "integral"})
TIGHT_OPERATORS = frozenset({"*", "/", "^", "**"})
SUM = frozenset({"add", "sub"})
PRODUCT = frozenset({"mul", "div"})
# statements aligned with their neighbours of the same kind: kind and the token aligned
ALIGNED = {"element_decl": ("element", ":"), "bare_element": ("element", ":"),
           "junction_decl": ("element", ":"), "param_decl": ("parameter", "="),
           "signal_decl": ("signal", "="), "integral_decl": ("signal", "="),
           "input_decl": ("input", "="), "constant_decl": ("constant", "="),
           "discrete_decl": ("discrete", "="), "port_decl": ("port", ":")}


class FormatBug(AssertionError):
    """The formatted text does not hold the input's tokens and comments: a bug of bgc fmt
    (never written out)."""


# ---------------------------------------------------------------- the concrete tree
class _NewlinesInBrackets:
    """bgc.front.parser's post-lexer as far as layout goes: a newline inside ( ) or [ ] does not end
    a statement.  (bgc.front.parser's own parse, which runs first, refuses keywords as names.)"""

    always_accept = ("_NL",)

    def process(self, stream):
        depth = 0
        for tok in stream:
            if tok.type in ("LPAR", "LSQB"):
                depth += 1
            elif tok.type in ("RPAR", "RSQB"):
                depth = max(0, depth - 1)
            elif tok.type == "_NL" and depth > 0:
                continue
            yield tok


_OPTIONS = dict(parser="lalr", lexer="contextual", propagate_positions=True,
                keep_all_tokens=True, maybe_placeholders=False, start="start")


@lru_cache(maxsize=1)
def _concrete() -> Lark:
    """The grammar's parser keeping every token.  Its tables take a few tenths of a second to
    build: kept in the compile cache as bgc.front.parser keeps the model parser's."""
    import pickle

    import lark
    text = (resource_dir("grammar") / "bg.lark").read_text(encoding="utf-8")
    key = hashlib.sha256(repr((text, _OPTIONS, lark.__version__, sys.version_info[:2]))
                         .encode()).hexdigest()[:40]
    directory = cache.own_cache_dir()
    path = directory / f"lark-concrete-{key}.pickle" if directory is not None else None
    if path is not None:
        try:
            with open(path, "rb") as f:
                return Lark.__new__(Lark)._load(f, postlex=_NewlinesInBrackets(),
                                                propagate_positions=True)
        except Exception:  # noqa: BLE001  (missing, damaged, another lark: built again)
            pass
    parser = Lark(text, postlex=_NewlinesInBrackets(), **_OPTIONS)
    if path is not None:
        try:
            cache.write_cached(path, lambda f: parser.save(f, ("postlex",)))
        except (OSError, pickle.PicklingError):
            pass
    return parser


@dataclass(frozen=True)
class _Comment:
    text: str  # "# ...", trailing blanks dropped
    line: int


def _leaves(tree) -> list[Token]:
    """The tree's tokens in order (no recursion: the tree is as deep as its expressions)."""
    out, stack = [], [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, Tree):
            stack.extend(reversed(node.children))
        else:
            out.append(node)
    return out


def _comments(text: str, tokens: list[Token]):
    """Each comment with the index of the token after it (len(tokens) at the end): read from
    the gaps between tokens, which hold only what the lexer skips."""
    starts = [0] + [i + 1 for i, ch in enumerate(text) if ch == "\n"]
    out, end = [], 0
    for k, tok in enumerate(tokens + [None]):
        stop = tok.start_pos if tok is not None else len(text)
        i = text.find("#", end, stop)
        while i >= 0:
            j = text.find("\n", i, stop)
            j = stop if j < 0 else j
            line = bisect.bisect_right(starts, i)
            out.append((k, _Comment(text[i:j].rstrip(), line)))
            i = text.find("#", j, stop)
        if tok is not None:
            end = tok.end_pos
    return out


def _first(node) -> Token:
    while isinstance(node, Tree):
        node = node.children[0]
    return node


def _last(node) -> Token:
    while isinstance(node, Tree):
        node = node.children[-1]
    return node


def _is(node, *values) -> bool:
    return isinstance(node, Token) and node.type not in ("STRING",) and str(node) in values


def _sep(node) -> bool:
    return isinstance(node, Token) and node.type in SEPARATORS


# ---------------------------------------------------------------- the document
@dataclass(frozen=True)
class _Ctx:
    brackets: bool = False  # inside ( ) or [ ]: a line may end anywhere
    tight: bool = False  # inside an index or a name's brackets: `link[i-1]`

    def line(self) -> Line:
        """Where a line may end: outside brackets only with a continuation."""
        return Line(" ") if self.brackets else Line(" ", " \\")


TOP = _Ctx()


class _Printer:
    def __init__(self, text: str, tree: Tree):
        self.tokens = [t for t in _leaves(tree)]
        self.leading: dict[int, list[_Comment]] = {}
        self.trailing: dict[int, list[_Comment]] = {}
        self.end: list[_Comment] = []
        self.comment_pad: dict[int, int] = {}  # token -> spaces more before its comment
        printed = [i for i, t in enumerate(self.tokens) if t.type not in SEPARATORS]
        for k, c in _comments(text, self.tokens):
            before = bisect.bisect_left(printed, k) - 1  # the printed token before it
            prev = self.tokens[printed[before]] if before >= 0 else None
            if prev is not None and prev.end_line == c.line:
                self.trailing.setdefault(id(prev), []).append(c)
            elif before + 1 < len(printed):
                self.leading.setdefault(id(self.tokens[printed[before + 1]]), []).append(c)
            else:
                self.end.append(c)

    # ------------------------------------------------------------ tokens
    def tok(self, t: Token, ctx: _Ctx, lead: bool = True):
        """t as written, after the comments on lines of their own before it (lead), with the
        comment after it on its line (which breaks the brackets around it)."""
        parts = [Comment(c.text) for c in self.leading.get(id(t), ())] if lead else []
        parts.append(str(t))
        parts += self.after(t, ctx)
        return parts if len(parts) > 1 else parts[0]

    def after(self, t: Token, ctx: _Ctx) -> list:
        parts = []
        for c in self.trailing.get(id(t), ()):
            parts.append(LineSuffix("  " + " " * self.comment_pad.get(id(t), 0) + c.text))
            if ctx.brackets:
                parts.append(BREAK_PARENT)
        return parts

    def take_leading(self, t: Token) -> list[_Comment]:
        """The comments on lines of their own before t, printed by a block, not with t."""
        return self.leading.pop(id(t), [])

    # ------------------------------------------------------------ nodes
    def node(self, n, ctx: _Ctx):
        if isinstance(n, Token):
            return self.tok(n, ctx)
        rule = getattr(self, "r_" + n.data, None)
        if rule is not None:
            return rule(n, ctx)
        return self.join(n.children, n.data, ctx)

    def join(self, children, rule: str, ctx: _Ctx, pad: int = 0, lines=(),
             indent: bool = True):
        """children one after another, the space between two chosen by _space; `pad`
        spaces more before the child that is aligned (see ALIGNED); a Line where lines
        (a set of child indices) say the statement may break, what follows the first of
        them indented (unless they are the statement's, which indents them)."""
        parts, prev, i = [], None, 0
        children = [c for c in children if not _sep(c)]
        cont = None  # where the continuation lines start, in parts
        while i < len(children):
            c = children[i]
            at = i
            if _is(c, "(") or (_is(c, "[") and rule == "vector"):
                j = _closing(children, i)
                d = self.brackets(children[i], children[i + 1:j], children[j], rule, ctx)
                first, last, i = c, children[j], j + 1
            else:
                d = self.node(c, ctx)
                first, last, i = _first(c), _last(c), i + 1
            if prev is not None:
                if at in lines:
                    cont = len(parts) if cont is None else cont
                    parts.append(ctx.line())
                else:
                    space = _space(prev, first, rule, ctx)
                    if pad and _is(c, ":", "=") and space:
                        space += " " * pad
                        pad = 0
                    parts.append(space)
            parts.append(d)
            prev = last
        if cont is not None and indent:
            parts[cont:] = [Indent(parts[cont:], CONTINUATION)]
        return parts

    def brackets(self, open_: Token, inside: list, close: Token, rule: str, ctx: _Ctx):
        """A bracket's contents on its line, or broken: one item a line (as many a line as
        fit for a vector of plain items), or the last item, a vector, hugged: `f(a, [`."""
        inner = _Ctx(brackets=True)
        if len(inside) == 1 and isinstance(inside[0], Tree) and inside[0].data in (
                "args", "cparams"):
            rule, inside = inside[0].data, inside[0].children
        items, item = [], []
        for c in inside:
            if _is(c, ","):
                items.append((item, c))
                item = []
            else:
                item.append(c)
        if item:
            items.append((item, None))
        matrix = rule == "vector" and any(_hug_vector(cs) for cs, _ in items)
        docs = [self.item(cs, rule, inner) for cs, _ in items]
        commas = [self.tok(comma, inner) if comma is not None else None for _, comma in items]
        dangling = [Comment(c.text) for c in self.leading.get(id(close), ())]
        opening, closing, after = self.tok(open_, inner), str(close), self.after(close, ctx)
        if not items and not dangling:
            return [opening, closing, after]
        ends = [comma is not None and (self.trailing.get(id(comma)) or self.trailing.get(
            id(_last(cs[-1])))) for cs, comma in items]  # (a comment ends the item's line)
        body = _listed(docs, commas, fill=not matrix and rule != "cparams", ends=ends)
        broken = [opening, Indent([SOFTLINE, body, dangling], CONTINUATION), SOFTLINE, closing]
        forced = bool(dangling) or any(_will_break(d) for d in docs)
        hug = _hug_vector(items[-1][0], calls=True) if items and not dangling else None
        vector, head = _final_group(docs[-1]) if hug is not None else (None, [])
        if not isinstance(vector, Group):
            return _then(Group(broken, brk=forced, stop=True), after)
        hugged_vector = Group(vector.contents, brk=True, stop=True)
        before = _listed(docs[:-1], commas[:-1], fill=False, flat=True)
        hugged = [opening, before, [commas[-2], " "] if len(docs) > 1 else [], head,
                  hugged_vector, closing]
        others = any(_will_break(d) for d in docs[:-1]) or _will_break(head) or any(ends)
        if others:
            return _then(Group(broken, brk=True, stop=True), after)
        if vector.brk:  # (the vector breaks anyway: hugged, or all broken)
            return _then(Group(hugged, states=(broken,), stop=True), after)
        return _then(Group(broken, states=(hugged, broken), stop=True), after)

    def item(self, children, rule: str, ctx: _Ctx):
        if len(children) == 1:
            return self.node(children[0], ctx)
        return self.join(children, rule, ctx)

    # ------------------------------------------------------------ expressions
    def chain(self, n: Tree, kinds: frozenset, ctx: _Ctx, breaks: bool):
        """A chain of one operator family (a + b - c, a*b/c, a or b) as one list: the
        operands in order (no recursion down the chain), a Line before each operator if it
        may break there."""
        ops = []
        while isinstance(n, Tree) and n.data in kinds:
            left, *op, right = n.children
            ops.append((op[0] if op else None, right, n.data))
            n = left
        parts = [self.node(n, ctx)]
        rest = []
        for op, right, rule in reversed(ops):
            spaced = not ctx.tight and str(op) not in TIGHT_OPERATORS
            if breaks and spaced:
                rest += [ctx.line(), self.tok(op, ctx), " ", self.node(right, ctx)]
            else:
                gap = " " if spaced else ""
                rest += [gap, self.tok(op, ctx), gap, self.node(right, ctx)]
        if breaks and ops:
            return Group([parts, Indent(rest, CONTINUATION)])
        return parts + rest

    def r_add(self, n, ctx):
        return self.chain(n, SUM, ctx, True)

    r_sub = r_add

    def r_mul(self, n, ctx):
        return self.chain(n, PRODUCT, ctx, False)

    r_div = r_mul

    def r_cond_or(self, n, ctx):
        return self.chain(n, frozenset({"cond_or"}), ctx, True)

    def r_cond_and(self, n, ctx):
        return self.chain(n, frozenset({"cond_and"}), ctx, True)

    def r_index(self, n, ctx):
        return self.join(n.children, "index", _Ctx(ctx.brackets, True))

    def r_decl_name(self, n, ctx):
        return self.join(n.children, "decl_name", _Ctx(ctx.brackets, True))

    def r_outseg(self, n, ctx):
        return self.join(n.children, "outseg", _Ctx(ctx.brackets, True))

    def r_if_expr(self, n, ctx):
        """`if c then a elif d then b else e`, broken before then, elif and else."""
        cs = n.children
        return Group(self.join(cs, "if_expr", ctx, lines={
            i for i, c in enumerate(cs) if _is(c, "then", "else")
            or (isinstance(c, Tree) and c.data == "elif_expr")}))

    def r_constraint(self, n, ctx):
        """A constraint's corrector may go on a line of its own."""
        cs = n.children
        return self.join(cs, "constraint", ctx, lines={
            i for i, c in enumerate(cs) if isinstance(c, Tree) and c.data == "corrector"},
            indent=False)

    # ------------------------------------------------------------ statements
    def statement(self, n: Tree, ctx: _Ctx, pad: int = 0):
        if n.data in BLOCKS:
            return self.block_statement(n, ctx)
        if n.data in ("element_decl", "junction_decl", "bare_element"):
            lines = {i for i, c in enumerate(n.children)
                     if isinstance(c, Tree) and c.data in ("init_clause", "constraint",
                                                           "jswitch")}
            return Group(self.join(n.children, n.data, ctx, pad, lines))
        if n.data == "port_decl" and pad:
            port, item = n.children
            return Group([self.tok(port, ctx), " ", self.join(item.children, "port_item",
                                                              ctx, pad)])
        if n.data in ("scene_outputs", "scene_effects", "port_decl"):
            return self.listing(n, ctx)
        if n.data == "bond_chain":
            return Group(self.join(n.children, "bond_chain", ctx, lines={
                i for i, c in enumerate(n.children) if _is(c, "->")}))
        return Group(self.join(n.children, n.data, ctx, pad))

    def listing(self, n: Tree, ctx: _Ctx):
        """`outputs a, b, ...`: as many a line as fit."""
        keyword, *rest = n.children
        parts, item = [], []
        for c in rest:
            if _is(c, ","):
                parts += [self.item(item, n.data, ctx), [self.tok(c, ctx), ctx.line()]]
                item = []
            else:
                item.append(c)
        parts.append(self.item(item, n.data, ctx))
        return Group([self.tok(keyword, ctx), " ", Indent(Fill(parts), CONTINUATION)])

    def block_statement(self, n: Tree, ctx: _Ctx):
        cs = n.children
        at = next(i for i, c in enumerate(cs) if _is(c, "{"))
        close = _closing(cs, at, "{", "}")
        head = Group(self.join(cs[:at], n.data, ctx) + [" ", self.tok(cs[at], ctx)])
        body = self.block([c for c in cs[at + 1:close] if not _sep(c)], cs[close])
        parts = [head, Indent([HARDLINE, body], BLOCK) if body else [], HARDLINE if body else [],
                 self.tok(cs[close], ctx, lead=False)]
        for c in cs[close + 1:]:
            parts += [" ", self.node(c, ctx)]
        return parts

    r_elif_part = r_else_part = block_statement

    def block(self, statements: list, close: Token | None) -> list:
        """A block's statements (the model's, at the top), one a line, each after the
        comments on lines of their own before it; consecutive declarations of one kind
        aligned."""
        leads = [self.take_leading(_first(s)) for s in statements]
        ending = self.take_leading(close) if close is not None else self.end
        pads = self.alignment(statements, leads)
        self.align_comments(statements, leads, pads)
        parts, last = [], None
        for s, pad, lead in zip(statements, pads, leads):
            for c in lead:
                parts += self.separate(last, c.line)
                parts.append(c.text)
                last = c.line
            parts += self.separate(last, _first(s).line)
            parts.append(self.statement(s, TOP, pad))
            last = _last(s).end_line
        for c in ending:
            parts += self.separate(last, c.line)
            parts.append(c.text)
            last = c.line
        return parts

    @staticmethod
    def separate(last: int | None, line: int) -> list:
        """Before an item of a block at `line`: a newline, and a blank line if the text had
        one or more (none before the first)."""
        if last is None:
            return []
        return [HARDLINE, HARDLINE] if line - last > 1 else [HARDLINE]

    def alignment(self, statements: list, leads: list) -> list[int]:
        """The spaces each statement takes before its `:` or `=` to line up with its
        neighbours: statements of one kind (ALIGNED), each on one line, none with a blank
        line or a comment line between them."""
        pads = [0] * len(statements)
        runs, run, prev = [], [], None
        for i, s in enumerate(statements):
            head = self.head_width(s)
            joined = (prev is not None and head is not None and run
                      and ALIGNED[s.data][0] == ALIGNED[statements[prev].data][0]
                      and _first(s).line - _last(statements[prev]).end_line <= 1
                      and not leads[i])
            if not joined:
                if len(run) > 1:
                    runs.append(run)
                run = []
            if head is not None:
                run.append((i, head))
                prev = i
            else:
                prev = None
        if len(run) > 1:
            runs.append(run)
        while runs:
            run = runs.pop()
            widest = max(h for _, h in run)
            width = {i: flat_width(self.statement(statements[i], TOP, widest - h))
                     for i, h in run}
            over = [k for k, (i, _) in enumerate(run) if width[i] is None or width[i] > WIDTH]
            if not over:
                for i, h in run:
                    pads[i] = widest - h
                continue
            cut = [-1] + over + [len(run)]
            runs += [run[a + 1:b] for a, b in zip(cut, cut[1:]) if b - a - 1 > 1]
        return pads

    def align_comments(self, statements: list, leads: list, pads: list):
        """The comments after consecutive one-line statements start in one column."""
        run, prev = [], None
        for i, s in enumerate(statements + [None]):
            width = None
            if s is not None and s.data not in BLOCKS and self.trailing.get(id(_last(s))):
                width = flat_width(self.statement(s, TOP, pads[i]))
                if width is not None:
                    width -= sum(len(c.text) + 2 for c in self.trailing[id(_last(s))])
            joined = (width is not None and width <= WIDTH and prev is not None and not leads[i]
                      and _first(s).line - _last(statements[prev]).end_line <= 1)
            if not joined:
                widest = max((w for _, w in run), default=0)
                for k, w in run:
                    self.comment_pad[id(_last(statements[k]))] = widest - w
                run = []
            if width is not None and width <= WIDTH:
                run.append((i, width))
                prev = i
            else:
                prev = None

    def head_width(self, s) -> int | None:
        """The width of what stands before the statement's `:` or `=` (None: not aligned)."""
        if not isinstance(s, Tree) or s.data not in ALIGNED:
            return None
        cs = s.children
        if s.data == "port_decl":
            if len(cs) != 2:
                return None
            cs = [cs[0]] + cs[1].children
        token = ALIGNED[s.data][1]
        at = next((i for i, c in enumerate(cs) if _is(c, token)), None)
        if at is None:
            return None
        return flat_width(self.join(cs[:at], s.data, TOP))

    def document(self, tree: Tree) -> list:
        statements = [c for c in tree.children if not _sep(c)]
        return self.block(statements, None)


def _closing(children, i: int, open_: str | None = None, close: str | None = None) -> int:
    """The index of the bracket closing children[i] among its siblings."""
    open_ = open_ or str(children[i])
    close = close or {"(": ")", "[": "]", "{": "}"}[open_]
    depth = 0
    for j in range(i, len(children)):
        if _is(children[j], open_):
            depth += 1
        elif _is(children[j], close):
            depth -= 1
            if depth == 0:
                return j
    raise FormatBug(f"no '{close}' for the '{open_}' at {children[i].line}:{children[i].column}")


def _then(group: Group, after: list):
    return [group, after] if after else group


def _final_group(doc) -> tuple[Group, list]:
    """The group a vector item ends with, and what comes before it in the item."""
    head = []
    while isinstance(doc, list) and doc:
        head += doc[:-1]
        doc = doc[-1]
    return doc, head


def _listed(docs, commas, fill: bool, flat: bool = False, ends=()):
    """Items and their commas, a Line after each comma (a space: flat; a newline where ends
    says a comment ends the line)."""
    parts = []
    for k, d in enumerate(docs):
        if k:
            line = HARDLINE if k - 1 < len(ends) and ends[k - 1] else Line(" ")
            parts.append([commas[k - 1], " " if flat else line])
        parts.append(d)
    if fill:
        return Fill([p for pair in zip(parts[::2], parts[1::2] + [None]) for p in pair
                     if p is not None])
    return parts


def _hug_vector(children, calls: bool = False) -> Tree | None:
    """The vector (or call) an item is or ends with (`[..]`, `phi = [..]`, `f(..)`), which
    its bracket hugs."""
    kinds = ("vector", "call") if calls else ("vector",)
    c = children[-1]
    if isinstance(c, Tree) and c.data in kinds:
        return c
    if len(children) == 1 and isinstance(c, Tree) and c.data in ("pos_arg", "law_arg",
                                                                 "kw_arg", "kwarg",
                                                                 "annotation"):
        v = c.children[-1]
        return v if isinstance(v, Tree) and v.data in kinds else None
    return None


def _will_break(doc) -> bool:
    """Whether doc cannot be printed on one line (a comment in it, a bracket that breaks)."""
    propagate_breaks(doc)
    return flat_width(doc) is None


def _space(a: Token, b: Token, rule: str, ctx: _Ctx) -> str:
    """The space between two tokens, the last of one child of `rule` and the first of the
    next."""
    x, y = str(a), str(b)
    if (x in ("(", "[") and a.type != "STRING") or (y in (")", "]", ",")
                                                   and b.type != "STRING"):
        return ""
    if a.type == "STRING" or b.type == "STRING":
        return " "
    if rule in ("neg", "pos") and x in ("-", "+"):
        return ""
    if rule in ("pow", "mul", "div"):
        return ""
    if y == "(":
        return "" if a.type == "NAME" or x in (")", "]") or x in CALL_KEYWORDS else " "
    if y == "[":
        return "" if a.type in ("NAME", "NUMBER", "INT") or x in (")", "]") else " "
    if x == "." or y == ".":
        return ""
    if x == "..":
        return "" if rule == "for_block" else " "
    if y == "..":
        return "" if rule == "for_block" else " "
    if x == "->" or y == "->":
        return "" if rule == "dim" else " "
    if x == "@":
        return ""
    if ctx.tight and rule in SUM:
        return ""
    return " "


# ---------------------------------------------------------------- the entry
def format_text(text: str, path: str = "<model>", width: int = WIDTH) -> str:
    """text in the canonical layout; ModelError (located) if it is not a model's text (a
    syntax error), FormatBug if the layout lost or changed a token or a comment."""
    parse(text, path)  # (bgc's own located syntax errors, its limits)
    out, kept = _layout(text, width)
    # (a text already in its layout holds its own tokens: parsed once, not again)
    if out != _ended(text) and _signature(out) != kept:
        raise FormatBug(f"{path}: formatting would change its tokens or comments")
    return out


def _ended(text: str) -> str:
    return text if text.endswith("\n") else text + "\n"


def _tree(text: str) -> tuple[str, Tree]:
    text = _ended(text)
    return text, _concrete().parse(text, start="start")


def _layout(text: str, width: int) -> tuple[str, tuple]:
    """The text laid out, and the input's _signature (of the same parse)."""
    text, tree = _tree(text)
    printer = _Printer(text, tree)
    doc = printer.document(tree)
    out = render(doc, width).rstrip("\n")
    return (out + "\n" if out else ""), _signature(text, tree)


def _signature(text: str, tree: Tree | None = None) -> tuple:
    """What formatting keeps: the tokens but statement ends, each statement end where one
    is (a `;` is a newline, several newlines one), and the comments' texts, in order."""
    if tree is None:
        text, tree = _tree(text)
    tokens = _leaves(tree)
    out, end = [], False
    for t in tokens:
        if t.type in SEPARATORS:
            end = True
            continue
        if end and out and str(t) != "}" and out[-1] != ("LBRACE", "{"):
            out.append(";")
        out.append((t.type, str(t)))
        end = False
    comments = tuple(c.text for _, c in _comments(text, tokens))
    return tuple(out), comments


def check_text(text: str, path: str = "<model>") -> bool:
    """Whether text is in the canonical layout already."""
    return format_text(text, path) == text


__all__ = ["FormatBug", "WIDTH", "check_text", "format_text", "ModelError"]
