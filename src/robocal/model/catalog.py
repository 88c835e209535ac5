"""The robot catalog: one YAML model file per robot in ``robocal/model/robots/``."""

from __future__ import annotations

import difflib
from functools import cache
from importlib import resources

from robocal.model.chain import Model
from robocal.model.files import load_model

__all__ = ["robot", "robots"]


def _directory():
    return resources.files("robocal.model") / "robots"


def robots() -> list[str]:
    """Names of the catalog robots, sorted."""
    return sorted(p.name.removesuffix(".yaml") for p in _directory().iterdir() if p.name.endswith(".yaml"))


@cache
def robot(name: str) -> Model:
    """The catalog model called ``name`` (lowercase, e.g. ``"ur10"``).

    Models are immutable, so the cached instance is shared safely.
    """
    names = robots()
    if name not in names and name.lower() in names:  # "UR10" is the ur10
        name = name.lower()
    if name not in names:
        close = difflib.get_close_matches(name.lower(), names, n=3)
        hint = f" Did you mean {', '.join(close)}?" if close else ""
        raise KeyError(f"unknown robot {name!r}.{hint} Available: {', '.join(names)}")
    with resources.as_file(_directory() / f"{name}.yaml") as path:
        return load_model(path)
