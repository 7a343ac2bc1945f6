"""Source spans and model diagnostics: `path:line:col: error: message`, the line, carets."""
from __future__ import annotations

import difflib
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Origin:
    """Text that is not the model file but is reported like it: an option's value on the
    command line (`--outputs`), an argument of the API, or a file the model reads (a table's:
    file True)."""

    name: str
    text: str
    file: bool = False


@dataclass(frozen=True)
class Span:
    """A region of one source file; lines and columns are 1-based, end exclusive.  origin:
    None for the model file, else the text the span is in."""

    line: int
    col: int
    end_line: int
    end_col: int
    origin: Origin | None = field(default=None, compare=False)
    # inside a component: the chain of instances that led here, innermost first, as
    # ((instance path, span of the instance's declaration), ...)
    chain: tuple = field(default=(), compare=False)

    def join(self, other: "Span") -> "Span":
        start = min((self.line, self.col), (other.line, other.col))
        end = max((self.end_line, self.end_col), (other.end_line, other.end_col))
        return Span(start[0], start[1], end[0], end[1], self.origin, self.chain)



@dataclass(frozen=True)
class Note:
    span: Span | None
    message: str


@dataclass(frozen=True)
class Diagnostic:
    severity: str  # "error" | "warning"
    span: Span | None
    message: str
    notes: tuple[Note, ...] = ()


class ModelError(Exception):
    """One or more errors in a model (never a bug in bgc)."""

    def __init__(self, diagnostics):
        self.diagnostics = tuple(diagnostics)
        super().__init__("; ".join(d.message for d in self.diagnostics))


def error(span: Span | None, message: str, *notes: Note) -> Diagnostic:
    return Diagnostic("error", span, message, tuple(notes))


def warning(span: Span | None, message: str, *notes: Note) -> Diagnostic:
    return Diagnostic("warning", span, message, tuple(notes))


def fail(span: Span | None, message: str, *notes: Note):
    raise ModelError([error(span, message, *notes)])


@dataclass
class Collector:
    """Semantic stages collect all their diagnostics, then stop (see raise_if_errors)."""

    items: list = field(default_factory=list)

    def error(self, span, message, *notes):
        self.items.append(error(span, message, *notes))

    def warning(self, span, message, *notes):
        self.items.append(warning(span, message, *notes))

    @property
    def errors(self):
        return [d for d in self.items if d.severity == "error"]

    @property
    def warnings(self):
        return tuple(d for d in self.items if d.severity == "warning")

    def raise_if_errors(self):
        if self.errors:
            raise ModelError(self.errors)


EXCERPT_WIDTH = 100  # longer source lines are shown as a window around the column


def _excerpt(source_lines, span: Span) -> list[str]:
    if span is None or not (1 <= span.line <= len(source_lines)):
        return []
    text = source_lines[span.line - 1].rstrip("\n").expandtabs(1)
    end_col = span.end_col if span.end_line == span.line else len(text) + 1
    start, col = 0, span.col
    if len(text) > EXCERPT_WIDTH:
        start = max(0, min(span.col - 1 - EXCERPT_WIDTH // 3, len(text) - EXCERPT_WIDTH))
        shown = text[start:start + EXCERPT_WIDTH]
        prefix = "..." if start > 0 else ""
        text = prefix + shown + ("..." if start + EXCERPT_WIDTH < len(text) else "")
        col = span.col - start + len(prefix)
        end_col = min(end_col - start + len(prefix), len(prefix) + len(shown) + 1)
    gutter = f"{span.line:>4} | "
    width = max(1, end_col - col)
    caret = " " * (len(gutter) - 2) + "| " + " " * (col - 1) + "^" + "~" * (width - 1)
    return [gutter + text, caret]


def _located(span: Span | None, path: str, source: str | None) -> tuple[str, list[str]]:
    """`path:line:col` and the source lines the span is in (an origin's, when it has one)."""
    if span is not None and span.origin is not None:
        path, source = span.origin.name, span.origin.text
    lines = source.splitlines() if source is not None else []
    return (f"{path}:{span.line}:{span.col}" if span else path), lines


def format_diagnostic(d: Diagnostic, path: str, source: str | None) -> str:
    where, lines = _located(d.span, path, source)
    out = [f"{where}: {d.severity}: {d.message}"]
    out += _excerpt(lines, d.span)
    for n in d.notes + instance_notes(d.span):
        nwhere, nlines = _located(n.span, path, source)
        out.append(f"{nwhere}: note: {n.message}")
        out += _excerpt(nlines, n.span)
    return "\n".join(out)


def instance_notes(span: Span | None) -> tuple[Note, ...]:
    """One note per level of the chain of instances a span inside a component came from."""
    if span is None:
        return ()
    return tuple(Note(at, f"in instance {path}") for path, at in span.chain)


def did_you_mean(name: str, candidates) -> str:
    """' (did you mean 'x'?)' for the closest candidate, or ''."""
    close = difflib.get_close_matches(name, sorted(set(candidates)), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""
