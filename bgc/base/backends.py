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
import py_compile
import re
import shlex
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

C_FLAGS = ("-O2", "-std=c99")  # the C backend's, unless $BGC_CFLAGS says otherwise
# A linked model part of more than LARGE_PART characters is compiled at -O1 where the flags
# are C_FLAGS: the compiler's time at -O2 grows faster than the code (two to three times
# -O1's on the 16- and 64-link chains and the 32-section ladder with symbolic resistances),
# and the model functions it makes run as fast (benchmarks/compile_scale.py measures both,
# in the same run).  80 kB: that ladder's part without the Jacobian (an explicit solver's
# run) is 90 kB, and took 1.0 s at -O2 against 0.67 s at -O1 with it.  The runtime stays at
# -O2.
LARGE_PART = 80_000
LARGE_PART_FLAGS = ("-O1", "-std=c99")
C_LIBS = ("-lm",)
_EXE_SUFFIX = ".exe" if os.name == "nt" else ""


class BackendError(RuntimeError):
    """The generated code could not be compiled or loaded (a bgc bug or a broken toolchain)."""


def cache_dir() -> Path:
    """$BGC_CACHE_DIR, else ~/.cache/bgc (created on demand); a private temporary directory,
    with a warning, when that one cannot be written."""
    return own_cache_dir() or _private_cache(str(_cache_path()))


def _cache_path() -> Path:
    return Path(os.environ.get("BGC_CACHE_DIR") or Path.home() / ".cache" / "bgc")


def own_cache_dir() -> Path | None:
    """The cache directory (created on demand) if it can be written, else None (and nothing
    said): for what is only worth keeping there (bgc.front.parser's tables)."""
    path = _cache_path()
    try:
        path.mkdir(parents=True, exist_ok=True)
        if os.access(path, os.W_OK | os.X_OK):
            return path
    except OSError:
        pass
    return None


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
    with the same compiler (compiler_identity) and flags, and the cached file is still one it
    can run (usable).  Written atomically (temporary file, then os.replace), so concurrent
    builds are safe."""
    command, flags, identity = _toolchain(cc, flags)
    key = _key([source, command, list(flags), list(C_LIBS), identity])
    return _cached(f"bgc-{key}{_EXE_SUFFIX}", True, lambda tmp: _build(
        tmp, command, flags, "model.c", source, [f"model{_EXE_SUFFIX}"], C_LIBS))


def compile_c_linked(model: str, runtime: str, cc: str | None = None,
                     flags: tuple[str, ...] | None = None) -> Path:
    """The executable of a model part (bgc.codegen.emit.emit_c(..., linked=True)) linked with the
    runtime unit (bgc.codegen.emit.c_runtime_unit).  The runtime is compiled once per machine: into
    the cache as an object file keyed by its source, the compiler (compiler_identity) and the
    flags; each model then costs only its own part.  Both are cached and checked as compile_c's
    programs are; an object that does not link is built again, once."""
    command, flags, identity = _toolchain(cc, flags)
    part_flags = model_part_flags(flags, len(model))
    key = _key(["linked", model, _runtime_key(runtime, command, flags, identity), command,
                list(part_flags), list(C_LIBS), identity])

    def runtime_object() -> Path:
        return compile_runtime(runtime, cc, flags)

    def link(tmp: Path) -> Path:
        objects = [str(runtime_object())]
        try:
            return _build(tmp, command, part_flags, "model.c", model,
                          [f"model{_EXE_SUFFIX}", *objects], C_LIBS)
        except CompilerOutOfSpace:
            raise
        except BackendError:
            evict(Path(objects[0]))  # (a runtime object damaged behind its checksum)
            return _build(tmp, command, part_flags, "model.c", model,
                          [f"model{_EXE_SUFFIX}", str(runtime_object())], C_LIBS)

    return _cached(f"bgc-{key}{_EXE_SUFFIX}", True, link)


def compile_runtime(runtime: str, cc: str | None = None,
                    flags: tuple[str, ...] | None = None) -> Path:
    """The runtime unit's object file (compile_c_linked), from the cache, else built into it
    once per machine, keyed by its source, the compiler and the flags."""
    command, flags, identity = _toolchain(cc, flags)
    return _cached(f"bgc-runtime-{_runtime_key(runtime, command, flags, identity)}.o", False,
                   lambda tmp: _build(tmp, command, flags, "runtime.c", runtime,
                                      ["-c", "runtime.o"]))


def _runtime_key(runtime: str, command, flags, identity: str) -> str:
    return _key(["runtime", runtime, command, list(flags), identity])


def compile_vm(sources: str, unit, cc: str | None = None,
               flags: tuple[str, ...] | None = None) -> Path:
    """The interpreter (bgc.codegen.vm), built once per machine into the cache from the text unit()
    returns, keyed by `sources` (the digest of the files that text is made of: so a run that
    finds it cached does not make the text) with the compiler and flags, and checked as
    compile_c's programs are."""
    command, flags, identity = _toolchain(cc, flags)
    key = _key(["vm", sources, command, list(flags), list(C_LIBS), identity])
    return _cached(f"bgc-vm-{key}{_EXE_SUFFIX}", True, lambda tmp: _build(
        tmp, command, flags, "vm.c", unit(), [f"vm{_EXE_SUFFIX}"], C_LIBS))


def cache_bytes(data: bytes, suffix: str) -> Path:
    """A file of the cache named by the SHA-256 of its bytes (checked before reuse, written
    atomically): an interpreter's program (bgc.codegen.vm)."""
    digest = hashlib.sha256(data).hexdigest()

    def write(tmp: Path) -> Path:
        (tmp / "program").write_bytes(data)
        return tmp / "program"

    return _cached(f"bgc-{digest[:40]}{suffix}", False, write)


def model_part_flags(flags: tuple[str, ...], size: int) -> tuple[str, ...]:
    """The flags a linked model part of `size` characters is compiled with: LARGE_PART_FLAGS
    for a large part when the flags are bgc's own C_FLAGS, else the flags as they are."""
    return LARGE_PART_FLAGS if size > LARGE_PART and tuple(flags) == C_FLAGS else tuple(flags)


def _toolchain(cc, flags) -> tuple[list[str], tuple[str, ...], str]:
    command = c_compiler(cc)
    if not command:
        raise BackendError("no C compiler given")
    flags = c_flags() if flags is None else tuple(flags)
    return command, flags, compiler_identity(tuple(command))


def _key(parts: list) -> str:
    return hashlib.sha256(json.dumps(parts).encode()).hexdigest()[:40]


def _build(tmp: Path, command, flags, name: str, source: str, out_args: list[str],
           libs=()) -> Path:
    """Compiles source (written to tmp/name) in directory tmp: `command flags name -o ARGS
    libs`, ARGS[0] the output (or `-c OUT`); the output's path.  File names are relative, so
    two builds of the same source give the same bytes."""
    (tmp / name).write_text(source, encoding="utf-8")
    if out_args[0] == "-c":
        argv, out = [*command, *flags, "-c", name, "-o", out_args[1]], out_args[1]
    else:
        argv, out = [*command, *flags, name, "-o", *out_args, *libs], out_args[0]
    run_compiler(argv, tmp, cwd=tmp)
    return tmp / out


def _cached(name: str, executable: bool, build) -> Path:
    """cache_dir()/name if it is usable; else build(a temporary directory in the cache) and
    the file it returns put in place with its SHA-256 beside it (both renamed into place, so
    no half-written file is ever seen under its name).  Whatever stands in the way (a
    directory, a file that cannot run) is replaced; a cache that cannot be written is a
    BackendError."""
    cache = cache_dir()
    path = cache / name
    if usable(path, executable):
        return path
    seed = PREBUILT / name
    if usable(seed, executable):  # built when bgc was installed (bgc.execute.prebuild): copied
        def build(tmp: Path, seed=seed) -> Path:
            shutil.copyfile(seed, tmp / "seed")
            return tmp / "seed"
    try:
        with tempfile.TemporaryDirectory(dir=cache, prefix="build-") as tmp:
            built = build(Path(tmp))
            digest = Path(tmp) / "sha256"
            digest.write_text(_sha256(built) + "\n")
            if executable:
                os.chmod(built, os.stat(built).st_mode | stat.S_IXUSR)
            for target in (path, _digest_path(path)):
                if target.is_dir() and not target.is_symlink():
                    shutil.rmtree(target, ignore_errors=True)
            os.replace(digest, _digest_path(path))
            os.replace(built, path)
    except OSError as error:
        raise BackendError(f"cannot write into the compile cache {cache}: "
                           f"{error.strerror or error}") from None
    return path


def write_cached(path: Path, write) -> None:
    """A file of the cache that is not a program (the parser's tables, bgc.front.parser): write(f)
    into a temporary file beside it, then renamed into place whole."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".build-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


# What bgc.execute.prebuild built when the package was installed, named as in the cache: the files
# whose every input (source, compiler, flags) matches a run's are copied from here instead of
# being built.  An editable install or a machine without a compiler has none.
PREBUILT = Path(__file__).resolve().parent.parent / "prebuilt"


def _digest_path(path: Path) -> Path:
    return path.with_name(path.name + ".sha256")


def usable(path: Path, executable: bool = True, sha256: str | None = None) -> bool:
    """Whether a file of the cache is one bgc built and can use: a regular file (not a link
    nor a directory), executable if it is a program, whose SHA-256 is the one kept beside it
    (NAME.sha256) and, if given, sha256.  Anything else is built again."""
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return False
        if executable and not os.access(path, os.X_OK):
            return False
        kept = _digest_path(path).read_text(encoding="ascii").strip()
        return (sha256 is None or kept == sha256) and kept == _sha256(path)
    except (OSError, ValueError):
        return False


def evict(path: Path) -> None:
    """Removes a file of the cache (and its digest) that turned out unusable: a program that
    could not be started, an object that did not link; the next use builds it again."""
    for target in (path, _digest_path(path)):
        try:
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target, ignore_errors=True)
            else:
                target.unlink()
        except OSError:
            pass


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


class CompilerOutOfSpace(BackendError):
    """The compiler could not write a file (a full disk, a quota, a file size limit): nothing
    in the cache is to blame, nothing is evicted."""


# What a compiler says when a file it writes cannot grow: a full disk, a quota, a file size
# limit (as an error, or as the death of its linker or assembler by SIGXFSZ).
_FULL = (("No space left on device", "No space left on device"),
         ("Disk quota exceeded", "Disk quota exceeded"),
         ("File too large", "File too large"),
         ("File size limit exceeded", "File too large"))


def _compiler_out_of_space(stderr: str, workdir: Path) -> str | None:
    """The one-line reason when the compiler failed because it could not write a file (its
    temporary files, in $TMPDIR; its output, in the build directory of the cache): the
    directory and the system's reason; None for any other failure."""
    for said, reason in _FULL:
        for line in stderr.splitlines():
            if said in line:
                where = workdir.parent  # (the cache: relative names are the build directory's)
                for path in re.findall(r"(/[^\s:'\"`]+)", line):
                    path = Path(path)
                    if path.parent.is_dir():
                        where = workdir.parent if path.parent == workdir else path.parent
                        break
                return f"the C compiler cannot write into {where}: {reason}"
    return None


def run_compiler(argv: list[str], workdir: Path, cwd: Path | None = None) -> None:
    """Runs the compiler (in directory cwd, if given); BackendError if it fails: a full disk
    (or quota, or file size limit) where it writes, told in one line with the directory; a
    broken or missing compiler when it cannot build a trivial program either (told as such),
    else a bug in bgc."""
    done = _compile(argv, cwd)
    if done.returncode == 0:
        return
    full = _compiler_out_of_space(done.stderr, workdir)
    if full:
        raise CompilerOutOfSpace(full)
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


class CannotStart(BackendError):
    """A program that could not be started (its file is not a program this machine runs, or
    not allowed to run); one in the cache is removed from it, so the next use builds it
    again."""

    def __init__(self, argv: list[str], error: OSError):
        self.path = Path(argv[0])
        where = self.path.parent
        evicted = where.is_dir() and where.resolve() == cache_dir().resolve()
        if evicted:
            evict(self.path)
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


def cache_python(source: str) -> Path:
    """Generated Python as a file in the cache (named by its SHA-256, checked before reuse,
    written atomically), for the warm runs of bgc.execute.warm."""
    digest = hashlib.sha256(source.encode("utf-8")).hexdigest()

    def write(tmp: Path) -> Path:
        (tmp / "model.py").write_text(source, encoding="utf-8", newline="")
        return tmp / "model.py"

    return _cached(f"bgc-{digest[:40]}.py", False, write)


def python_bytecode(source: Path) -> Path | None:
    """The bytecode of a cached Python program (bgc-....TAG.pyc beside it, TAG this
    interpreter's, e.g. cpython-311), compiled once, so that a run starts without compiling
    the whole runtime again (`python model.py` does, about 40 ms); None where there is none
    (the program then runs from its source)."""
    tag = sys.implementation.cache_tag
    if tag is None:
        return None

    def write(tmp: Path) -> Path:
        py_compile.compile(str(source), cfile=str(tmp / "model.pyc"), dfile=str(source),
                           doraise=True,
                           invalidation_mode=py_compile.PycInvalidationMode.UNCHECKED_HASH)
        return tmp / "model.pyc"

    try:
        return _cached(f"{source.stem}.{tag}.pyc", False, write)
    except (BackendError, py_compile.PyCompileError):
        return None


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


def stack_usage(source: Path, include: Path, cc: str | None = None) -> dict[str, int] | None:
    """Each function's stack frame in bytes, as the C compiler reports it compiling `source`
    with -O2 -fstack-usage (gcc, clang); None without a compiler or when it cannot tell."""
    if not have_c_compiler(cc):
        return None
    with tempfile.TemporaryDirectory(prefix="bgc-stack-") as tmp:
        out = Path(tmp) / "unit.o"
        done = subprocess.run([*c_compiler(cc), "-std=c99", "-O2", "-fstack-usage",
                               f"-I{Path(include).resolve()}", "-c",
                               str(Path(source).resolve()), "-o", str(out)],
                              capture_output=True, text=True, cwd=tmp)
        usage = Path(tmp) / "unit.su"
        if done.returncode != 0 or not usage.exists():
            return None
        frames = {}
        for line in usage.read_text().splitlines():
            parts = line.split("\t")
            if len(parts) >= 2 and parts[1].strip().isdigit():
                frames[parts[0].rsplit(":", 1)[-1]] = int(parts[1])
        return frames
