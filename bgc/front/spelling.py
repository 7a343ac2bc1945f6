"""An expression as its modeller wrote it: the names of conditions in the event log, in `bgc
check` and in the runtimes' messages (docs/hybrid.md: a condition is named as the model
writes it, with its path).

The text is the source of the expression's span, with its comments left out and each run of
whitespace made one space, and with each name written as the model-level name it stands for:
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
SPACE = re.compile(r"\s+")
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
        pieces += [_gap(text[at:a]), _spelled(leaf, text[a:b], names or {})]
        at = b
    pieces.append(_gap(text[at:end]))
    return "".join(pieces).strip() or None


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


def _gap(text: str) -> str:
    """What lies between two leaves: operators, parentheses, spaces; comments dropped."""
    return SPACE.sub(" ", COMMENT.sub("", text))


def _offset(text: str, line: int, col: int) -> int:
    starts = _line_starts(text)
    k = min(max(line, 1), len(starts)) - 1
    return min(starts[k] + max(col, 1) - 1, len(text))


@functools.lru_cache(maxsize=8)
def _line_starts(text: str) -> tuple[int, ...]:
    return (0,) + tuple(m.end() for m in re.finditer("\n", text))


__all__ = ["as_written"]
