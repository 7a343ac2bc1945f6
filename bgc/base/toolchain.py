"""The C toolchain: which compiler bgc builds generated code with (cc, else $CC), its flags
and identity, and running it, with its failures told apart (a full disk, a broken compiler, a
bug in bgc).  What it builds is kept in the compile cache (bgc.base.cache).

A compiler failure on generated code is a bug in bgc, not a model error: it raises
BackendError with the compiler's messages.  BackendError is also the failure of the cache
and of starting or importing generated code (bgc.base.cache, bgc.base.processes).
"""
from __future__ import annotations

import functools
import os
import re
import shlex
import shutil
import subprocess
import tempfile
from pathlib import Path


class BackendError(RuntimeError):
    """The generated code could not be compiled or loaded (a bgc bug or a broken toolchain)."""


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


def c_compiler(cc: str | None = None) -> list[str]:
    """The compiler command: cc, else $CC, else "cc" (split like a shell word list)."""
    return shlex.split(cc or os.environ.get("CC") or "cc")


def have_c_compiler(cc: str | None = None) -> bool:
    command = c_compiler(cc)
    return bool(command) and shutil.which(command[0]) is not None


def c_flags() -> tuple[str, ...]:
    """The compile flags of the C backend: $BGC_CFLAGS (split like shell words) if set, else
    C_FLAGS.  The test suite sets -O0 (five times faster to build; with -std=c99 and no
    -ffast-math the arithmetic is the same IEEE arithmetic at every level)."""
    given = os.environ.get("BGC_CFLAGS")
    return tuple(shlex.split(given)) if given else C_FLAGS


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


def model_part_flags(flags: tuple[str, ...], size: int) -> tuple[str, ...]:
    """The flags a linked model part of `size` characters is compiled with: LARGE_PART_FLAGS
    for a large part when the flags are bgc's own C_FLAGS, else the flags as they are."""
    return LARGE_PART_FLAGS if size > LARGE_PART and tuple(flags) == C_FLAGS else tuple(flags)


def select(cc, flags) -> tuple[list[str], tuple[str, ...], str]:
    """What a build uses: the compiler command (cc, else $CC, else cc), the flags (flags, else
    c_flags()) and the compiler's identity (compiler_identity)."""
    command = c_compiler(cc)
    if not command:
        raise BackendError("no C compiler given")
    flags = c_flags() if flags is None else tuple(flags)
    return command, flags, compiler_identity(tuple(command))


def build(tmp: Path, command, flags, name: str, source: str, out_args: list[str],
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


def _compile(argv: list[str], cwd: Path | None = None) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(argv, capture_output=True, text=True, cwd=cwd)
    except OSError as error:
        raise BackendError(f"cannot run the C compiler {argv[0]!r}: {error.strerror}.  Set CC "
                           "to a working C99 compiler, or use --backend python.") from None


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
