"""Checks of the files the tools read and write: one owner, called by every reader and writer.

Reading (:func:`check_input`, :func:`open_input`): only a regular file (a symbolic link to one is
fine) is read, and at most a limit of bytes per kind of file. A FIFO, a device or a directory
is refused *before* it is read: ``open`` of a FIFO without a writer blocks forever, ``/dev/zero``
never ends, a directory is not a file. :func:`open_input` opens with ``O_NONBLOCK`` and checks
the opened file itself (``fstat``), so a file swapped for a FIFO between the check and the open
is refused too.

Writing (:func:`check_output`, :func:`write_with`): an existing target that is not a regular file
(a directory, a FIFO, a device such as ``/dev/null`` or ``/dev/full``) is refused before anything
is written; an atomic save (:meth:`switchobs_core.table.gains.GainTable.save`) checks its target here
first, so its temporary file is always created beside a regular target, in the target's own
folder (``-o /tmp``, a directory, is refused: its temporary file was created in ``/``). Any
``OSError`` while writing (a full disk) is one line of the caller's error class.

Private folders (:func:`check_private`): a folder or file that another user owns, or that group
or others may write, is refused (as ssh refuses such key files), for caches whose content is
trusted.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from .exceptions import InvalidArgument, SwitchobsError
from .ranges import OUTPUT_BUDGET_BYTES, fmt_bytes

__all__ = [
    "MAX_BAG_BYTES",
    "MAX_METADATA_BYTES",
    "kind_of",
    "check_input",
    "open_input",
    "check_output",
    "write_with",
    "check_private",
]

#: Largest bag data file read (``.mcap`` / ``.db3``): the offline tools hold its messages in memory
#: (several times the file's bytes). A 10-minute 100 Hz estimate bag with covariances is 450 MiB.
MAX_BAG_BYTES = OUTPUT_BUDGET_BYTES
#: Largest ``metadata.yaml`` of a bag read (a real one is a few kB).
MAX_METADATA_BYTES = 1 << 20


def kind_of(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words (for the messages)."""
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_input(path: str | Path, what: str, *, exc: type[SwitchobsError] = InvalidArgument,
                max_bytes: int | None = None) -> os.stat_result:
    """Refuse, before reading, ``path`` unless it is a regular file of at most ``max_bytes``.

    A missing file raises ``FileNotFoundError`` (callers word that themselves).
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise
    except OSError as err:
        raise exc(f"cannot read {what} {path}: {err.strerror or err}") from None
    _check_regular(st, path, what, exc, max_bytes)
    return st


def _check_regular(st: os.stat_result, path: str | Path, what: str, exc: type[SwitchobsError],
                   max_bytes: int | None) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise exc(f"{what} {path} is {kind_of(st.st_mode)}, not a regular file: give the path of a file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise exc(f"{what} {path} is larger than {fmt_bytes(max_bytes)} ({fmt_bytes(st.st_size)}; the limit for "
                  "this kind of file)")


def open_input(path: str | Path, what: str, *, exc: type[SwitchobsError] = InvalidArgument,
               max_bytes: int | None = None) -> BinaryIO:
    """``path`` opened for binary reading, after :func:`check_input`'s checks on the opened file.

    Opening does not block on a FIFO (``O_NONBLOCK``); the file is checked with ``fstat``.
    A missing file raises ``FileNotFoundError``.
    """
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise
    except OSError as err:
        raise exc(f"cannot read {what} {path}: {err.strerror or err}") from None
    try:
        _check_regular(os.fstat(fd), path, what, exc, max_bytes)
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def check_output(path: str | Path, what: str, *, exc: type[SwitchobsError] = InvalidArgument) -> Path:
    """Refuse an output target that exists and is not a regular file, or whose folder is a file."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None
    except OSError as err:
        raise exc(f"cannot write {what} {path}: {err.strerror or err}") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise exc(f"{what} {path} is {kind_of(st.st_mode)}: refusing to replace it; give the path of a new or "
                  "regular file")
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise exc(f"cannot write {what} {path}: {parent} is not a folder")
    return path


def write_with(path: str | Path, what: str, write: Callable[[Path], object], *,
               exc: type[SwitchobsError] = InvalidArgument) -> Path:
    """Check the target (:func:`check_output`), make its folder, call ``write(path)``; an
    ``OSError`` (a full disk) becomes one line of ``exc``. For writers with their own file
    handling (matplotlib's ``savefig``, a CSV)."""
    path = check_output(path, what, exc=exc)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write(path)
    except OSError as err:
        raise exc(f"cannot write {what} {path}: {err.strerror or err}") from None
    return path


def check_private(path: str | Path, what: str, *, exc: type[SwitchobsError] = InvalidArgument,
                  hint: str = "", named: bool = True) -> None:
    """Refuse ``path`` if another user (not root) owns it or group/others may write it (ssh's rule).
    The messages say ``"<what> <path> is ..."``, or ``"<what> ..."`` with ``named`` False (``what``
    then names the path itself)."""
    it = f"{what} {path} is" if named else what
    try:
        st = os.stat(path)
    except OSError as err:
        raise exc(f"cannot check {what} {path}: {err.strerror or err}") from None
    me = os.geteuid()
    if st.st_uid not in (me, 0):
        raise exc(f"{it} owned by another user (uid {st.st_uid}), so its content cannot be trusted{hint}")
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        who = "group and others" if st.st_mode & stat.S_IWOTH and st.st_mode & stat.S_IWGRP else \
            "others" if st.st_mode & stat.S_IWOTH else "the group"
        raise exc(f"bad permissions: {it} writable by {who} (mode {stat.S_IMODE(st.st_mode):04o}), so "
                  f"its content cannot be trusted; chmod go-w it{hint}")
