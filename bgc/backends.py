"""Running generated code: compile C into a content-keyed cache, run it, import Python.

A compiler failure on generated code is a bug in bgc, not a model error: it raises
BackendError with the compiler's messages.
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

C_FLAGS = ("-O2", "-std=c99")
C_LIBS = ("-lm",)
_EXE_SUFFIX = ".exe" if os.name == "nt" else ""


class BackendError(RuntimeError):
    """The generated code could not be compiled or loaded (a bgc bug or a broken toolchain)."""


def cache_dir() -> Path:
    """$BGC_CACHE_DIR, else ~/.cache/bgc (created on demand)."""
    path = Path(os.environ.get("BGC_CACHE_DIR") or Path.home() / ".cache" / "bgc")
    path.mkdir(parents=True, exist_ok=True)
    return path


def c_compiler(cc: str | None = None) -> list[str]:
    """The compiler command: cc, else $CC, else "cc" (split like a shell word list)."""
    return shlex.split(cc or os.environ.get("CC") or "cc")


def have_c_compiler(cc: str | None = None) -> bool:
    command = c_compiler(cc)
    return bool(command) and shutil.which(command[0]) is not None


def compile_c(source: str, cc: str | None = None, flags: tuple[str, ...] = C_FLAGS) -> Path:
    """The executable built from source, from the cache when the same source, compiler and
    flags were built before.  Written atomically (temporary file, then os.replace)."""
    command = c_compiler(cc)
    if not command:
        raise BackendError("no C compiler given")
    key = hashlib.sha256(json.dumps([source, command, list(flags), list(C_LIBS)]).encode())
    exe = cache_dir() / f"bgc-{key.hexdigest()[:40]}{_EXE_SUFFIX}"
    if exe.is_file():
        return exe
    with tempfile.TemporaryDirectory(dir=cache_dir(), prefix="build-") as tmp:
        src, out = Path(tmp) / "model.c", Path(tmp) / f"model{_EXE_SUFFIX}"
        src.write_text(source, encoding="utf-8")
        _run_compiler([*command, *flags, str(src), "-o", str(out), *C_LIBS])
        os.replace(out, exe)
    return exe


def _run_compiler(argv: list[str]) -> None:
    try:
        done = subprocess.run(argv, capture_output=True, text=True)
    except OSError as error:
        raise BackendError(f"cannot run the C compiler {argv[0]!r}: {error}") from error
    if done.returncode != 0:
        raise BackendError(
            f"the C compiler failed on generated code (a bug in bgc), status {done.returncode}:\n"
            f"$ {shlex.join(argv)}\n{done.stderr}")


def run_c(exe: Path | str, args=(), timeout: float | None = None) -> tuple[int, str, str]:
    """Runs a compiled model: (returncode, stdout, stderr)."""
    done = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)
    return done.returncode, done.stdout, done.stderr


def load_python_module(source: str, name: str | None = None) -> ModuleType:
    """Imports generated Python source as a fresh module (not entered in sys.modules)."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    name = name or f"bgc_generated_{digest}"
    with tempfile.TemporaryDirectory(prefix="bgc-py-") as tmp:
        path = Path(tmp) / f"{name}.py"
        path.write_text(source, encoding="utf-8")
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise BackendError(f"cannot load generated module {name}")
        module = importlib.util.module_from_spec(spec)
        dont_write = sys.dont_write_bytecode
        sys.dont_write_bytecode = True
        try:
            spec.loader.exec_module(module)
        except Exception as error:
            raise BackendError(f"generated Python failed to import (a bug in bgc): {error}") \
                from error
        finally:
            sys.dont_write_bytecode = dont_write
    return module


def run_python(source: str, args=(), timeout: float | None = None) -> tuple[int, str, str]:
    """Run generated Python as a program (`python model.py ARGS`), as run_c runs a C program."""
    with tempfile.TemporaryDirectory(prefix="bgc-") as tmp:
        path = Path(tmp) / "model.py"
        path.write_text(source, encoding="utf-8")
        proc = subprocess.run([sys.executable, str(path), *map(str, args)], capture_output=True,
                              text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr
