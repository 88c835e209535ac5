"""``robocal gui``: start the web app (the framework is imported only when it runs)."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Annotated

import typer

from robocal.console import fail

__all__ = ["register"]

WorkdirOption = Annotated[
    Path | None,
    typer.Option(
        "--workdir",
        metavar="DIR",
        help="keep uploads, runs and results in DIR across restarts (default: a temporary "
        "directory removed when the server stops)",
    ),
]


def gui_command(
    port: Annotated[int, typer.Option("--port", metavar="PORT", help="port on localhost")] = 8050,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="do not open a browser window")] = False,
    workdir: WorkdirOption = None,
) -> None:
    """The model builder and the calibration in a browser window (localhost, offline; Ctrl-C stops it)."""
    if not 1 <= port <= 65535:
        raise fail(f"--port {port}: a port number between 1 and 65535")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        if s.connect_ex(("127.0.0.1", port)) == 0:
            raise fail(f"--port {port}: the port is in use; choose another with --port")
    try:
        from robocal.apps.gui.app import serve
    except ImportError as err:
        raise fail(f"the GUI needs Dash: pip install 'robocal[gui]' ({err})") from None
    if workdir is None:
        serve(port, open_browser=not no_browser)
        return
    from robocal.folder_lock import FolderBusyError, lock_beside
    from robocal.run_ids import ForeignFileError

    workdir = _checked_workdir(workdir)
    try:
        with lock_beside(workdir, 0.0):  # one server per work dir: two would run each other's queue
            serve(port, open_browser=not no_browser, workdir=workdir)
    except (FolderBusyError, ForeignFileError) as err:
        raise fail(f"--workdir {workdir}: another robocal gui keeps its runs there ({err})") from None


def _checked_workdir(workdir: Path) -> Path:
    """``workdir`` made (with its parents) and absolute; one error line when it cannot be."""
    workdir = workdir.expanduser().absolute()
    if workdir.exists() and not workdir.is_dir():
        raise fail(f"--workdir {workdir}: is a file; give a directory")
    try:
        workdir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise fail(f"--workdir {workdir}: cannot be made ({err.strerror})") from None
    return workdir


def register(app: typer.Typer) -> None:
    """Add ``gui`` to the ``robocal`` app."""
    app.command("gui")(gui_command)
