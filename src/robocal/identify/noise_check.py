"""Does the model explain the data down to the stated measurement noise?
:func:`fit_to_noise` and its verdict :class:`FitToNoise` (a χ² test of the position
residuals after a calibration, one of the guards of :mod:`robocal.identify.guards`).
Units: m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["FitToNoise", "fit_to_noise"]


@dataclass(frozen=True)
class FitToNoise:
    """How the residuals of a calibration compare with the stated measurement noise.

    Attributes:
        ratio: RMS of the position residuals in units of their standard deviation,
            corrected for the degrees of freedom the fit used (≈ 1 when the model
            explains the data down to the noise).
        p_value: probability of residuals at least this large if the model were right
            and the noise as stated (χ² distribution with ``dof`` degrees of freedom).
        dof: degrees of freedom of the position residuals.
        noise_rms: the RMS 3D position residual that noise alone would leave (m).
        unmodelled_rms: RMS 3D position error beyond the noise (m): the part of the
            data the model does not represent; 0 unless the χ² test (at ``significance``
            in :func:`fit_to_noise`) tells the residuals from noise.
    """

    ratio: float
    p_value: float
    dof: float
    noise_rms: float
    unmodelled_rms: float

    def to_dict(self) -> dict[str, float]:
        return {
            "ratio": self.ratio,
            "p_value": self.p_value,
            "dof": self.dof,
            "noise_rms_mm": self.noise_rms * 1e3,
            "unmodelled_rms_mm": self.unmodelled_rms * 1e3,
        }

    @classmethod
    def from_dict(cls, d: dict[str, float]) -> FitToNoise:
        """The inverse of :meth:`to_dict`."""
        return cls(d["ratio"], d["p_value"], d["dof"], d["noise_rms_mm"] / 1e3, d["unmodelled_rms_mm"] / 1e3)

    @classmethod
    def from_sums(
        cls, chi2: float, squares: float, noise: float, n: int, n_estimated: float, significance: float = 1e-3
    ) -> FitToNoise:
        """:func:`fit_to_noise` from the sums over the ``n`` poses' position rows: ``Σ(r/σ)²``,
        ``Σr²`` and ``Σσ²`` (m²)."""
        import scipy.special

        m = 3 * n
        dof = max(m - float(n_estimated), 1.0)
        noise_ms = noise / n * dof / m  # mean over the poses of Σσ², (m - p) / m of it
        ms = squares / n
        p_value = float(scipy.special.chdtrc(dof, chi2))  # the χ² survival function
        # only what the χ² test tells from noise (a model that explains the data leaves
        # residuals a little above their expectation half of the time)
        unmodelled = math.sqrt(max(ms - noise_ms, 0.0)) if p_value < significance else 0.0
        return cls(math.sqrt(chi2 / dof), p_value, dof, math.sqrt(noise_ms), unmodelled)

    @property
    def p_text(self) -> str:
        return "p < 1e-15" if self.p_value < 1e-15 else f"p = {self.p_value:.2g}"

    def summary(self) -> str:
        """One line: the residuals against the noise, and what is left unexplained."""
        head = f"residuals {self.ratio:.2f}x the stated noise ({self.p_text})"
        if self.warning() is None:
            return f"{head}: the model explains the data down to the measurement noise"
        if self.ratio > 1.0:
            return f"{head}: about {self.unmodelled_rms * 1e3:.3g} mm RMS the model does not represent"
        return f"{head}: the stated noise is probably too large"

    def warning(self, significance: float = 1e-3) -> str | None:
        """A sentence for the user when the residuals are significantly above the noise
        (χ² test at ``significance``) or far below it (σ overstated), else None."""
        if self.p_value < significance and self.ratio > 1.0:
            return (
                f"the residuals are {self.ratio:.2f}x the stated measurement noise (χ² test, "
                f"{self.p_text}): about {self.unmodelled_rms * 1e3:.3g} mm RMS of error that the "
                "model does not represent remains (joint effects, temperature, a moving device, or a "
                "noise level stated too small); the uncertainties are scaled to the residuals, and "
                "the held-out error will not fall below this"
            )
        if 1.0 - self.p_value < significance and self.ratio < 1.0:
            return (
                f"the residuals are only {self.ratio:.3g}x the stated measurement noise: the stated "
                "noise (sigma) is probably too large"
            )
        return None


def fit_to_noise(
    residuals: ArrayLike, sigma: ArrayLike, n_estimated: float, significance: float = 1e-3
) -> FitToNoise:
    """Compare position residuals with their stated standard deviations.

    Args:
        residuals: ``(n, 3)`` position residuals after the fit (m).
        sigma: ``(n, 3)`` their standard deviations (m).
        n_estimated: the number of estimated parameters spent on these residuals (for
            pose measurements, the position rows' share of them).

    With the right model and Gaussian noise of the stated σ, ``Σ (r/σ)²`` follows a χ²
    distribution with ``3n - p`` degrees of freedom.  The expected squared 3D residual
    is then ``mean(Σ σ²) (3n - p) / 3n``; whatever the mean squared residual exceeds
    that by is error the model does not represent.
    """
    import robocal.identify.kernels.check as check_kernels  # numba: imported on first use

    r = np.ascontiguousarray(residuals, dtype=float).reshape(-1, 3)
    s = np.ascontiguousarray(sigma, dtype=float).reshape(-1, 3)
    _, _, squares, chi2, noise = check_kernels.position_errors(r, s)
    return FitToNoise.from_sums(chi2, squares, noise, len(r), n_estimated, significance)
