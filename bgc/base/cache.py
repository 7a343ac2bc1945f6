"""The compile cache: what bgc builds (programs, the runtime's object, the interpreter, Python
bytecode) kept in one directory under names made from what it was made of (the source, the
compiler's identity, the flags), each file with its SHA-256 beside it, checked before every
use and put in place whole, so that concurrent runs share it safely.  The compiler is
bgc.base.toolchain's.
"""
from __future__ import annotations

import atexit
import functools
import hashlib
import json
import os
import py_compile
import shutil
import stat
import sys
import tempfile
from pathlib import Path

from . import toolchain
from .toolchain import BackendError, C_LIBS, CompilerOutOfSpace

_EXE_SUFFIX = ".exe" if os.name == "nt" else ""

# What bgc.execute.prebuild built when the package was installed, named as in the cache: the files
# whose every input (source, compiler, flags) matches a run's are copied from here instead of
# being built.  An editable install or a machine without a compiler has none.
PREBUILT = Path(__file__).resolve().parent.parent / "prebuilt"


def cache_dir() -> Path:
    """$BGC_CACHE_DIR, else ~/.cache/bgc (created on demand); a private temporary directory,
    with a warning, when that one cannot be written."""
    return own_cache_dir() or _private_cache(str(_cache_path()))


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


def _cache_path() -> Path:
    return Path(os.environ.get("BGC_CACHE_DIR") or Path.home() / ".cache" / "bgc")


@functools.lru_cache(maxsize=None)
def _private_cache(unusable: str) -> Path:
    print(f"warning: the cache directory {unusable} cannot be written; compiling into a "
          "temporary directory (set BGC_CACHE_DIR)", file=sys.stderr)
    tmp = tempfile.TemporaryDirectory(prefix="bgc-cache-")
    atexit.register(tmp.cleanup)
    return Path(tmp.name)


def compile_c(source: str, cc: str | None = None, flags: tuple[str, ...] | None = None) -> Path:
    """The executable built from source, from the cache when the same source was built before
    with the same compiler (toolchain.compiler_identity) and flags, and the cached file is
    still one it can run (usable).  Written atomically (temporary file, then os.replace), so
    concurrent builds are safe."""
    command, flags, identity = toolchain.select(cc, flags)
    key = _key([source, command, list(flags), list(C_LIBS), identity])
    return _cached(f"bgc-{key}{_EXE_SUFFIX}", True, lambda tmp: toolchain.build(
        tmp, command, flags, "model.c", source, [f"model{_EXE_SUFFIX}"], C_LIBS))


def compile_c_linked(model: str, runtime: str, cc: str | None = None,
                     flags: tuple[str, ...] | None = None) -> Path:
    """The executable of a model part (bgc.codegen.emit.emit_c(..., linked=True)) linked with the
    runtime unit (bgc.codegen.emit.c_runtime_unit).  The runtime is compiled once per machine: into
    the cache as an object file keyed by its source, the compiler (toolchain.compiler_identity)
    and the flags; each model then costs only its own part.  Both are cached and checked as
    compile_c's programs are; an object that does not link is built again, once."""
    command, flags, identity = toolchain.select(cc, flags)
    part_flags = toolchain.model_part_flags(flags, len(model))
    key = _key(["linked", model, _runtime_key(runtime, command, flags, identity), command,
                list(part_flags), list(C_LIBS), identity])

    def runtime_object() -> Path:
        return compile_runtime(runtime, cc, flags)

    def link(tmp: Path) -> Path:
        objects = [str(runtime_object())]
        try:
            return toolchain.build(tmp, command, part_flags, "model.c", model,
                                   [f"model{_EXE_SUFFIX}", *objects], C_LIBS)
        except CompilerOutOfSpace:
            raise
        except BackendError:
            evict(Path(objects[0]))  # (a runtime object damaged behind its checksum)
            return toolchain.build(tmp, command, part_flags, "model.c", model,
                                   [f"model{_EXE_SUFFIX}", str(runtime_object())], C_LIBS)

    return _cached(f"bgc-{key}{_EXE_SUFFIX}", True, link)


def compile_runtime(runtime: str, cc: str | None = None,
                    flags: tuple[str, ...] | None = None) -> Path:
    """The runtime unit's object file (compile_c_linked), from the cache, else built into it
    once per machine, keyed by its source, the compiler and the flags."""
    command, flags, identity = toolchain.select(cc, flags)
    return _cached(f"bgc-runtime-{_runtime_key(runtime, command, flags, identity)}.o", False,
                   lambda tmp: toolchain.build(tmp, command, flags, "runtime.c", runtime,
                                               ["-c", "runtime.o"]))


def _runtime_key(runtime: str, command, flags, identity: str) -> str:
    return _key(["runtime", runtime, command, list(flags), identity])


def compile_vm(sources: str, unit, cc: str | None = None,
               flags: tuple[str, ...] | None = None) -> Path:
    """The interpreter (bgc.codegen.vm), built once per machine into the cache from the text unit()
    returns, keyed by `sources` (the digest of the files that text is made of: so a run that
    finds it cached does not make the text) with the compiler and flags, and checked as
    compile_c's programs are."""
    command, flags, identity = toolchain.select(cc, flags)
    key = _key(["vm", sources, command, list(flags), list(C_LIBS), identity])
    return _cached(f"bgc-vm-{key}{_EXE_SUFFIX}", True, lambda tmp: toolchain.build(
        tmp, command, flags, "vm.c", unit(), [f"vm{_EXE_SUFFIX}"], C_LIBS))


def cache_bytes(data: bytes, suffix: str) -> Path:
    """A file of the cache named by the SHA-256 of its bytes (checked before reuse, written
    atomically): an interpreter's program (bgc.codegen.vm)."""
    digest = hashlib.sha256(data).hexdigest()

    def write(tmp: Path) -> Path:
        (tmp / "program").write_bytes(data)
        return tmp / "program"

    return _cached(f"bgc-{digest[:40]}{suffix}", False, write)


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


def _key(parts: list) -> str:
    return hashlib.sha256(json.dumps(parts).encode()).hexdigest()[:40]


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


def _digest_path(path: Path) -> Path:
    return path.with_name(path.name + ".sha256")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()
