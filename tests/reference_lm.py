"""The numpy Levenberg-Marquardt iteration the compiled kernels (robocal.identify.kernels.lm)
are tested (tests/test_lm_kernels.py) and timed (benchmarks/bench_lm.py) against: the numpy
path a process takes while numba's cache is cold, robocal.identify.kernels.numpy_lm."""

from robocal.identify.kernels.numpy_lm import damped_steps, levenberg_marquardt_batch_numpy

__all__ = ["damped_steps", "levenberg_marquardt_batch_numpy"]
