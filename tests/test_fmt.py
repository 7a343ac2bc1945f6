"""bgc fmt (bgc/editor/fmt.py): the canonical layout of a model's text, and its command.

The references are independent of the formatter: a file's own bytes (formatting a formatted
file, or a file formatted once, changes nothing), the golden generated code of models/ (written
from the models before they were formatted), the generated code of the same model written in a
scrambled layout, the token stream the lexer reads, exit statuses and the bytes of files left
alone."""
from __future__ import annotations

import importlib.util
import os
import random
from dataclasses import fields, is_dataclass
from functools import lru_cache
from pathlib import Path

import pytest
from click.testing import CliRunner

from bgc import api
from bgc.cli import main
from bgc.base.diagnostics import ModelError, Span
from bgc.editor import fmt
from bgc.front import instantiate
from bgc.codegen.emit import c_runtime_parts, emit_c, emit_python, python_runtime
from conftest import run_bgc

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "golden"
MODELS = sorted([*ROOT.glob("models/*.bg"), *ROOT.glob("tests/models/*.bg"),
                 *ROOT.glob("benchmarks/models/*.bg")])
LIBRARIES = sorted(ROOT.glob("bgc/library/*.bg"))
# Left in their own layout: their expected diagnostics (tests/errors/*.err: line:col and the
# source line) and the fuzzers' regressions (the text that once failed, as it was found).
LEFT_ALONE = sorted([*ROOT.glob("tests/errors/*.bg"), *ROOT.glob("tests/fuzz_regressions/*.bg")])


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def _tool():
    spec = importlib.util.spec_from_file_location("fmt_docs", ROOT / "tools" / "fmt_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ---------------------------------------------------------------- the repository is formatted
def test_every_model_and_library_of_the_repository_is_formatted():
    result = run_bgc("fmt", "--check", *[_rel(p) for p in MODELS + LIBRARIES])
    assert result.returncode == 0 and result.stdout == "", result.stdout + result.stderr


def test_every_bg_block_of_the_manual_is_formatted():
    tool = _tool()
    stale = [p.name for p in tool.pages() if tool.format_page(p.read_text("utf-8")) !=
             p.read_text("utf-8")]
    assert not stale, f"run python tools/fmt_docs.py: {stale}"


def _texts():
    for p in MODELS + LIBRARIES + LEFT_ALONE:
        yield pytest.param(p.read_bytes().decode("utf-8", "replace"), id=_rel(p))
    tool = _tool()
    for page in tool.pages():
        for k, block in enumerate(page.read_text("utf-8").split("```bg")[1:]):
            yield pytest.param(block.split("\n", 1)[1].split("```")[0],
                               id=f"{page.name}-{k}")


@pytest.mark.parametrize("text", list(_texts()))
def test_formatting_twice_changes_nothing_more(text):
    """Every .bg text of the repository (those left in their own layout too, and the manual's
    blocks, error examples included) that parses: formatted once is formatted."""
    try:
        once = fmt.format_text(text)
    except ModelError:
        return  # (a syntax error: test_a_syntax_error_leaves_the_file_alone)
    assert fmt.format_text(once) == once


# ---------------------------------------------------------------- meaning
def scrambled(text: str, seed: int) -> str:
    """text in another layout, made from the tokens the lexer reads: random blanks between
    them, line breaks inside brackets, line continuations outside, `;` for some newlines;
    comments and blank lines where they were."""
    rng = random.Random(seed)
    text, tree = fmt._tree(text)
    tokens = fmt._leaves(tree)
    before = {}
    for k, c in fmt._comments(text, tokens):
        before.setdefault(k, []).append(c)
    out, depth, prev = [], 0, None
    for k, tok in enumerate(tokens):
        for c in before.get(k, ()):
            own = prev is None or prev.end_line != c.line
            out.append(("\n" if own and depth else " ") + c.text + ("\n" if depth else ""))
        if tok.type == "_NL":
            plain = (tok == "\n" and k not in before and k + 1 not in before
                     and prev is not None and str(prev) != "{")
            out.append(" ; " if plain and rng.random() < 0.3 else str(tok))
        else:
            if prev is not None and prev.type != "_NL":
                r = rng.random()
                if depth and r < 0.2:
                    out.append("\n" + " " * rng.randrange(9))
                elif not depth and r < 0.1 and str(prev) != ";":
                    out.append(" \\\n" + " " * rng.randrange(9))
                else:
                    out.append(" " * rng.randrange(1, 4))
            out.append(str(tok))
            depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(str(tok), 0) * (tok.type != "STRING")
        prev = tok
    return "".join(out)


def test_the_scrambler_keeps_the_tokens():
    """(The test's own tool: the lexer reads the same tokens and comments from a scrambled
    text, and it is another layout.)"""
    text = (ROOT / "models" / "pendulum_chain.bg").read_text("utf-8")
    other = scrambled(text, 1)
    assert other != text and fmt._signature(other) == fmt._signature(text)


@lru_cache(maxsize=None)
def _code(path: str, text: str) -> tuple[str, str]:
    """The generated C and Python of the text's default scene (built once per text)."""
    program = api.build(api.Source(path, text)).program
    (c,), (py,) = emit_c(program).values(), emit_python(program).values()
    return c, py


def _meaning(path: str, text: str):
    """The flat model the front end makes of the text (parsed, components and libraries
    instantiated, constants and `for` expanded), without its source spans: what every later
    stage reads besides the spans, which reach only the messages (the models of models/ show
    it above: their scrambled layouts generate the golden code)."""
    work, out = [instantiate.front(api.Source(path, text))], []
    while work:  # (iteratively: a long sum is a deep tree)
        node = work.pop()
        if isinstance(node, Span) or node == text:  # (the model keeps its text: messages)
            out.append("span")
        elif is_dataclass(node) and not isinstance(node, type):
            out.append(type(node).__name__)
            work.extend(getattr(node, f.name) for f in reversed(fields(node)))
        elif isinstance(node, (tuple, list)):
            out.append(("(", len(node)))
            work.extend(reversed(node))
        elif isinstance(node, dict):
            out.append(("{", len(node)))
            work.extend(x for k in reversed(list(node)) for x in (node[k], k))
        else:
            out.append(node)
    return out


def model_part(text: str) -> str:
    """The generated file without the runtime every program holds, as the golden files keep
    it (tests/test_golden.py)."""
    parts = dict(c_runtime_parts(), python=python_runtime())
    for name, part in parts.items():
        text = text.replace(part, f"[runtime: {name}]\n")
    return text


@pytest.mark.parametrize("path", MODELS, ids=_rel)
def test_formatting_is_the_layout_alone(path):
    """A model in a scrambled layout formats to the file (which is formatted), and means the
    same: for models/, it generates the golden files' C and Python byte for byte (written from
    the models before they were formatted); for the others, the same flat model as the file's
    own text, spans apart (_meaning)."""
    text = path.read_text("utf-8")
    other = scrambled(text, seed=len(text))
    assert fmt.format_text(other) == text
    if path.parent == ROOT / "models":
        c, py = _code(str(path), other)
        golden = GOLDEN / path.stem / "default"
        assert model_part(c) == golden.with_suffix(".c").read_text("utf-8")
        assert model_part(py) == golden.with_suffix(".py").read_text("utf-8")
    else:
        assert _meaning(str(path), other) == _meaning(str(path), text)


def test_a_comment_stays_with_what_it_follows():
    text = ("model m  # the model\n"
            "# the parameters\n"
            "parameter a = 1 # first\n"
            "parameter bb = 2\n"
            "\n\n\n"
            "x : I(f(a, # inside\n"
            "  bb))\n"
            "scene s { # the scene\n"
            "  time 0 .. 1 # time\n"
            "  # last\n"
            "}\n")
    assert fmt.format_text(text) == ("model m  # the model\n"
                                     "# the parameters\n"
                                     "parameter a  = 1  # first\n"
                                     "parameter bb = 2\n"
                                     "\n"
                                     "x : I(f(\n"
                                     "    a,  # inside\n"
                                     "    bb\n"
                                     "))\n"
                                     "scene s {  # the scene\n"
                                     "  time 0 .. 1  # time\n"
                                     "  # last\n"
                                     "}\n")


def test_a_long_statement_breaks_inside_its_brackets_at_100_columns():
    args = ", ".join(f"a{i}*b{i}" for i in range(30))
    text = f"model m\nx : MSe(f({args}))\n"
    out = fmt.format_text(text)
    assert max(len(line) for line in out.splitlines()) <= fmt.WIDTH
    assert fmt._signature(out) == fmt._signature(text)
    assert out.splitlines()[1] == "x : MSe(f("


# ---------------------------------------------------------------- the command
BAD = "model m\nx : 1  (\n"
LOOSE = "model m\nparameter a=1;x:I( a )\n"
TIGHT = "model m\nparameter a = 1\nx : I(a)\n"


def test_check_names_what_would_change_and_changes_nothing(tmp_path):
    loose, tight = tmp_path / "loose.bg", tmp_path / "tight.bg"
    loose.write_text(LOOSE)
    tight.write_text(TIGHT)
    result = run_bgc("fmt", "--check", loose, tight)
    assert result.returncode == 1 and result.stdout == f"{loose}\n"
    assert loose.read_text() == LOOSE


def test_diff_prints_what_would_change(tmp_path):
    loose = tmp_path / "loose.bg"
    loose.write_text(LOOSE)
    result = run_bgc("fmt", "--diff", loose)
    assert result.returncode == 0 and loose.read_text() == LOOSE
    removed = [x[1:] for x in result.stdout.splitlines() if x[:1] == "-" and x[:3] != "---"]
    added = [x[1:] for x in result.stdout.splitlines() if x[:1] == "+" and x[:3] != "+++"]
    assert removed == ["parameter a=1;x:I( a )"] and added == TIGHT.splitlines()[1:]


def test_formatting_rewrites_the_file_and_keeps_its_mode(tmp_path):
    loose = tmp_path / "loose.bg"
    loose.write_text(LOOSE)
    os.chmod(loose, 0o640)
    assert run_bgc("fmt", loose).returncode == 0
    assert loose.read_text() == TIGHT and (os.stat(loose).st_mode & 0o777) == 0o640
    assert [p.name for p in tmp_path.iterdir()] == ["loose.bg"]  # (no file left beside it)
    assert run_bgc("fmt", "--check", loose).returncode == 0


def test_a_syntax_error_leaves_the_file_alone(tmp_path):
    bad = tmp_path / "bad.bg"
    bad.write_text(BAD)
    result = run_bgc("fmt", bad)
    assert result.returncode == 1
    assert result.stderr.startswith(f"{bad}:2:8: error: syntax error: unexpected '('")
    assert bad.read_text() == BAD and "Traceback" not in result.stderr


def test_standard_input_to_standard_output():
    result = CliRunner().invoke(main, ["fmt", "-"], input=LOOSE)
    assert result.exit_code == 0 and result.stdout == TIGHT
