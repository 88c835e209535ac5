"""robocal's version, as installed (``0.0.0`` when running from a source tree): a core
module, so that library modules that record it need not import the package's facade."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__"]

try:
    __version__ = version("robocal")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"
