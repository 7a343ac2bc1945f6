"""Files the command line writes, and the one place that decides how each is written.

An output named `-` (STDOUT) is standard output, for every output option; the command line
writes it (bgc.cli), nothing here checks or replaces it.  Any other target (`-o`, `--plot`, a
table, a trajectory) is checked before any work (check_target): not a directory, in a
directory that exists and can be written, not read-only, and not a file the same command
reads (the model, a library or a table it reads, a reference: the same file under any name,
through a symbolic or a hard link: compared by device and inode).  Then, by what the path
names (destination):

- nothing yet, or a regular file: the data goes to a hidden file beside it (created with the
  user's umask, like any new file) renamed into place at the end, so that a reader never sees
  half a file and a failed command leaves nothing behind;
- a symbolic link: the same, beside the file the link leads to, which is replaced; the link
  stays a link;
- a character device (`-o /dev/null`) or a FIFO: written straight into, as a shell's `>`
  does; it is never replaced by a regular file;
- anything else (a socket, a block device) is refused.

A simulation's CSV is the exception to "all or nothing": its rows stream into the hidden file
as the run computes them, and if the run fails or is interrupted, the rows computed are
renamed into place all the same (`Partial.keep`), cut back to the last whole row, the command
saying so.  Only a process killed outright (SIGKILL) leaves the hidden file,
`.NAME.bgc-PID.part`, behind.

A write that fails (a full disk, a closed pipe, an I/O error) is an OutputError that says so in
one line: `cannot write 'out.csv': No space left on device`; the hidden file is removed.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path


class OutputError(Exception):
    """The output path cannot be written (the message says why, for people)."""


class OutputIsInput(OutputError):
    """The output path names a file the same command reads (an error of the run, not of the
    command line's form: bgc exits 1)."""


STDOUT = "-"  # an output of this name is standard output (`./-` names a file)


def is_stdout(path) -> bool:
    """Whether an output option's value names standard output."""
    return path is not None and os.fspath(path) == STDOUT


def identity(path) -> tuple[int, int] | None:
    """(device, inode) of the file path leads to (through symbolic links), None if none."""
    info = _stat(path)
    return None if info is None else (info.st_dev, info.st_ino)


def stdout_identity() -> tuple[int, int] | None:
    """(device, inode) of the regular file standard output is (`> out.csv`), else None."""
    try:
        info = os.fstat(1)
    except OSError:
        return None
    return (info.st_dev, info.st_ino) if stat.S_ISREG(info.st_mode) else None


def same_target(a, b) -> bool:
    """Whether two output paths name one file: the same device and inode, or, where one is
    not there yet, the same path once symbolic links are followed."""
    first, second = identity(a), identity(b)
    if first is not None and second is not None:
        return first == second
    try:
        return os.path.realpath(a) == os.path.realpath(b)
    except (OSError, ValueError):
        return os.path.abspath(a) == os.path.abspath(b)


def reason(error: OSError) -> str:
    """An OSError as people read it: `No space left on device`."""
    return error.strerror or str(error)


def _stat(path) -> os.stat_result | None:
    """os.stat through symbolic links; None if nothing is there (or a link leads nowhere)."""
    try:
        return os.stat(path)
    except (OSError, ValueError):  # (missing, a link to nowhere or in a loop, a NUL in it)
        return None


def _kind(mode: int) -> str:
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def streamed(mode: int) -> bool:
    """A file written straight into, never replaced: a character device or a FIFO."""
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def check_target(path: str | os.PathLike, inputs=()) -> Path:
    """The path as a Path, if a file can be written there (`-`, standard output, is not
    looked at); else OutputError.  inputs: the files the command reads, as (what, path) pairs
    (("the model file", "m.bg")); an output that is one of them, under any name, is an
    OutputIsInput."""
    if is_stdout(path):
        return Path(path)
    try:
        return _check_target(path, inputs)
    except OutputError:
        raise
    except (OSError, ValueError) as error:  # (a name too long, a loop of links ...)
        raise OutputError(f"cannot write '{path}': {reason(error)}") from None


def _check_target(path, inputs) -> Path:
    target = Path(path)
    info = _stat(target)
    if info is not None:
        for what, name in inputs:
            if identity(name) == (info.st_dev, info.st_ino):
                same = "" if os.path.abspath(name) == os.path.abspath(path) else f" '{name}'"
                raise OutputIsInput(f"cannot write '{path}': it is {what}{same}, which this "
                                    "command reads; name another output file")
        if stat.S_ISDIR(info.st_mode):
            raise OutputError(f"cannot write '{path}': it is a directory")
        if not stat.S_ISREG(info.st_mode) and not streamed(info.st_mode):
            raise OutputError(f"cannot write '{path}': it is {_kind(info.st_mode)}")
        if not os.access(target, os.W_OK):
            raise OutputError(f"cannot write '{path}': the file exists and is read-only")
        if streamed(info.st_mode):
            return target
    elif target.is_dir():  # (a directory that cannot be searched)
        raise OutputError(f"cannot write '{path}': it is a directory")
    parent = destination(target)[0].parent
    if not parent.is_dir():
        raise OutputError(f"cannot write '{path}': directory '{parent}' does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write '{path}': directory '{parent}' is not writable")
    return target


def destination(path: str | os.PathLike) -> tuple[Path, bool]:
    """Where the data for `path` goes, and whether straight into it (a character device or a
    FIFO) rather than by a hidden file beside it renamed into place: the path itself, or, for
    a symbolic link, the file it leads to (which need not exist yet)."""
    target = Path(path)
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    info = _stat(target)
    return target, info is not None and streamed(info.st_mode)


def hidden_name(name: str) -> str:
    """The hidden file's name for an output named `name`: `.NAME.bgc-PID.part`, NAME cut to
    its first 150 characters when it is long (a file name has at most 255 bytes)."""
    if len(name.encode("utf-8", "surrogateescape")) > 200:
        name = name[:150]
    return f".{name}.bgc-{os.getpid()}.part"


class Partial:
    """A file being written for `path` (see the module's docstring): .file (binary) is a
    hidden file beside it, or the device or FIFO itself; commit() (or keep()) puts it into
    place, discard() removes it; leaving the `with` block without either removes it.  A write
    through write() and a commit that fail raise OutputError (the hidden file removed)."""

    def __init__(self, path: str | os.PathLike):
        self.target = check_target(path)
        self.name = str(path)
        self.dest, self.direct = destination(self.target)
        if self.direct:
            self.tmp = None
            flags = os.O_WRONLY
        else:
            self.tmp = self.dest.with_name(hidden_name(self.dest.name))
            flags = os.O_RDWR | os.O_CREAT | os.O_TRUNC  # (read back: the last row)
        try:
            fd = os.open(self.tmp or self.dest, flags, 0o666)
        except OSError as error:
            raise OutputError(f"cannot write '{path}': {reason(error)}") from None
        self.file = os.fdopen(fd, "wb")
        self.done = False

    def failed(self, error: OSError) -> OutputError:
        """The OutputError for a write that failed, the hidden file removed."""
        self.discard()
        return OutputError(f"cannot write '{self.name}': {reason(error)}")

    def write(self, data: bytes) -> None:
        try:
            self.file.write(data)
        except OSError as error:
            raise self.failed(error) from None

    def commit(self) -> None:
        try:
            self.file.close()
            if not self.direct:
                os.replace(self.tmp, self.dest)
        except OSError as error:
            raise self.failed(error) from None
        self.done = True

    def keep(self) -> None:
        """A failed run's rows, into place all the same, cut back to the last whole row (a
        device or a FIFO keeps what it was given)."""
        if not self.direct:
            try:
                self.file.flush()
            except OSError:
                pass  # (what did not reach the file is not in it; the cut below holds)
            cut_to_whole_rows(self.file.fileno(), 0)
        self.commit()

    def rows_end(self) -> str | None:
        """The time of the last whole row written so far (None: none, or a device or FIFO,
        which cannot be read back)."""
        if self.direct:
            return None
        try:
            self.file.flush()
        except OSError:
            pass
        return last_row_time_fd(self.file.fileno(), 0)

    def discard(self) -> None:
        if not self.file.closed:
            try:
                self.file.close()
            except OSError:
                pass  # (the data that could not be written goes with the file)
        if not self.done and self.tmp is not None:
            try:
                self.tmp.unlink(missing_ok=True)
            except OSError:
                pass
        self.done = True

    def __enter__(self) -> Partial:
        return self

    def __exit__(self, *exc) -> None:
        if not self.done:
            self.discard()


def write_atomic(path: str | os.PathLike, text: str | bytes) -> None:
    """All of `text` (UTF-8; or bytes as they are) at `path`, or nothing (OutputError)."""
    with Partial(path) as out:
        out.write(text if isinstance(text, bytes) else text.encode("utf-8"))
        out.commit()


class _Reading:
    """A descriptor that reads the file behind fd: fd itself, or, for one opened to write only
    (a shell's `> out.csv` on stdout), the same file opened again to read (through /proc or
    /dev/fd, where the system has them); OSError if there is none."""

    def __init__(self, fd: int):
        self.fd, self.own = fd, False
        try:
            os.pread(fd, 0, 0)
            return
        except OSError:
            pass
        info = os.fstat(fd)
        for name in (f"/proc/self/fd/{fd}", f"/dev/fd/{fd}"):
            try:
                again = os.open(name, os.O_RDONLY)
            except OSError:
                continue
            same = os.fstat(again)
            if (same.st_dev, same.st_ino) == (info.st_dev, info.st_ino):
                self.fd, self.own = again, True
                return
            os.close(again)
        raise OSError(f"cannot read back descriptor {fd}")

    def __enter__(self) -> int:
        return self.fd

    def __exit__(self, *exc) -> None:
        if self.own:
            os.close(self.fd)


def _rfind_newline(fd: int, start: int, end: int) -> int:
    """The offset of the last newline in [start, end) of the file behind fd, or -1."""
    pos = end
    while pos > start:
        begin = max(start, pos - (1 << 16))
        data = os.pread(fd, pos - begin, begin)
        i = data.rfind(b"\n")
        if i >= 0:
            return begin + i
        pos = begin
    return -1


def offset(fd: int) -> int:
    """Where the next write to fd lands (its end when it appends: `>> out.csv`); OSError
    for a descriptor that has none (a pipe)."""
    where = os.lseek(fd, 0, os.SEEK_CUR)
    try:
        import fcntl
        if fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_APPEND:
            where = os.fstat(fd).st_size
    except (ImportError, OSError):
        pass
    return where


def cut_to_whole_rows(fd: int, start: int) -> None:
    """Cuts the regular file behind fd back to its last complete line, no further back than
    offset `start` (what was there before is not ours); the file offset goes to its new end.
    Anything but a regular file, or a file that cannot be cut, is left as it is."""
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return
        end = os.fstat(fd).st_size
        with _Reading(fd) as reading:
            keep = max(_rfind_newline(reading, start, end) + 1 or start, start)
        if keep < end:
            os.ftruncate(fd, keep)
        os.lseek(fd, keep, os.SEEK_SET)
    except OSError:
        pass


def _row_time(line: bytes) -> str | None:
    if not line or line.startswith(b"t,") or line.startswith(b"s,") or line == b"s":
        return None  # (the header, and the units' row of --units)
    return line.split(b",", 1)[0].decode("ascii", "replace")


def last_row_time_fd(fd: int, start: int) -> str | None:
    """The time of the last complete row of the CSV behind fd from offset `start` on (its
    header aside), or None if it has none or cannot be read back (a pipe)."""
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        with _Reading(fd) as reading:
            last = _rfind_newline(reading, start, os.fstat(fd).st_size)
            if last < 0:
                return None
            first = max(_rfind_newline(reading, start, last) + 1 or start, start)
            return _row_time(os.pread(reading, min(last - first, 64), first))
    except OSError:
        return None


def last_row_time(path: str | os.PathLike) -> str | None:
    """The time of the last complete row of a CSV (its header aside), or None if it has none:
    what a failed run's kept file holds, as the command line reports it."""
    with open(path, "rb") as f:
        return last_row_time_fd(f.fileno(), 0)


def last_row_time_text(text: str) -> str | None:
    """The same for CSV text: the time of its last complete row, or None."""
    lines = text.encode("utf-8", "replace").split(b"\n")[:-1]
    return _row_time(lines[-1]) if lines else None
