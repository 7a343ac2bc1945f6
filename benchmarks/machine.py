"""What the benchmarks print about the machine they ran on: the C compiler, the processor and
the load, so that tables from different runs can be told apart."""
from __future__ import annotations

import os
import platform
import subprocess


def cc_version(cc: list[str]) -> str:
    """The first line of `cc --version`, or a note that it is missing."""
    try:
        done = subprocess.run([*cc, "--version"], capture_output=True, text=True)
        return done.stdout.splitlines()[0]
    except (OSError, IndexError):
        return f"{' '.join(cc)}: not found"


def processor() -> str:
    """The processor's model name (/proc/cpuinfo), else what platform knows."""
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            name = next(line.split(":", 1)[1].strip() for line in fh
                        if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return name


def load_average() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
