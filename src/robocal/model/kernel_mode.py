"""Whether this process runs robocal's compiled (numba) kernels or their numpy path.

The compiled kernels are the default.  A command that finds numba's cache cold
(:func:`robocal.identify.kernel_cache.first_use`) switches the process to the numpy path
before its first calculation — the same results to round-off, without the half-minute
compile — while another process fills the cache for the next command.  The choice is the
process's, made once: one calibration never mixes the two.  ``ROBOCAL_KERNELS=numpy`` or
``=compiled`` in the environment overrides it (the warm-up process sets ``compiled``).
No numba is imported here.
"""

from __future__ import annotations

import os

__all__ = ["ENVIRONMENT", "compiled_wanted", "use_numpy_path"]

#: the environment variable that overrides the choice: ``numpy`` or ``compiled``
ENVIRONMENT = "ROBOCAL_KERNELS"
_NUMPY: list[bool] = []  # [True] once the process is switched to the numpy path


def compiled_wanted() -> bool:
    """Whether the compiled kernels are to be used (numba permitting): the environment's
    ``ROBOCAL_KERNELS`` when it says ``numpy`` or ``compiled``, else the process's choice
    (compiled unless :func:`use_numpy_path` was called)."""
    forced = os.environ.get(ENVIRONMENT, "").strip().lower()
    if forced in ("numpy", "compiled"):
        return forced == "compiled"
    return not _NUMPY


def use_numpy_path(on: bool = True) -> None:
    """Switch this process to the numpy path (``on``) or back to the compiled kernels."""
    _NUMPY.clear()
    if on:
        _NUMPY.append(True)
