"""bgc fmt for the manual: the `bg` blocks of README.md and docs/*.md in the canonical layout.

    python tools/fmt_docs.py            # rewrite the pages whose blocks are not formatted
    python tools/fmt_docs.py --check    # name them, exit 1 if there is one

Every `bg` block is formatted (complete models, `file=` and `fragment` blocks: the fences as
tests/test_docs.py reads them) but those marked `error`, a model bgc refuses shown as it is, its
located error where the page says (as tests/errors/*.bg keep their layout), and those marked
`keep-layout`, whose layout is what they show (`;`, a line continuation)."""
from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bgc.editor.fmt import format_text  # noqa: E402

FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")


def pages() -> list[Path]:
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def formatted(block: str, info: str) -> str:
    """A block's text in the canonical layout (as it is if it is not a `bg` block, or is one
    marked `error`)."""
    words = shlex.split(info)
    if not words or words[0] != "bg" or any(w.split("=")[0] in ("error", "keep-layout")
                                            for w in words[1:]):
        return block
    return format_text(block, "<docs>")


def format_page(text: str) -> str:
    """The page with its `bg` blocks formatted (the rest as it is)."""
    lines = text.split("\n")
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        out.append(lines[i])
        i += 1
        if not m:
            continue
        body = []
        while i < len(lines) and not lines[i].strip().startswith(m["fence"]):
            body.append(lines[i][len(m["indent"]):])
            i += 1
        block = formatted("\n".join(body) + "\n", m["info"].strip())
        out += [m["indent"] + x if x else x for x in block.split("\n")[:-1]]
        if i < len(lines):
            out.append(lines[i])
            i += 1
    return "\n".join(out)


def main(argv: list[str]) -> int:
    check = "--check" in argv
    stale = []
    for page in pages():
        text = page.read_text(encoding="utf-8")
        new = format_page(text)
        if new != text:
            stale.append(page)
            if not check:
                page.write_text(new, encoding="utf-8")
    for page in stale:
        print(page.relative_to(ROOT))
    return 1 if check and stale else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
