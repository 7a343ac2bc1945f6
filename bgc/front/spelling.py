"""An expression as its modeller wrote it: the names of conditions in the event log, in `bgc
check` and in the runtimes' messages (docs/hybrid.md: a condition is named as the model
writes it, with its path).

The text is the source of the expression's span, with its comments left out and spaced as bgc
fmt spaces it (whatever the blanks and line breaks written: a model and its formatted text give
the same names, and so the same generated code), and with each name written as the model-level
name it stands for:
inside a component the instance's path (`x` of instance `a` is `a.x`), an element's own `e`
in its law the element's (`valve.e`), an indexed name its index's value (`link[i]` is
`link[2]`), a compile-time constant its value.  The leaves of a flat AST (bgc.front.instantiate)
carry those names and the spans of what was written, so the text between them is the
model's own: operators, parentheses, `^` or `**` as written.  Deterministic: the same model
gives the same names.
"""
from __future__ import annotations

import functools
import re
from dataclasses import fields, is_dataclass

from . import ast
from ..base.diagnostics import Span

COMMENT = re.compile(r"#[^\n]*")
# what lies between two leaves: operators, brackets, commas, keywords, function and option names
TOKEN = re.compile(r"\.\.|->|<=|>=|==|!=|\*\*|[A-Za-z_]\w*|[^\s\\]")
KEYWORDS = frozenset("and or not if then elif else".split())
TIGHT = frozenset(("*", "/", "^", "**"))
LEAVES = (ast.Num, ast.Name, ast.Field, ast.Str, ast.Ident)


def as_written(node, model_text: str, names=None) -> str | None:
    """node's text as written (see the module's doc); names: {name: symbol} of the scope's
    own variables (an element's e, f), written by the symbol's name.  None where the text is
    not at hand (an AST built without its source) or the leaves do not lie in order inside
    the node's span."""
    span = getattr(node, "span", None)
    text = _source(span, model_text)
    if not text:
        return None
    start, end = _offset(text, span.line, span.col), _offset(text, span.end_line, span.end_col)
    pieces, at = [], start
    for leaf in _leaves(node):
        a, b = _bounds(leaf.span, span, text)
        if a is None or a < at or b > end:
            return None
        pieces += [(t, False) for t in _gap(text[at:a])]
        pieces.append((_spelled(leaf, text[a:b], names or {}), True))
        at = b
    pieces += [(t, False) for t in _gap(text[at:end])]
    return _joined(pieces) or None


def _source(span: Span | None, model_text: str) -> str:
    if span is None:
        return ""
    return span.origin.text if span.origin is not None else model_text


def _bounds(leaf: Span, outer: Span, text: str):
    """The leaf's offsets in text, or (None, None) if it is not in the same text."""
    if leaf is None or (leaf.origin is None) != (outer.origin is None) or (
            leaf.origin is not None and leaf.origin.name != outer.origin.name):
        return None, None
    return _offset(text, leaf.line, leaf.col), _offset(text, leaf.end_line, leaf.end_col)


def _leaves(node) -> list:
    """The leaves of an expression node (names, numbers, strings), in the order of its fields."""
    out, todo = [], [node]
    while todo:
        n = todo.pop()
        if isinstance(n, LEAVES):
            out.append(n)
        elif isinstance(n, tuple):
            todo.extend(reversed(n))
        elif is_dataclass(n) and not isinstance(n, (type, Span)):
            todo.extend(reversed([getattr(n, f.name) for f in fields(n)]))
    return out


def _spelled(leaf, source: str, names: dict) -> str:
    if isinstance(leaf, ast.Name):
        own = names.get(leaf.name)
        return str(own) if own is not None else leaf.name
    if isinstance(leaf, ast.Field):
        return f"{leaf.owner}.{leaf.field}"
    if isinstance(leaf, ast.Num):
        return leaf.text
    return source  # a string or a keyword, as written


def _gap(text: str) -> list[str]:
    """The tokens between two leaves (operators, brackets, keywords); blanks, line
    continuations and comments dropped."""
    return TOKEN.findall(COMMENT.sub("", text))


def _joined(pieces) -> str:
    """The tokens, (text, is a leaf), spaced as bgc fmt spaces an expression: nothing inside
    brackets, before a comma or around `*`, `/`, `^`, `.`; a sign against what it signs; a call's
    or an index's bracket against what it follows; `+` and `-` tight inside an index; one space
    around every other operator and keyword, and after a comma."""
    out, prev, brackets = [], None, []
    for text, leaf in pieces:
        kind = _kind(text, leaf, prev)
        if prev is not None:
            out.append(_between(prev, kind, text, brackets))
        if kind == "open":
            brackets.append("index" if text == "[" and prev in ("operand", "close") else text)
        elif kind == "close" and brackets:
            brackets.pop()
        out.append(text)
        prev = kind
    return "".join(out).strip()


def _kind(text: str, leaf: bool, prev: str | None) -> str:
    if leaf:
        return "operand"
    if text in ("(", "["):
        return "open"
    if text in (")", "]"):
        return "close"
    if text in (",", "."):
        return text
    if text in ("+", "-"):
        return "binary" if prev in ("operand", "close") else "sign"
    if text in TIGHT:
        return "tight"
    if text[0].isalpha() or text[0] == "_":
        return "keyword" if text in KEYWORDS else "name"
    return "operator"


def _between(prev: str, kind: str, text: str, brackets: list) -> str:
    if prev == "open" or kind in ("close", ","):
        return ""
    if prev == ",":
        return " "
    if "." in (prev, kind) or "tight" in (prev, kind) or prev == "sign":
        return ""
    if kind == "open":
        return "" if prev in ("operand", "close", "name") else " "
    if "binary" in (prev, kind) and brackets and brackets[-1] == "index":
        return ""
    return " "


def _offset(text: str, line: int, col: int) -> int:
    starts = _line_starts(text)
    k = min(max(line, 1), len(starts)) - 1
    return min(starts[k] + max(col, 1) - 1, len(text))


@functools.lru_cache(maxsize=8)
def _line_starts(text: str) -> tuple[int, ...]:
    return (0,) + tuple(m.end() for m in re.finditer("\n", text))


__all__ = ["as_written"]
