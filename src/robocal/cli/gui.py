"""``robocal gui``: start the web app (the framework is imported only when it runs)."""

from __future__ import annotations

import socket
from typing import Annotated

import typer

from robocal.console import fail

__all__ = ["register"]


def gui_command(
    port: Annotated[int, typer.Option("--port", metavar="PORT", help="port on localhost")] = 8050,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="do not open a browser window")] = False,
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
    serve(port, open_browser=not no_browser)


def register(app: typer.Typer) -> None:
    """Add ``gui`` to the ``robocal`` app."""
    app.command("gui")(gui_command)
