"""Where ``robocal demo`` writes by default: ``robocal-demo`` in the user's home directory."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["default_folder"]


def default_folder() -> Path:
    """``HOME/robocal-demo``: never the file system's root nor the working directory (which
    may be a checkout).

    Raises:
        ValueError: there is no usable home directory (``HOME`` empty, relative, the root,
            or not a folder); the message says to give ``--out``.
    """
    raw = os.environ.get("HOME")
    try:
        home = Path(os.path.expanduser("~")) if raw is None or os.name == "nt" else Path(raw)
    except RuntimeError:  # no home directory in the user database either
        home = Path()
    problem = None
    if raw is not None and not raw.strip():
        problem = "HOME is empty"
    elif not home.is_absolute():
        problem = f"the home directory {str(home)!r} is not an absolute path"
    elif home == Path(home.anchor):
        problem = f"the home directory is the root {home}"
    elif not home.is_dir():
        problem = f"the home directory {home} is not a folder"
    if problem is not None:
        raise ValueError(f"{problem}: give the demo's folder with --out DIR")
    return home / "robocal-demo"
