"""editors/vscode: the VS Code extension's files hold together, and its TextMate grammar knows
the language as bgc does (the keywords, element kinds and functions of bgc's own tables)."""
from __future__ import annotations

import json
import re
from pathlib import Path

from bgc.front.kinds import KINDS, SWITCHED
from bgc.front.parser import KEYWORDS
from bgc.front.resolve import FUNCTIONS

VSCODE = Path(__file__).resolve().parent.parent / "editors" / "vscode"
GRAMMAR = json.loads((VSCODE / "syntaxes" / "bg.tmLanguage.json").read_text("utf-8"))


def _words(rule: str) -> set[str]:
    """The alternatives of a grammar rule's `\\b(a|b|c)` group."""
    return set(re.search(r"\((?:\?<=:\)\\s\*\()?([\w|]+)\)", GRAMMAR["repository"][rule]["match"])
               [1].split("|"))


def test_the_extension_names_files_that_exist():
    package = json.loads((VSCODE / "package.json").read_text("utf-8"))
    (language,) = package["contributes"]["languages"]
    (grammar,) = package["contributes"]["grammars"]
    assert language["id"] == grammar["language"] == "bg" and language["extensions"] == [".bg"]
    assert grammar["scopeName"] == GRAMMAR["scopeName"]
    for path in (language["configuration"], grammar["path"], package["main"]):
        assert (VSCODE / path).is_file(), path
    assert package["contributes"]["configuration"]["properties"]["bgc.args"]["default"] == \
        ["lsp"]
    config = json.loads((VSCODE / "language-configuration.json").read_text("utf-8"))
    assert config["comments"] == {"lineComment": "#"}


def test_the_grammar_knows_the_language_as_bgc_does():
    assert _words("keyword") == set(KEYWORDS)
    assert _words("kind") == {*KINDS, *SWITCHED, "0", "1"}
    assert set(FUNCTIONS) <= _words("function")


def test_the_grammar_s_patterns_compile():
    """(Python's re reads these patterns as Oniguruma does: no construct of either alone.)"""
    found = 0
    for rule in GRAMMAR["repository"].values():
        for key in ("match", "begin", "end"):
            if key in rule:
                re.compile(rule[key])
                found += 1
    assert found >= len(GRAMMAR["repository"])
