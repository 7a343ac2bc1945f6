"""Files the command line writes: the target checked before any work, the data written to a
hidden file beside it (created with the user's umask, like any new file) and renamed into
place, so that a reader never sees half a file and a failed command leaves nothing behind.

A simulation's CSV is the exception to "all or nothing": its rows stream into the hidden file
as the run computes them, and if the run fails or is interrupted, the rows computed are
renamed into place all the same (`Partial.keep`), the command saying so.  Only a process
killed outright (SIGKILL) leaves the hidden file, `.NAME.bgc-PID.part`, behind.
"""
from __future__ import annotations

import os
from pathlib import Path


class OutputError(Exception):
    """The output path cannot be written (the message says why, for people)."""


def check_target(path: str | os.PathLike) -> Path:
    """The path as a Path, if a file can be written there; else OutputError."""
    target = Path(path)
    parent = target.parent
    if target.is_dir():
        raise OutputError(f"cannot write '{path}': it is a directory")
    if not parent.is_dir():
        raise OutputError(f"cannot write '{path}': directory '{parent}' does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write '{path}': directory '{parent}' is not writable")
    if target.exists() and not os.access(target, os.W_OK):
        raise OutputError(f"cannot write '{path}': the file exists and is read-only")
    return target


class Partial:
    """A file being written for `path`: .file (binary) is a hidden file beside it; commit()
    (or keep()) renames it into place, discard() removes it; leaving the `with` block without
    either removes it."""

    def __init__(self, path: str | os.PathLike):
        self.target = check_target(path)
        self.tmp = self.target.with_name(f".{self.target.name}.bgc-{os.getpid()}.part")
        try:
            fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        except OSError as error:
            raise OutputError(f"cannot write '{path}': {error.strerror}") from None
        self.file = os.fdopen(fd, "wb")
        self.done = False

    def commit(self) -> None:
        self.file.close()
        os.replace(self.tmp, self.target)
        self.done = True

    keep = commit  # a failed run's rows: into place all the same

    def discard(self) -> None:
        if not self.file.closed:
            self.file.close()
        if not self.done:
            self.tmp.unlink(missing_ok=True)
        self.done = True

    def __enter__(self) -> Partial:
        return self

    def __exit__(self, *exc) -> None:
        if not self.done:
            self.discard()


def write_atomic(path: str | os.PathLike, text: str | bytes) -> None:
    """All of `text` (UTF-8; or bytes as they are) at `path`, or nothing."""
    with Partial(path) as out:
        out.file.write(text if isinstance(text, bytes) else text.encode("utf-8"))
        out.commit()


def last_row_time(path: str | os.PathLike) -> str | None:
    """The time of the last complete row of a CSV (its header aside), or None if it has none:
    what a failed run's kept file holds, as the command line reports it."""
    with open(path, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(max(0, size - 4096))
        lines = f.read().split(b"\n")
    rows = [line for line in lines[:-1] if line and not line.startswith(b"t,")]
    if not rows:
        return None
    return rows[-1].split(b",", 1)[0].decode("ascii", "replace")
