"""Every example in README.md and docs/*.md, run.

The convention (docs/architecture.md, "Examples in the documentation"): every fenced block has
an info string, a language followed by words `key` or `key=value` (a value may be quoted):

  bg                  a complete model: `bgc check` passes for its default scene and for
                      each of its scenes
  bg file=NAME        the same, and the model is saved as NAME for the page's later blocks
  bg fragment         part of a model: it must parse (after a `model` line if it has none);
                      it is not checked further
  bg keep-layout      (with any of the others) its layout is what the block shows: bgc fmt
                      leaves it as it is (tools/fmt_docs.py); every other bg block but an
                      error's is in bgc fmt's layout (tests/test_fmt.py)
  bg error            a model that bgc refuses: `bgc check` (with scene=NAME, `--scene NAME`)
                      exits 1 with a located error; error="TEXT": the report contains TEXT
  sh                  commands, one a line (`\\` continues a line, `#` starts a comment); each
                      must exit 0 (status=N: each must exit N)
  sh dry-run          commands too slow for the tests (`bgc accuracy`): each is parsed as
                      bgc would parse it and its model built for its scene, but not run
  sh skip="REASON"    not run at all, for the reason given
  sh needs=PROGRAM    run only where PROGRAM is on the PATH (Graphviz's `dot` for `bgc draw`
                      to SVG or PNG), else not run: an optional tool, not a slow command
  python              run; a page's python blocks share one namespace
  c file=NAME         saved as NAME for a later sh block
  text output=STREAM  what the last command of the sh block before it writes on STREAM
                      (stdout or stderr): compared with it, the processor seconds (`cpu=`)
                      masked
  text, c             other output and listings: not run

A page's blocks run in order in a fresh directory, where `models` is the repository's models/
directory.  A `bgc` command without shell syntax runs in this process (click's CliRunner),
with the default backend (auto, as a user's: what it writes is what the page shows);
any other line runs in bash, with `bgc` and `python` on the PATH.  For speed, C is compiled
without optimisation: bgc's C backend with -O0 ($BGC_CFLAGS, set in conftest.py), and `-O2`
in a command line reads `-O0`; the generated code's results do not depend on it (test_emit and the
golden files test the code itself).  Marks that leave a block unrun or partly run (fragment,
dry-run, skip) are counted, and their number is bounded below (MAX_MARKS).
No numbers are copied from bgc's output unchecked: commands must succeed, where a page states
a result (a closed form) its python block checks it independently, and output a page shows is
marked `output=` and compared.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner

from bgc import api
from bgc.cli import main
from bgc.front.parser import parse

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
LANGUAGES = {"bg", "sh", "python", "text", "c"}
KEYS = {"bg": {"file", "fragment", "error", "scene", "keep-layout"},
        "sh": {"status", "dry-run", "skip", "needs"},
        "python": set(), "text": {"output"}, "c": {"file"}}
# Blocks left unrun or partly run, at most (keep them few: every other example runs).
MAX_MARKS = {"fragment": 4, "dry-run": 2, "skip": 1}
SHELL_SYNTAX = re.compile(r"[|&;<>()$`]")
FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")


class Block:
    def __init__(self, page: Path, line: int, info: str, text: str):
        self.page, self.line, self.text = page, line, text
        words = shlex.split(info)
        self.lang = words[0] if words else ""
        self.opts = {}
        for w in words[1:]:
            key, _, value = w.partition("=")
            self.opts[key] = value or True

    def __repr__(self):
        return f"{self.page.relative_to(ROOT)}:{self.line} ({self.lang})"


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a Markdown page, with their info strings."""
    out, lines, i = [], page.read_text(encoding="utf-8").splitlines(), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, start, body = m["fence"], i + 1, []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i][len(m["indent"]):])
            i += 1
        out.append(Block(page, start, m["info"].strip(), "\n".join(body) + "\n"))
        i += 1
    return out


ALL = [b for page in PAGES for b in blocks(page)]


def test_every_block_is_marked():
    """Every block says what it is, with known words: nothing is left out silently."""
    bad = [f"{b}: info string {b.lang!r} {sorted(b.opts)}" for b in ALL
           if b.lang not in LANGUAGES or set(b.opts) - KEYS[b.lang]]
    assert not bad, "blocks without a known info string:\n" + "\n".join(bad)


def test_marks_are_few():
    marks = Counter(k for b in ALL for k in b.opts if k in MAX_MARKS)
    over = {k: n for k, n in marks.items() if n > MAX_MARKS[k]}
    assert not over, f"too many blocks not run ({over}; limits {MAX_MARKS})"
    assert all("skip" not in b.opts or b.opts["skip"] is not True for b in ALL), \
        "a skipped block gives its reason: skip=\"...\""


def test_readme_keeps_the_ci_commands():
    """The README's first block is what .ci/run runs: keep it as it is."""
    first = blocks(ROOT / "README.md")[0]
    assert first.text.splitlines() == [
        "pip install . && bgc simulate models/pendulum.bg --scene swing -o pendulum.csv",
        "pip install '.[test]' && python -m pytest -q -n auto"]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert "bgc simulate" in ci and "python -m pytest -q -n auto" in ci


LINK = re.compile(r"\]\(([^)#\s]+)(#[^)]*)?\)")
OUTSIDE = ("/" + "work/", "../" + "shared", "shared/" + "spec", "LANGUAGE" + ".md",
           "INTERFACES" + ".md")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_stay_in_the_repository(page):
    """Relative links point at files of the repository; no page names a path outside it."""
    text = page.read_text(encoding="utf-8")
    prose = re.sub(r"`[^`\n]*`", "", "\n".join(
        line for b, line in _outside_blocks(text.splitlines()) if not b))
    for target, anchor in LINK.findall(prose):
        if re.match(r"[a-z]+:", target):
            continue
        path = (page.parent / target).resolve()
        assert path.is_relative_to(ROOT), f"{page.name}: link {target} leaves the repository"
        assert path.exists(), f"{page.name}: link {target} points at nothing"
        if anchor and path.suffix == ".md":
            assert anchor[1:] in anchors(path), f"{page.name}: no heading {anchor} in {target}"
    for anchor in re.findall(r"\]\((#[^)]+)\)", prose):
        assert anchor[1:] in anchors(page), f"{page.name}: no heading {anchor}"
    for word in OUTSIDE:
        assert word not in text, f"{page.name} refers to {word!r}, outside the repository"


def anchors(page: Path) -> set[str]:
    """The anchors GitHub gives a page's headings: lower case, punctuation out, spaces -."""
    out = set()
    for inside, line in _outside_blocks(page.read_text(encoding="utf-8").splitlines()):
        m = re.match(r"#{1,6} (.*)", line)
        if m and not inside:
            out.add(re.sub(r"[^\w\- ]", "", m[1].strip().lower()).replace(" ", "-"))
    return out


def _outside_blocks(lines):
    """(inside a fenced block?, line) for every line of a page."""
    fence = None
    for line in lines:
        m = FENCE.match(line)
        if m and (fence is None or line.strip().startswith(fence)):
            fence = m["fence"] if fence is None else None
            yield True, line
        else:
            yield fence is not None, line


def test_no_file_refers_outside_the_repository():
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    found = []
    for name in tracked.stdout.splitlines():
        path = ROOT / name
        if path.suffix in (".png",) or not path.is_file():
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        found += [f"{name}: {w}" for w in OUTSIDE if w in text]
    assert not found, "references outside the repository:\n" + "\n".join(found)


# ---------------------------------------------------------------- running a page


class Page:
    """A page's working directory and state: files saved by blocks, the python namespace."""

    def __init__(self, directory: Path):
        self.dir = directory
        (directory / "models").symlink_to(ROOT / "models", target_is_directory=True)
        bin_ = directory / ".bin"
        bin_.mkdir()
        for name, command in (("bgc", "-m bgc "), ("python", "")):
            (bin_ / name).write_text(f'#!/bin/sh\nexec "{sys.executable}" {command}"$@"\n')
            (bin_ / name).chmod(0o755)
        self.env = dict(os.environ, PATH=f"{bin_}{os.pathsep}{os.environ.get('PATH', '')}",
                        PYTHONPATH=os.pathsep.join(
                            [str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
        self.namespace = {"__name__": "__docs__"}
        self.runner = _runner()
        self.models = 0
        self.last = None  # {"stdout": ..., "stderr": ...} of the last command run


def _runner() -> CliRunner:
    try:
        return CliRunner(mix_stderr=False)  # click < 8.2
    except TypeError:
        return CliRunner()


def commands(text: str) -> list[str]:
    """The command lines of an sh block: continuations joined, blank and comment lines out."""
    out, current = [], ""
    for line in text.splitlines():
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        current += line
        if current.strip() and not current.strip().startswith("#"):
            out.append(current.strip())
        current = ""
    return out


def run_bgc(page: Page, args: list[str]) -> tuple[int, str]:
    """A bgc command in this process, with the backend a user's has by default (auto, not the
    suite's $BGC_BACKEND): the messages it writes are the ones a page shows."""
    result = page.runner.invoke(main, args, catch_exceptions=True, env={"BGC_BACKEND": "auto"})
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    page.last = {"stdout": result.stdout, "stderr": result.stderr}
    return result.exit_code, result.stderr


def run_command(page: Page, line: str) -> tuple[int, str]:
    words = shlex.split(line, comments=True)
    if words and words[0] == "bgc" and not SHELL_SYNTAX.search(line.split("#")[0]):
        return run_bgc(page, words[1:])
    line = re.sub(r"(?<=\s)-O2(?=\s)", "-O0", line)
    done = subprocess.run(["bash", "-c", line], cwd=page.dir, env=page.env,
                          capture_output=True, text=True, timeout=120)
    page.last = {"stdout": done.stdout, "stderr": done.stderr}
    return done.returncode, done.stderr


CPU = re.compile(r"(?<=cpu=)\S+")  # processor seconds: the one figure that varies run to run


def check_output(page: Page, block: Block):
    """A text block marked output=STREAM shows what the last command wrote on STREAM."""
    stream = block.opts["output"]
    assert stream in ("stdout", "stderr"), f"{block}: output=stdout or output=stderr"
    assert page.last is not None, f"{block}: no command ran before this output"
    shown, actual = (CPU.sub("*", t).rstrip("\n") for t in (block.text, page.last[stream]))
    assert shown == actual, f"{block}: the page shows\n{shown}\nbut the command wrote\n{actual}"


def dry_run(page: Page, line: str):
    """Parse a bgc command as bgc would, and build its model for its scene; do not run it."""
    words = shlex.split(line, comments=True)
    assert words[0] == "bgc", f"dry-run takes bgc commands only: {line}"
    command = main.commands[words[1]]
    with main.make_context("bgc", [words[1]], resilient_parsing=True) as parent:
        ctx = command.make_context(words[1], words[2:], parent=parent)
    p = ctx.params
    api.build(p["model"], p.get("scene"), algebra=p.get("algebra", "auto"),
              outputs=p.get("outputs"), effects=p.get("effects"), program=False)


def run_bg(page: Page, block: Block):
    name = block.opts.get("file")
    if not isinstance(name, str):
        page.models += 1
        name = f"block{page.models}.bg"
    path = page.dir / name
    path.write_text(block.text, encoding="utf-8")
    if "fragment" in block.opts:
        text = block.text if block.text.lstrip().startswith("model") else \
            "model fragment\n" + block.text
        parse(text, name)
        return
    if "error" in block.opts:
        args = ["check", name] + (["--scene", block.opts["scene"]] if "scene" in block.opts
                                  else [])
        code, err = run_bgc(page, args)
        assert code == 1, f"{block}: the model should be refused, `bgc check` gave {code}"
        assert re.search(rf"^{re.escape(name)}:\d+:\d+: error: ", err, re.M), err
        if isinstance(block.opts["error"], str):
            assert block.opts["error"] in err, f"{block}: expected {block.opts['error']!r}:\n{err}"
        return
    code, err = run_bgc(page, ["check", name])
    assert code == 0, f"{block}: `bgc check` failed:\n{err}"
    graph_scenes = api.build(str(path), program=False).graph.scenes
    for scene in graph_scenes:
        api.build(str(path), scene.name, program=False)


def run_block(page: Page, block: Block):
    if block.lang == "bg":
        run_bg(page, block)
    elif block.lang == "text" and "output" in block.opts:
        check_output(page, block)
    elif block.lang == "c" and "file" in block.opts:
        (page.dir / block.opts["file"]).write_text(block.text, encoding="utf-8")
    elif block.lang == "python":
        cwd = os.getcwd()
        os.chdir(page.dir)
        sys.path.insert(0, str(page.dir))  # as `python` does for a script: modules written here
        # a module of the same name imported elsewhere (benchmarks/pendulum.py) must not hide
        # the one the page wrote
        hidden = {f.stem: sys.modules.pop(f.stem) for f in page.dir.glob("*.py")
                  if f.stem in sys.modules}
        try:
            exec(compile(block.text, f"{block}", "exec"), page.namespace)
        finally:
            sys.path.remove(str(page.dir))
            os.chdir(cwd)
            for name, module in list(sys.modules.items()):
                if str(getattr(module, "__file__", None) or "").startswith(str(page.dir)):
                    del sys.modules[name]
            sys.modules.update(hidden)
    elif block.lang == "sh" and "skip" not in block.opts and \
            shutil.which(block.opts.get("needs", "sh")) is not None:
        want = int(block.opts.get("status", 0))
        for line in commands(block.text):
            if "dry-run" in block.opts:
                dry_run(page, line)
                continue
            code, err = run_command(page, line)
            assert code == want, f"{block}: `{line}` exited {code}, not {want}:\n{err}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_page(page, tmp_path, monkeypatch):
    """A page's blocks, in order, in one working directory."""
    monkeypatch.chdir(tmp_path)
    state = Page(tmp_path)
    for block in blocks(page):
        run_block(state, block)
