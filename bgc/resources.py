"""Locate grammar/ and templates/: beside the package in a source tree, inside it once installed."""
from __future__ import annotations

import importlib.resources
from pathlib import Path


def resource_dir(name: str) -> Path:
    """The directory `name` ("grammar" or "templates"), source tree first, then the installed copy."""
    source = Path(__file__).resolve().parent.parent / name
    if source.is_dir():
        return source
    return Path(str(importlib.resources.files(f"bgc.{name}")))
