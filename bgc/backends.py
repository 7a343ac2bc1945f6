"""Running generated code: compile C into a content-keyed cache, run it, import Python.

A compiler failure on generated code is a bug in bgc, not a model error: it raises
BackendError with the compiler's messages.
"""
from __future__ import annotations

import atexit
import codecs
import functools
import hashlib
import importlib.util
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

C_FLAGS = ("-O2", "-std=c99")  # the C backend's, unless $BGC_CFLAGS says otherwise
C_LIBS = ("-lm",)
_EXE_SUFFIX = ".exe" if os.name == "nt" else ""


class BackendError(RuntimeError):
    """The generated code could not be compiled or loaded (a bgc bug or a broken toolchain)."""


def cache_dir() -> Path:
    """$BGC_CACHE_DIR, else ~/.cache/bgc (created on demand); a private temporary directory,
    with a warning, when that one cannot be written."""
    path = Path(os.environ.get("BGC_CACHE_DIR") or Path.home() / ".cache" / "bgc")
    try:
        path.mkdir(parents=True, exist_ok=True)
        if os.access(path, os.W_OK | os.X_OK):
            return path
    except OSError:
        pass
    return _private_cache(str(path))


@functools.lru_cache(maxsize=None)
def _private_cache(unusable: str) -> Path:
    print(f"warning: the cache directory {unusable} cannot be written; compiling into a "
          "temporary directory (set BGC_CACHE_DIR)", file=sys.stderr)
    tmp = tempfile.TemporaryDirectory(prefix="bgc-cache-")
    atexit.register(tmp.cleanup)
    return Path(tmp.name)


def c_compiler(cc: str | None = None) -> list[str]:
    """The compiler command: cc, else $CC, else "cc" (split like a shell word list)."""
    return shlex.split(cc or os.environ.get("CC") or "cc")


def have_c_compiler(cc: str | None = None) -> bool:
    command = c_compiler(cc)
    return bool(command) and shutil.which(command[0]) is not None


@functools.lru_cache(maxsize=None)
def compiler_identity(command: tuple[str, ...]) -> str:
    """What names the compiler in the cache key: its resolved path, size and modification
    time, and what `--version` prints (so an upgraded or different compiler builds anew)."""
    where = shutil.which(command[0]) if command else None
    facts = [str(where)]
    if where:
        info = os.stat(where)
        facts.append(f"{info.st_size}:{info.st_mtime_ns}")
        try:
            done = subprocess.run([*command, "--version"], capture_output=True, text=True,
                                  timeout=30)
            facts.append(done.stdout)
        except (OSError, subprocess.SubprocessError):
            pass
    return "\n".join(facts)


def c_flags() -> tuple[str, ...]:
    """The compile flags of the C backend: $BGC_CFLAGS (split like shell words) if set, else
    C_FLAGS.  The test suite sets -O0 (five times faster to build; with -std=c99 and no
    -ffast-math the arithmetic is the same IEEE arithmetic at every level)."""
    given = os.environ.get("BGC_CFLAGS")
    return tuple(shlex.split(given)) if given else C_FLAGS


def compile_c(source: str, cc: str | None = None, flags: tuple[str, ...] | None = None) -> Path:
    """The executable built from source, from the cache when the same source was built before
    with the same compiler (compiler_identity) and flags, and the cached file is still the one
    built (its SHA-256, kept beside it, checked before each use).  Written atomically
    (temporary file, then os.replace), so concurrent builds are safe."""
    command = c_compiler(cc)
    if not command:
        raise BackendError("no C compiler given")
    flags = c_flags() if flags is None else tuple(flags)
    key = hashlib.sha256(json.dumps([source, command, list(flags), list(C_LIBS),
                                     compiler_identity(tuple(command))]).encode())
    cache = cache_dir()
    exe = cache / f"bgc-{key.hexdigest()[:40]}{_EXE_SUFFIX}"
    digest = exe.with_name(exe.name + ".sha256")
    if exe.is_file() and digest.is_file() and digest.read_text().strip() == _sha256(exe):
        return exe
    with tempfile.TemporaryDirectory(dir=cache, prefix="build-") as tmp:
        src, out = Path(tmp) / "model.c", Path(tmp) / f"model{_EXE_SUFFIX}"
        src.write_text(source, encoding="utf-8")
        _run_compiler([*command, *flags, str(src), "-o", str(out), *C_LIBS], Path(tmp))
        (Path(tmp) / "sha256").write_text(_sha256(out) + "\n")
        os.replace(out, exe)
        os.replace(Path(tmp) / "sha256", digest)
    return exe


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _run_compiler(argv: list[str], workdir: Path, cwd: Path | None = None) -> None:
    """Runs the compiler (in directory cwd, if given); BackendError if it fails: a broken or
    missing compiler when it cannot build a trivial program either (told as such), else a bug
    in bgc."""
    done = _compile(argv, cwd)
    if done.returncode == 0:
        return
    trivial = workdir / "trivial.c"
    trivial.write_text("int main(void) { return 0; }\n")
    check = _compile([argv[0], *C_FLAGS, str(trivial), "-o", str(workdir / "trivial")])
    if check.returncode != 0:
        raise BackendError(
            f"the C compiler does not work: '{shlex.join(argv[:1])}' cannot build a trivial "
            f"program either (status {check.returncode}).  Set CC to a working C99 compiler, or "
            f"use --backend python.\n$ {shlex.join(argv)}\n{done.stderr}".rstrip())
    raise BackendError(
        f"the C compiler failed on generated code (a bug in bgc), status {done.returncode}:\n"
        f"$ {shlex.join(argv)}\n{done.stderr}".rstrip())


def _compile(argv: list[str], cwd: Path | None = None) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(argv, capture_output=True, text=True, cwd=cwd)
    except OSError as error:
        raise BackendError(f"cannot run the C compiler {argv[0]!r}: {error.strerror}.  Set CC "
                           "to a working C99 compiler, or use --backend python.") from None


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
        proc = subprocess.Popen(argv, stdout=fd if fd is not None else subprocess.PIPE,
                                stderr=err if progress is None else subprocess.PIPE,
                                env=child_env(), restore_signals=False)
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
    done = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=child_env())
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


def cache_python(source: str) -> Path:
    """Generated Python as a file in the cache (named by its SHA-256, checked before reuse,
    written atomically), for the warm runs of bgc.warm."""
    digest = hashlib.sha256(source.encode("utf-8")).hexdigest()
    path = cache_dir() / f"bgc-{digest[:40]}.py"
    if path.is_file() and _sha256(path) == digest:
        return path
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".build-", suffix=".py")
    with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
        f.write(source)
    os.replace(tmp, path)
    return path


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
