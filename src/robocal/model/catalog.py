"""The robot catalog: one YAML model file per robot in ``robocal/model/robots/``."""

from __future__ import annotations

import difflib
import os
from functools import cache
from importlib import resources
from pathlib import Path

from robocal.model.chain import Model
from robocal.model.files import load_model
from robocal.model.yaml_files import ModelFileError, read_yaml

__all__ = ["find_model", "is_geometry_file", "is_model_path", "robot", "robots"]


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


def find_model(name_or_path: str | os.PathLike[str]) -> Model:
    """The one model lookup of robocal: a catalog robot by name (``"ur10"``, any case), or a
    model file by path (a ``.yaml``/``.yml`` name, or any path that exists).

    Raises:
        ModelFileError: one line naming the input: no name given, an unknown robot (with the
            closest names), a missing or unreadable file, a joint-geometry file given where a
            model is expected (with the command that builds one), a malformed model file.
    """
    text = os.fspath(name_or_path)
    if not text.strip():
        raise ModelFileError("no robot given: a catalog name (robocal robots) or a model file")
    path = Path(text)
    if not is_model_path(text):
        try:
            return robot(text)
        except KeyError as err:
            raise ModelFileError(str(err.args[0])) from None
    from robocal.console import input_problem  # the one check of an input path

    problem = input_problem(path, "model file")
    if problem is not None:
        raise ModelFileError(f"model file {problem}")
    if is_geometry_file(path):
        raise ModelFileError(
            f"{path} is a joint-geometry file: build a model from it first, "
            f"e.g. robocal model build {path} -o model.yaml"
        )
    return load_model(path)


def is_model_path(name_or_path: str | os.PathLike[str]) -> bool:
    """Whether :func:`find_model` reads ``name_or_path`` as a file (a ``.yaml``/``.yml`` name or
    an existing path) rather than as a catalog name."""
    path = Path(name_or_path)
    return path.suffix in (".yaml", ".yml") or path.exists()


def is_geometry_file(path: str | os.PathLike[str]) -> bool:
    """Whether a YAML file holds joint geometry for the builder (``joints:``) rather than a
    model (``steps:``); False for a file that cannot be read (the model loader reports it)."""
    try:  # read_yaml: the size and entry limits are checked before the file is parsed
        data = read_yaml(path, "model")
    except (OSError, ModelFileError):
        return False
    return isinstance(data, dict) and "joints" in data and "steps" not in data
