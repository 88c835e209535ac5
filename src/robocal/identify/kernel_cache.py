"""Whether robocal's compiled kernels are in numba's on-disk cache, the time spent compiling
them, and compiling them ahead.

The first calibration after installation compiles them (numba, ``cache=True``): 30-45 s of
CPU on a 2-core machine, once; later processes load the machine code in a fraction of a
second.  :func:`kernels_to_compile` lets a command say so before that silence instead of
leaving a user to wonder; :func:`work_clock` is the clock a calibration times itself with,
stopped while numba compiles, so a calibration's ``seconds`` (result.json, the report's
"calibration time") never include compilation; :func:`first_use` reports the compilation
apart, once (the cache keeps the code).

The first command without the compile: :func:`first_use` finds the cache cold, switches the
process to the numpy path (:mod:`robocal.model.kernel_mode`: the same results to round-off)
and starts :func:`warm_up` — another process, at a lower priority, compiling the kernels
into the cache by the quick demo — so that the next command finds them compiled
(:func:`wait_for_warm_up` waits for it; one warm-up at a time per cache).

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
import hashlib
import importlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

from robocal.model.kernel_mode import ENVIRONMENT, compiled_wanted, use_numpy_path

__all__ = [
    "FIRST_USE_NOTICE",
    "KERNELS",
    "choose_path",
    "compile_seconds",
    "first_use",
    "kernels_to_compile",
    "stage_kernels",
    "start_kernels",
    "wait_for_warm_up",
    "warm_up",
    "warm_up_lock",
    "work_clock",
]

#: the compiled entry points a calibration uses: ``(module, function)``
KERNELS = (
    ("robocal.model.kernels", "forward"),
    ("robocal.model.kernels_evaluate", "evaluate"),
    ("robocal.model.rank_kernels", "sequential_test"),
    ("robocal.model.rank_kernels", "gram_sequential_test"),
    ("robocal.identify.kernels.start", "frames_and_tools"),
    ("robocal.identify.kernels.lm", "propose"),
    ("robocal.identify.kernels.stage", "screen"),
    ("robocal.identify.kernels.fused", "fit"),
    ("robocal.identify.kernels.check", "data_ranges"),
)

FIRST_USE_NOTICE = (
    "first use after installation: this run computes with numpy while another process compiles "
    "robocal's numerical kernels (numba, about 30 s once; later runs load them from numba's cache)"
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


# ---------------------------------------------------------------------- the numpy path until warm
def stage_kernels() -> ModuleType:
    """:mod:`robocal.identify.kernels.stage`, or its numpy path
    (:mod:`robocal.identify.kernels.numpy_path`, the same functions) when this process
    computes with numpy (:func:`robocal.model.kernel_mode.compiled_wanted`)."""
    name = "stage" if compiled_wanted() else "numpy_path"
    return importlib.import_module(f"robocal.identify.kernels.{name}")


def start_kernels() -> ModuleType:
    """:mod:`robocal.identify.kernels.start`, or its numpy path (as :func:`stage_kernels`)."""
    name = "start" if compiled_wanted() else "numpy_path"
    return importlib.import_module(f"robocal.identify.kernels.{name}")


def choose_path(warm: bool = True) -> bool:
    """Before a command's first calculation: the numpy path for this process when some
    kernels are not in numba's cache (and the environment does not say
    ``ROBOCAL_KERNELS``), with :func:`warm_up` started when ``warm``.  Returns whether the
    numpy path was chosen."""
    if os.environ.get(ENVIRONMENT, "").strip().lower() in ("numpy", "compiled") or not kernels_to_compile():
        return False
    use_numpy_path(True)
    if warm:
        warm_up()
    return True


def warm_up_lock() -> Path:
    """The lock file a warm-up holds while it compiles (one per user and numba cache: the
    ``NUMBA_CACHE_DIR`` or this installation's source directory)."""
    where = os.environ.get("NUMBA_CACHE_DIR") or str(Path(__file__).resolve().parents[1])
    key = hashlib.sha256(where.encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / f"robocal-warm-up-{os.getuid()}-{key}.lock"


# The warm-up process: the lock first (another warm-up holding it: nothing to do), at a low
# priority, the quick demo into a temporary folder (every kernel of a calibration, its
# compensation and evaluation), then its CPU seconds into the lock file.  A script rather
# than an import of the demo: the demo sits above this package.
_WARM_UP = """
import fcntl, os, resource, sys, tempfile
lock = open(sys.argv[1], "a+")
try:
    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
except OSError:
    sys.exit(0)
os.nice(10)
from robocal.demo import run_demo
with tempfile.TemporaryDirectory(prefix="robocal-warm-up-") as folder:
    run_demo(out=folder, quick=True, verbose=False)
usage = resource.getrusage(resource.RUSAGE_SELF)
lock.seek(0); lock.truncate(); lock.write(f"{usage.ru_utime + usage.ru_stime:.3f}"); lock.flush()
"""


def warm_up() -> subprocess.Popen:
    """Start compiling the kernels into numba's cache in another process (detached, lower
    priority, its output discarded; the compiled path forced there)."""
    env = dict(os.environ, **{ENVIRONMENT: "compiled"})
    return subprocess.Popen(
        [sys.executable, "-c", _WARM_UP, str(warm_up_lock())],
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # not stopped by the terminal's Ctrl-C of the command
    )


def wait_for_warm_up() -> float | None:
    """Wait until no warm-up holds the lock; the CPU seconds the last one wrote (None when
    none has finished)."""
    import fcntl

    lock = warm_up_lock()
    if not lock.exists():
        return None
    with lock.open("a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        handle.seek(0)
        text = handle.read().strip()
    try:
        return float(text)
    except ValueError:
        return None


@contextlib.contextmanager
def first_use(console: Any, min_seconds: float = 0.5) -> Iterator[None]:
    """Around a command's use of the kernels: with some kernels not compiled, the numpy path
    for this command and the warm-up for the next (:func:`choose_path`) with a notice; and
    any compilation's time after (when at least ``min_seconds``), apart from the command's
    own times (printed once: numba's cache keeps the code for later processes)."""
    if choose_path():
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
