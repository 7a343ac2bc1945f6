"""Locate grammar/ and templates/: inside the package once installed (bgc/grammar,
bgc/templates, see pyproject.toml), beside it in a source tree."""
from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def resource_dir(name: str) -> Path:
    """The directory `name` ("grammar" or "templates")."""
    for candidate in (_HERE / name, _HERE.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"bgc is installed without its {name}/ directory")
