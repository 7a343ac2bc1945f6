"""A layout document and its printer: Wadler's "prettier printer" as Prettier implements it
(groups that break as a whole, fills that break where they must, a choice among layouts), for
bgc fmt.  The formatter builds a document from a model's tokens; this module decides where the
lines end, for a width, and knows nothing of the language.

A document is a str (text without newlines), a list (the parts in order), or one of the nodes
below.  Printing never recurses with the document's depth: an explicit stack of commands, as
Prettier's printDocToString."""
from __future__ import annotations

from dataclasses import dataclass, field

BREAK, FLAT = "break", "flat"


@dataclass(eq=False)
class Group:
    """Its contents on one line if they fit, else with every Line of its own broken.
    brk: broken whatever the width (a comment inside).  states: layouts to try in order after the flat one (Prettier's
    conditionalGroup); the last is used broken.  stop: a break inside does not break the
    groups around it (a bracket's contents on lines of their own need not break the lines
    of the statement that holds it)."""

    contents: object
    brk: bool = False
    states: tuple = ()
    stop: bool = False


@dataclass(eq=False)
class Indent:
    contents: object
    n: int = 4


@dataclass(frozen=True)
class Line:
    """A place where a line may end: `flat` when its group is on one line, else a newline
    (after `tail`: " \\" where a statement goes on, outside brackets).  hard: always a
    newline."""

    flat: str = " "
    tail: str = ""
    hard: bool = False


@dataclass(frozen=True)
class Comment:
    """A comment on a line of its own, at the indentation where it stands: starts a line
    (unless one is just started) and ends it."""

    text: str


@dataclass(frozen=True)
class LineSuffix:
    """Text put off to the end of the line (a comment after the code on its line)."""

    text: str


@dataclass(frozen=True)
class BreakParent:
    """Breaks the groups around it (up to and with the first that stops breaks)."""


@dataclass(eq=False)
class Fill:
    """[content, separator, content, ...]: each separator breaks only if the content after
    it does not fit on the line (a list of outputs, a vector of numbers)."""

    parts: list = field(default_factory=list)


HARDLINE = Line(hard=True)
SOFTLINE = Line("")
BREAK_PARENT = BreakParent()


def propagate_breaks(doc) -> bool:
    """Marks broken every group that holds a hard line, a Comment or a BreakParent (not
    through a group that stops breaks); whether `doc` itself holds one."""
    # post-order without recursion: (node, children visited?); a node the document holds in
    # several places (a group's layouts share their parts) is visited once
    stack, result, expanded = [(doc, False)], {}, set()
    while stack:
        node, done = stack.pop()
        kids = _children(node)
        if not done:
            if id(node) in expanded:
                continue
            expanded.add(id(node))
            stack.append((node, True))
            stack.extend((k, False) for k in kids)
            continue
        if isinstance(node, (Comment, BreakParent)) or (isinstance(node, Line) and node.hard):
            result[id(node)] = True
            continue
        inner = any(result.get(id(k), False) for k in kids)
        if isinstance(node, Group):
            if inner:
                node.brk = True
            result[id(node)] = node.brk and not node.stop
        else:
            result[id(node)] = inner
    return result.get(id(doc), False)


def _children(node) -> list:
    if isinstance(node, list):
        return node
    if isinstance(node, Group):
        return [node.contents, *node.states]
    if isinstance(node, Indent):
        return [node.contents]
    if isinstance(node, Fill):
        return node.parts
    return []


def _fits(cmd, rest, width: int, must_be_flat: bool = False) -> bool:
    """Whether the command's text up to its first newline fits in width columns (the rest of
    the commands after it, in their own modes, until a newline)."""
    rest_i = len(rest)
    cmds = [cmd]
    while width >= 0:
        if not cmds:
            if rest_i == 0:
                return True
            rest_i -= 1
            cmds.append(rest[rest_i])
            continue
        ind, mode, doc = cmds.pop()
        if isinstance(doc, str):
            width -= len(doc)
        elif isinstance(doc, list):
            cmds.extend((ind, mode, d) for d in reversed(doc))
        elif isinstance(doc, Fill):
            cmds.extend((ind, mode, d) for d in reversed(doc.parts))
        elif isinstance(doc, Indent):
            cmds.append((ind, mode, doc.contents))
        elif isinstance(doc, Group):
            if must_be_flat and doc.brk:
                return False
            m = BREAK if doc.brk else mode
            cmds.append((ind, m, doc.states[-1] if doc.states and m == BREAK
                         else doc.contents))
        elif isinstance(doc, Line):
            if mode == BREAK or doc.hard:
                return width >= len(doc.tail)
            width -= len(doc.flat)
        elif isinstance(doc, Comment):
            return True
    return False


def render(doc, width: int = 100) -> str:
    """The document printed in `width` columns (lines longer only where nothing can break)."""
    propagate_breaks(doc)
    out: list[str] = []
    pos = 0
    fresh = True  # at the start of a line (only its indentation written)
    suffixes: list[str] = []
    cmds = [(0, BREAK, doc)]

    def newline(ind: int):
        nonlocal pos, fresh
        while out and out[-1].endswith(" "):  # (no trailing whitespace)
            out[-1] = out[-1].rstrip(" ")
            if not out[-1]:
                out.pop()
        if suffixes:
            out.extend(suffixes)
            suffixes.clear()
        out.append("\n" + " " * ind)
        pos, fresh = ind, True

    while cmds:
        ind, mode, doc = cmds.pop()
        if isinstance(doc, str):
            if doc:
                out.append(doc)
                pos += len(doc)
                fresh = False
        elif isinstance(doc, list):
            cmds.extend((ind, mode, d) for d in reversed(doc))
        elif isinstance(doc, Indent):
            cmds.append((ind + doc.n, mode, doc.contents))
        elif isinstance(doc, Group):
            _group(doc, ind, mode, cmds, width - pos)
        elif isinstance(doc, Fill):
            _fill(doc, ind, mode, cmds, width - pos)
        elif isinstance(doc, Line):
            if mode == FLAT and not doc.hard:
                out.append(doc.flat)
                pos += len(doc.flat)
                fresh = fresh and not doc.flat
            elif doc.hard or not fresh:
                if doc.tail:
                    out.append(doc.tail)
                newline(ind)
            elif out and out[-1].startswith("\n"):  # (a line just started, after a
                out[-1] = "\n" + " " * ind              # comment: at this one's indentation)
                pos = ind
        elif isinstance(doc, Comment):
            if not fresh:
                newline(ind)
            out.append(doc.text)
            newline(ind)
        elif isinstance(doc, LineSuffix):
            suffixes.append(doc.text)
    if suffixes:
        out.extend(suffixes)
    return "".join(out)


def _group(doc: Group, ind: int, mode: str, cmds: list, room: int):
    if mode == FLAT and not doc.brk:
        cmds.append((ind, FLAT, doc.contents))
        return
    flat = (ind, FLAT, doc.contents)
    if not doc.brk and _fits(flat, cmds, room):
        cmds.append(flat)
        return
    if not doc.states:
        cmds.append((ind, BREAK, doc.contents))
        return
    if not doc.brk:
        for state in doc.states[:-1]:
            cmd = (ind, FLAT, state)
            if _fits(cmd, cmds, room):
                cmds.append(cmd)
                return
    cmds.append((ind, BREAK, doc.states[-1]))


def _fill(doc: Fill, ind: int, mode: str, cmds: list, room: int):
    parts = doc.parts
    if not parts:
        return
    # (each measure goes on to the separator after, broken: its comma, its " \\")
    content = parts[0]
    content_flat = (ind, FLAT, content)
    content_fits = _fits(content_flat, [(ind, BREAK, parts[1])] if len(parts) > 1 else [],
                         room, True)
    if len(parts) == 1:
        cmds.append(content_flat if content_fits else (ind, BREAK, content))
        return
    sep = parts[1]
    if len(parts) == 2:
        cmds.extend([(ind, FLAT, sep), content_flat] if content_fits
                    else [(ind, BREAK, sep), (ind, BREAK, content)])
        return
    rest = (ind, mode, Fill(parts[2:]))
    both = _fits((ind, FLAT, [content, sep, parts[2]]),
                 [(ind, BREAK, parts[3])] if len(parts) > 3 else [], room, True)
    if both:
        cmds.extend([rest, (ind, FLAT, sep), content_flat])
    elif content_fits:
        cmds.extend([rest, (ind, BREAK, sep), content_flat])
    else:
        cmds.extend([rest, (ind, BREAK, sep), (ind, BREAK, content)])


def flat_width(doc) -> int | None:
    """The width of doc on one line, or None if it cannot be on one (a comment, a hard line,
    a group that must break inside it)."""
    propagate_breaks(doc)
    width, stack = 0, [doc]
    while stack:
        d = stack.pop()
        if isinstance(d, str):
            width += len(d)
        elif isinstance(d, list):
            stack.extend(reversed(d))
        elif isinstance(d, Fill):
            stack.extend(reversed(d.parts))
        elif isinstance(d, Indent):
            stack.append(d.contents)
        elif isinstance(d, Group):
            if d.brk:
                return None
            stack.append(d.contents)
        elif isinstance(d, Line):
            if d.hard:
                return None
            width += len(d.flat)
        elif isinstance(d, (Comment, BreakParent)):
            return None
        elif isinstance(d, LineSuffix):
            width += len(d.text)
    return width
