"""The ``robocal`` command's last line of defence: no traceback ever reaches the user.

Every command reports the failures it expects itself (one line naming the input, exit 2;
exit 1 for a failed calibration or check).  What escapes a command is turned into one line
here by :class:`RobocalGroup`, the Typer group of the ``robocal`` app:

* an operating-system error (disk full, permission denied, a missing directory, a read-only
  file system ...) names the file and says what to do, exit 2;
* running out of memory or nesting too deep names the limit, exit 2;
* anything else is a bug: one line with the error, and the full traceback is written to a
  file in the temporary directory (``robocal-traceback-*.txt``) whose path is printed, exit 1.
"""

from __future__ import annotations

import errno
import os
import tempfile
import traceback

import typer
from typer.core import TyperGroup

from robocal.console import err_console, safe

__all__ = ["RobocalGroup", "explain"]

#: exit status of a bug (an exception no command expected)
INTERNAL_ERROR = 1
BAD_INPUT = 2

_OS_FIX = {
    errno.ENOSPC: "the disk is full: free space or write elsewhere, then run again "
    "(nothing was half-written)",
    errno.EDQUOT: "the disk quota is used up: free space or write elsewhere, then run again",
    errno.EACCES: "permission denied: check the file's permissions or choose another path",
    errno.EPERM: "operation not permitted: check the file's permissions or choose another path",
    errno.ENOENT: "no such file or directory: check the path",
    errno.EROFS: "read-only file system: write elsewhere",
    errno.EISDIR: "is a directory: give a file",
    errno.ENOTDIR: "a part of the path is not a directory: check the path",
    errno.ENAMETOOLONG: "the file name is too long: choose a shorter path",
    errno.EMFILE: "too many open files: raise the limit (ulimit -n) or process fewer files at once",
    errno.EIO: "input/output error: check the disk",
    errno.EEXIST: "already exists: remove it or choose another path",
}


def explain(exc: BaseException) -> tuple[str, int] | None:
    """The one-line message and exit status of an expected failure, or None for a bug."""
    if isinstance(exc, OSError):
        what = _OS_FIX.get(exc.errno or -1, exc.strerror or str(exc))
        name = exc.filename if exc.filename is not None else None
        if name is None:
            return f"{what}", BAD_INPUT
        return f"{os.fsdecode(name)}: {what}", BAD_INPUT
    if isinstance(exc, MemoryError):
        return (
            "not enough memory for this input: make it smaller (the limits are listed in the README, "
            "section 'Limits')",
            BAD_INPUT,
        )
    if isinstance(exc, RecursionError):
        return "the input is nested too deeply to be read", BAD_INPUT
    if isinstance(exc, _input_errors()):  # a reader's or writer's own error: it names the input
        return str(exc), BAD_INPUT
    return None


def _input_errors() -> tuple[type[BaseException], ...]:
    """The error classes whose messages name the input (imported only when one is needed)."""
    from robocal.compensate.programs.syntax import ProgramError
    from robocal.folder_lock import FolderBusyError
    from robocal.measure.measurements import MeasurementFileError
    from robocal.model.geometry import GeometryError
    from robocal.model.urdf.read import URDFError
    from robocal.model.yaml_files import ModelFileError
    from robocal.run_ids import FolderMixedError
    from robocal.study import StudyError

    return (
        ProgramError,
        MeasurementFileError,
        GeometryError,
        ModelFileError,
        URDFError,
        FolderBusyError,
        FolderMixedError,
        StudyError,
    )


def _first_line(text: str, limit: int = 300) -> str:
    line = text.strip().splitlines()[0] if text.strip() else ""
    return line if len(line) <= limit else line[:limit] + " ..."


def _write_traceback(exc: BaseException) -> str | None:
    """Write the full traceback to a new file in the temporary directory; its path, or None."""
    try:
        fd, path = tempfile.mkstemp(prefix="robocal-traceback-", suffix=".txt")
        with os.fdopen(fd, "w", encoding="utf-8", errors="replace") as fh:
            fh.write("".join(traceback.format_exception(exc)))
        return path
    except OSError:  # the disk may be full: the one line still goes out
        return None


def report(exc: BaseException) -> int:
    """Print the one line for ``exc`` on stderr; the exit status."""
    known = explain(exc)
    if known is not None:
        message, code = known
        err_console.print("[bold red]error:[/] " + safe(message), highlight=False, markup=True)
        return code
    path = _write_traceback(exc)
    where = f"the full traceback is in {path}" if path else "the traceback could not be written"
    text = _first_line(str(exc))
    err_console.print(
        "[bold red]error:[/] "
        + safe(
            f"internal error ({type(exc).__name__}{': ' + text if text else ''}); {where}; "
            "please report it with the command that led to it"
        ),
        highlight=False,
        markup=True,
    )
    return INTERNAL_ERROR


class RobocalGroup(TyperGroup):
    """The ``robocal`` app's group: any exception a command lets through becomes one line."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        from robocal.cli.options import tidy_help

        tidy_help(self)  # every subcommand is built by now: no `<bool>` shown for a flag

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except Exception as exc:
            if type(exc).__module__.split(".")[0] in ("typer", "click"):  # exits, usage errors
                raise
            if isinstance(exc, OSError) and exc.errno == errno.EPIPE:  # `robocal ... | head`
                raise
            raise typer.Exit(report(exc)) from None
