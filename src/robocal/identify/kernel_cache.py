"""Whether robocal's compiled kernels are in numba's on-disk cache.

The first calibration after installation compiles them (numba, ``cache=True``): about 30 s
on a 2-core machine, once; later processes load the machine code in a fraction of a
second.  :func:`kernels_to_compile` lets a command say so before that silence instead of
leaving a user to wonder.
"""

from __future__ import annotations

import importlib

__all__ = ["FIRST_USE_NOTICE", "KERNELS", "kernels_to_compile"]

#: the compiled entry points a calibration uses: ``(module, function)``
KERNELS = (
    ("robocal.model.kernels", "forward"),
    ("robocal.model.kernels_evaluate", "evaluate"),
    ("robocal.model.rank_kernels", "sequential_test"),
    ("robocal.identify.start_kernels", "frames_and_tools"),
    ("robocal.identify.lm_kernels", "propose"),
    ("robocal.identify.stage_kernels", "screen"),
    ("robocal.identify.fused_kernels", "fit"),
    ("robocal.identify.check_kernels", "data_ranges"),
)

FIRST_USE_NOTICE = (
    "first use after installation: compiling robocal's numerical kernels (numba, about 30 s once; "
    "later runs load them from numba's cache)"
)


def kernels_to_compile() -> list[str]:
    """The kernels of :data:`KERNELS` with no machine code for this source in numba's
    cache (``module.function``).  Imports them (and numba).  Reads numba's cache index
    through a private interface: a kernel it cannot check counts as cached (no notice
    rather than a wrong one)."""
    missing = []
    for module, name in KERNELS:
        dispatcher = getattr(importlib.import_module(module), name)
        try:
            cached = bool(dispatcher._cache._cache_file._load_index())
        except Exception:  # another numba's internals: cannot tell
            cached = True
        if not cached:
            missing.append(f"{module}.{name}")
    return missing
