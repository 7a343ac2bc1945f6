"""bgc lsp (bgc/editor/lsp.py) end to end: the server started as an editor starts it, `bgc
lsp` on stdin and stdout, spoken to by pygls's own client (a real LSP client: JSON-RPC with
Content-Length headers).  One server for the module.

The references are independent of the server: the located errors of `bgc check` (the golden
.err files of tests/errors, and `bgc check` run on the same text), the library's own files read
as text, `bgc fmt`'s output, and the server still answering after a seeded run of random
edits."""
from __future__ import annotations

import asyncio
import random
import re
import sys
from pathlib import Path

import pytest

pytest.importorskip("pygls")

from lsprotocol import types as T  # noqa: E402
from pygls.lsp.client import LanguageClient  # noqa: E402

from bgc.editor import fmt, language  # noqa: E402
from conftest import run_bgc  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
ERRORS = ROOT / "tests" / "errors"
LIBRARY = ROOT / "bgc" / "library"
TIMEOUT = 20.0  # seconds a step may take at most (a slow machine), never waited when done


class Session:
    """The client, its own event loop (run while a step waits), what the server published."""

    def __init__(self):
        self.loop = asyncio.new_event_loop()
        self.client = LanguageClient("bgc-tests", "1")
        self.published: dict[str, T.PublishDiagnosticsParams] = {}
        self.versions: dict[str, int] = {}
        self.log: list[str] = []  # the server's window/logMessage errors (a bug of bgc)

        @self.client.feature(T.TEXT_DOCUMENT_PUBLISH_DIAGNOSTICS)
        def diagnostics(params: T.PublishDiagnosticsParams):
            self.published[params.uri] = params

        @self.client.feature(T.WINDOW_LOG_MESSAGE)
        def logged(params: T.LogMessageParams):
            self.log.append(params.message)

    def run(self, coro, timeout: float = TIMEOUT):
        return self.loop.run_until_complete(asyncio.wait_for(coro, timeout))

    def start(self):
        self.run(self.client.start_io(sys.executable, "-m", "bgc", "lsp"))
        self.init = self.run(self.client.initialize_async(T.InitializeParams(
            capabilities=T.ClientCapabilities(), root_uri=ROOT.as_uri())))
        self.client.initialized(T.InitializedParams())

    def stop(self):
        try:
            self.run(self.client.shutdown_async(None), 5)
            self.client.exit(None)
            self.run(self.client.stop(), 5)
        finally:
            self.loop.close()

    # documents
    def open(self, path: Path, text: str | None = None) -> str:
        uri = path.as_uri()
        self.versions[uri] = 1
        self.client.text_document_did_open(T.DidOpenTextDocumentParams(T.TextDocumentItem(
            uri, "bg", 1, path.read_text("utf-8") if text is None else text)))
        return uri

    def change(self, uri: str, start, end, text: str) -> int:
        self.versions[uri] += 1
        self.client.text_document_did_change(T.DidChangeTextDocumentParams(
            T.VersionedTextDocumentIdentifier(uri=uri, version=self.versions[uri]),
            [T.TextDocumentContentChangePartial(range=T.Range(T.Position(*start),
                                                               T.Position(*end)), text=text)]))
        return self.versions[uri]

    def close(self, uri: str):
        self.client.text_document_did_close(T.DidCloseTextDocumentParams(
            T.TextDocumentIdentifier(uri)))

    def diagnostics(self, uri: str, until=lambda ds: True, version: int | None = None):
        """The diagnostics the server published for the document's version, once `until`
        holds for them (the server publishes again when the reduce stage is done)."""
        version = self.versions[uri] if version is None else version

        async def wait():
            while True:
                p = self.published.get(uri)
                if p is not None and p.version == version and until(p.diagnostics):
                    return p.diagnostics
                await asyncio.sleep(0.005)
        try:
            return self.run(wait())
        except asyncio.TimeoutError:
            p = self.published.get(uri)
            pytest.fail(f"no diagnostics as expected for {uri} v{version}; last: {p}")

    # requests
    def ask(self, method: str, uri: str, line: int, char: int):
        doc, pos = T.TextDocumentIdentifier(uri), T.Position(line, char)
        if method == "hover":
            return self.run(self.client.text_document_hover_async(T.HoverParams(doc, pos)))
        if method == "definition":
            return self.run(self.client.text_document_definition_async(
                T.DefinitionParams(doc, pos)))
        return self.run(self.client.text_document_completion_async(
            T.CompletionParams(doc, pos)))


@pytest.fixture(scope="module")
def lsp():
    session = Session()
    session.start()
    yield session
    session.stop()


def test_the_server_says_what_it_offers(lsp):
    caps = lsp.init.capabilities
    assert caps.hover_provider and caps.definition_provider and caps.document_symbol_provider
    assert caps.document_formatting_provider and "." in caps.completion_provider.trigger_characters
    assert lsp.init.server_info.name == "bgc"


# ---------------------------------------------------------------- diagnostics
ENTRY = re.compile(r"^(?P<path>[^\s:][^:]*?)(?::(?P<line>\d+):(?P<col>\d+))?: "
                   r"(?P<severity>error|warning|note): (?P<message>.*)$")
EXCERPT = re.compile(r"^ *(\d+) \| (.*)$")
CARET = re.compile(r"^ +\| *(\^~*)$")


def located(report: str):
    """The diagnostics of a `bgc check` report: [(severity, path, line, col, width or None,
    message, [(path, line, col, message) of its notes])], from its `path:line:col:` lines and
    carets (the width when the line is shown whole)."""
    out, shown = [], None
    for line in report.splitlines():
        m, e, c = ENTRY.match(line), EXCERPT.match(line), CARET.match(line)
        if m:
            at = (m["path"], int(m["line"] or 0), int(m["col"] or 0))
            if m["severity"] == "note":
                out[-1][6].append((*at, m["message"]))
            else:
                out.append([m["severity"], *at, None, m["message"], []])
            shown = None
        elif e:
            shown = e[2]
        elif c and shown is not None and "..." not in shown and not out[-1][6]:
            # (a range ends at its line's end at most: the end of a line or file marked)
            out[-1][4] = min(len(c[1]), len(shown) - out[-1][3] + 1)
    return out


def _same(published, expected, uri_path: Path) -> bool:
    """Whether the server's diagnostics are the report's: severity, message, place (a
    library's error at the first place in the document, the library's in the first related
    note), the notes with places."""
    if len(published) != len(expected):
        return False
    for d, (severity, path, line, col, width, message, notes) in zip(published, expected):
        if d.severity != {"error": T.DiagnosticSeverity.Error,
                          "warning": T.DiagnosticSeverity.Warning}[severity]:
            return False
        if d.message.split("\nnote: ")[0] != message:
            return False
        related = [(r.location.uri, r.location.range.start.line + 1,
                    r.location.range.start.character + 1, r.message)
                   for r in d.related_information or ()]
        ours = Path(path).resolve() == uri_path.resolve()
        if line and ours:
            if (d.range.start.line + 1, d.range.start.character + 1) != (line, col):
                return False
            if width is not None and d.range.start.line == d.range.end.line and \
                    d.range.end.character - d.range.start.character != width:
                return False
        if line and not ours:
            if not related or related[0][:3] != (Path(path).resolve().as_uri(), line, col):
                return False
            related = related[1:]
        want = [(Path(p).resolve().as_uri(), ln, cl, msg) for p, ln, cl, msg in notes if ln]
        if related != want:
            return False
    return True


def _cases():
    out = []
    for p in sorted(ERRORS.glob("*.bg")):
        try:
            p.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            continue  # (an editor sends text: a file that is not UTF-8 never reaches it)
        out.append(p)
    return out


@pytest.mark.parametrize("path", _cases(), ids=lambda p: p.stem)
def test_each_error_case_is_published_as_bgc_check_locates_it(lsp, path):
    """tests/errors: each bad model, opened, gives exactly the diagnostics of its .err file
    (`bgc check`'s report: message, line, column, width, notes)."""
    report = (ERRORS / f"{path.stem}.err").read_text("utf-8")
    report = report.replace("tests/errors/", f"{ERRORS}/")
    expected = located(report)
    uri = lsp.open(path)
    found = lsp.diagnostics(uri, lambda ds: _same(ds, expected, path))
    assert found is not None
    lsp.close(uri)


def test_a_change_is_checked_again_and_ranges_follow_bgc_check(lsp, tmp_path):
    """An edit that breaks the model: the new error where `bgc check` puts it for that text;
    the edit undone: no diagnostics."""
    path = tmp_path / "rc.bg"
    text = ("model rc\nparameter R = 1000\nparameter C = 1e-3\nsupply : Se(10)\n"
            "loop : 1\nr : R(R)\nc : C(C)\nsupply -> loop\nloop -> r\nloop -> c\n")
    uri = lsp.open(path, text)
    assert lsp.diagnostics(uri) == ()
    lsp.change(uri, (5, 6), (5, 7), "Rx")  # r : R(Rx): an unknown name
    broken = text.replace("r : R(R)", "r : R(Rx)")
    path.write_text(broken)
    report = run_bgc("check", path).stderr
    expected = located(report)
    assert expected and expected[0][5].startswith("unknown name 'Rx'")
    lsp.diagnostics(uri, lambda ds: _same(ds, expected, path))
    lsp.change(uri, (5, 6), (5, 8), "R")
    lsp.diagnostics(uri, lambda ds: ds == ())
    lsp.close(uri)


DRIVE = ROOT / "tests" / "models" / "dc_drive.bg"


def test_a_warm_check_parses_only_the_document(monkeypatch):
    """Warm, a check of a 100-line model parses its own text and nothing else: the libraries
    it imports were parsed once, before (what keeps diagnostics under 100 ms as one types;
    the time itself is measured by benchmarks/lsp.py, not here).  Its diagnostics are those
    of the cold check."""
    from bgc.front import parser
    text = DRIVE.read_text("utf-8")
    assert len(text.splitlines()) >= 100
    cold = language.check(text, str(DRIVE))
    assert language.reducible(cold) and language.check_reduced(cold) == ()
    parsed = []
    real = parser.parse

    def counting(source, path, *args, **kwargs):
        parsed.append(path)
        return real(source, path, *args, **kwargs)

    monkeypatch.setattr(parser, "parse", counting)
    monkeypatch.setattr(language, "parse", counting)
    warm = language.check(text, str(DRIVE))
    assert parsed == [str(DRIVE)]
    assert warm.diagnostics == cold.diagnostics
    assert language.check_reduced(warm) == ()


# ---------------------------------------------------------------- hover, definition, completion
MODEL = """model circuit "a resistor and a capacitor of the library"
import electrical as el
parameter Rl = 2 unit "Ohm" "the load"
supply : el.voltage_source(v = 5)
load : el.resistor(r = Rl)
store : el.capacitor(c = 1e-3)
gnd : el.ground()
n1 : 0
supply.p -> n1
n1 -> load.p
load.n -> store.p
store.n -> gnd.p
mx : I(1)
"""


def _component(lib: str, name: str) -> tuple[int, int, str]:
    """Line and column (from 0) of a component's name in a library file, and its doc string:
    read off the file's text."""
    lines = (LIBRARY / lib).read_text("utf-8").splitlines()
    k = next(i for i, x in enumerate(lines) if x.startswith(f"component {name}("))
    head = next(x for x in lines[k:] if x.endswith("{"))
    return k, len("component "), re.search(r'"([^"]*)" \{$', head)[1]


@pytest.fixture(scope="module")
def circuit(lsp, tmp_path_factory):
    uri = lsp.open(tmp_path_factory.mktemp("circuit") / "circuit.bg", MODEL)
    lsp.diagnostics(uri)
    return uri


def test_hover_a_library_component_shows_its_doc_ports_and_parameters(lsp, circuit):
    line = MODEL.splitlines().index("load : el.resistor(r = Rl)")
    hover = lsp.ask("hover", circuit, line, len("load : el.res"))
    text = hover.contents.value
    _, _, doc = _component("electrical.bg", "resistor")
    assert doc in text and "`p : electrical`" in text and "`n : electrical`" in text
    assert "`r = 1` unit `Ohm`" in text


def test_hover_an_element_kind_shows_its_law_and_a_parameter_its_value(lsp, circuit):
    lines = MODEL.splitlines()
    kind = lsp.ask("hover", circuit, lines.index("mx : I(1)"), len("mx : "))
    assert "dp/dt = e" in kind.contents.value
    param = lsp.ask("hover", circuit, lines.index("load : el.resistor(r = Rl)"),
                    len("load : el.resistor(r = R"))
    assert "= `2`" in param.contents.value and "unit `Ohm`" in param.contents.value
    assert "the load" in param.contents.value


def test_definition_jumps_into_the_imported_library(lsp, circuit):
    line = MODEL.splitlines().index("store : el.capacitor(c = 1e-3)")
    found = lsp.ask("definition", circuit, line, len("store : el.cap"))
    k, col, _ = _component("electrical.bg", "capacitor")
    assert found.uri == (LIBRARY / "electrical.bg").resolve().as_uri()
    assert (found.range.start.line, found.range.start.character) == (k, col)
    here = lsp.ask("definition", circuit, MODEL.splitlines().index("n1 -> load.p"), 7)
    assert here.uri == circuit and here.range.start.line == MODEL.splitlines().index(
        "load : el.resistor(r = Rl)")


def test_completion_of_ports_after_an_instance_and_components_after_an_alias(lsp, circuit):
    end = len(MODEL.splitlines())
    version = lsp.change(circuit, (end, 0), (end, 0), "load.")
    ports = {i.label for i in lsp.ask("completion", circuit, end, len("load.")).items}
    lines = (LIBRARY / "electrical.bg").read_text("utf-8").splitlines()
    k, _, _ = _component("electrical.bg", "resistor")
    body = lines[k:lines.index("}", k)]
    assert {"p", "n"} <= ports and {"r", "i", "res"} <= ports
    assert all(re.match(r"\s*port (\w+)", x)[1] in ports for x in body if "port " in x)
    lsp.change(circuit, (end, 0), (end, 5), "x : el.")
    components = {i.label for i in lsp.ask("completion", circuit, end, len("x : el.")).items}
    assert components == set(re.findall(r"^component (\w+)\(", "\n".join(lines), re.M))
    lsp.change(circuit, (end, 0), (end, 7), "x : ")
    kinds = {i.label for i in lsp.ask("completion", circuit, end, len("x : ")).items}
    assert {"Se", "Sf", "I", "C", "R", "TF", "GY", "MTF", "0", "1", "el"} <= kinds
    lsp.change(circuit, (end, 0), (end, 4), "")
    assert version


def test_the_outline_and_formatting(lsp, tmp_path):
    text = "model m\nparameter a=1;x:I( a )\nscene s { time 0 .. 1 }\n"
    uri = lsp.open(tmp_path / "m.bg", text)
    symbols = lsp.run(lsp.client.text_document_document_symbol_async(
        T.DocumentSymbolParams(T.TextDocumentIdentifier(uri))))
    assert [(s.name, s.kind) for s in symbols] == [
        ("m", T.SymbolKind.Module), ("a", T.SymbolKind.Constant), ("x", T.SymbolKind.Object),
        ("s", T.SymbolKind.Event)]
    edits = lsp.run(lsp.client.text_document_formatting_async(T.DocumentFormattingParams(
        T.TextDocumentIdentifier(uri), T.FormattingOptions(tab_size=2, insert_spaces=True))))
    assert len(edits) == 1 and edits[0].new_text == fmt.format_text(text)
    assert edits[0].range.start == T.Position(0, 0)
    lsp.close(uri)


# ---------------------------------------------------------------- never stopped
def test_random_edits_never_stop_the_server(lsp, tmp_path):
    """A seeded run of edits that delete and insert tokens anywhere (a model broken in every
    way on the way), each followed by a request: the server answers each, and checks the
    last version."""
    rng = random.Random(43)
    text = (ROOT / "models" / "gantry_crane.bg").read_text("utf-8")
    uri = lsp.open(tmp_path / "crane.bg", text)
    pieces = ["(", ")", "[", "]", "{", "}", "->", ":", "=", ",", ".", "@", "\n", " 0 ", "x",
              "el.", "import electrical as el\n", "component c(", "1e999", '"', "#", "\\\n",
              "scene s {", "for i in 1..3 {", "if ", "when t > 1 {", "^", "-", "init"]
    for step in range(60):
        lines = text.split("\n")
        line = rng.randrange(len(lines))
        col = rng.randrange(len(lines[line]) + 1)
        if rng.random() < 0.5 and lines[line]:
            end = min(len(lines[line]), col + rng.randrange(1, 6))
            new, piece = lines[line][:col] + lines[line][end:], ""
            lsp.change(uri, (line, col), (line, end), "")
        else:
            piece = rng.choice(pieces)
            new = lines[line][:col] + piece + lines[line][col:]
            lsp.change(uri, (line, col), (line, col), piece)
        lines[line] = new
        text = "\n".join(lines)
        method = ("hover", "definition", "completion")[step % 3]
        line = rng.randrange(len(lines))
        lsp.ask(method, uri, line, rng.randrange(len(lines[line]) + 1))
        if step % 10 == 9:  # (saved: checked at once, not after the pause for typing)
            lsp.client.text_document_did_save(T.DidSaveTextDocumentParams(
                T.TextDocumentIdentifier(uri)))
            lsp.diagnostics(uri)
    path = tmp_path / "crane.bg"
    path.write_text(text)
    expected = located(run_bgc("check", path).stderr)
    lsp.diagnostics(uri, lambda ds: _same(ds, expected, path))
    assert lsp.log == []


def test_a_model_too_large_to_reduce_at_each_change_gets_the_other_stages_diagnostics(lsp,
                                                                                      tmp_path):
    """A ladder of 150 RC stages (more equations than REDUCE_EQUATIONS): its diagnostics are
    those of the stages before reduce, published without waiting for SymPy (a warning that
    only those stages find: a junction without bonds)."""
    text = ("model ladder\nconstant N = 150\nsupply : Se(1)\nfor i in 1..N {\n"
            "  node[i] : 0\n  r[i] : R(1)\n  c[i] : C(1)\n  link[i] : 1\n"
            "  node[i] -> c[i]\n  link[i] -> r[i]\n}\n"
            "supply -> link[1]\nlink[1] -> node[1]\n"
            "for i in 2..N {\n  node[i-1] -> link[i]\n  link[i] -> node[i]\n}\nidle : 0\n")
    checked = language.check(text, str(tmp_path / "ladder.bg"))
    assert not language.reducible(checked)
    uri = lsp.open(tmp_path / "ladder.bg", text)
    found = lsp.diagnostics(uri)
    assert [d.message for d in found] == ["junction 'idle' has no bonds"]
    assert found[0].range.start.line == text.splitlines().index("idle : 0")
