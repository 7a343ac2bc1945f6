"""Warm runs: `bgc simulate` of a model it has compiled before starts the cached program at
once, without importing SymPy or running the pipeline again.

After a cold run the command line stores a *record* in the cache directory
(bgc.base.cache.cache_dir): which program the model compiled to (the file's name and SHA-256)
and what the command line needs from the compiled model to run it exactly as the cold path
would — the warnings the model gave (as printed), the parameters' names, the scene's settings (the
bgc.base.run_settings.RunSettings compiled into the program), whether a constraint has a pid or pd
corrector, whether the program has the Jacobian (one built for an explicit solver has not:
an implicit solver's run is then cold, and its record replaces this one), and what `--plot`
says of the model and its outputs (bgc.reports.plot.describe).

A record's key is the SHA-256 of everything its contents depend on: this record format, bgc's
version and the size and modification time of every file bgc is made of (so an edited or
upgraded bgc misses), the model's path as given (it appears in the warnings, and imports look
beside it) and the SHA-256 of its bytes, the scene and ad-hoc scene options, the algebra,
--project-initial and --allow-inconsistent, the backend, $BGC_PATH (where imports look), and
the C compiler's resolved path, size and modification time with $CC and the flags (or, for the
Python backend, the interpreter).  Nothing in the key is a timestamp of the model: the same
text under the same name hits, whatever its mtime.

The files a model reads besides itself are not in the key; the record names them with their
SHA-256, and a record whose files no longer have those bytes is a miss (their contents are
compiled into the program): a table's CSV file, each library an `import` read (the model's and
the libraries' own, the standard library's too), and each place an import looked at before the
file it found, recorded as no file (a library made there later would be found first: a miss).
Paths are recorded as the compile used them (relative ones to the working directory, as the
compile of the same command there would read them).

A record is used only if it reads as one (anything else is a miss), its files are unchanged,
and the program it names is still the file that was built and can run (bgc.base.cache.usable: a
regular file, executable, its SHA-256 the one recorded; like the program cache itself); a program
that still cannot be started is removed from the cache and the run goes the cold way (bgc.cli). 
Records are written to a temporary file and renamed into place, so concurrent runs are safe: each
sees a whole record or none.

This module imports the standard library only (and bgc.base.cache, bgc.base.toolchain,
bgc.base.resources, bgc.base.run_settings, bgc.execute.runner and bgc.base.solvers, which do too;
bgc.reports.plot when a cold run makes a record).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from ..base import cache, solvers, toolchain
from . import runner
from ..base.resources import read_bounded
from ..base.run_settings import RunSettings

FORMAT = 8  # of the record; change it when its fields change


@dataclass(frozen=True)
class Request:
    """What a `bgc simulate` compiles: the model and every option that changes the program."""
    model: str
    scene: str | None
    outputs: str | None
    effects: str | None
    algebra: str
    project_initial: bool
    allow_inconsistent: bool
    backend: str
    consts: tuple = ()  # --const NAME=VALUE, as ((name, value), ...)


@dataclass(frozen=True)
class Record:
    program: str  # the file's name in the cache directory
    sha256: str
    warnings: str  # the model's warnings, as the cold path printed them
    params: tuple[str, ...]
    settings: RunSettings  # the scene's, compiled into the program
    correctors: bool  # a constraint has a pid or pd corrector (bgc.analysis.stability's warnings)
    plot_title: tuple[str, ...] = ()  # for --plot (bgc.reports.plot.describe)
    plot_columns: tuple[tuple, ...] = ()  # (name, kind, doc, unit) of each output
    interpreter: str = ""  # the interpreter backend (bgc.codegen.vm): its file in the cache ...
    interpreter_sha256: str = ""  # ... and SHA-256; the program is then its program file
    rhs_ops: int = 0  # the right side's operations (bgc.ir.count_ops), for runner.short_run
    states: int = 0
    inputs: tuple[str, ...] = ()  # the program's inputs (`input NAME`), in order
    jacobian: bool = True  # the program has the Jacobian the implicit solvers need
    files: tuple[tuple[str, str | None], ...] = ()  # (path, SHA-256) of each file it read,
    #                                               None: a place an import found no file


def _installation() -> list:
    """bgc's files (package, runtime, grammar, templates): name, size, modification time."""
    from ..base.resources import PACKAGE_DIR, resource_dir
    dirs = [PACKAGE_DIR, *sorted(p.parent for p in PACKAGE_DIR.glob("*/__init__.py"))]
    for name in ("grammar", "templates"):
        try:
            dirs.append(resource_dir(name))
        except FileNotFoundError:
            pass
    facts = []
    for d in dirs:
        try:
            entries = sorted(os.scandir(d), key=lambda e: e.name)
        except OSError:
            continue
        for e in entries:
            if e.is_file() and not e.name.endswith((".pyc", ".pyo")):
                info = e.stat()
                facts.append([str(d), e.name, info.st_size, info.st_mtime_ns])
    return facts


def _toolchain(backend: str) -> list:
    if backend == "python":
        return ["python", sys.executable, sys.version]
    command = toolchain.c_compiler()
    where = shutil.which(command[0]) if command else None
    facts = ["c", command, list(toolchain.c_flags()), str(where)]
    if where:
        info = os.stat(where)
        facts.append([info.st_size, info.st_mtime_ns])
    return facts


def key(request: Request, source: bytes) -> str:
    from .. import __version__
    parts = [FORMAT, __version__, _installation(), hashlib.sha256(source).hexdigest(),
             asdict(request), _toolchain(request.backend), os.environ.get("BGC_PATH", "")]
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def _record_path(digest: str) -> Path:
    return cache.cache_dir() / f"warm-{digest[:40]}.json"


def lookup(request: Request) -> tuple[Record, Path] | None:
    """The record of an earlier cold run of this request, and the program it names; None if
    there is none, the record is unreadable, or the program is no longer the one built."""
    try:
        source = read_bounded(request.model)
    except OSError:
        return None
    path = _record_path(key(request, source))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.pop("format") != FORMAT:
            return None
        data["params"] = tuple(data["params"])
        data["settings"] = RunSettings(**dict(data["settings"], params=()))
        data["plot_title"] = tuple(data["plot_title"])
        data["plot_columns"] = tuple(map(tuple, data["plot_columns"]))
        data["files"] = tuple(map(tuple, data["files"]))
        record = Record(**data)
        if not all(_sha256(name) == digest for name, digest in record.files):
            return None
        program = path.parent / record.program
        if Path(record.program).name != record.program or not cache.usable(
                program, executable=program.suffix not in (".py", ".bgvm"),
                sha256=record.sha256):
            return None
        if record.interpreter and (Path(record.interpreter).name != record.interpreter
                                   or not cache.usable(path.parent / record.interpreter,
                                                       sha256=record.interpreter_sha256)):
            return None
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None
    return record, program


def _sha256(path: str) -> str | None:
    """A table's or a library's SHA-256 (of at most one byte more than a table may have, more
    than a library may have), None when it is not a regular file (a library's place that
    must stay empty; nothing else is opened, a FIFO included)."""
    from ..front.tables import MAX_TABLE_BYTES
    try:
        if not os.path.isfile(path):
            return None
        return hashlib.sha256(read_bounded(path, MAX_TABLE_BYTES)).hexdigest()
    except OSError:
        return None


def store(request: Request, source: bytes, record: Record) -> None:
    """Keep `record` for this request (atomically; a failure to write is not an error: the
    next run is cold again)."""
    path = _record_path(key(request, source))
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".warm-", suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump({"format": FORMAT, **asdict(record)}, f, sort_keys=True)
        os.replace(tmp, path)
    except OSError:
        try:
            os.unlink(tmp)
        except (OSError, UnboundLocalError):
            pass


def program(record: Record, path: Path) -> runner.Program:
    """The cached program a record names, to run (bgc.execute.runner)."""
    if record.interpreter:
        return runner.Program("vm", record.settings, record.params, path=path,
                              interpreter=path.parent / record.interpreter)
    if path.suffix == ".py":
        return runner.Program("python", record.settings, record.params, path=path,
                              bytecode=cache.python_bytecode(path))
    return runner.Program("c", record.settings, record.params, path=path)


def needs_model(record: Record, solver: str | None, step) -> bool:
    """Whether a run with these options needs the compiled model, which a warm run does not
    have: a fixed-step run of a model with a pid or pd corrector (bgc.analysis.stability checks the
    step against the corrector, on the model), or an implicit solver's run of a program
    built without the Jacobian (for an explicit solver: it is built again, with it)."""
    method = solvers.get(solver or record.settings.solver)
    if method.uses_jacobian and not record.jacobian:
        return True
    fixed = step is not None or method.family == "fixed"
    return record.correctors and fixed


def record_for(compiled, program: runner.Program, warnings: str) -> Record:
    """The record of a cold run: compiled (bgc.api.Compiled) prepared as program, whose
    warnings printed as `warnings`."""
    from ..reports import plot
    interp = program.interpreter
    return Record(
        program=program.path.name, sha256=hashlib.sha256(program.path.read_bytes()).hexdigest(),
        warnings=warnings, params=program.params, settings=program.defaults,
        correctors=any(c.corrector in ("pid", "pd") for c in compiled.reduced.constraints),
        inputs=tuple(u.name for u in compiled.program.inputs),
        **plot.describe(compiled), interpreter=interp.name if interp else "",
        interpreter_sha256=hashlib.sha256(interp.read_bytes()).hexdigest() if interp else "",
        rhs_ops=rhs_ops(compiled.program), states=len(compiled.program.states),
        jacobian=compiled.program.has_jacobian,
        files=tuple((t.file, _sha256(t.file)) for t in compiled.program.tables if t.file)
        + tuple(compiled.graph.libraries))


def rhs_ops(program) -> int:
    """The right side's operations, as bgc.ir.count_ops counts them (solves by their flops)."""
    from .. import ir
    ops = ir.count_ops(program, ("rhs",))
    return sum(v for k, v in ops.items() if k != "solve")
