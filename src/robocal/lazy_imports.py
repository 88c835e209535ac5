"""Lazy package exports: ``import robocal`` (and the ``robocal`` command) loads a module only
when one of its names is first used.

A package lists its public names and the module each lives in; the standard library's
PEP 562 module ``__getattr__`` does the rest. One detail needs a module class: some packages
export a function named like one of their modules (``robocal.identify.calibrate``,
``robocal.measure.simulate``). Imported eagerly, the function was bound
after the module and won; imported lazily, the import system would bind the module on the
package when it is first loaded, hiding the function. The package class below keeps the
exported function in that case, so ``from robocal.identify import calibrate`` is the function
whatever was imported before.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

__all__ = ["lazy_package"]


class _LazyPackage(types.ModuleType):
    _lazy_exports: dict[str, str]
    _lazy_submodules: tuple[str, ...]

    def __getattr__(self, name: str) -> Any:
        module = self.__dict__.get("_lazy_exports", {}).get(name)
        if module is None:  # a subpackage or module (rc.measure), as the eager imports bound them
            full = f"{self.__name__}.{name}"
            try:
                return importlib.import_module(full)
            except ModuleNotFoundError as err:
                if err.name != full:
                    raise
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        self.__dict__[name] = value
        return value

    def __setattr__(self, name: str, value: object) -> None:
        exports = self.__dict__.get("_lazy_exports", {})
        if (
            name in exports
            and isinstance(value, types.ModuleType)
            and value.__name__ == f"{self.__name__}.{name}"
        ):
            return  # the import system binding a submodule named like an exported function
        super().__setattr__(name, value)

    def __delattr__(self, name: str) -> None:
        exports = self.__dict__.get("_lazy_exports", {})
        if name not in exports and name not in self.__dict__:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        exports.pop(name, None)  # deleted means gone, not loaded again on the next access
        self.__dict__.pop(name, None)

    def __dir__(self) -> list[str]:
        lazy = set(self.__dict__.get("_lazy_exports", {})) | set(self.__dict__.get("_lazy_submodules", ()))
        return sorted(set(super().__dir__()) | lazy)


def lazy_package(name: str, exports: dict[str, tuple[str, ...]], submodules: tuple[str, ...] = ()) -> None:
    """Make package ``name`` load its exports on first use.

    Args:
        name: the package's ``__name__``.
        exports: module name -> the public names it provides.
        submodules: public submodules (``robocal.spatial``) loaded on first attribute access
            rather than with the package; listed by ``dir()`` like the exports.
    """
    package = sys.modules[name]
    package.__class__ = _LazyPackage
    package.__dict__["_lazy_submodules"] = tuple(submodules)
    package.__dict__["_lazy_exports"] = {attr: module for module, attrs in exports.items() for attr in attrs}
