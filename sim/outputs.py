"""Files a flattening run writes: layout (OBJ/SVG), history CSV, plot PNG; and how every output is written.

Every writer goes through :func:`atomic_write`, so an interrupted or failed
run never leaves a partial file behind; inside :func:`all_or_nothing` several
outputs appear together or not at all; :func:`atomic_directory` does the same
for a directory.  An OS error while writing is an :class:`OutputWriteError`,
one line: ``cannot write '<path>': <reason>``.

The policy: outputs are regular files.  A symbolic link is written through (its
final target is replaced, the link stays); a path that is not a regular file (a
device, a FIFO, a socket, a directory), or a link to one, is refused and never
replaced; no output may be the same file as an input or another output
(:func:`check_distinct`, by device and inode).  SIGINT, SIGTERM or SIGHUP (:func:`on_interrupt`)
never lets anything be put in place afterwards.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import json
import math
import os
import secrets
import shutil
import signal
import stat
import struct
import sys
import threading
import unicodedata
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from golden_model.files import file_kind, read_regular_file, resolved_parent_key, same_file_key
from golden_model.files import describe_os_error
from golden_model.mesh import folded_faces, one_line, signed_areas_2d, triangle_areas_3d
from golden_model.modes import Step
from golden_model.results import FlattenResult

from .exit_codes import STOP_SIGNALS
from .mesh_io import save_obj
from .mesh_io.polygons import plural

HISTORY_HEADER = ("iteration", "dt", "area_error", "shape_error", "energy", "flipped", "folded", "accepted")
LAYOUT_SUFFIXES = (".obj", ".svg")


class OutputError(ValueError):
    """An output path that cannot be written; one line for the user."""


class OutputWriteError(OutputError):
    """An OS error on an output: ``cannot write [<what> ]'<path>': <reason>``."""

    def __init__(self, path: Path, error: OSError, what: str = "", left: str = ""):
        self.path, self.error, self.what, self.left = path, error, what, left
        super().__init__(f"cannot write {what + ' ' if what else ''}'{path}': {describe_os_error(error)}"
                         + (f"; {left}" if left else ""))


#: The ``filename`` of an OS error writing the standard output (:class:`NamedStandardOutput`).
STANDARD_OUTPUT = "<standard output>"


class NamedStandardOutput:
    """``sys.stdout`` whose write errors (a full disk, a closed pipe) are ``OSError`` naming it
    (:data:`STANDARD_OUTPUT`): a command's error line can then say what it could not write."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, STANDARD_OUTPUT) from None

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, STANDARD_OUTPUT) from None

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def directory_name_problem(text: str) -> str | None:
    """Why ``text`` cannot name an output file, if it ends in a separator (which names a directory:
    ``Path`` would drop it, and ``new.dxf/`` would write the file ``new.dxf``); ``None`` if it does not."""
    if text.endswith(("/", os.sep)):
        return f"expected a file name, got {text!r} (a trailing '/' names a directory)"
    last = text.replace(os.sep, "/").rsplit("/", 1)[-1]
    if last in (".", ".."):  # Path drops a final '.': 'new.dxf/.' would write the file new.dxf
        return f"expected a file name, got {text!r} (a trailing '{last}' names a directory)"
    return None


def ending_name_problem(path: Path, what: str) -> str | None:
    """Why ``path`` is a file-name ending (``.pdf``, ``.flat.svg``: a batch's ``--out``) given where a file
    name belongs, if its name is hidden: that would write a dot file nobody asked for. ``None`` if not."""
    if not Path(path).name.startswith("."):
        return None
    return (f"{what} '{path}' is a file-name ending, not a file name: name the file (e.g. "
            f"'{Path(path).parent / ('pattern' + Path(path).name)}')")


def output_target(path: Path) -> Path:
    """The file an output path writes: ``path`` itself or, for a symbolic link, the file the link finally
    points to (written through: the link stays, its target is replaced; see :func:`atomic_write`)."""
    path = path if isinstance(path, Path) else Path(path)  # keeps a TypedPath as typed
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _refuse_special(target: Path, path: Path, what: str) -> None:
    """An existing ``target`` that is not a regular file (a directory, a device, a FIFO, a socket), or that
    the user may not write, is refused: springflat never replaces one (a rename would, permission or not)."""
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} '{path}' is a directory")
    if not stat.S_ISREG(st.st_mode):
        via = f" (the link's target '{target}')" if target != Path(path) else ""
        raise OutputError(f"{what} '{path}'{via} is a {file_kind(st.st_mode)}, not a regular file: "
                          "springflat writes regular files only")
    # a file with no write permission for anyone is read-only for root too (root may write it, but a user who
    # took every write bit away, in a container where everyone is root, meant it to stay)
    if not os.access(target, os.W_OK) or not st.st_mode & 0o222:
        raise OutputError(f"{what} '{path}' is read-only: springflat does not replace a file you may not write "
                          "(make it writable, or name another)")
    if _sticky_and_not_ours(target, st):
        raise OutputError(f"{what} '{path}' is another user's file in a sticky directory (as /tmp is): only its "
                          "owner may replace it (name another file)")


def _sticky_and_not_ours(target: Path, st: os.stat_result) -> bool:
    """Whether ``target`` (its ``st``) is in a sticky directory whose owner, like the file's, is someone else:
    there only they may rename over it, whatever the file's mode (root may)."""
    me = os.geteuid()
    if me == 0 or st.st_uid == me:
        return False
    try:
        parent = os.stat(Path(target).parent if str(Path(target).parent) else ".")
    except OSError:
        return False
    return bool(parent.st_mode & stat.S_ISVTX) and parent.st_uid != me


#: Bytes a temporary name may always take, whatever the target's name: every file system in use
#: allows names of 255 bytes, the oldest 30 or so; the name of a longer target is shortened.
TEMPORARY_NAME_MIN = 32
_TEMPORARY_SUFFIX = ".part"


def temporary_name(name: str, token: str) -> str:
    """``.<name>.<token>.part``, the name shortened so that the whole takes no more bytes than
    ``max(len(name), TEMPORARY_NAME_MIN)`` (in the file-system encoding): it fits wherever ``name`` does."""
    budget = max(len(os.fsencode(name)), TEMPORARY_NAME_MIN)
    room = budget - len(os.fsencode(f"..{token}{_TEMPORARY_SUFFIX}"))
    while len(os.fsencode(name)) > room:  # characters, not bytes: a multi-byte character is never split
        name = name[:-1]
    return f".{name}.{token}{_TEMPORARY_SUFFIX}"


def _make_temporary(directory: Path, name: str, *, is_dir: bool = False) -> Path:
    """Create a new file (mode 0600) or directory (0700) named by :func:`temporary_name` in ``directory``.

    A directory with no write permission for anyone is refused as the OS refuses it to its users
    (``PermissionError``), also to root: a user who took every write bit away, in a container where everyone
    is root, meant it to stay as it is (as :func:`_refuse_special` says of a file)."""
    if os.name == "posix" and not os.stat(directory).st_mode & 0o222:  # (Windows's read-only folder flag is no lock)
        raise PermissionError(errno.EACCES, f"directory '{directory}' is read-only (no write permission for "
                              "anyone): springflat does not write into it (make it writable, or name another)",
                              str(directory))
    for _ in range(100):
        candidate = Path(directory) / temporary_name(name, secrets.token_hex(4))
        try:
            if is_dir:
                os.mkdir(candidate, 0o700)
            else:
                os.close(os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0),
                                 0o600))
            return candidate
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(directory))


def file_ending(path: Path) -> str:
    """A file name's kind as its name says it: its last suffix, lower case (``.csv``)."""
    return Path(path).suffix.lower()


def check_link_target(path: Path, what: str, ending: Callable[[Path], str | None] = file_ending) -> None:
    """Refuse a symbolic link whose target's name does not end as the link's own does (``ending``: a pattern's
    ``.pdf`` linking to a mesh's ``.obj``): the output would be written through it over a file of another kind.
    Callers check it after :func:`check_distinct`, which names a link to an input as that input."""
    path = path if isinstance(path, Path) else Path(path)
    if path.is_symlink() and (kind := ending(target := output_target(path))) != ending(path):
        raise OutputError(f"{what} '{path}' is a symbolic link to '{target}', a file of another kind "
                          f"({kind or target.suffix.lower() or 'no ending'}, not {ending(path)}): springflat does not "
                          "write over it")


def check_output_path(path: Path, what: str, suffixes: tuple[str, ...] | None = None, typed: bool = True,
                      ending_hint: str = "") -> None:
    """Fail early (before a long run) on an output path that cannot work.

    Besides the suffix and the directory, this refuses a path that exists and is
    not a regular file (a symbolic link counts as its target) or that the user
    may not write, and creates and removes a temporary file where
    :func:`atomic_write` will, so that a directory without write permission or a
    name too long is refused up front. ``typed``: the user typed the name, so a
    hidden one is a file-name ending given for a file (:func:`ending_name_problem`), refused with
    ``ending_hint`` added (what the command takes endings in).
    """
    path = path if isinstance(path, Path) else Path(path)  # keeps a TypedPath as typed
    if typed and (problem := ending_name_problem(path, what)) is not None:  # a batch builds '.scan.dxf' for '.scan'
        raise OutputError(problem + ending_hint)
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(f"{what} '{path}' must end in {' or '.join(suffixes)}")
    try:
        target = output_target(path)
        parent = target.parent if str(target.parent) else Path(".")
        if not parent.exists():
            raise OutputError(f"{what} '{path}': directory '{parent}' does not exist")
        if not parent.is_dir():
            raise OutputError(f"{what} '{path}': '{parent}' is not a directory")
        _refuse_special(target, path, what)
        _refuse_locked_directory(parent, f"{what} '{path}'")
        os.unlink(_make_temporary(parent, target.name))
    except OSError as exc:
        raise OutputWriteError(path, exc, what) from None


#: Linux's inode flags (``chattr``) that keep a directory's files from being replaced: ``a``, ``i``.
_LOCKING_FLAGS = {0x20: "append-only (chattr +a): no file in it can be replaced, nor a temporary one removed",
                  0x10: "immutable (chattr +i): no file in it can be written"}
#: ``FS_IOC_GETFLAGS``: ``_IOR('f', 1, long)``.
_FS_IOC_GETFLAGS = (2 << 30) | (struct.calcsize("l") << 16) | (ord("f") << 8) | 1


def _refuse_locked_directory(directory: Path, what: str) -> None:
    """Refuse a directory whose inode flags keep its files from being replaced, before a probe file is made in it
    (which an append-only directory would keep: it can be made there, not removed). On Linux only (the ioctl
    is Linux's); where the flags cannot be read (another file system), the writes say what goes wrong."""
    if sys.platform != "linux":
        return
    try:
        import fcntl

        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except (ImportError, OSError):
        return
    try:
        flags = int.from_bytes(fcntl.ioctl(fd, _FS_IOC_GETFLAGS, bytes(struct.calcsize("l")))[:4], sys.byteorder)
    except OSError:
        return
    finally:
        os.close(fd)
    for flag, why in _LOCKING_FLAGS.items():
        if flags & flag:
            raise OutputError(f"{what}: directory '{directory}' is {why}")


#: :func:`folds_case`'s answers, by directory ``(st_dev, st_ino)``.
_FOLDS_CASE: dict[tuple, bool] = {}


def folds_case(directory: Path) -> bool:
    """Whether the file system holding ``directory`` (or, where it does not exist yet, its nearest existing
    parent, which it will be made in) takes names that differ only in case for one file, as macOS's and
    Windows's do by default: a probe file is made there and looked up under its name in the other case. ``False``
    where no probe can be made (the write's own check says why)."""
    directory = Path(os.path.abspath(directory))
    while not directory.is_dir() and directory != directory.parent:
        directory = directory.parent
    key = same_file_key(directory)
    if key not in _FOLDS_CASE:
        try:
            _refuse_locked_directory(directory, "")  # (a probe made in an append-only one would stay)
            probe = _make_temporary(directory, "case")
        except (OSError, OutputError):
            return False
        try:
            _FOLDS_CASE[key] = os.path.exists(probe.with_name(probe.name.swapcase()))
        finally:
            os.unlink(probe)
    return _FOLDS_CASE[key]


def folded_name(name: str, directory: Path) -> str:
    """``name`` as ``directory``'s file system tells names apart: composed (NFC) and in lower case where
    :func:`folds_case` (``Ab.svg`` and ``ab.svg`` are one file there; ``ß`` stays, as those systems keep it), else
    as it is."""
    return unicodedata.normalize("NFC", name).lower() if folds_case(directory) else name


def _identity(path: Path) -> tuple:
    """What decides whether two paths are one file: ``(st_dev, st_ino)`` of an existing file (links
    followed), else the directory's ``(st_dev, st_ino)`` and the name the file will get (:func:`folded_name`)."""
    key = same_file_key(path)
    if key is not None:
        return key
    target = output_target(path)
    parent = resolved_parent_key(target)
    if parent is None:
        return (os.path.abspath(target),)
    return (*parent[:-1], folded_name(parent[-1], target.parent if str(target.parent) else Path(".")))


def check_distinct(outputs: list[tuple[str, Path | None]], inputs: list[tuple[str, Path | None]]) -> None:
    """Refuse an output that is the same file as an input or as another output.

    ``outputs``, ``inputs``: ``(what, path)`` pairs (``path`` None: not given; an input that is no
    existing file, such as a built-in mesh's name, is skipped).  Files are compared by device and
    inode (:func:`golden_model.files.same_file_key`), never by spelling: a symbolic or hard link to
    the mesh is the mesh.
    """
    seen: dict[tuple, str] = {}
    for what, path in inputs:
        key = same_file_key(path) if path is not None and str(path) else None
        if key is not None:
            seen.setdefault(key, f"{what} '{path}'")
    for what, path in outputs:
        if path is None:
            continue
        key = _identity(Path(path))
        if key in seen:
            raise OutputError(f"{what} '{path}' is the same file as {seen[key]}")
        seen[key] = f"{what} '{path}'"


#: The renames :func:`all_or_nothing` holds back: (temporary file, final path, the path as given).
_PENDING: ContextVar[list[tuple[Path, Path, Path]] | None] = ContextVar("springflat_pending_outputs", default=None)


def _file_mode(target: Path) -> int:
    """The mode a replaced file keeps; a new file gets 0666 less the umask."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except FileNotFoundError:
        return 0o666 & ~current_umask()


def _keep_owner(tmp: Path, target: Path) -> None:
    """``tmp`` takes the owner and group of the ``target`` it replaces, as far as this process may give them:
    root gives both (a user's pattern rewritten under ``sudo`` stays the user's), another user only a group
    it belongs to. Before the mode is set: a change of owner clears the set-user-ID and set-group-ID bits."""
    try:
        old, new = os.stat(target), os.stat(tmp)
    except FileNotFoundError:
        return
    if (old.st_uid, old.st_gid) == (new.st_uid, new.st_gid):
        return
    for uid in (old.st_uid, -1):
        try:
            os.chown(tmp, uid, old.st_gid)
            return
        except OSError:  # not ours to give (or a file system without owners): the writer's
            continue


def _flush_to_disk(tmp: Path) -> None:
    """fsync the temporary file: a full disk or an I/O error shows now, before the rename, not later."""
    fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _replace(tmp: Path, target: Path, path: Path) -> None:
    """Rename ``tmp`` over ``target``, unless ``target`` became something other than a regular file."""
    _refuse_special(target, path, "output")
    os.replace(tmp, target)


def _put_in_place(moves: list[tuple[Path, Path, Path]], what: str = "") -> None:
    """Rename each ``(source, target, shown)`` over its target, all of them or none: a target's old file is
    kept under a temporary name beside it (a hard link, or a copy where the file system allows none) until
    every rename is done. Where one fails (a file that may not be replaced, a busy mount point), those done
    are undone, the old files put back, and :class:`OutputWriteError` names its ``shown`` path (and any file
    that could not be put back, with where its old file is)."""
    done: list[tuple[Path, Path | None | object, Path]] = []  # (target, its old file's second name, None if it
    # was new, the path as given)

    def undo(error: OSError, shown: Path) -> OutputWriteError:
        left = []
        for target, kept, given in reversed(done):
            try:
                if kept is _NOT_KEPT:
                    left.append(f"'{given}' is the new file (its old one could not be kept)")
                elif kept is None:
                    os.unlink(target)
                else:
                    os.replace(kept, target)
            except OSError:
                left.append(f"'{given}' is the new file" + ("" if kept is None else f", its old one '{kept}'"))
        done.clear()
        return OutputWriteError(shown, error, what, "; ".join(left))

    try:
        for source, target, shown in moves:
            try:
                kept = _keep_old_file(target)
            except OSError as exc:
                raise undo(exc, shown) from None
            try:
                os.replace(source, target)
            except OSError as exc:
                if isinstance(kept, Path):
                    with contextlib.suppress(OSError):  # (in a sticky directory a second name may stay)
                        os.unlink(kept)
                raise undo(exc, shown) from None
            done.append((target, kept, shown))
    finally:
        for _, kept, _ in done:
            if isinstance(kept, Path):
                with contextlib.suppress(OSError):
                    os.unlink(kept)


#: What :func:`_keep_old_file` gives for a file it could neither link nor copy (a full disk).
_NOT_KEPT = object()


def _keep_old_file(target: Path) -> Path | None | object:
    """A second name beside ``target`` for its file (``None`` if there is none): a hard link, or a copy (of a
    symbolic link: the link); :data:`_NOT_KEPT` where neither can be made (the rename goes ahead: only
    its undoing is lost)."""
    if not os.path.lexists(target):
        return None
    for _ in range(100):
        kept = Path(target).parent / temporary_name(Path(target).name, secrets.token_hex(4))
        try:
            os.link(target, kept, follow_symlinks=False)
            return kept
        except FileExistsError:
            continue
        except OSError:  # no hard links here (a FAT file system, a protected link): a copy
            pass
        try:
            if os.path.islink(target):  # a link in a directory output, which its new file replaces
                os.symlink(os.readlink(target), kept)
                return kept
            fd = os.open(kept, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600)
        except FileExistsError:
            continue
        except OSError:
            return _NOT_KEPT
        try:
            with open(fd, "wb") as copy, open(target, "rb") as original:  # (the descriptor closed either way)
                shutil.copyfileobj(original, copy)
            shutil.copymode(target, kept)
            return kept
        except OSError:  # a full disk, a file one may not read
            with contextlib.suppress(OSError):
                os.unlink(kept)
            return _NOT_KEPT
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(Path(target).parent))


@contextmanager
def atomic_write(path: Path, mode: str = "w") -> Iterator[str]:
    """Yield a temporary path next to ``path``'s file; rename it over that file on success.

    A symbolic link is written through: the file it finally points to is
    replaced and the link stays (:func:`output_target`).  A path that is not a
    regular file is never replaced (:class:`OutputError`).  The temporary name
    fits wherever the target's does (:func:`temporary_name`).  The data is
    flushed to disk before the rename, so a full disk or an I/O error is
    reported and leaves the old file as it was; a replaced file keeps its mode, and its owner and group
    as far as this process may give them (:func:`_keep_owner`).
    Inside :func:`all_or_nothing` the rename waits for the end of that block.
    An OS error (here or in the caller's block) removes the temporary file
    and is raised as :class:`OutputWriteError` naming ``path``.
    """
    path = path if isinstance(path, Path) else Path(path)  # keeps a TypedPath as typed
    tmp = None
    try:
        target = output_target(path)
        _refuse_special(target, path, "output")
        tmp = _make_temporary(target.parent if str(target.parent) else Path("."), target.name)
        yield str(tmp)
        _flush_to_disk(tmp)
        _keep_owner(tmp, target)
        os.chmod(tmp, _file_mode(target))  # the temporary file is 0600
        pending = _PENDING.get()
        if pending is None:
            with deferred_interrupts():
                _replace(tmp, target, path)
                _written(path)
        else:
            pending.append((tmp, target, path))
        tmp = None
    except OSError as exc:
        raise OutputWriteError(path, exc) from None
    finally:
        if tmp is not None and os.path.lexists(tmp):
            os.unlink(tmp)


#: Set by :func:`on_interrupt` (SIGINT, SIGTERM or SIGHUP); the commits of :func:`atomic_write`,
#: :func:`all_or_nothing` and :func:`atomic_directory` refuse to put anything in place once it is set.
_INTERRUPTED = threading.Event()
#: The signal that set it (``signal.SIGINT`` until one arrives).
_RECEIVED = [signal.SIGINT]
#: Called by :func:`on_interrupt` as a signal arrives, before anything else runs (:func:`when_interrupted`).
_INTERRUPT_HOOKS: list[Callable[[], None]] = []


def write_text_file(path: Path, text: str) -> None:
    """``text`` into ``path`` through :func:`atomic_write`: whole or not at all, never in place of a FIFO, a
    device or a directory (for the benchmark and corpus scripts' ``--markdown`` and ``--json`` files, written
    after long runs; check them first with :func:`check_output_path`)."""
    with atomic_write(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


@contextmanager
def when_interrupted(hook: Callable[[], None]) -> Iterator[None]:
    """In the block, ``hook()`` is called the moment SIGINT, SIGTERM or SIGHUP arrives (in :func:`on_interrupt`), before
    the ``KeyboardInterrupt`` unwinds anything: for what other threads must stop doing at once."""
    _INTERRUPT_HOOKS.append(hook)
    try:
        yield
    finally:
        _INTERRUPT_HOOKS.remove(hook)


def on_interrupt(signum, frame) -> None:
    """The commands' SIGINT, SIGTERM and SIGHUP handler: :class:`KeyboardInterrupt`, as Python's own for SIGINT.

    So a ``kill`` ends a command as Ctrl-C does: nothing is put in place, and the child process a
    command waits on (``subprocess.run``: Yosys, nextpnr) is killed on the way out instead of running on.
    Inside a finaliser (``__del__``, run by the garbage collector anywhere) Python would print
    the exception and drop it; there the signal is only recorded and sent again a moment later.
    Either way no output is put in place afterwards (:func:`check_not_interrupted`).
    """
    _INTERRUPTED.set()
    _RECEIVED[0] = signal.Signals(signum)
    for hook in list(_INTERRUPT_HOOKS):
        hook()
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            threading.Timer(0.05, os.kill, (os.getpid(), signum)).start()
            return
        frame = frame.f_back
    raise KeyboardInterrupt


def received_signal() -> signal.Signals:
    """The signal :func:`on_interrupt` last answered (SIGINT if none)."""
    return _RECEIVED[0]


def reset_interrupted() -> None:
    """Forget an earlier signal (a command run in-process after another)."""
    _INTERRUPTED.clear()
    _RECEIVED[0] = signal.SIGINT


#: The outputs a command has put in place, as given (``None``: not recording, as in the API's calls).
_WRITTEN: list[str] | None = None


def record_written_outputs(recording: bool) -> None:
    """Start (``True``: from none) or stop recording the outputs put in place (:func:`written_outputs`)."""
    global _WRITTEN
    _WRITTEN = [] if recording else None


def written_outputs() -> tuple[str, ...]:
    """The outputs put in place since :func:`record_written_outputs` started: a signal that comes after them
    (while the command still prints) cannot take them back, and its line says so."""
    return tuple(_WRITTEN or ())


def _written(*paths: Path | str, directory: bool = False) -> None:
    """Record ``paths`` as put in place; a file of a directory being built (``directory`` false) is not yet."""
    if _WRITTEN is not None and (directory or _BUILDING.get() is None):
        _WRITTEN.extend(str(path) for path in paths)


def check_not_interrupted() -> None:
    """:class:`KeyboardInterrupt` if SIGINT, SIGTERM or SIGHUP arrived (even one a finaliser swallowed): nothing is
    committed."""
    if _INTERRUPTED.is_set():
        raise KeyboardInterrupt


@contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back for the duration of the block (a few renames, a slice of a wait), then
    answer them: an interrupt never leaves half of a set of outputs in place, or a lock held.  Outside the main
    thread: no effect.

    Under a command's handler (:func:`on_interrupt`) the answer is the command's (its hooks run,
    ``KeyboardInterrupt``, the signal noted); in a program that uses the API the signal goes to the handler
    that program had (a ``KeyboardInterrupt`` for Python's own SIGINT handler, its own SIGTERM handler, or
    the default action), and nothing is noted: its next write works as before."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    def hold(signum, frame) -> None:
        received.append(signum)

    # an ignored signal stays ignored; one with a handler Python did not install (None) is left to it
    held = [number for number in (getattr(signal, name) for name in STOP_SIGNALS)
            if signal.getsignal(number) not in (signal.SIG_IGN, None)]
    previous = {number: signal.signal(number, hold) for number in held}
    try:
        check_not_interrupted()
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    if received:
        if previous[received[0]] is not on_interrupt:  # a program using the API: its own handlers answer
            for number in dict.fromkeys(received):
                if callable(previous[number]):  # called, not raised again: a wakeup fd (asyncio's
                    previous[number](number, None)  # add_signal_handler) has had the signal once already
                else:
                    signal.raise_signal(number)  # SIG_DFL: the default action
            return
        on_interrupt(received[0], None)  # the command's answer: its hooks too (what other threads must stop)


@contextmanager
def all_or_nothing() -> Iterator[None]:
    """The files :func:`atomic_write` writes inside the block appear at its end, all of them or none."""
    pending: list[tuple[Path, Path, Path]] = []
    token = _PENDING.set(pending)
    try:
        yield
        _PENDING.reset(token)
        token = None
        with deferred_interrupts():
            for _, target, path in pending:  # checked again just before: nothing is renamed if one fails
                _refuse_special(target, path, "output")
            _put_in_place(pending)
            _written(*(path for _, _, path in pending))
    finally:
        if token is not None:
            _PENDING.reset(token)
        for tmp, _, _ in pending:
            if os.path.lexists(tmp):
                os.unlink(tmp)


def check_output_directory(out: Path, what: str = "--out", files: tuple[str, ...] = (),
                           inputs: list[tuple[str, Path | None]] = (), labels: dict[str, str] | None = None) -> None:
    """Fail early on an output directory that cannot work: it must be a directory if it exists (a link to
    one counts), its parent must exist, and it (if it exists) or its parent must take a new directory.
    ``files``: names the command may write into it, refused now (not after the work, as
    :func:`atomic_directory` would) where one is anything but a regular file or one of ``inputs``;
    ``labels``: what a message calls one of them (``output`` by default)."""
    out = out if isinstance(out, Path) else Path(out)  # keeps a TypedPath as typed
    labels = labels or {}
    try:
        target = output_target(out)
        check_distinct([(labels.get(name, "output"), out / name) for name in files], list(inputs))
        for name in files:
            if os.path.lexists(target / name):
                _refuse_special(target / name, out / name, labels.get(name, "output"))
        if target.exists() and not target.is_dir():
            st = os.stat(target)
            raise OutputError(f"{what} '{out}' exists and is a {file_kind(st.st_mode)}, not a directory")
        parent = target.parent if str(target.parent) else Path(".")
        if parent.exists() and not parent.is_dir():
            raise OutputError(f"{what} '{out}': '{parent}' is not a directory")
        if not parent.is_dir():
            raise OutputError(f"{what} '{out}': directory '{parent}' does not exist")
        _refuse_locked_directory(_build_parent(target), f"{what} '{out}'")
        os.rmdir(_make_temporary(_build_parent(target), target.name, is_dir=True))
    except OSError as exc:
        raise OutputWriteError(out, exc, what) from None


@contextmanager
def atomic_directory(out: Path, what: str = "--out", stale: Sequence[str] = (),
                     inputs: list[tuple[str, Path | None]] = (), owned: Sequence[str] | None = None) -> Iterator[Path]:
    """Yield a new empty directory to build an output directory in; at the end of the block its contents
    become ``out``: all of them, or (on an exception, an interrupt included) none. It is made beside a new
    ``out``, and inside an existing one (hidden, removed at the end): on the file system the files end on,
    so that renames put them there (an existing ``out`` may be a mount point, a file system of its own).

    A new ``out`` is the built directory, renamed.  An existing ``out`` (or the directory a link
    points to) keeps the files the build did not write; those it did write replace their namesakes,
    one rename each with SIGINT held back, after checking that none of them is anything but a
    regular file, nor one of ``inputs`` (``(what, path)`` as for :func:`check_distinct`).
    ``stale``: names removed from an existing ``out`` unless the build wrote them (a result an
    earlier run left that would now mislead), read when the block ends (a caller may fill it in the
    block); a directory they leave empty goes too. ``owned``: where given, the files of an existing ``out``
    that an earlier run wrote; any other namesake of a built file is the user's (a project's own README.md),
    refused in one line, not replaced (checked by :func:`check_build_so_far` before long work, and again here).
    """
    out = out if isinstance(out, Path) else Path(out)  # keeps a TypedPath as typed
    check_output_directory(out, what)
    target = output_target(out)
    build = _make_temporary(_build_parent(target), target.name, is_dir=True)
    building = _BUILDING.set((build, out, list(inputs), None if owned is None else frozenset(owned), what))
    try:
        try:
            yield build
        except OutputWriteError as exc:  # a file of the build (atomic_write): named as the file it becomes
            if _names_paths_outside(OSError(0, "", str(exc.path)), build):
                raise
            raise OutputWriteError(out / os.path.relpath(exc.path, build), exc.error, what) from None
        except OSError as exc:
            if _names_paths_outside(exc, build):
                raise  # not a write of the output: a tool that cannot be started, an input
            raise OutputWriteError(out, exc, what) from None
        try:
            with deferred_interrupts():
                os.chmod(build, 0o777 & ~current_umask())
                if not target.exists():
                    os.rename(build, target)
                else:
                    check_not_foreign(out, _built_names(build), owned, what)
                    _merge_directory(build, target, out, stale, inputs, what)
                _written(out, directory=True)
        except OSError as exc:
            raise OutputWriteError(out, exc, what) from None
    finally:
        _BUILDING.reset(building)
        if build.exists():
            shutil.rmtree(build, ignore_errors=True)


#: The :func:`atomic_directory` being built: ``(build, out, inputs, owned, what)`` (:func:`check_build_so_far`).
_BUILDING: ContextVar[tuple | None] = ContextVar("springflat_building", default=None)


def check_build_so_far() -> None:
    """Refuse now, not after the work, a file already in the :func:`atomic_directory` being built that would
    replace one of its inputs when it is put in place (a ``--formats`` file named as a bundle's file,
    inside ``--out``), or a file of the user's there (``owned``). Called before a long step (a synthesis tool's
    run); nothing outside such a block."""
    if (building := _BUILDING.get()) is not None:
        build, out, inputs, owned, what = building
        _check_no_input_replaced(_built_files(build), build, out, inputs)
        check_not_foreign(out, _built_names(build), owned, what)


def _built_files(build: Path) -> list[Path]:
    """The files in ``build`` so far, sorted."""
    return sorted(p for p in build.rglob("*") if not p.is_dir())


def _check_no_input_replaced(files: list[Path], build: Path, out: Path, inputs: list[tuple[str, Path | None]]) -> None:
    """:func:`check_distinct` of ``files`` of ``build`` (as the ``out`` files they become) against ``inputs``."""
    check_distinct([("output", out / p.relative_to(build)) for p in files], list(inputs))


def _built_names(build: Path) -> list[str]:
    return [p.relative_to(build).as_posix() for p in _built_files(build)]


def check_not_foreign(out: Path, names: Sequence[str], owned: Sequence[str] | None, what: str = "--out") -> None:
    """Refuse, in one line, ``names`` (relative paths) that an output directory ``out`` already holds and that
    are not ``owned`` (what an earlier run wrote there): files of the user's that writing ``names`` would replace.
    No check where ``owned`` is ``None`` or ``out`` is no directory yet (:func:`atomic_directory`'s ``owned``; a
    command that knows its names calls it before its work)."""
    target = output_target(out)
    if owned is None or not target.is_dir():
        return
    foreign = sorted(name for name in names if name not in owned and os.path.lexists(target / name))
    if foreign:
        shown = ", ".join(foreign[:4]) + (f" and {len(foreign) - 4} more" if len(foreign) > 4 else "")
        raise OutputError(f"{what} '{out}' holds {shown}, which this run would replace and no earlier run of this "
                          f"command wrote there: move {'it' if len(foreign) == 1 else 'them'}, or give a new directory")


def holds_marker(out: Path, marker: tuple) -> bool:
    """Whether the directory ``out`` holds ``marker`` = ``(name, key)`` or ``(name, key, value)``: a JSON file of
    that name (a regular file, not a link: springflat writes none), an object with that key (and value): what a
    springflat output of one kind always writes. A FIFO of that name is not opened."""
    name, key, *value = marker
    path = output_target(out) / name
    if path.is_symlink():
        return False
    try:
        found = json.loads(read_regular_file(path))
    except (OSError, ValueError, RecursionError):  # (RecursionError: JSON nested too deep)
        return False
    return isinstance(found, dict) and key in found and (not value or found[key] == value[0])


def report_owned(out: Path, title: str, names: Sequence[str]) -> tuple[str, ...]:
    """``names`` where the directory ``out`` holds an earlier report of this kind (its report.md's first line is
    ``title``), else none: :func:`check_not_foreign`'s ``owned`` for a command whose report is a directory."""
    try:  # (a FIFO of that name is not opened)
        first = read_regular_file(output_target(out) / "report.md").split(b"\n", 1)[0]
    except OSError:
        return ()
    return tuple(names) if first == title.encode() else ()


def _names_paths_outside(error: OSError, directory: Path) -> bool:
    """Whether ``error`` names a path and none of the paths it names (``filename``, and ``filename2`` of a copy
    or a rename) is ``directory`` or lies in it (made absolute, links not followed)."""
    names = [name for name in (error.filename, error.filename2) if isinstance(name, (str, bytes, os.PathLike))]
    inside = os.path.abspath(directory)
    return bool(names) and all(os.path.commonpath([os.path.abspath(os.fsdecode(name)), inside]) != inside
                               for name in names)


def _build_parent(target: Path) -> Path:
    """Where :func:`atomic_directory` builds ``target``: inside it when it exists, else beside it."""
    return target if target.is_dir() else target.parent if str(target.parent) else Path(".")


def current_umask() -> int:
    """The process's file-creation mask (read by setting it, then setting it back)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _merge_directory(build: Path, target: Path, out: Path, stale: tuple[str, ...],
                     inputs: list[tuple[str, Path | None]], what: str) -> None:
    """Move every file of ``build`` into ``target`` (same relative paths), replacing regular files only, all
    of them or none (:func:`_put_in_place`)."""
    files = _built_files(build)
    _check_no_input_replaced(files, build, out, inputs)
    for p in files:
        _refuse_special(target / p.relative_to(build), out / p.relative_to(build), "output")
    written = {p.relative_to(build) for p in files}  # before the moves empty the build
    input_files = {_identity(path) for _, path in inputs if path is not None}
    moves = []
    for p in files:
        destination = target / p.relative_to(build)
        destination.parent.mkdir(parents=True, exist_ok=True)
        if destination.exists():  # a replaced file keeps its owner and mode, as atomic_write's do
            _keep_owner(p, destination)
            # (and a new script its execute bits: it stays runnable over an old copy that lost them)
            os.chmod(p, _file_mode(destination) | (stat.S_IMODE(os.stat(p).st_mode) & 0o111))
        moves.append((p, destination, out / p.relative_to(build)))
    _put_in_place(moves, what)
    emptied = set()
    for name in stale:  # an earlier result this run did not write again; never an input of this run
        if (Path(name) not in written and in_directory(target, name) and (target / name).is_file()
                and _identity(target / name) not in input_files):
            (target / name).unlink()
            emptied.add((target / name).parent)
    for directory in sorted(emptied, key=lambda d: -len(d.parts)):  # (sim_models/ of an earlier bundle)
        if directory != target and not any(directory.iterdir()):
            directory.rmdir()


def in_directory(directory: Path, name: str) -> bool:
    """Whether the relative path ``name`` is a file's place inside ``directory`` itself: not absolute, no
    ``..``, and no part of it a symbolic link (through which a removal would reach a file elsewhere)."""
    parts = Path(name).parts
    if not parts or Path(name).is_absolute() or ".." in parts:
        return False
    return not any((directory.joinpath(*parts[:k])).is_symlink() for k in range(1, len(parts) + 1))


# --------------------------------------------------------------------------- per-face distortion colouring

#: Colour of folded faces (pattern orientation disagrees, or zero area): not in :data:`DISTORTION_CMAP`.
FOLD_COLOUR = "#000000"
#: Colour of every unfolded face when no 3D areas are known (no distortion to show).
PLAIN_COLOUR = "#c8c8c8"
#: The diverging map of ``|A'|/A`` on a log scale: blue = shrunk, white = 1, red = stretched.
#: RdBu reversed, its near-black ends cut off so that black stays free for folds.
DISTORTION_CMAP = "RdBu_r"
_CMAP_RANGE = (0.1, 0.9)
#: The colour scale spans ``[1/r, r]`` with ``r`` the 98th percentile of ``max(ρ, 1/ρ)``,
#: clipped to ``[MIN_SCALE, MAX_SCALE]`` (beyond it colours saturate).
MIN_SCALE, MAX_SCALE = 1.1, 2.0
#: Draw triangle edges when the median edge is longer than this many pixels (plot) ...
EDGE_MIN_PIXELS = 8.0
#: ... or, in an SVG, longer than this fraction of the pattern's size (≈ 3 mm on a 20 cm print).
SVG_EDGE_MIN_FRACTION = 1 / 60


@dataclass(frozen=True)
class FaceColours:
    """Per-face colours of a layout by its area distortion.

    Attributes:
        ratio: ``(F,)`` ``|A'_t| / A_t`` (NaN when no 3D areas were given).
        folded: ``(F,)`` bool, :func:`golden_model.mesh.folded_faces`.
        rgba: ``(F, 4)`` floats in [0, 1]; folded faces are :data:`FOLD_COLOUR`.
        scale: the map spans ``[1/scale, scale]`` (log-symmetric around 1).
    """

    ratio: np.ndarray
    folded: np.ndarray
    rgba: np.ndarray
    scale: float

    @property
    def n_folded(self) -> int:
        return int(self.folded.sum())

    @property
    def has_ratio(self) -> bool:
        return bool(np.isfinite(self.ratio).any())

    @property
    def limits(self) -> tuple[float, float]:
        return 1.0 / self.scale, self.scale

    def ticks(self) -> np.ndarray:
        """Five colour-bar ticks, log-evenly spaced from ``1/scale`` through 1 to ``scale``."""
        return np.exp(np.linspace(-1.0, 1.0, 5) * math.log(self.scale))


def distortion_cmap():
    """The :data:`DISTORTION_CMAP` without its darkest ends (a matplotlib colormap)."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    base = colormaps[DISTORTION_CMAP]
    cmap = ListedColormap(base(np.linspace(*_CMAP_RANGE, 256)), name="springflat_distortion")
    return cmap.with_extremes(over=cmap(1.0), under=cmap(0.0))


def area_ratio(positions: np.ndarray, faces: np.ndarray, areas_3d: np.ndarray) -> np.ndarray:
    """``(F,)`` area distortion ``|A'_t| / A_t`` of a 2D layout against the 3D areas."""
    return np.abs(signed_areas_2d(positions, faces)) / np.asarray(areas_3d, dtype=np.float64)


def ratio_rgba(ratio: np.ndarray, scale: float) -> np.ndarray:
    """``(N, 4)`` colours of area ratios on the log map ``[1/scale, scale]`` (1 → its white centre)."""
    from matplotlib.colors import LogNorm

    ratio = np.maximum(np.asarray(ratio, dtype=np.float64), 1e-300)
    return np.asarray(distortion_cmap()(LogNorm(1.0 / scale, scale)(ratio)), dtype=np.float64)


def distortion_scale(ratio: np.ndarray, folded: np.ndarray | None = None) -> float:
    """``r`` ≥ 1 so that ``[1/r, r]`` holds 98 % of the unfolded faces, within ``[MIN_SCALE, MAX_SCALE]``."""
    ratio = np.asarray(ratio, dtype=np.float64)
    keep = np.isfinite(ratio) & (ratio > 0)
    if folded is not None:
        keep &= ~np.asarray(folded, dtype=bool)
    if not keep.any():
        return MAX_SCALE
    spread = float(np.percentile(np.abs(np.log(ratio[keep])), 98))
    return float(np.clip(math.exp(spread), MIN_SCALE, MAX_SCALE))


def face_colours(positions: np.ndarray, faces: np.ndarray, areas_3d: np.ndarray | None = None,
                 scale: float | None = None) -> FaceColours:
    """Colour each face of the layout ``positions`` by ``|A'|/A`` (folded faces: :data:`FOLD_COLOUR`).

    ``areas_3d`` are the mesh's ``A_t`` (:attr:`Mesh.face_areas`); without
    them every unfolded face is :data:`PLAIN_COLOUR`.  ``scale`` fixes the
    map's range ``[1/scale, scale]`` (default :func:`distortion_scale`), e.g.
    to colour two layouts alike.
    """
    from matplotlib.colors import to_rgba

    positions = np.asarray(positions, dtype=np.float64)
    faces = np.asarray(faces)
    folded = folded_faces(positions, faces)
    if areas_3d is None:
        ratio = np.full(len(faces), np.nan)
        rgba = np.tile(to_rgba(PLAIN_COLOUR), (len(faces), 1))
        scale = MAX_SCALE if scale is None else float(scale)
    else:
        ratio = area_ratio(positions, faces, areas_3d)
        scale = distortion_scale(ratio, folded) if scale is None else float(scale)
        rgba = ratio_rgba(ratio, scale)
    rgba = np.array(rgba, dtype=np.float64)
    rgba[folded] = to_rgba(FOLD_COLOUR)
    return FaceColours(ratio, folded, rgba, scale)


def _hex(rgba: np.ndarray) -> list[str]:
    """``#rrggbb`` of each row of ``rgba`` (alpha dropped)."""
    rgb = np.clip(np.rint(np.asarray(rgba)[:, :3] * 255), 0, 255).astype(int)
    return [f"#{r:02x}{g:02x}{b:02x}" for r, g, b in rgb]


def _typical_edge(positions: np.ndarray, faces: np.ndarray) -> float:
    """The median edge length of the layout (robust to a few long boundary edges)."""
    p = positions[faces]
    return float(np.median(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2)))


def write_layout(path: Path, positions: np.ndarray, faces: np.ndarray, *, vertices: np.ndarray | None = None,
                 units: str | None = None) -> None:
    """The layout as OBJ (z = 0, same faces) or, for ``.svg``, as an SVG drawing.

    For SVG only: ``vertices`` (the 3D mesh's ``(V, 3)`` positions) colour the
    faces by their area distortion (:func:`face_colours`); ``units`` (one of
    :data:`SVG_UNITS`, the mesh's length unit) sets the SVG's ``width`` and
    ``height`` so that it prints at real size.
    """
    with atomic_write(path) as tmp:
        if Path(path).suffix.lower() == ".svg":
            _write_svg(tmp, positions, faces, vertices=vertices, units=units)
        else:
            save_obj(tmp, positions, faces)


#: Length units an SVG can be printed in (value: the SVG unit and its factor).
SVG_UNITS = {"mm": ("mm", 1.0), "cm": ("cm", 1.0), "m": ("mm", 1000.0), "in": ("in", 1.0)}


def _nice_length(target: float) -> float:
    """The largest 1, 2 or 5 × 10^k not above ``target``."""
    power = 10.0 ** math.floor(math.log10(target))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= target * (1 + 1e-9))


def _svg_number(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _write_svg(path: str, positions: np.ndarray, faces: np.ndarray, *, vertices: np.ndarray | None = None,
               units: str | None = None) -> None:
    """Triangles as filled SVG polygons in mesh units (y up, as in the plots), a legend strip below.

    One ``<polygon>`` per face: the unfolded ones in face order in group
    ``pattern``, then the folded ones in group ``folded`` (drawn on top, so
    that a fold is never hidden).  Group ``legend`` holds the colour bar, the
    fold swatch and a scale bar.  No strokes once edges would merge in print.
    """
    positions = np.asarray(positions, dtype=np.float64)
    faces = np.asarray(faces)
    areas = None if vertices is None else triangle_areas_3d(np.asarray(vertices, dtype=np.float64), faces)
    colours = face_colours(positions, faces, areas)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    size = float(max(hi - lo)) or 1.0
    decimals = max(0, 5 - math.floor(math.log10(size)))
    margin = 0.03 * size
    font = 0.025 * size

    def num(value: float) -> str:
        return _svg_number(float(value), decimals)

    # the pattern, y flipped (SVG's y axis points down), then a legend strip under it
    corners = positions[faces] * np.array([1.0, -1.0])
    x0, y0 = lo[0] - margin, -hi[1] - margin
    legend_top = -lo[1] + margin
    legend_height = 5.2 * font
    width = max(hi[0] - lo[0] + 2 * margin, 0.95 * size)
    height = (legend_top - y0) + legend_height
    size_attributes = ""
    if units is not None:
        if units not in SVG_UNITS:
            raise OutputError(f"SVG units must be one of {', '.join(SVG_UNITS)}, got {units!r}")
        unit, factor = SVG_UNITS[units]
        size_attributes = f' width="{width * factor:.6g}{unit}" height="{height * factor:.6g}{unit}"'
    stroke = _typical_edge(positions, faces) > SVG_EDGE_MIN_FRACTION * size
    fills = np.array(_hex(colours.rgba))
    fmt = " ".join([f"%.{decimals}f,%.{decimals}f"] * 3)
    coordinates = np.round(corners.reshape(len(faces), 6), decimals) + 0.0  # no "-0.000"

    def polygons(which: np.ndarray) -> Iterator[str]:
        for row, fill in zip(coordinates[which], fills[which]):
            yield f'<polygon points="{fmt % tuple(row)}" fill="{fill}"/>\n'

    with open(path, "w", encoding="utf-8") as out:
        out.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        out.write(f'<svg xmlns="http://www.w3.org/2000/svg"{size_attributes} '
                  f'viewBox="{num(x0)} {num(y0)} {num(width)} {num(height)}">\n')
        scale_note = (f"1 user unit = 1 {units}, printed at real size" if units is not None
                      else "1 user unit = 1 length unit of the mesh; print so that the scale bar measures true")
        colour_note = ("faces filled by area ratio |A'|/A (log scale, blue shrunk, white 1, red stretched)"
                       if colours.has_ratio else "faces not coloured (no 3D areas given)")
        out.write(f"<!-- springflat pattern: {scale_note}; {colour_note}; "
                  f"{colours.n_folded} folded faces filled {FOLD_COLOUR} -->\n")
        if stroke:
            out.write(f'<g id="pattern" stroke="#3a3a3a" stroke-width="{num(0.0015 * size)}" '
                      'stroke-linejoin="round">\n')
        else:
            out.write('<g id="pattern" stroke="none" shape-rendering="crispEdges">\n')  # no seams
        out.writelines(polygons(~colours.folded))
        out.write("</g>\n")
        out.write(f'<g id="folded" stroke="{FOLD_COLOUR}" stroke-width="{num(0.002 * size)}" '
                  'stroke-linejoin="round">\n')
        out.writelines(polygons(colours.folded))
        out.write("</g>\n")
        _write_svg_legend(out, colours, x0 + margin, legend_top, size, num, units)
        out.write("</svg>\n")


def _write_svg_legend(out, colours: FaceColours, left: float, top: float, size: float, num,
                      units: str | None) -> None:
    """Colour bar (log scale) with ticks, the fold swatch and a scale bar, in group ``legend``.

    The group draws in its own frame, 1000 units to the pattern's size, so that
    text is never sized in tiny user units (renderers mishandle fonts below 1).
    """
    k = size / 1000.0

    def n(value: float) -> str:
        return _svg_number(float(value), 2)

    font, bar_width, bar_height = 25.0, 450.0, 22.0
    bar_top = 1.5 * font
    out.write(f'<g id="legend" transform="translate({num(left)} {num(top)}) scale({k:.6g})" '
              f'font-family="sans-serif" font-size="{n(font)}" fill="#000000">\n')
    x = 0.0
    if colours.has_ratio:
        out.write(f'<text x="0" y="{n(font)}">area ratio |A\'|/A (log scale): blue shrunk, red stretched</text>\n')
        out.write('<g id="colourbar" stroke="none">\n')
        steps = 48
        log_scale = math.log(colours.scale)
        rgba = ratio_rgba(np.exp(np.linspace(-log_scale, log_scale, steps)), colours.scale)  # the faces' map
        step = bar_width / steps
        for j, fill in enumerate(_hex(rgba)):
            out.write(f'<rect x="{n(j * step)}" y="{n(bar_top)}" width="{n(step + 0.5)}" height="{n(bar_height)}" '
                      f'fill="{fill}"/>\n')
        out.write("</g>\n")
        out.write(f'<rect x="0" y="{n(bar_top)}" width="{n(bar_width)}" height="{n(bar_height)}" fill="none" '
                  'stroke="#000000" stroke-width="1"/>\n')
        for j, tick in enumerate(colours.ticks()):
            out.write(f'<text x="{n(bar_width * j / 4)}" y="{n(bar_top + bar_height + 1.05 * font)}" '
                      f'text-anchor="middle">{tick:.3g}</text>\n')
        x = bar_width + 1.5 * font
    out.write(f'<rect x="{n(x)}" y="{n(bar_top)}" width="{n(bar_height)}" height="{n(bar_height)}" '
              f'fill="{FOLD_COLOUR}"/>\n')
    out.write(f'<text x="{n(x + bar_height + 0.4 * font)}" y="{n(bar_top + 0.85 * bar_height)}">'
              f"folded: {colours.n_folded}</text>\n")
    # scale bar: a round length in the mesh's unit
    length = _nice_length(0.2 * size)
    sy = bar_top + bar_height + 1.9 * font
    unit = f" {units}" if units is not None else " (mesh units)"
    out.write(f'<path d="M{n(x)} {n(sy)}h{n(length / k)}" stroke="#000000" stroke-width="4"/>\n')
    out.write(f'<text x="{n(x + length / k + 0.4 * font)}" y="{n(sy + 0.35 * font)}">{length:g}{unit}</text>\n')
    out.write("</g>\n")


class _NoProgress:
    """A progress bar when none is shown: tqdm starts its monitor thread, which stays for the process's life,
    even for a disabled bar (an API call shows none)."""

    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> "_NoProgress":
        return self

    def __exit__(self, *exc) -> None:
        pass


def print_note(text: str) -> None:
    """``springflat: note: text`` on stderr, as one line of text: what a file put in a note (an OBJ's unknown
    statement, a file name) cannot move the terminal's cursor or colour it (:func:`golden_model.mesh.one_line`)."""
    print(f"springflat: note: {one_line(text)}", file=sys.stderr)


def progress_bar(total: int | None, enabled: bool, unit: str = "it", label: str | None = None):
    """A tqdm bar on stderr, ``label:`` before it, that appears only for work longer than ~2 s (``enabled``: the
    caller's terminal check), else :class:`_NoProgress`."""
    if not enabled:
        return _NoProgress()
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=label, delay=2.0, file=sys.stderr, leave=False)


def write_history(path: Path, result: FlattenResult) -> None:
    """CSV of :data:`HISTORY_HEADER`, row 0 = initial layout (empty ``dt`` and ``accepted``). ``dt`` is the paper
    dynamics' time step, empty for the momentum dynamics, which has none (its step is the node weights, scaled
    by the guard); ``accepted`` is 0 for a step the guard rolled back (its row repeats the layout kept). A row
    that is no one step (``History.accepted`` ``None``: the start, and the end row of the RTL and board engines,
    which keep no per-iteration record) has both empty."""
    timed = result.params.mode.step is not Step.MOMENTUM
    history = result.history
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(HISTORY_HEADER)
        for (k, dt, area, shape, energy, flipped, folded), accepted in zip(history.rows(), history.accepted):
            one_step = accepted is not None
            writer.writerow([k, repr(dt) if timed and one_step and not math.isnan(dt) else "", repr(area),
                             repr(shape), repr(energy), flipped, folded, int(accepted) if one_step else ""])


def _draw_faces(ax, positions: np.ndarray, faces: np.ndarray, colours: FaceColours):
    """Two PolyCollections on ``ax``: the unfolded faces, then the folded ones on top (outlined so they show)."""
    from matplotlib.collections import PolyCollection

    corners = positions[faces]
    body = PolyCollection(corners[~colours.folded], facecolors=colours.rgba[~colours.folded], linewidths=0,
                          edgecolors="none", antialiaseds=False, rasterized=False)
    folds = PolyCollection(corners[colours.folded], facecolors=FOLD_COLOUR, edgecolors=FOLD_COLOUR,
                           linewidths=0.6, zorder=3)
    ax.add_collection(body)
    ax.add_collection(folds)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    pad = 0.03 * float(max(hi - lo) or 1.0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    return body


def show_edges(positions: np.ndarray, faces: np.ndarray, pixels_per_unit: float) -> bool:
    """Whether triangle edges stay apart when drawn: the median edge spans > :data:`EDGE_MIN_PIXELS`."""
    return _typical_edge(positions, faces) * pixels_per_unit > EDGE_MIN_PIXELS


def _set_edges(ax, body, positions: np.ndarray, faces: np.ndarray) -> bool:
    """Thin edges on ``body`` when the median edge spans more than :data:`EDGE_MIN_PIXELS` (call after layout)."""
    ax.apply_aspect()
    pixels_per_unit = ax.get_window_extent().width / abs(np.diff(ax.get_xlim())[0])
    visible = show_edges(positions, faces, pixels_per_unit)
    if visible:
        body.set_edgecolor((0.15, 0.15, 0.15, 0.45))
        body.set_linewidth(0.35)
        body.set_antialiased(True)
    return visible


def write_plot(path: Path, result: FlattenResult, faces: np.ndarray, title: str = "", *,
               vertices: np.ndarray | None = None, turn: float = 0.0) -> None:
    """PNG a person reads at a glance: the final pattern coloured by area distortion, the initial layout, errors;
    both layouts turned by ``turn`` (radians, anticlockwise: the pattern files' :attr:`PatternDrawing.turn`).

    The main panel fills each face by ``|A'|/A`` (:func:`face_colours`, a
    diverging log-scale map centred on 1, with a colour bar) and marks folded
    faces in :data:`FOLD_COLOUR`; a small panel shows the initial layout on
    the same scale; the third panel has ``E_S``, ``E_C`` (and the energy) per
    iteration.  ``vertices`` (the mesh's 3D positions) are needed for the
    colours; without them the faces are plain grey.
    """
    import warnings

    with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        # a diverged run's 1e300 on a log axis: matplotlib's overflow notes are no news to the user
        warnings.simplefilter("ignore", RuntimeWarning)
        _draw_plot(path, result, faces, title, vertices, turn)


def _draw_plot(path: Path, result: FlattenResult, faces: np.ndarray, title: str, vertices: np.ndarray | None,
               turn: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Patch
    from matplotlib.ticker import NullLocator

    faces = np.asarray(faces)
    areas = None if vertices is None else triangle_areas_3d(np.asarray(vertices, dtype=np.float64), faces)
    c, s = math.cos(turn), math.sin(turn)
    final_xy, initial_xy = (np.asarray(xy, dtype=np.float64) @ np.array([[c, s], [-s, c]])
                            for xy in (result.positions, result.initial_positions))
    final = face_colours(final_xy, faces, areas)
    initial = face_colours(initial_xy, faces, areas, scale=final.scale)

    dpi = 110
    fig = plt.figure(figsize=(12.5, 6.6), dpi=dpi)
    grid = fig.add_gridspec(2, 4, width_ratios=(1.75, 0.045, 0.36, 1), height_ratios=(1, 1), wspace=0.05,
                            hspace=0.38)
    ax_main = fig.add_subplot(grid[:, 0])
    ax_bar = fig.add_subplot(grid[:, 1])
    ax_initial = fig.add_subplot(grid[0, 3])
    ax_errors = fig.add_subplot(grid[1, 3])

    body = _draw_faces(ax_main, final_xy, faces, final)
    body_initial = _draw_faces(ax_initial, initial_xy, faces, initial)
    what = ("coloured by area ratio |A'|/A: red stretched, blue shrunk" if final.has_ratio
            else "not coloured: no 3D areas given")
    ax_main.set_title(f"final pattern, {what}", fontsize=10)
    ax_main.set_anchor("E")  # against the colour bar
    ax_initial.set_title(f"initial layout (same colours), {initial.n_folded} folded", fontsize=9)
    for ax in (ax_main, ax_initial):
        ax.tick_params(labelsize=7, colors="0.4")
        for spine in ax.spines.values():
            spine.set_color("0.75")
    ax_initial.tick_params(labelsize=6)
    ax_main.legend(handles=[Patch(facecolor=FOLD_COLOUR, label=f"folded faces: {final.n_folded}")],
                   loc="upper right", fontsize=8, framealpha=0.85)
    if final.has_ratio:
        mappable = ScalarMappable(LogNorm(*final.limits), distortion_cmap())
        bar = fig.colorbar(mappable, cax=ax_bar, extend="both")
        bar.set_label("area ratio |A'|/A  (log scale)", fontsize=9)
        bar.set_ticks(final.ticks(), labels=[f"{t:.3g}" for t in final.ticks()])
        bar.ax.yaxis.set_minor_locator(NullLocator())
        bar.ax.tick_params(labelsize=8)
    else:
        ax_bar.set_axis_off()

    history = result.history
    k = np.array(history.iteration)
    curves = [(np.asarray(history.area_error, dtype=float), "tab:green", "area error $E_S$"),
              (np.asarray(history.shape_error, dtype=float), "tab:purple", "shape error $E_C$")]
    params = result.params
    for values, colour, label in curves:
        ax_errors.plot(k, values, "-", color=colour, lw=1.3, label=label)
    for tolerance, colour in ((params.tol_area, "tab:green"), (params.tol_shape, "tab:purple")):
        if tolerance > 0:  # a zero tolerance (rule off) has no place on a log axis
            ax_errors.axhline(tolerance, color=colour, ls=":", lw=0.8)
    if all(np.all(np.isfinite(v) & (v > 0)) for v, _, _ in curves):
        ax_errors.set_yscale("log")
    energy = np.asarray(history.energy, dtype=float)
    handles, labels = ax_errors.get_legend_handles_labels()
    if len(energy) and np.all(np.isfinite(energy)):
        ax_energy = ax_errors.twinx()
        (line,) = ax_energy.plot(k, energy, "--", color="0.45", lw=1.0, label="energy (right axis)")
        if np.all(energy > 0):
            ax_energy.set_yscale("log")
        ax_energy.tick_params(which="both", labelsize=7, colors="0.4")
        handles, labels = handles + [line], labels + [line.get_label()]
    ax_errors.legend(handles, labels, fontsize=7, loc="upper right")
    ax_errors.set_xlabel("iteration", fontsize=8)
    ax_errors.set_ylabel("relative error (dotted: tolerance)", fontsize=8)
    ax_errors.tick_params(which="both", labelsize=7)
    how = "momentum dynamics" if params.mode.step is Step.MOMENTUM else f"paper dynamics, {params.step} step"
    ax_errors.set_title(f"errors ({how})", fontsize=9)
    ax_errors.grid(alpha=0.3)

    summary = (f"{result.status} after {plural(result.iterations, 'iteration')}:  "
               f"$E_S$ = {history.area_error[-1]:.3g},  "
               f"$E_C$ = {history.shape_error[-1]:.3g},  {final.n_folded} of {len(faces)} faces folded")
    fig.suptitle(f"{title} — {summary}" if title else summary, fontsize=12)
    fig.subplots_adjust(left=0.04, right=0.95, top=0.88, bottom=0.08)
    _set_edges(ax_main, body, final_xy, faces)
    _set_edges(ax_initial, body_initial, initial_xy, faces)
    with atomic_write(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
