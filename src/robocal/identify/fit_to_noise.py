"""Fit to noise: does the calibration explain the data down to the device's noise (chi-square of the
residuals), and the residual variance estimate (re-exported by :mod:`robocal.identify.guards`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


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
    import scipy.special

    r = np.asarray(residuals, dtype=float).reshape(-1, 3)
    s = np.asarray(sigma, dtype=float).reshape(-1, 3)
    m = r.size
    dof = max(m - float(n_estimated), 1.0)
    chi2 = float(np.sum((r / np.maximum(s, 1e-300)) ** 2))
    noise_ms = float(np.mean(np.sum(s**2, axis=1))) * dof / m
    ms = float(np.mean(np.sum(r**2, axis=1)))
    p_value = float(scipy.special.chdtrc(dof, chi2))  # the χ² survival function
    return FitToNoise(
        ratio=math.sqrt(chi2 / dof),
        p_value=p_value,
        dof=dof,
        noise_rms=math.sqrt(noise_ms),
        # only what the χ² test tells from noise (a model that explains the data leaves
        # residuals a little above their expectation half of the time)
        unmodelled_rms=math.sqrt(max(ms - noise_ms, 0.0)) if p_value < significance else 0.0,
    )


def residual_variance(chi2: ArrayLike, dof: ArrayLike, known: ArrayLike, significance: float = 1e-3) -> Array:
    """The variance factor of weighted residuals for a covariance, ``χ²/dof`` or 1.

    With weights 1/σ from a stated noise (``known``) the factor is 1 — the Cramér–Rao
    covariance — unless a χ² test rejects the stated noise at ``significance`` (either
    way): a few degrees of freedom cannot estimate it, and a model that explains the
    data leaves χ²/dof ≈ 1 anyway.  Without a stated noise it is estimated, ``χ²/dof``.
    Arrays broadcast (the batched study engine).
    """
    import scipy.special

    chi2, dof = np.asarray(chi2, dtype=float), np.maximum(np.asarray(dof, dtype=float), 1.0)
    estimated = chi2 / dof
    upper = scipy.special.chdtrc(dof, chi2)  # P(χ² >= observed)
    rejected = (upper < significance) | (1.0 - upper < significance)
    return np.where(np.asarray(known, dtype=bool) & ~rejected, 1.0, estimated)
