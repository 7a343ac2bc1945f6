"""bgc lsp: a Language Server Protocol server on stdin and stdout, on pygls (the `lsp` extra).

What it offers (bgc.editor.language computes it; this module speaks the protocol):
- diagnostics as the user types: the errors and warnings of `bgc check`, their notes as
  related information, an error in an imported library shown where the document leads there;
- hover (an element's law, a component's ports, parameters, units and doc, a parameter's
  value, unit and doc), go to definition (across imports), completion (kinds, a library's
  components after `alias.`, an instance's ports and variables after `inst.`), the outline,
  and formatting by bgc fmt.

Work is bounded and never in the way: bgc's stages run on one worker thread, one job at a time,
in the order asked; a change is checked DEBOUNCE seconds after the last one, and a check that a
newer change made stale is dropped before it starts and never published.  The reduce stage
(SymPy) runs after the other stages' diagnostics are out, and only for systems small enough
(bgc.editor.language.REDUCE_EQUATIONS, estimated before the work).  Nothing a document holds
stops the server: a request that fails answers nothing (and says why in the client's log)."""
from __future__ import annotations

import asyncio
import functools
import logging
import os
import sys
from concurrent.futures import ThreadPoolExecutor

from lsprotocol import types as T
from pygls import uris
from pygls.lsp.server import LanguageServer
from pygls.workspace import PositionCodec
from pygls.workspace.position_codec import ServerTextPosition

from ..base.diagnostics import ModelError
from . import fmt, language

DEBOUNCE = 0.15  # seconds from the last change to the check of a document
SEVERITY = {"error": T.DiagnosticSeverity.Error, "warning": T.DiagnosticSeverity.Warning}
SYMBOLS = {"model": T.SymbolKind.Module, "library": T.SymbolKind.Package,
           "import": T.SymbolKind.Package, "parameter": T.SymbolKind.Constant,
           "element": T.SymbolKind.Object, "signal": T.SymbolKind.Variable,
           "port": T.SymbolKind.Interface, "constant": T.SymbolKind.Constant,
           "component": T.SymbolKind.Class, "scene": T.SymbolKind.Event}
ITEMS = {"kind": T.CompletionItemKind.Class, "component": T.CompletionItemKind.Class,
         "library": T.CompletionItemKind.Module, "port": T.CompletionItemKind.Interface,
         "parameter": T.CompletionItemKind.Constant, "element": T.CompletionItemKind.Variable,
         "signal": T.CompletionItemKind.Variable, "variable": T.CompletionItemKind.Field}

log = logging.getLogger("bgc.lsp")


def _version() -> str:
    try:
        from importlib.metadata import version
        return version("bgc")
    except Exception:  # noqa: BLE001  (a source tree, not installed)
        return "0"


class BgcServer(LanguageServer):
    """The server: the documents' last checks and indexes, and the one worker of bgc."""

    def __init__(self):
        super().__init__("bgc", _version(), text_document_sync_kind=T.TextDocumentSyncKind.Incremental)
        self.work = ThreadPoolExecutor(max_workers=1, thread_name_prefix="bgc")
        self.pending: dict[str, asyncio.Task] = {}
        self.indexes: dict[str, tuple[int, language.File | None]] = {}  # uri -> (version, File)
        self.good: dict[str, language.File] = {}  # uri -> the last version that parsed

    # ------------------------------------------------------------ documents
    def path_of(self, uri: str) -> str:
        return uris.to_fs_path(uri) or uri

    def text_of(self, uri: str) -> tuple[int, str]:
        doc = self.workspace.get_text_document(uri)
        return doc.version or 0, doc.source

    def current(self, uri: str, version: int) -> bool:
        return uri in self.workspace.text_documents and self.text_of(uri)[0] == version

    async def run(self, fn, *args):
        """fn(*args) on the worker; None if it failed (said in the client's log: a bug of
        bgc, never the server's end)."""
        loop = asyncio.get_running_loop()
        value, error = await loop.run_in_executor(self.work,
                                                  functools.partial(_guarded, fn, *args))
        if error is not None:
            self.window_log_message(T.LogMessageParams(type=T.MessageType.Error,
                                                       message=f"bgc lsp: {error}"))
        return value

    def schedule(self, uri: str, delay: float):
        """Check the document delay seconds from now (a newer change cancels the check)."""
        old = self.pending.pop(uri, None)
        if old is not None:
            old.cancel()
        self.pending[uri] = asyncio.ensure_future(self.diagnose(uri, delay))

    async def diagnose(self, uri: str, delay: float):
        try:
            await asyncio.sleep(delay)
            version, text = self.text_of(uri)
            path = self.path_of(uri)
            checked = await self.run(language.check, text, path)
            if checked is None or not self.current(uri, version):
                return
            self.publish(uri, version, text, checked.diagnostics)
            if language.reducible(checked):
                found = await self.run(language.check_reduced, checked)
                if found is not None and self.current(uri, version):
                    self.publish(uri, version, text, found)
        except asyncio.CancelledError:
            pass
        except Exception as error:  # noqa: BLE001  (never the server's end)
            log.error("checking %s failed: %r", uri, error)

    def publish(self, uri: str, version: int, text: str, diagnostics):
        out = []
        for d in diagnostics:
            where = language.locate(d)
            out.append(T.Diagnostic(
                range=self.range(where.where, text), message=where.message,
                severity=SEVERITY.get(d.severity, T.DiagnosticSeverity.Error), source="bgc",
                related_information=[T.DiagnosticRelatedInformation(
                    location=self.location(uri, p, text), message=m) for p, m in where.related]
                or None))
        self.text_document_publish_diagnostics(
            T.PublishDiagnosticsParams(uri=uri, diagnostics=out, version=version))

    # ------------------------------------------------------------ positions
    @property
    def codec(self) -> PositionCodec:
        return self.workspace.position_codec

    def range(self, p: language.Place, text: str) -> T.Range:
        lines = text.split("\n")
        return T.Range(start=self.position(p.start, lines), end=self.position(p.end, lines))

    def position(self, pos: tuple[int, int], lines: list[str]) -> T.Position:
        line, char = pos
        if line >= len(lines):
            return T.Position(line=max(0, len(lines) - 1), character=self.codec.client_num_units(
                lines[-1]) if lines else 0)
        return self.codec.position_to_client_units(lines, ServerTextPosition(line, max(0, char)))

    def location(self, uri: str, p: language.Place, text: str) -> T.Location:
        if p.path is None:
            return T.Location(uri=uri, range=self.range(p, text))
        lib = language.library(p.path)
        return T.Location(uri=uris.from_fs_path(p.path) or p.path,
                          range=self.range(p, lib.text if lib is not None else ""))

    def server_position(self, uri: str, position: T.Position) -> tuple[int, int]:
        lines = self.text_of(uri)[1].split("\n")
        pos = self.codec.position_from_client_units(lines, position)
        return pos.line, pos.character

    # ------------------------------------------------------------ indexes
    def index(self, uri: str, version: int, text: str) -> language.File | None:
        """The document's index (on the worker): of this version, or of the last that parsed
        (the document with the line being written left out first)."""
        kept = self.indexes.get(uri)
        if kept is not None and kept[0] == version:
            return kept[1] or self.good.get(uri)
        path = self.path_of(uri)
        found = language.index(text, path)
        if found is not None:
            self.good[uri] = found
        self.indexes[uri] = (version, found)
        return found or self.good.get(uri)

    async def index_at(self, uri: str, pos: tuple[int, int], blank_line: bool = False):
        version, text = self.text_of(uri)
        found = await self.run(self.index, uri, version, text)
        if found is not None and found.text == text or not blank_line:
            return found
        lines = text.split("\n")  # (a completion while the line does not parse yet)
        if 0 <= pos[0] < len(lines):
            lines[pos[0]] = ""
        return await self.run(language.index, "\n".join(lines), self.path_of(uri)) or found


def _guarded(fn, *args):
    """(fn(*args), None), or (None, what went wrong)."""
    try:
        return fn(*args), None
    except Exception as error:  # noqa: BLE001  (a bug of bgc: said, never the server's end)
        log.error("%s failed: %r", getattr(fn, "__name__", fn), error, exc_info=True)
        return None, f"{getattr(fn, '__name__', fn)} failed: {error!r}"


server = BgcServer()


@server.feature(T.TEXT_DOCUMENT_DID_OPEN)
def did_open(ls: BgcServer, params: T.DidOpenTextDocumentParams):
    ls.schedule(params.text_document.uri, 0)


@server.feature(T.TEXT_DOCUMENT_DID_CHANGE)
def did_change(ls: BgcServer, params: T.DidChangeTextDocumentParams):
    ls.schedule(params.text_document.uri, DEBOUNCE)


@server.feature(T.TEXT_DOCUMENT_DID_SAVE)
def did_save(ls: BgcServer, params: T.DidSaveTextDocumentParams):
    ls.schedule(params.text_document.uri, 0)


@server.feature(T.TEXT_DOCUMENT_DID_CLOSE)
def did_close(ls: BgcServer, params: T.DidCloseTextDocumentParams):
    uri = params.text_document.uri
    task = ls.pending.pop(uri, None)
    if task is not None:
        task.cancel()
    ls.indexes.pop(uri, None)
    ls.good.pop(uri, None)
    ls.text_document_publish_diagnostics(T.PublishDiagnosticsParams(uri=uri, diagnostics=[]))


@server.feature(T.TEXT_DOCUMENT_HOVER)
async def hover(ls: BgcServer, params: T.HoverParams):
    uri = params.text_document.uri
    pos = ls.server_position(uri, params.position)
    f = await ls.index_at(uri, pos)
    found = await ls.run(language.hover, f, pos) if f is not None else None
    if found is None:
        return None
    text, (start, end) = found
    return T.Hover(contents=T.MarkupContent(kind=T.MarkupKind.Markdown, value=text),
                   range=ls.range(language.Place(None, start, end), ls.text_of(uri)[1]))


@server.feature(T.TEXT_DOCUMENT_DEFINITION)
async def definition(ls: BgcServer, params: T.DefinitionParams):
    uri = params.text_document.uri
    pos = ls.server_position(uri, params.position)
    f = await ls.index_at(uri, pos)
    found = await ls.run(language.definition, f, pos) if f is not None else None
    if found is None:
        return None
    return ls.location(uri, found, ls.text_of(uri)[1])


@server.feature(T.TEXT_DOCUMENT_COMPLETION, T.CompletionOptions(trigger_characters=[".", ":"]))
async def completion(ls: BgcServer, params: T.CompletionParams):
    uri = params.text_document.uri
    pos = ls.server_position(uri, params.position)
    f = await ls.index_at(uri, pos, blank_line=True)
    if f is None:
        return None
    items = await ls.run(language.complete, f, ls.text_of(uri)[1], pos) or []
    return T.CompletionList(is_incomplete=False, items=[
        T.CompletionItem(label=i.label, kind=ITEMS.get(i.what), detail=i.detail or None,
                         documentation=T.MarkupContent(kind=T.MarkupKind.Markdown, value=i.doc)
                         if i.doc else None) for i in items])


@server.feature(T.TEXT_DOCUMENT_DOCUMENT_SYMBOL)
async def symbols(ls: BgcServer, params: T.DocumentSymbolParams):
    uri = params.text_document.uri
    version, text = ls.text_of(uri)
    f = await ls.run(ls.index, uri, version, text)
    if f is None:
        return None
    found = await ls.run(language.outline, f) or []
    lines_text = f.text

    def convert(s: language.Symbol) -> T.DocumentSymbol:
        return T.DocumentSymbol(name=s.name, kind=SYMBOLS.get(s.what, T.SymbolKind.Variable),
                                range=ls.range(s.where, lines_text),
                                selection_range=ls.range(s.name_at, lines_text),
                                detail=s.detail or None,
                                children=[convert(c) for c in s.children] or None)
    return [convert(s) for s in found]


@server.feature(T.TEXT_DOCUMENT_FORMATTING)
async def formatting(ls: BgcServer, params: T.DocumentFormattingParams):
    uri = params.text_document.uri
    version, text = ls.text_of(uri)
    out = await ls.run(_formatted, text, ls.path_of(uri))
    if out is None or out == text:
        return []
    lines = text.split("\n")
    end = ls.position((len(lines) - 1, len(lines[-1])), lines)
    return [T.TextEdit(range=T.Range(start=T.Position(line=0, character=0), end=end),
                       new_text=out)]


def _formatted(text: str, path: str) -> str | None:
    """bgc fmt's text, or None: a syntax error (the diagnostics show it)."""
    try:
        return fmt.format_text(text, path)
    except ModelError:
        return None


def main() -> None:
    """Serve on stdin and stdout until the client says exit."""
    logging.basicConfig(stream=sys.stderr, level=os.environ.get("BGC_LSP_LOG", "WARNING"),
                        format="bgc lsp: %(levelname)s: %(message)s")
    server.start_io()
