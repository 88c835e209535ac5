"""Result folders written as transactions: all of a result or none of it, never a mix.

A calibration folder (``model.yaml``, ``measurement_model.yaml``, ``result.json``, and the
report and data files written with it) is one result: its files only make sense together.
:func:`transaction` writes such a folder into a temporary sibling directory
(``.NAME.<random>.staging``) and swaps it in as a whole:

* ``NAME`` does not exist (or is empty): one ``rename`` of the staging directory;
* ``NAME`` holds an earlier result: on Linux the two directories are exchanged in one
  atomic ``renameat2(RENAME_EXCHANGE)``, elsewhere by two renames with the earlier result
  kept as ``.NAME.<random>.old`` in between (restored by the next writer or reader if a
  crash comes between the two);
* files in ``NAME`` that the writer does not own (a user's notes, another tool's files) are
  carried over (hard links, or copies across devices); files it owns are replaced or
  dropped, so no stale ``measurement_model.yaml`` of an earlier calibration survives;
* robocal replaces or drops only the files robocal wrote: those listed in the folder's
  manifest ``.robocal-files`` (the run id and the names a transaction wrote) or carrying a
  run id.  A user's file under one of the result's names (their ``model.yaml`` given as
  the input, their ``report.html``) is never replaced: the transaction is refused
  (:class:`ForeignFileError`, whatever ``--force`` said), and one the result does not
  write is kept;
* a folder that cannot or should not be renamed (the working directory or a parent of
  it, a mount point, a folder with sub-folders or more than 50 other files: a home
  directory given as ``--out``) is written file by file, ``result.json`` last; the run
  ids then let readers detect a mix left by a crash in between.

Writers of the same folder are serialised by a lock file ``.NAME.lock`` beside it
(:mod:`robocal.folder_lock`: ``flock``, never through a link; removed on release): a
second writer stops at once with a message naming the process that holds the lock.  A
process killed at any point leaves either the earlier or the new result in ``NAME``; its
leftover ``.NAME.<12 hex>.staging`` / ``.old`` directories (this user's real directories,
not links) are removed by the next writer, and readers ignore them; a user's
``.NAME.old`` or ``.NAME.v1.staging`` is not robocal's and is never touched.

Every file of a result carries the same run id (``result.json``: ``"run_id"``; YAML and CSV
files: a ``# robocal run: ID`` comment line; the HTML report: ``<meta name="robocal-run"
content="ID">``); :func:`check_consistent` refuses a folder whose files disagree.

Files that belong together but do not form a folder (a simulation's measurements, truth and
models; a KRL ``.src`` and its ``.dat``; a study's ``summary.json`` and ``summary.png``) are
written by :func:`file_set` / :func:`write_together`: temporary names beside them, then
one rename each, the earlier files put back should a rename fail.

Every file robocal writes goes through :func:`atomic_write_bytes` (a temporary file
beside it, then one rename): this module holds the one atomic writer, which
:mod:`robocal.model.files` re-exports.

For tests: the environment variable ``ROBOCAL_TEST_KILL_AT`` names a write step
(:data:`STEPS`) at which the process kills itself with SIGKILL, to check that every
interruption leaves a complete result; ``ROBOCAL_TEST_NO_EXCHANGE=1`` takes the two-rename
path of systems without ``renameat2`` (``parked`` is the step between its renames).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import os
import re
import secrets
import shutil
import signal
import stat
import tempfile
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from robocal.folder_lock import FolderBusyError, check_not_busy
from robocal.folder_lock import lock_beside as _lock
from robocal.run_ids import (  # re-exported: the run ids of the files a transaction writes
    MANIFEST,
    FolderMixedError,
    ForeignFileError,
    check_consistent,
    check_robocal_files,
    input_names,
    is_mine,
    is_own_regular_file,
    is_run_id,
    manifest_text,
    new_run_id,
    read_run_id,
    robocal_names,
    run_id_line,
    run_id_meta,
)

__all__ = [
    "STEPS",
    "FolderBusyError",
    "FolderMixedError",
    "ForeignFileError",
    "Stage",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_consistent",
    "check_not_busy",
    "check_robocal_files",
    "file_set",
    "is_run_id",
    "new_run_id",
    "read_run_id",
    "restore",
    "robocal_names",
    "run_id_line",
    "run_id_meta",
    "transaction",
    "write_together",
]

#: the write steps of a transaction, in order (see ``ROBOCAL_TEST_KILL_AT``)
STEPS = ("locked", "staged", "carried", "parked", "swapped", "cleaned")


def _test_step(step: str) -> None:
    if os.environ.get("ROBOCAL_TEST_KILL_AT") == step:
        os.kill(os.getpid(), signal.SIGKILL)


# ------------------------------------------------------------------ swapping
def _renameat2():
    """glibc's ``renameat2`` (Linux 3.15+, glibc 2.28+) or None."""
    if not hasattr(os, "O_DIRECTORY") or os.uname().sysname != "Linux":
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        function = libc.renameat2
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap directories ``a`` and ``b`` atomically; False when the system cannot."""
    function = _renameat2()
    if function is None:
        return False
    rc = function(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):  # not on this file system
        return False
    raise OSError(err, os.strerror(err), str(b))


def _leftovers(target: Path) -> list[Path]:
    """The staging and parked directories robocal's writers of ``target`` left: named
    ``.NAME.<12 hex digits>.staging`` / ``.old`` as :func:`transaction` names them, real
    directories (not links) of this user; a user's ``.NAME.old`` or ``.NAME.v1.staging``
    is none of them and is never touched."""
    pattern = re.compile(re.escape(f".{target.name}.") + r"[0-9a-f]{12}\.(?:staging|old)")
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    found = []
    for name in names:
        if not pattern.fullmatch(name):
            continue
        try:
            info = os.lstat(target.parent / name)
        except OSError:
            continue
        if stat.S_ISDIR(info.st_mode) and is_mine(info):
            found.append(target.parent / name)
    return found


def recover(target: Path) -> None:
    """Undo what a killed writer left: restore an earlier result parked as ``.NAME.*.old``
    when ``NAME`` is missing, and remove leftover staging and parked directories.  Call
    with the folder's lock held."""
    leftovers = _leftovers(target)
    if not os.path.lexists(target):
        parked = sorted((p for p in leftovers if p.name.endswith(".old")), key=lambda p: p.stat().st_mtime)
        if parked:
            os.rename(parked[-1], target)
            leftovers.remove(parked[-1])
    for path in leftovers:
        shutil.rmtree(path, ignore_errors=True)


def restore(target: str | os.PathLike[str]) -> None:
    """For readers: when ``target`` is missing but a writer killed between its two renames
    left the earlier result parked beside it, put that back (under the folder's lock)."""
    target = Path(os.path.abspath(target))
    if target.exists() or not any(p.name.endswith(".old") for p in _leftovers(target)):
        return
    with contextlib.suppress(FolderBusyError), _lock(target, wait_s=5.0):
        recover(target)


def _carry_over(old: Path, stage: Path, dropped: Collection[str]) -> None:
    """Hard-link (or copy) into ``stage`` what ``old`` holds beyond the files of the earlier
    result (``dropped``: robocal's, replaced or left out by the new one)."""
    for entry in os.scandir(old):  # files only (a folder with sub-folders is written in place)
        if entry.name in dropped or entry.name == MANIFEST or (stage / entry.name).exists():
            continue
        src, dst = Path(entry.path), stage / entry.name
        if entry.is_symlink():
            os.symlink(os.readlink(src), dst)
        else:
            _link_or_copy(src, dst)


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


@dataclass(frozen=True)
class Stage:
    """The staging directory of a transaction (``path``) and the run id its files carry."""

    path: Path
    run_id: str


#: a folder with more entries than this that the writer does not own (or with a folder of
#: its own) is not a result folder but, say, a home directory: it is written in place
MAX_CARRIED = 50


def _in_place_only(target: Path, owned: Collection[str]) -> bool:
    """Whether ``target`` must not be renamed: the working directory (or one of its
    parents), a mount point, or a folder holding sub-folders or many files of others."""
    try:
        cwd = Path.cwd().resolve()
    except OSError:
        return True
    if target == cwd or target in cwd.parents or os.path.ismount(target):
        return True
    foreign = 0
    with os.scandir(target) as entries:
        for entry in entries:
            if entry.name in owned:
                continue
            foreign += 1
            if foreign > MAX_CARRIED or entry.is_dir(follow_symlinks=False):
                return True
    return False


@contextlib.contextmanager
def transaction(
    target: str | os.PathLike[str],
    owned: Collection[str],
    *,
    run_id: str | None = None,
    wait_s: float = 1.0,
) -> Iterator[Stage]:
    """Write the result folder ``target`` as a whole.

    Write every file of the result into ``stage.path`` inside the ``with`` block; on a
    normal exit the folder is swapped in whole (see the module docstring), on an exception
    nothing changes.  ``owned`` names the files a result of this kind consists of (replaced
    or dropped; everything else in ``target`` is kept).

    Raises:
        FolderBusyError: another process holds the folder's lock (after ``wait_s`` seconds:
            a moment, so that a :func:`check_not_busy` probe never stops a writer).
    """
    target = _target_folder(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    owned = frozenset(owned)
    with _lock(target, wait_s):
        _test_step("locked")
        recover(target)
        stage = Stage(
            Path(target.parent, f".{target.name}.{secrets.token_hex(6)}.staging"), run_id or new_run_id()
        )
        os.mkdir(stage.path)
        try:
            yield stage
            _test_step("staged")
            earlier = _claim(stage, target, owned)
            if target.is_dir() and _in_place_only(target, owned):
                _move_files_in(stage.path, target, earlier)
                return
            if target.is_dir():
                _carry_over(target, stage.path, earlier)
            _test_step("carried")
            _swap(stage.path, target)
            _test_step("swapped")
        finally:
            shutil.rmtree(stage.path, ignore_errors=True)
        _test_step("cleaned")


def _target_folder(target: str | os.PathLike[str]) -> Path:
    """The absolute folder a transaction writes: an existing folder (or a link to one)
    resolved; a link to anything else, or to nothing, is refused (never replaced)."""
    target = Path(os.path.abspath(target))
    if target.is_dir():
        return target.resolve()
    if os.path.islink(target):
        raise ForeignFileError(
            f"{target}: a symbolic link to no folder; robocal does not replace it: remove it or "
            "choose another output folder"
        )
    return target


def _claim(stage: Stage, target: Path, owned: Collection[str]) -> frozenset[str]:
    """Refuse the result when one of its files would replace one in ``target`` that robocal
    did not write or an input its ``result.json`` names (:class:`ForeignFileError`, whatever
    ``--force`` said); list its files in its manifest; return the earlier result's files
    (robocal's among ``owned``, not inputs), which the new result replaces or drops."""
    written = sorted(n for n in os.listdir(stage.path) if n != MANIFEST)
    earlier: frozenset[str] = frozenset()
    if target.is_dir():
        inputs = input_names(target, written, stage.path / "result.json")  # refused if replaced
        check_robocal_files(target, written)
        earlier = robocal_names(target, owned) - inputs  # an input is kept
    (stage.path / MANIFEST).write_text(manifest_text(stage.run_id, written), encoding="utf-8")
    return earlier


def _swap(stage: Path, target: Path) -> None:
    """Put ``stage`` in ``target``'s place; the earlier ``target`` ends at ``stage``."""
    if not target.exists():
        os.rename(stage, target)
        return
    if not target.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "not a directory", str(target))
    try:
        os.rmdir(target)  # an empty folder: nothing to keep
    except OSError:
        pass
    else:
        os.rename(stage, target)
        return
    if os.environ.get("ROBOCAL_TEST_NO_EXCHANGE") != "1" and _exchange(stage, target):
        return
    parked = target.parent / f".{target.name}.{secrets.token_hex(6)}.old"
    os.rename(target, parked)
    _test_step("parked")
    os.rename(stage, target)
    os.rename(parked, stage)


def _move_files_in(stage: Path, target: Path, earlier: Collection[str]) -> None:
    """The working directory or a mount point is written file by file (it cannot be
    renamed): the earlier result's files (``earlier``, robocal's) that the new one does not
    have are removed, then the new files moved in, the manifest and ``result.json`` last;
    the run ids let readers detect a mix should the process die in between."""
    for name in earlier:
        if not (stage / name).exists():
            with contextlib.suppress(FileNotFoundError):
                (target / name).unlink()
    last = {MANIFEST: 1, "result.json": 2}
    for entry in sorted(os.listdir(stage), key=lambda n: last.get(n, 0)):
        os.replace(stage / entry, target / entry)


# ------------------------------------------------------------------ the one atomic writer
def _read_umask() -> int:
    mask = os.umask(0)  # the only way to read it; set back at once (at import, before any threads)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename (never half-written)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def remove_stale_temporaries(path: Path) -> None:
    """Remove the ``.NAME.<pid>.*.tmp`` files that writers of ``path`` killed before their
    rename left behind (those whose process is gone)."""
    prefix = f".{path.name}."
    try:
        names = [n for n in os.listdir(path.parent) if n.startswith(prefix) and n.endswith(".tmp")]
    except OSError:
        return
    for name in names:
        pid = name[len(prefix) :].split(".", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid() or not is_own_regular_file(path.parent / name):
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:  # its writer is gone
            with contextlib.suppress(OSError):
                os.unlink(path.parent / name)
        except (PermissionError, OverflowError):
            continue


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename (never half-written)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        # mkstemp makes the file private (0600); give it the permissions of a normal new file
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        if err.filename is None:  # a failed write() (disk full) names no file: name the target
            raise OSError(err.errno, err.strerror, str(path)) from None
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


# ------------------------------------------------------------------ sets of files beside each other
def _temporary_beside(path: Path, kind: str) -> Path:
    """``.NAME.<pid>.<random>.KIND.tmp`` beside ``path`` (removed by
    :func:`atomic_write_bytes` once its process is gone)."""
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.{kind}.tmp")


def _commit_set(paths: Sequence[Path], temporaries: Sequence[Path]) -> None:
    """Rename every temporary onto its path; should a rename fail, put the earlier files
    back (kept as hard links, or copies) and remove the new ones that had no earlier file."""
    backups: dict[Path, Path] = {}
    renamed: list[Path] = []
    try:
        for path in paths:
            if path.is_file():
                backups[path] = _temporary_beside(path, "old")
                _link_or_copy(path, backups[path])
        for index, (path, tmp) in enumerate(zip(paths, temporaries, strict=True)):
            if index:
                _test_step("set-renaming")
            os.replace(tmp, path)
            renamed.append(path)
    except BaseException:
        for path in renamed:
            with contextlib.suppress(OSError):
                if path in backups:
                    os.replace(backups.pop(path), path)
                else:
                    path.unlink()
        raise
    finally:
        for backup in backups.values():
            with contextlib.suppress(OSError):
                backup.unlink()


@contextlib.contextmanager
def file_set(paths: Sequence[str | os.PathLike[str]], *, wait_s: float = 1.0) -> Iterator[list[Path]]:
    """Write several files that belong together (a program and its ``.dat``, measurements
    and their truth) all or none: yields one temporary path beside each of ``paths``; write
    every one of them inside the ``with`` block.  On a normal exit they are renamed into
    place (first path first); on an exception, or a failed rename, the earlier files stay
    (or none, when there were none) and the temporaries are removed.  Writers are serialised
    by the lock of the first path (:class:`FolderBusyError` after ``wait_s`` seconds).

    A process killed between the renames can leave a mix: give the files a run id
    (:func:`run_id_line`) so that their reader can refuse it."""
    targets = [Path(os.path.abspath(p)) for p in paths]
    if len(set(targets)) != len(targets):
        raise ValueError(f"the same file is given twice among {', '.join(map(str, paths))}")
    for target in targets:
        target.parent.mkdir(parents=True, exist_ok=True)
    with _lock(targets[0], wait_s):
        for target in targets:
            remove_stale_temporaries(target)  # those of killed writers
        temporaries = [_temporary_beside(t, "new") for t in targets]
        try:
            yield temporaries
            missing = [str(t) for t, tmp in zip(targets, temporaries, strict=True) if not tmp.is_file()]
            if missing:
                raise RuntimeError(f"internal error: not written: {', '.join(missing)}")
            _commit_set(targets, temporaries)
        finally:
            for tmp in temporaries:
                with contextlib.suppress(OSError):
                    tmp.unlink()


def write_together(files: dict[Path, bytes], *, wait_s: float = 1.0) -> None:
    """Write ``files`` (path -> content) all or none (see :func:`file_set`)."""
    paths = list(files)
    with file_set(paths, wait_s=wait_s) as temporaries:
        for path, tmp in zip(paths, temporaries, strict=True):
            atomic_write_bytes(tmp, files[path])
