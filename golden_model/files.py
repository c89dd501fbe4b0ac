"""Reading the files a run is given: regular files only.

The mesh, a layout file (``--init``) and a format-set file (``--formats``) must be regular files
(or symbolic links to one).  A named pipe (FIFO) would block the reader until something writes
to it, a device could be endless or have side effects on open, so neither is opened at all: the
path is looked at with ``stat`` first, and the file opened (without blocking) is checked again
with ``fstat`` to be the same regular file.  A refusal is an :class:`OSError` whose ``strerror``
reads as the end of a one-line message (``is a named pipe (FIFO), not a regular file``), so that
callers word it like any other OS error (:func:`describe_os_error`).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

__all__ = ["NotRegularFileError", "describe_os_error", "read_file_bytes", "file_kind", "read_regular_file", "same_file_key", "resolved_parent_key"]

_KINDS = ((stat.S_ISDIR, "directory"), (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"),
          (stat.S_ISFIFO, "named pipe (FIFO)"), (stat.S_ISSOCK, "socket"), (stat.S_ISLNK, "symbolic link"),
          (stat.S_ISREG, "regular file"))


def file_kind(mode: int) -> str:
    """``regular file``, ``directory``, ``character device``, ``named pipe (FIFO)``, ... of an ``st_mode``."""
    return next((name for test, name in _KINDS if test(mode)), "special file")


class NotRegularFileError(OSError):
    """A path that exists but is not a regular file (``strerror``: ``is a <kind>, not a regular file``)."""

    def __init__(self, path: str | os.PathLike, kind: str):
        super().__init__(errno.EINVAL, f"is a {kind}, not a regular file", os.fspath(path))
        self.kind = kind


def _refuse_unless_regular(path: str | os.PathLike, st: os.stat_result) -> None:
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), os.fspath(path))
    if not stat.S_ISREG(st.st_mode):
        raise NotRegularFileError(path, file_kind(st.st_mode))


def read_regular_file(path: str | os.PathLike) -> bytes:
    """The bytes of the regular file ``path`` (a symbolic link is followed).

    Raises :class:`OSError`: the usual ones (no such file, permission denied, ...),
    :class:`IsADirectoryError` for a directory and :class:`NotRegularFileError` for anything
    else that is not a regular file (FIFO, device, socket), which is never opened, so this never
    blocks on a FIFO nor touches a device.
    """
    _refuse_unless_regular(path, os.stat(path))
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb") as handle:
        # the path could have been swapped for a FIFO between stat and open: O_NONBLOCK made the
        # open return at once, and fstat tells what was opened
        _refuse_unless_regular(path, os.fstat(handle.fileno()))
        return handle.read()


def same_file_key(path: str | os.PathLike) -> tuple[int, int] | None:
    """``(st_dev, st_ino)`` of the file ``path`` names (links followed), or ``None`` if there is none that
    can be looked at (it does not exist, or ``stat`` fails: the reader or writer reports why).

    Two paths name the same file exactly when their keys are equal, however they are spelled
    (``./a``, ``../d/a``, a symbolic link, a hard link).
    """
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def resolved_parent_key(path: str | os.PathLike) -> tuple[int, int, str] | None:
    """For a path that does not exist yet: ``(st_dev, st_ino)`` of its directory and its name, or ``None``."""
    p = Path(path)
    key = same_file_key(p.parent if str(p.parent) else Path("."))
    return None if key is None else (*key, p.name)


def describe_os_error(exc: OSError) -> str:
    """The OS error in the words of a one-line message: ``permission denied``, ``is a directory``, ..."""
    if exc.errno == errno.ENOENT:
        return "no such file"
    text = exc.strerror or str(exc) or type(exc).__name__
    return text[:1].lower() + text[1:]


def read_file_bytes(path: str | Path, what: str, error: type[ValueError]) -> bytes:
    """The bytes of the regular file ``path``; any OS error, and a path that is no regular file (a FIFO, a
    device: :func:`read_regular_file`), becomes ``error("cannot read <what> '<path>': <reason>")``. Give a
    name as typed: pathlib drops a trailing ``/``, which makes ``scan.obj/`` (no file, the OS says) the file."""
    try:
        return read_regular_file(path)  # a FIFO or a device is refused, never opened
    except OSError as exc:
        raise error(f"cannot read {what} '{path}': {describe_os_error(exc)}") from None
