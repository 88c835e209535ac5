"""The lock that serialises the writers of one output (a result folder, a set of files).

``.NAME.lock`` beside the output ``NAME``, held with ``flock`` and removed on release; it
holds the holder's process id, for the message of a second writer.  The lock file is
opened without following a symbolic link (``O_NOFOLLOW``) and used only when it is this
user's plain file with a single name: a link planted as ``.NAME.lock`` (to make robocal
truncate the file it points to) is refused by name (:class:`ForeignFileError`), never
written through.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import time
from collections.abc import Iterator
from pathlib import Path

from robocal.run_ids import ForeignFileError, is_mine

__all__ = ["FolderBusyError", "check_not_busy", "lock_beside"]

_NO_FOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOSE_ON_EXEC = getattr(os, "O_CLOEXEC", 0)


class FolderBusyError(RuntimeError):
    """Another process is writing the same result folder."""


def _lock_path(target: Path) -> Path:
    return target.parent / f".{target.name}.lock"


def _not_a_lock(lock_path: Path, what: str) -> ForeignFileError:
    return ForeignFileError(
        f"{lock_path}: {what}, not a lock file robocal made; robocal does not write through it: "
        "remove it (when no robocal process is writing there) or write elsewhere"
    )


def _open_lock(lock_path: Path) -> int:
    """The lock file opened (created when missing) without following a link; anything but
    this user's plain file with one name is refused."""
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | _NO_FOLLOW | _CLOSE_ON_EXEC, 0o644)
    except OSError as err:
        if err.errno in (errno.ELOOP, errno.EMLINK):  # a symbolic link (EMLINK: FreeBSD's answer)
            raise _not_a_lock(lock_path, "a symbolic link") from None
        raise
    info = os.fstat(fd)
    problem = None
    if not stat.S_ISREG(info.st_mode):
        problem = "not a plain file"
    elif info.st_nlink != 1:  # a hard link to a file elsewhere: writing it writes that file
        problem = "a file with several names (a hard link)"
    elif not is_mine(info):
        problem = "another user's file"
    if problem is not None:
        os.close(fd)
        raise _not_a_lock(lock_path, problem)
    return fd


def _try_lock(lock_path: Path, fd: int) -> tuple[str, str]:
    """``("locked", "")`` when ``fd`` now holds the lock of the current lock file,
    ``("busy", holder's pid text)`` when another process holds it, ``("stale", "")`` when
    the file was replaced after our open (its previous holder removed it): open again."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return "busy", os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    try:
        same = os.fstat(fd).st_ino == os.lstat(lock_path).st_ino
    except FileNotFoundError:
        same = False
    return ("locked" if same else "stale"), ""


@contextlib.contextmanager
def lock_beside(target: Path, wait_s: float) -> Iterator[None]:
    """Hold ``.NAME.lock`` beside ``target`` (flock), removed on release (no lock where the
    system has no flock: Windows).

    Raises:
        FolderBusyError: another process holds it after ``wait_s`` seconds.
        ForeignFileError: ``.NAME.lock`` is a link, not a plain file, or another user's.
    """
    try:
        import fcntl  # noqa: F401
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return

    lock_path = _lock_path(target)
    deadline = time.monotonic() + wait_s
    while True:
        fd = _open_lock(lock_path)
        state, holder = _try_lock(lock_path, fd)
        if state == "locked":
            break
        os.close(fd)
        if state == "busy":
            if time.monotonic() >= deadline:
                raise FolderBusyError(
                    f"{target} is being written by another robocal process"
                    + (f" (pid {holder})" if holder.isdigit() else "")
                    + "; wait for it to finish or write elsewhere"
                )
            time.sleep(0.05)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock_path)
        os.close(fd)


def check_not_busy(target: str | os.PathLike[str]) -> None:
    """Raise :class:`FolderBusyError` at once when another process is writing ``target``
    (for commands that would otherwise compute for minutes before finding out), and
    :class:`ForeignFileError` when its lock file is not one robocal can use."""
    target = Path(os.path.abspath(target))
    if os.path.lexists(_lock_path(target)):
        with lock_beside(target, 0.0):
            pass
