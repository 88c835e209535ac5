"""Where a study or a fleet runs: this process, a Dask ``LocalCluster`` made here
(:func:`local_cluster`) or an existing cluster (a scheduler address or a client)."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from robocal.study.config import StudyError

#: local worker processes per core at most: one per core is the default (each single-threaded
#: worker keeps a core busy); more only contend, and each costs ~150 MB and a second to start
MAX_WORKERS_PER_CORE = 4

#: seconds to reach a Dask scheduler before giving up (Dask retries a refused port until
#: then): an address that does not answer ends the command, not a 30 s wait
CONNECT_TIMEOUT_S = 5


def max_local_workers() -> int:
    """The most worker processes of a local cluster on this machine
    (:data:`MAX_WORKERS_PER_CORE` per core)."""
    return MAX_WORKERS_PER_CORE * (os.cpu_count() or 1)


def check_workers(workers: int) -> int:
    """``workers`` when a local cluster may have that many processes; else
    :class:`StudyError` naming the limit."""
    if workers < 0:
        raise StudyError(f"--workers {workers}: give 1 or more (0 runs in this process)")
    if workers > max_local_workers():
        raise StudyError(
            f"--workers {workers}: at most {max_local_workers()} local worker processes on this machine "
            f"({MAX_WORKERS_PER_CORE} per core); for more, start a Dask cluster and give --scheduler"
        )
    return workers


def _warm_up() -> bool:
    import contextlib

    import robocal.identify.calibrate
    import robocal.identify.validate
    import robocal.measure.poses
    import robocal.measure.simulate  # noqa: F401

    with contextlib.suppress(ImportError):  # numba and the compiled kernels (~0.3 s per process)
        pass
    return True


def _prime(fn: Callable, item: Any) -> bool:
    """Run ``fn(item)`` and drop the result: the first task of a process pays the cached
    kernels' loading and the chain's plans (0.25 s, twice a later task of 50 robots)."""
    try:
        fn(item)
    except Exception:  # the real task reports it
        return False
    return True


def local_cluster(workers: int | None = None):
    """A Dask ``LocalCluster`` set up for robocal's tasks: ``workers`` single-threaded worker
    processes (default one per core), no dashboard, and the settings below (use it as
    ``Client(local_cluster(2))``; :func:`run_study` makes one unless given a client or a
    scheduler address)."""
    import logging

    import dask
    from distributed import LocalCluster

    n = check_workers(workers) if workers is not None else (os.cpu_count() or 1)
    # Dask starts workers with MALLOC_TRIM_THRESHOLD_=65536, which also freezes glibc's
    # mmap threshold at 128 KiB: every Jacobian-sized array is then mmapped and
    # page-faulted afresh, and freed heap is given back at once, ~1.5x slower here
    # (benchmarks/bench_throughput.py --malloc).  Arrays up to 16 MiB come from the
    # heap instead, and up to 64 MiB of freed heap is kept.  (The nanny sets these
    # variables in this process before it spawns a worker: put them back after.)
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ["MALLOC_MMAP_THRESHOLD_"] = 16 << 20
    environ["MALLOC_TRIM_THRESHOLD_"] = 64 << 20
    environ.setdefault("OPENBLAS_NUM_THREADS", 1)  # one core per worker: BLAS threads only contend
    environ.setdefault("OMP_NUM_THREADS", 1)
    environ.setdefault("MKL_NUM_THREADS", 1)
    saved = {k: os.environ.get(k) for k in environ}
    settings = {
        "distributed.nanny.pre-spawn-environ": environ,
        # the statistical profiler feeds the dashboard (off here) and samples the
        # task's stack every 10 ms: ~15 % of a worker's time in this code
        "distributed.worker.profile.enabled": False,
        # each worker holds its next task while computing one (the default 1.1 hands a
        # single-threaded worker its next task only when it asks: a scheduler round trip
        # between tasks); the tasks are few and of equal size
        "distributed.scheduler.worker-saturation": 2.0,
        # housekeeping that wakes every process on two cores shared by the workers, the
        # scheduler and this client: the event-loop watchdog (every 20 ms), the system
        # monitor (psutil, every 500 ms) and the memory monitor (every 100 ms); less often
        "distributed.admin.tick.interval": "500ms",
        "distributed.admin.system-monitor.interval": "2s",
        "distributed.worker.memory.monitor-interval": "1s",
        # equal tasks, one per worker core at a time: nothing to steal
        "distributed.scheduler.work-stealing": False,
    }
    try:
        with dask.config.set(settings):
            return LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,  # not the workers' shutdown chatter
            )
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _connect(scheduler: str):
    """A client of the Dask scheduler at ``scheduler``, or :class:`StudyError` after
    :data:`CONNECT_TIMEOUT_S` seconds (refused, unreachable, or not an address)."""
    import dask
    from distributed import Client

    timeout = f"{CONNECT_TIMEOUT_S}s"
    try:
        with dask.config.set({"distributed.comm.timeouts.connect": timeout}):
            return Client(scheduler, timeout=timeout)
    except (OSError, ValueError, TimeoutError) as err:  # unreachable, or not an address Dask knows
        why = " ".join(str(err).split()) or type(err).__name__
        raise StudyError(
            f"Dask scheduler {scheduler}: not reached within {CONNECT_TIMEOUT_S} s ({why}); "
            "check the address and that the scheduler runs"
        ) from None


class Executor:
    """In-process execution or a Dask client (local cluster or a scheduler address)."""

    def __init__(self, workers: int | None, scheduler: str | None) -> None:
        self.client = None
        self.cluster = None
        self.workers = 0
        if scheduler is None and workers == 0:
            return
        from distributed import Client

        if scheduler is not None:
            self.client = _connect(scheduler)
            self.workers = len(self.client.scheduler_info().get("workers", {}))
        else:
            n = check_workers(workers if workers is not None else (os.cpu_count() or 1))
            self.cluster = local_cluster(n)
            self.client = Client(self.cluster)
            self.workers = n
        self.warm_up()

    def warm_up(self) -> None:
        """Import robocal on every worker now, not inside the first task (excluded from timing)."""
        if self.client is not None:
            self.client.run(_warm_up)

    def prime(self, fn: Callable, item: Any) -> None:
        """Run ``fn(item)`` once on every worker (a small task: start-up, not throughput)."""
        if self.client is not None:
            self.client.run(_prime, fn, item)

    def map(self, fn: Callable, items: Sequence, on_error: Callable) -> Iterator[tuple[Any, Any]]:
        """``(item, fn(item))`` as they complete; a failed task yields ``(item, on_error(item, exc))``."""
        if self.client is None:
            for item in items:
                try:
                    yield item, fn(item)
                except Exception as err:
                    yield item, on_error(item, err)
            return
        from distributed import as_completed

        futures = {self.client.submit(fn, item, pure=False): item for item in items}
        for future in as_completed(futures):
            item = futures[future]
            try:
                yield item, future.result()
            except Exception as err:
                yield item, on_error(item, err)
            future.release()

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def executor_for(workers: int | None, scheduler: str | None, client: Any = None) -> Executor:
    """The executor of a run: ``client`` when given (it stays open after the run), else one
    made for ``workers`` / ``scheduler`` (as :class:`_Executor`)."""
    if client is None:
        return Executor(workers, scheduler)
    executor = Executor(0, None)
    executor.client = client
    executor.workers = len(client.scheduler_info().get("workers", {}))
    executor.warm_up()
    return executor
