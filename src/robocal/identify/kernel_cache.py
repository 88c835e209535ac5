"""Whether robocal's compiled kernels are in numba's on-disk cache, the time spent compiling
them, and compiling them ahead.

The first calibration after installation compiles them (numba, ``cache=True``): 30-45 s of
CPU on a 2-core machine, once; later processes load the machine code in a fraction of a
second.  :func:`kernels_to_compile` lets a command say so before that silence instead of
leaving a user to wonder; :func:`work_clock` is the clock a calibration times itself with,
stopped while numba compiles, so a calibration's ``seconds`` (result.json, the report's
"calibration time") never include compilation; :func:`first_use` reports the compilation
apart, once (the cache keeps the code).

Compiling ahead: ``robocal demo --quick --out DIR`` compiles every kernel of the demo's
calibration, compensation and evaluation into numba's cache (a step for an image or an
installer: a wheel runs no code at installation, a build hook runs in pip's isolated build
environment without the runtime's numba, and numba's machine code is specific to the CPU,
the numba version and the source files' time stamps, so it cannot ship in the wheel).  Where the
cache lives is numba's choice: ``__pycache__`` beside the kernels when that is writable
(git-ignored in a checkout), else numba's user cache, or ``NUMBA_CACHE_DIR``.
"""

from __future__ import annotations

import contextlib
import importlib
import time
from collections.abc import Iterator
from typing import Any

__all__ = [
    "FIRST_USE_NOTICE",
    "KERNELS",
    "compile_seconds",
    "first_use",
    "kernels_to_compile",
    "work_clock",
]

#: the compiled entry points a calibration uses: ``(module, function)``
KERNELS = (
    ("robocal.model.kernels", "forward"),
    ("robocal.model.kernels_evaluate", "evaluate"),
    ("robocal.model.rank_kernels", "sequential_test"),
    ("robocal.identify.kernels.start", "frames_and_tools"),
    ("robocal.identify.kernels.lm", "propose"),
    ("robocal.identify.kernels.stage", "screen"),
    ("robocal.identify.kernels.fused", "fit"),
    ("robocal.identify.kernels.check", "data_ranges"),
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


_LISTENER: list[Any] = []  # the numba listener timing compilations, once registered


def _listener() -> Any:
    from numba.core import event

    class _CompileTimer(event.Listener):
        """Seconds spent in outermost compilations (nested ones are inside them)."""

        def __init__(self) -> None:
            self.depth, self.seconds, self.started = 0, 0.0, 0.0

        def on_start(self, event: Any) -> None:
            if self.depth == 0:
                self.started = time.perf_counter()
            self.depth += 1

        def on_end(self, event: Any) -> None:
            self.depth -= 1
            if self.depth == 0:
                self.seconds += time.perf_counter() - self.started

    listener = _CompileTimer()
    event.register("numba:compile", listener)  # numba fires it on a cache miss only
    return listener


def compile_seconds() -> float:
    """Seconds this process has spent compiling numba functions since the first call (which
    imports numba and starts counting; numba compiles one function at a time)."""
    if not _LISTENER:
        _LISTENER.append(_listener())
    return float(_LISTENER[0].seconds)


def work_clock() -> float:
    """``time.perf_counter()`` less the compilation time (s): differences of it time a
    calibration without numba compiling its kernels on first use."""
    compiling = compile_seconds()
    return time.perf_counter() - compiling


@contextlib.contextmanager
def first_use(console: Any, min_seconds: float = 0.5) -> Iterator[None]:
    """Around a command's use of the kernels: the notice before when some are to be compiled,
    and the compilation's time after (when at least ``min_seconds``), apart from the command's
    own times (printed once: numba's cache keeps the code for later processes)."""
    if kernels_to_compile():
        console.print(FIRST_USE_NOTICE, style="dim", highlight=False)
    before = compile_seconds()
    yield
    spent = compile_seconds() - before
    if spent >= min_seconds:
        console.print(
            f"compiling robocal's kernels took {spent:.1f} s (once: numba's cache keeps them); "
            "not counted in the calibration time",
            style="dim",
            highlight=False,
        )
