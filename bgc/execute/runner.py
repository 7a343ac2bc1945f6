"""Running a generated program: the one place bgc runs a simulation.  The command line (cold and
warm), bgc.simulate, Model.simulate, `bgc accuracy` and `bgc sweep` all come here for the
backend (and the fallback when there is no C compiler), the run's settings (a
bgc.base.run_settings.RunSettings over the program's own, parameter overrides checked once) and
the run.

A Program is a generated program ready to run: a file in the cache started as a process (C, or
Python), or generated Python loaded in this process (the API's Python backend, whose errors
are the module's own exceptions).  run() starts it with the settings that differ from the ones
it was compiled with, so that a run with the scene's settings starts it exactly as bgc always
has.  The rows go to a sink (the command line's file or stdout, which it owns) or come back
as text; the caller decides what a failure means (bgc.api raises, the command line keeps the
rows and says so, bgc.analysis.accuracy records it).

Light on purpose, like bgc.base.run_settings: the standard library and bgc.base's cache,
toolchain and processes only at import (a warm `bgc simulate` runs through here without
importing SymPy or numpy); the emitter is imported only to prepare a program from a compiled
model.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

from ..base import cache, processes, toolchain
from . import outfile
from ..base.run_settings import RunSettings, parameter_overrides, run_span_problem

NO_C_COMPILER = "warning: no C compiler found (cc or $CC); using the Python backend"
INTERPRETED = ("bgc: no cached build for this model; running it in the interpreter (--backend c "
               "to build)")
VM_WORK = 10_000_000  # runner.short_run: the most output rows x (operations + states)


def short_run(settings: RunSettings, rhs_ops: int, states: int) -> bool:
    """Whether `bgc simulate` runs a model it has no build of in the interpreter (bgc.codegen.vm)
    rather than building it: when the run's output rows ((t_end - t0) / dt + 1) times the
    right side's operations and states (bgc.ir.count_ops, as `bgc check` counts them) is at
    most VM_WORK, where the interpreter's extra time is below what the C build of the
    model's part costs (benchmarks/cold.py measures both)."""
    rows = (settings.t_end - settings.t0) / settings.dt + 1
    return rows * (rhs_ops + states) <= VM_WORK


def choose_backend(backend: str) -> tuple[str, str | None]:
    """The backend that runs, and the warning to print about it (None: nothing to say): "c"
    and "vm" (whose interpreter is built once per machine) fall back to "python" when there is
    no C compiler."""
    if backend in ("c", "vm") and not toolchain.have_c_compiler():
        return "python", NO_C_COMPILER
    return backend, None


@dataclass(frozen=True)
class RunPolicy:
    """How `bgc simulate` runs a model (run_policy): the backend, the warning its fallback
    prints, whether a warm record may serve the run, and whether bgc chooses between the C
    build and the interpreter for a model it has no C build of (interpreted)."""

    backend: str  # "c", "vm" or "python": what runs unless interpreted() says "vm"
    warning: str | None = None  # choose_backend's, None: nothing to say
    warm: bool = True  # a warm record may run it (bgc.execute.warm); else it is built anew
    auto: bool = False  # --backend auto with a C compiler: the interpreter for a short run
    t_end: float | None = None  # the run's --t-end and --dt (None: the scene's)
    dt: float | None = None

    def interpreted(self, scene: RunSettings, rhs_ops: int, states: int) -> bool:
        """Whether a model without a C build that the interpreter runs (bgc.codegen.vm.supports)
        runs there: when bgc chooses (auto) and the run, the model's scene settings with this
        run's span, is short (short_run of the model's right side and states)."""
        return self.auto and short_run(scene.with_options(t_end=self.t_end, dt=self.dt),
                                       rhs_ops, states)


def run_policy(backend: str, t_end: float | None = None, dt: float | None = None,
               warm: bool = True) -> RunPolicy:
    """The policy of a `bgc simulate` run given --backend (auto, c, vm, python), --t-end and
    --dt: auto is C, which choose_backend turns into Python without a C compiler (and then
    nothing is chosen); warm False for a program that is built each time (sensitivities)."""
    auto = backend == "auto"
    backend, warning = choose_backend("c" if auto else backend)
    return RunPolicy(backend, warning, warm, auto and backend == "c", t_end, dt)


@dataclass(frozen=True)
class Program:
    """A generated program ready to run."""

    backend: str  # "c", "vm" or "python"
    defaults: RunSettings  # the scene's settings, compiled into it
    params: tuple[str, ...]  # its parameters, in order
    outputs: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()  # its inputs (`input NAME`), in order
    path: Path | None = None  # the file started as a process (C executable or Python), or
    #                           the interpreter's program file (bgc.codegen.vm)
    module: object = None  # or: generated Python loaded in this process
    interpreter: Path | None = None  # the interpreter that runs path (bgc.codegen.vm)
    bytecode: Path | None = None  # Python: path compiled (cache.python_bytecode), if any

    def argv(self) -> list[str]:
        """The command that starts it."""
        if self.interpreter is not None:
            return [str(self.interpreter), str(self.path)]
        if self.path.suffix == ".py":
            return [sys.executable, str(self.bytecode or self.path)]
        return [str(self.path)]


def prepare(compiled, backend: str, in_process: bool = False) -> Program:
    """compiled's program (bgc.api.Compiled), emitted and built for `backend` (the C program
    into the cache; the interpreter's program into the cache, with the interpreter built
    once per machine; Python into the cache, or loaded in this process when in_process)."""
    from ..codegen.emit import emit_python
    p = compiled.program
    facts = dict(defaults=p.scene, params=tuple(q.name for q in p.params), outputs=p.outputs,
                 inputs=tuple(u.name for u in p.inputs))
    if backend == "c":
        return Program("c", path=c_executable(p), **facts)
    if backend == "vm":
        from ..codegen.vm import interpreter, program_bytes
        path = cache.cache_bytes(program_bytes(p), ".bgvm")
        return Program("vm", path=path, interpreter=interpreter(), **facts)
    (text,) = emit_python(p).values()
    if in_process:
        return Program("python", module=processes.load_python_module(text), **facts)
    path = cache.cache_python(text)
    return Program("python", path=path, bytecode=cache.python_bytecode(path), **facts)


def c_executable(program) -> Path:
    """The C executable of a program (bgc.ir.Program), built into the cache: its model part
    linked with the runtime built once (bgc.codegen.emit.c_runtime_unit), or, for a model whose
    parameters do not fit that runtime (bgc.codegen.emit.linkable), the standalone program."""
    from ..codegen.emit import c_runtime_unit, emit_c, linkable
    if linkable(program):
        (text,) = emit_c(program, linked=True).values()
        return cache.compile_c_linked(text, c_runtime_unit())
    (text,) = emit_c(program).values()
    return cache.compile_c(text)


def settings_for(defaults: RunSettings, names, params: dict | None = None,
                 **options) -> RunSettings:
    """A run's settings: a program's own (`defaults`, its scene's) with the options given
    (None: its own) and the parameter overrides, checked against its parameters (`names`, in
    the order an error lists them) and its scene's start (ValueError, for people)."""
    overrides = parameter_overrides(params, names)
    settings = defaults.with_options(params=dict(overrides), **options)
    problem = run_span_problem(settings)
    if problem:
        raise ValueError(problem)
    return settings


WRITE_FAILED = "error: cannot write the output: "  # how a generated program says so (then why)


@dataclass(frozen=True)
class Result:
    """How a run ended.  status is bgc's exit status for it: 0; 2 for settings the program
    refused (a usage error); 128 + the signal that interrupted it; -1 over the time budget;
    else 1 (a failed run, a violated constraint, a program killed by a signal, a CSV that
    could not be written)."""

    status: int
    stderr: str = ""  # the program's messages (progress lines apart)
    csv: str | None = None  # the rows as the program wrote them, when no sink took them
    t: object = None  # in this process: the times and the rows (the module's arrays)
    values: object = None
    killed: int = 0  # the signal that killed the program (not one bgc passed on), else 0
    write_error: str | None = None  # why the CSV could not be written ("No space left ...")
    last_line: str = ""  # the last whole line a sink without a descriptor was given

    @property
    def stats(self) -> dict:
        """The counters of a run with stats=True: {name: text}."""
        for line in self.stderr.splitlines():
            if line.startswith("stats:"):
                return {k: v for k, _, v in (part.partition("=") for part in line.split()[1:])}
        return {}

    @property
    def message(self) -> str:
        """A failed run's last error, without its `error:`."""
        if self.killed:
            return f"the generated program was killed by {signal_name(self.killed)}"
        lines = self.stderr.strip().splitlines()
        errors = [ln for ln in lines if ln.startswith("error:")]
        if errors:
            return errors[-1][len("error:"):].strip()
        return lines[-1] if lines else "failed"

    @property
    def messages(self) -> str:
        """The program's stderr as the command line shows it: the report of a write that
        failed taken out (the command line says it with the file's name)."""
        if self.write_error is None:
            return self.stderr
        return "".join(line for line in self.stderr.splitlines(keepends=True)
                       if not line.startswith(WRITE_FAILED))


def signal_name(number: int) -> str:
    """SIGKILL for 9 (the number itself for a signal Python does not name)."""
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def _write_error(stderr: str) -> str | None:
    for line in stderr.splitlines():
        if line.startswith(WRITE_FAILED):
            return line[len(WRITE_FAILED):].strip()
    return None


def _status(code: int, signal: int = 0) -> int:
    if signal:
        return 128 + signal
    return code if code in (0, 2) else 1


def run(program, settings: RunSettings | None = None, sink=None, progress=None,
        stats: bool = False, timeout: float | None = None, backend: str = "c") -> Result:
    """Runs program (a Program, or a bgc.api.Compiled, prepared here for `backend` after
    choose_backend) with settings (None: its own).  sink: a file (or anything with write())
    that the CSV streams into as the run goes, SIGINT and SIGTERM passed on to the program
    (the command line); None: the CSV comes back in Result.csv.  progress: called with
    (t, t0, t_end) as the run goes.  stats: the program prints its counters (Result.stats).
    timeout: seconds, then the run is stopped (status -1).  A program loaded in this process
    returns its arrays, and its errors are raised (the generated module's SimulationError,
    ValueError)."""
    if isinstance(program, Program):
        return _run_prepared(program, settings, sink, progress, stats, timeout)
    compiled = program
    program = prepare(compiled, choose_backend(backend)[0])
    try:
        return _run_prepared(program, settings, sink, progress, stats, timeout)
    except processes.CannotStart:  # (a cached program damaged behind its checksum: evicted)
        return _run_prepared(prepare(compiled, program.backend), settings, sink, progress,
                             stats, timeout)


def _run_prepared(program: Program, settings, sink, progress, stats, timeout) -> Result:
    """run's work on a prepared program: in this process, or started as a process with its
    rows streamed into sink or captured; input data given as numbers first written to files
    the program reads."""
    settings = program.defaults if settings is None else settings
    if settings.input_data and program.module is None:  # numbers: to files the program reads
        with tempfile.TemporaryDirectory(prefix="bgc-inputs-") as where:
            files = []
            for k, (name, t, u) in enumerate(settings.input_data):
                path = os.path.join(where, f"input{k}.csv")
                with open(path, "w", encoding="utf-8") as f:
                    f.write(f"t,{name}\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t, u)))
                files.append(path)
            return _run_prepared(program, replace(settings, input_data=(),
                                                  input_files=settings.input_files + tuple(files)),
                                 sink, progress, stats, timeout)
    if program.module is not None:
        t, values = program.module.simulate(**settings.options(program.defaults))
        return Result(0, t=t, values=values)
    argv = program.argv() + settings.args(program.defaults) + ["--stats"] * stats \
        + ["--progress"] * (progress is not None)
    if sink is not None:
        done = processes.run_streaming(argv, sink, progress)
        failed = done.sink_error
        write_error = outfile.reason(failed) if failed is not None else _write_error(done.stderr)
        killed = -done.code if done.code < 0 and not done.signal and failed is None else 0
        return Result(_status(done.code, done.signal), done.stderr, killed=killed,
                      write_error=write_error, last_line=done.last_line)
    try:
        done = processes.run_captured(argv, timeout)
    except subprocess.TimeoutExpired:
        return Result(-1, f"stopped after {timeout:g} s (the time budget per run)", "")
    return Result(_status(done.returncode), done.stderr, done.stdout,
                  killed=max(0, -done.returncode), write_error=_write_error(done.stderr))



class SessionFailed(Exception):
    """A session's program ended or answered other than with a result (the message says how)."""


class Session:
    """Runs of one program, one after another in one process, each from parameters given when
    the last has ended (its batch mode read from stdin, bgc/runtime/batch.c): a run's numbers
    are a separate run's, bit for bit, without a process start each.  The C program and the
    interpreter run as one process each; the Python module loaded in this process runs its
    batch_rows generator.  run(params) gives the run's row: {"status", each metric, "steps",
    "rejected", "rhs", "cpu", "message"}."""

    def __init__(self, program: Program, settings: RunSettings, metrics):
        self.metrics = tuple(metrics)
        self.pending = None
        if program.module is not None:
            options = settings.options(program.defaults)
            unknown = set(options) - {"t_end", "dt", "solver", "rtol", "atol", "params", "step",
                                      "max_steps", "project_initial", "allow_inconsistent",
                                      "error_states"}
            if unknown:
                raise ValueError(f"a session cannot set {', '.join(sorted(unknown))}")
            self.proc = None
            self.rows = program.module.batch_rows(iter(self._next_line, None), self.metrics,
                                                  **options)
            return
        argv = program.argv() + settings.args(program.defaults) + ["--batch", "-"]
        for m in self.metrics:
            argv += ["--metric", m]
        self.proc = processes.start_piped(argv)
        self.header = self.proc.stdout.readline().rstrip("\n").split(",")
        if self.header[:2] != ["run", "status"]:
            self._fail()

    def _next_line(self):
        line, self.pending = self.pending, None
        return line

    def run(self, params: dict) -> dict:
        line = " ".join(f"{name}={float(v)!r}" for name, v in params.items())
        if self.proc is None:
            self.pending = line
            return next(self.rows)
        try:
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()
            answer = self.proc.stdout.readline()
        except (BrokenPipeError, OSError):
            answer = ""
        if not answer.endswith("\n"):
            self._fail()
        import csv
        (fields,) = csv.reader([answer])
        row = dict(zip(self.header, fields))
        for name in self.metrics + ("cpu",):
            row[name] = float(row[name])
        for name in ("steps", "rejected", "rhs"):
            row[name] = int(row[name])
        return row

    def _fail(self):
        """The program ended (or broke its pipe): SessionFailed with its last message."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        err = self.proc.stderr.read()
        self.close()
        lines = [ln for ln in err.strip().splitlines() if ln]
        raise SessionFailed(lines[-1] if lines else
                            f"the program ended (status {self.proc.returncode})")

    def close(self) -> None:
        if self.proc is None:
            self.rows.close()
            return
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        self.proc.wait()
        for f in (self.proc.stdout, self.proc.stderr):
            if f:
                f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
