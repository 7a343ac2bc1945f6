"""Generated programs run as processes: started with bgc's environment and signal
dispositions (they die with bgc), run to their end with their output captured or streamed as
it is written, or kept for a line-by-line exchange; and generated Python imported into this
process.  A program of the compile cache (bgc.base.cache) that cannot be started is removed
from it (CannotStart), so that the next use builds it again.
"""
from __future__ import annotations

import codecs
import hashlib
import importlib.util
import os
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from . import cache
from .toolchain import BackendError


class CannotStart(BackendError):
    """A program that could not be started (its file is not a program this machine runs, or
    not allowed to run); one in the cache is removed from it, so the next use builds it
    again."""

    def __init__(self, argv: list[str], error: OSError):
        self.path = Path(argv[0])
        where = self.path.parent
        evicted = where.is_dir() and where.resolve() == cache.cache_dir().resolve()
        if evicted:
            cache.evict(self.path)
        super().__init__(
            f"cannot start the program {self.path}: {error.strerror or error}"
            + ("; it was removed from the compile cache (if it was just built, the cache "
               "directory may be on a file system that does not allow programs: set "
               "BGC_CACHE_DIR)" if evicted else ""))


def _start(argv: list[str], **options) -> subprocess.Popen:
    """A generated program started with child_env() (it dies with bgc) and bgc's signal
    dispositions (see run_streaming)."""
    options.setdefault("env", child_env())
    options.setdefault("restore_signals", False)
    try:
        return subprocess.Popen(argv, **options)
    except OSError as error:
        raise CannotStart(argv, error) from None


def start_piped(argv: list[str]) -> subprocess.Popen:
    """argv started with its stdin and stdout as pipes of text lines, stderr captured, for a
    caller that writes a line and reads the answer (a batch read from stdin,
    bgc.execute.runner.Session); CannotStart if it cannot be started."""
    return _start(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                  text=True, bufsize=1)


def run_captured(argv: list[str], timeout: float | None = None) -> subprocess.CompletedProcess:
    """Runs argv to its end: its status, stdout and stderr as text (subprocess.run's result);
    CannotStart if it cannot be started; subprocess.TimeoutExpired after timeout seconds
    (the program killed); a timeout longer than the system's waits take (weeks) is none."""
    if timeout is not None and timeout > 1e6:
        timeout = None
    with _start(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


@dataclass
class Finished:
    """How a program run by run_streaming ended: its exit status (-N: killed by signal N), its
    stderr, the signal (SIGINT, SIGTERM) that interrupted bgc and was passed on, else 0; the
    write to a sink without a descriptor that failed (then the program was stopped), and the
    last whole line such a sink was given (for the time of the last row)."""
    code: int
    stderr: str
    signal: int = 0
    sink_error: OSError | None = None
    last_line: str = ""


PROGRESS_PREFIX = b"bgc-progress "
PARENT_ENV = "BGC_PARENT_PID"  # a generated program started by bgc dies with it (see child_env)


def child_env() -> dict:
    """The environment a generated program is started with: bgc's own, and its process id in
    BGC_PARENT_PID, which the program reads to die with bgc rather than run on as an orphan
    when bgc is killed (SIGKILL can be neither caught nor passed on): the C program on Linux
    by prctl(PR_SET_PDEATHSIG), the Python module by watching its parent."""
    return dict(os.environ, **{PARENT_ENV: str(os.getpid())})


def _read_stderr(pipe, err, progress) -> None:
    """A program's stderr, line by line: `bgc-progress T T0 T_END` lines to progress(t, t0,
    t_end), the others into err."""
    for line in iter(pipe.readline, b""):
        if line.startswith(PROGRESS_PREFIX):
            try:
                t, t0, t_end = map(float, line[len(PROGRESS_PREFIX):].split())
            except ValueError:
                err.write(line)
            else:
                progress(t, t0, t_end)
        else:
            err.write(line)
    pipe.close()


def _feed_lines(pipe, stdout) -> tuple[str, OSError | None]:
    """A program's stdout into a text sink without a descriptor, whole lines only (a cut last
    line is dropped); the last line given, and the error of a write that failed (then the
    rest is read and dropped, so that the program is not blocked)."""
    decoder = codecs.getincrementaldecoder("utf-8")("replace")
    pending, last, failed = "", "", None
    for chunk in iter(lambda: pipe.read(1 << 16), b""):
        if failed is not None:
            continue
        pending += decoder.decode(chunk)
        cut = pending.rfind("\n") + 1
        if cut:
            lines, pending = pending[:cut], pending[cut:]
            try:
                stdout.write(lines)
            except OSError as error:
                failed = error
                continue
            last = lines[lines.rfind("\n", 0, len(lines) - 1) + 1:-1]
    pipe.close()
    return last, failed


def run_streaming(argv: list[str], stdout, progress=None) -> Finished:
    """Runs argv with its standard output going to `stdout` as it is written (a file with a
    descriptor gets it directly; anything else with write() is fed whole lines), so memory
    does not grow with the output.  SIGINT and SIGTERM received meanwhile are passed on to the
    program, which stops at its next step with its rows written; a second one kills it.  A
    sink without a descriptor that cannot be written stops the program.  progress: called
    with (t, t0, t_end) for each progress line the program writes on stderr (run with
    --progress), which then is not in .stderr.

    The program starts with bgc's signal dispositions (restore_signals=False): SIGPIPE and
    SIGXFSZ ignored, as Python has them, so that a closed pipe or a file size limit is a write
    error the program reports (and stops at), not a death by signal; and with child_env(), so
    that it dies with bgc."""
    try:
        fd = stdout.fileno()
    except (AttributeError, OSError, ValueError):
        fd = None
    got: list[int] = []
    with tempfile.TemporaryFile() as err:
        if fd is not None:
            stdout.flush()
        proc = _start(argv, stdout=fd if fd is not None else subprocess.PIPE,
                      stderr=err if progress is None else subprocess.PIPE)
        reader = None
        if progress is not None:
            reader = threading.Thread(target=_read_stderr, args=(proc.stderr, err, progress),
                                      daemon=True)
            reader.start()

        def forward(sig, frame):
            if got:
                proc.kill()
            else:
                got.append(sig)
                proc.send_signal(sig)

        replaced = []
        if threading.current_thread() is threading.main_thread():
            replaced = [(sig, signal.signal(sig, forward))
                        for sig in (signal.SIGINT, signal.SIGTERM)]
        last, failed = "", None
        try:
            if fd is None:  # a text stream without a descriptor (a test's captured output)
                last, failed = _feed_lines(proc.stdout, _Stopping(stdout, proc))
            code = proc.wait()
            if reader is not None:
                reader.join()
        finally:
            for sig, handler in replaced:
                signal.signal(sig, handler)
        err.seek(0)
        return Finished(code, err.read().decode("utf-8", "replace"), got[0] if got else 0,
                        failed, last)


class _Stopping:
    """A sink that stops the program when a write to it fails (the error raised on)."""

    def __init__(self, sink, proc):
        self.sink, self.proc = sink, proc

    def write(self, text: str) -> None:
        try:
            self.sink.write(text)
        except OSError:
            self.proc.kill()
            raise


def run_c(exe: Path | str, args=(), timeout: float | None = None) -> tuple[int, str, str]:
    """Runs a compiled model: (returncode, stdout, stderr)."""
    done = run_captured([str(exe), *map(str, args)], timeout)
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


def python_program(source: str, directory: str) -> list[str]:
    """The command that runs generated Python as a program, written into `directory`."""
    path = Path(directory) / "model.py"
    path.write_text(source, encoding="utf-8")
    return [sys.executable, str(path)]


def run_python(source: str, args=(), timeout: float | None = None) -> tuple[int, str, str]:
    """Run generated Python as a program (`python model.py ARGS`), as run_c runs a C program."""
    with tempfile.TemporaryDirectory(prefix="bgc-") as tmp:
        path = Path(tmp) / "model.py"
        path.write_text(source, encoding="utf-8")
        proc = subprocess.run([sys.executable, str(path), *map(str, args)], capture_output=True,
                              text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr
