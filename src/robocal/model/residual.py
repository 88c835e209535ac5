"""The learned residual of a calibrated model: joint angle errors as functions of the joint angles.

After the physical model (complete geometry + seed 003's joint effects) a real robot
keeps a repeatable, configuration-dependent error.  On the real UR10 of
``shared/data/ur10_laser_tracker`` it is about 0.38 mm and, measured, almost all of it is
a sum of *per-joint angle errors that depend on that joint's own angle* (the kinematic
error of the gearbox and the encoder's eccentricity: a transmission error with many
harmonics per revolution).  robocal represents it so, as a residual of the joints::

    δθ_j(q_j) = Σ_{h=1..H} a_jh cos(h q_j) + b_jh sin(h q_j)          (rad)

added to the joint perturbations ``(δα, δβ, δθ)`` that every part of robocal already
passes to the chain (FK, Jacobians, IK, compensation, paths, the report).  The
coefficients carry a Gaussian posterior (mean and covariance, from Bayesian linear
regression with a prior that is a stationary Gaussian process on each joint's circle:
amplitude per joint, one spectral length scale; :mod:`robocal.identify.residual.stage`), so
every prediction has a variance.

The candidates compared, the numbers behind this choice and the cross-validated choice
of H are in ``benchmarks/bench_real_accuracy.py`` and the README.

Units: angles in rad, coefficients in rad, covariances in rad².
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.model.fourier import fourier_basis, fourier_gram, fourier_series

__all__ = [
    "FADE",
    "GLOBAL_HARMONICS",
    "SERIES_CHUNK",
    "JointAngleResidual",
    "covered_intervals",
    "fourier_basis",
    "fourier_gram",
    "fourier_series",
    "one_blas_thread",
]

Array = NDArray[np.float64]
FADE = 0.1  # rad: outside its calibrated range a joint's learned angle error fades out over this
#: harmonics (once and twice per revolution: a gear's or encoder's eccentricity and
#: ellipticity) that a fit keeps where the rest fades: a property of the whole joint, fitted
#: from all its angles (the hybrid's physics is fitted together with them: fading them
#: left it without its partner).  Series A's CV at 100 poses: lower with them kept in 4 of
#: 5 seeds, equal in one (docs/concepts/residual.md)
GLOBAL_HARMONICS = 2
#: poses per block of :meth:`JointAngleResidual.angle_errors`: its seven ``(block, joints)``
#: work arrays stay in the core's cache (20,000 poses a block: 1.5x the time)
SERIES_CHUNK = 2048


def covered_intervals(angles: ArrayLike, gap: float = 0.2) -> tuple[tuple[float, float], ...]:
    """The intervals ``((lo, hi), ...)`` (rad) that ``angles`` ``(n,)`` cover: sorted angles
    closer than ``gap`` are joined."""
    a = np.sort(np.asarray(angles, dtype=float).reshape(-1))
    breaks = np.flatnonzero(np.diff(a) > gap)
    starts, ends = np.r_[0, breaks + 1], np.r_[breaks, len(a) - 1]
    return tuple((float(a[i]), float(a[j])) for i, j in zip(starts, ends, strict=True))


def _distance(angles: Array, intervals: tuple[tuple[float, float], ...]) -> Array:
    """``(n,)`` distance (rad) of each angle to the nearest of the intervals (0 inside)."""
    lo, hi = np.array(intervals).T
    return np.min(np.maximum(lo - angles[:, None], 0.0) + np.maximum(angles[:, None] - hi, 0.0), axis=1)


_BLAS_LIMITED = [0]  # depth of nested one_blas_thread contexts


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """A context in which BLAS/LAPACK run on one thread (threadpoolctl): the evidence's
    factorisations of ``(m, m)`` matrices ran 4x slower with OpenBLAS's threads on a shared
    2-core machine, and its idle threads spinning doubled the default calibration's CPU time;
    without threadpoolctl, nothing changes.  Nested contexts cost nothing (setting the limit
    costs 0.4 ms: the model choice enters hundreds).  The residual's covariances of many
    poses run in it too (a held-out validation of 11,611 poses: 0.60 s of CPU with two
    threads, 0.38 s with one)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        yield
        return
    limit = threadpool_limits(1, user_api="blas") if _BLAS_LIMITED[0] == 0 else contextlib.nullcontext()
    _BLAS_LIMITED[0] += 1
    try:
        with limit:
            yield
    finally:
        _BLAS_LIMITED[0] -= 1


@dataclass(frozen=True)
class JointAngleResidual:
    """Learned angle errors ``δθ_j(q_j)`` of some joints of a chain (see the module docstring).

    Attributes:
        joints: names of the joints whose angle errors are modelled, in chain order.
        joint_index: their indices among the chain's joints (0-based).
        harmonics: H, harmonics per revolution.
        coefficients: ``(m,)`` posterior mean (rad), ``m = len(joints) * 2 H``, ordered
            joint by joint, then ``cos 1, sin 1, cos 2, ...``.
        covariance: ``(m, m)`` posterior covariance (rad²); zeros when unknown (a model
            file alone does not carry it: ``result.json`` does).
        noise_std: σ (m) per axis of what remains: the measurement noise and the error
            neither the physics nor this residual represents (the evidence's estimate).
        amplitudes: prior standard deviation per joint (rad), the fitted hyperparameters.
        length_scale: the prior's spectral length scale (rad): harmonic ``h`` has prior
            variance proportional to ``exp(-(h ℓ)²/2)`` (normalised so that the amplitude is
            the RMS of the joint's angle error).
        coverage: per joint, the angle intervals ``((lo, hi), ...)`` (rad) the calibration
            poses covered (angles closer than ``2 fade_width`` joined).  Where the data says
            nothing — beyond the range or in a gap — a Fourier series would go on
            oscillating (a UR10 with a 0.28 rad gap in its shoulder angles: 5 mrad, 8 mm at
            the tool), so each joint's angle error fades to zero within ``fade_width`` rad
            of its covered intervals (cos² taper); None: no fading.
        angle_rms: per joint, the RMS (rad) of the learned angle error's fading part (the
            harmonics above ``global_harmonics``) over the calibration poses: where the
            residual fades out, an error of about this size is what it no longer predicts
            (its share of the predicted uncertainty there).
        fade_width: how far (rad) beyond its coverage an angle error fades out: the prior's
            correlation length ``length_scale``, at least :data:`FADE` (:meth:`covering`);
            a smooth residual is supported by its data that far (a virtual UR10 with
            ℓ = 0.24 rad lost 15 % of its accuracy inside its poses' range to gaps of
            0.2-0.3 rad faded at 0.1), a rough one (the real UR10: ℓ ≈ 0.06 rad at 48
            harmonics) not beyond :data:`FADE`.
        global_harmonics: the first harmonics, which never fade (0 in files from before:
            all fade; :data:`GLOBAL_HARMONICS` from a fit).
    """

    joints: tuple[str, ...]
    joint_index: tuple[int, ...]
    harmonics: int
    coefficients: Array = field(repr=False)
    covariance: Array = field(repr=False)
    noise_std: float
    amplitudes: tuple[float, ...]
    length_scale: float
    coverage: tuple[tuple[tuple[float, float], ...], ...] | None = None
    angle_rms: tuple[float, ...] | None = None
    fade_width: float = FADE
    global_harmonics: int = 0

    kind = "joint_fourier"

    def __post_init__(self) -> None:
        m = len(self.joints) * 2 * self.harmonics
        c = np.asarray(self.coefficients, dtype=float).reshape(-1)
        C = np.asarray(self.covariance, dtype=float)
        if len(self.joint_index) != len(self.joints) or len(self.amplitudes) != len(self.joints):
            raise ValueError("residual: joints, joint_index and amplitudes must have the same length")
        if c.shape != (m,) or C.shape != (m, m):
            raise ValueError(
                f"residual: {len(self.joints)} joints x {self.harmonics} harmonics need {m} coefficients and "
                f"a {m}x{m} covariance, got {c.shape} and {C.shape}"
            )
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(C))):
            raise ValueError("residual: coefficients and covariance must be finite")
        if not (self.harmonics >= 1 and np.isfinite(self.noise_std) and self.noise_std >= 0):
            raise ValueError("residual: harmonics must be >= 1 and noise_std finite and >= 0")
        if not 0 <= self.global_harmonics <= self.harmonics:
            raise ValueError(f"residual: global_harmonics must lie in 0..{self.harmonics}")
        if not (math.isfinite(self.fade_width) and self.fade_width > 0):
            raise ValueError(f"residual: fade_width must be finite and > 0 rad, got {self.fade_width!r}")
        if self.coverage is not None:
            cover = tuple(tuple((float(lo), float(hi)) for lo, hi in joint) for joint in self.coverage)
            ok = len(cover) == len(self.joints) and all(
                joint and all(math.isfinite(lo) and math.isfinite(hi) and lo <= hi for lo, hi in joint)
                for joint in cover
            )
            if not ok:
                raise ValueError("residual: coverage needs finite (lo <= hi) intervals for every joint")
            object.__setattr__(self, "coverage", cover)
        c.setflags(write=False)
        C = C.copy()
        C.setflags(write=False)
        object.__setattr__(self, "coefficients", c)
        object.__setattr__(self, "covariance", C)

    @property
    def size(self) -> int:
        return len(self.coefficients)

    def basis(self, q: ArrayLike) -> Array:
        """``(n, k, 2 H)`` basis values at joint values ``q`` ``(n, dof)``, faded outside the
        calibrated angle ranges."""
        angles = np.atleast_2d(np.asarray(q, dtype=float))[:, list(self.joint_index)]
        B = fourier_basis(angles, self.harmonics)
        if self.coverage is None:
            return B
        B[:, :, 2 * self.global_harmonics :] *= self.fade(q)[:, :, None]
        return B

    def angle_errors(self, q: ArrayLike) -> Array:
        """``(n, k)`` angle errors δθ (rad) of the modelled joints at ``q`` ``(n, dof)``.

        The series is summed by :func:`fourier_series` (Clenshaw), :data:`SERIES_CHUNK`
        poses at a time, without holding the ``(n, k, 2H)`` basis; the first
        ``global_harmonics`` apart from the fading rest.  1,000,000 poses, 6 joints, 48
        harmonics: 1.1 s (the angle-addition recurrence before it: 2.5-3.4 s)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        angles = q[:, list(self.joint_index)]
        coef = self.coefficients.reshape(len(self.joints), self.harmonics, 2)
        split = 0 if self.coverage is None else self.global_harmonics
        fading = coef.copy()
        fading[:, :split] = 0.0  # summed apart: they never fade
        out = np.empty(angles.shape)
        for lo in range(0, len(q), SERIES_CHUNK):
            s = slice(lo, lo + SERIES_CHUNK)
            c1, s1 = np.cos(angles[s]), np.sin(angles[s])
            out[s] = fourier_series(c1, s1, fading)
            if self.coverage is not None:
                out[s] *= self.fade(q[s])
            if split:
                out[s] += fourier_series(c1, s1, coef[:, :split])
        return out

    def perturbations(self, q: ArrayLike, dof: int | None = None) -> Array:
        """Joint perturbations ``(n, dof, 3)`` (δα, δβ, δθ; only δθ is non-zero) at ``q``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.zeros((len(q), q.shape[1] if dof is None else dof, 3))
        out[:, list(self.joint_index), 2] = self.angle_errors(q)
        return out

    def design(self, q: ArrayLike, P: Array) -> Array:
        """``(n, r, m)`` derivative of the tool position (``r = 3``) or pose (``r = 6``) wrt the
        coefficients, from the perturbation Jacobian ``P`` ``(n, r, dof, 3)`` at ``q``."""
        B = self.basis(q)  # (n, k, 2H)
        cols = P[:, :, list(self.joint_index), 2]  # (n, r, k)
        return (cols[:, :, :, None] * B[:, None, :, :]).reshape(len(B), P.shape[1], -1)

    def position_covariance(self, q: ArrayLike, P: Array) -> Array:
        """``(n, 3, 3)`` covariance (m²) of the residual's position prediction at ``q``: the
        coefficients' posterior, and where the residual fades out (outside the covered
        angles) the angle errors it no longer predicts, at their size on the calibration
        poses (``angle_rms``) (the noise ``noise_std`` is not included)."""
        with one_blas_thread():
            return self._position_covariance(np.atleast_2d(np.asarray(q, dtype=float)), P)

    def _position_covariance(self, q: Array, P: Array) -> Array:
        B = fourier_basis(q[:, list(self.joint_index)], self.harmonics)  # (n, k, 2H)
        fade = None if self.coverage is None else self.fade(q)  # (n, k), once for both uses
        if fade is not None:
            B[:, :, 2 * self.global_harmonics :] *= fade[:, :, None]
        cols = P[:, :3, list(self.joint_index), 2]  # (n, 3, k): position per rad of each joint
        cov = cols @ self._basis_covariance(B) @ np.swapaxes(cols, 1, 2)
        if fade is not None:
            rms = np.asarray(self.amplitudes if self.angle_rms is None else self.angle_rms)
            missing = (1.0 - fade**2) * rms**2  # (n, k) rad²
            cov = cov + np.einsum("nrk,nk,nsk->nrs", cols, missing, cols)
        return cov

    def _basis_covariance(self, B: Array, chunk: int = 2048) -> Array:
        """``(n, k, k)``: the covariance of the angle errors at poses with basis ``B``
        ``(n, k, 2H)``, ``M_n = B̃_n C B̃_nᵀ`` (``B̃_n`` the pose's basis rows, block-diagonal
        over the joints; ``C`` the coefficients' covariance).  ``A C Aᵀ`` with ``A`` the
        :meth:`design` is then ``cols M colsᵀ``: ``n m²`` multiply-adds in one large product
        per joint instead of ``3 n m²`` in a small one per pose (11,811 poses, 6 joints x 48
        harmonics: 2.2 s before); ``chunk`` poses at a time bound the memory."""
        n, k, h2 = B.shape
        C = self.covariance.reshape(k, h2, k * h2)
        M = np.empty((n, k, k))
        for start in range(0, n, chunk):
            Bc, Mc = B[start : start + chunk], M[start : start + chunk]
            for a in range(k):  # M is symmetric: the blocks b >= a, mirrored (7/12 of the work for 6 joints)
                X = (Bc[:, a, :] @ C[a, :, a * h2 :]).reshape(len(Bc), k - a, h2)  # (B̃ C) rows of joint a
                Mc[:, a, a:] = np.einsum("nbh,nbh->nb", X, Bc[:, a:, :])
                Mc[:, a + 1 :, a] = Mc[:, a, a + 1 :]
        return M

    def coefficient_map(self, q: ArrayLike, P: Array, X: Array) -> Array:
        """``(n, 3, p)`` = ``A Xᵀ`` for ``X`` ``(p, m)`` (e.g. a cross-covariance with other
        parameters) and ``A`` the position rows of :meth:`design` at ``q``, without forming
        ``A`` (``(n, 3, m)``: 160 MB at 11,811 poses and 576 coefficients)."""
        B = self.basis(q)  # (n, k, 2H)
        _, k, h2 = B.shape
        cols = P[:, :3, list(self.joint_index), 2]  # (n, 3, k)
        Xk = np.asarray(X, dtype=float).reshape(len(X), k, h2)
        with one_blas_thread():
            V = np.stack([B[:, a, :] @ Xk[:, a, :].T for a in range(k)], axis=1)  # (n, k, p)
        return cols @ V

    def mean_position_variance(
        self, q: ArrayLike, P: Array, J: Array | None = None, X: Array | None = None
    ) -> float:
        """The mean over the poses ``q`` of ``trace`` :meth:`position_covariance` (m²) and,
        given other parameters' position columns ``J`` ``(n, 3, p)`` and their
        cross-covariance ``X`` ``(p, m)`` with the coefficients, of ``trace(J X Aᵀ + A Xᵀ Jᵀ)``
        (``A`` the position rows of :meth:`design`): the residual's share of the expected
        squared error at ``q``, without the ``(n, 3, 3)`` covariances.

        ``Σ_n tr(A_n C A_nᵀ) = Σ_ab ⟨C_ab, Σ_n W_n[a, b] B_naᵀ B_nb⟩`` with ``W_n = colsᵀ cols``
        (``k x k``) and ``B_na`` the pose's basis row of joint ``a``: one product over all
        poses per pair of joints (``b >= a``, the matrix is symmetric)."""
        with one_blas_thread():
            return self._mean_position_variance(np.atleast_2d(np.asarray(q, dtype=float)), P, J, X)

    def _mean_position_variance(self, q: Array, P: Array, J: Array | None, X: Array | None) -> float:
        # the basis joint by joint, each joint's (n, 2H) rows contiguous (BLAS wants them so;
        # copying them out of basis()'s (n, k, 2H) took as long as the products: 11,611 poses)
        rows = fourier_basis(q[:, list(self.joint_index)].T, self.harmonics)  # (k, n, 2H)
        k, n, h2 = rows.shape
        fade = None if self.coverage is None else self.fade(q)  # (n, k), once for both uses
        if fade is not None:
            rows[:, :, 2 * self.global_harmonics :] *= fade.T[:, :, None]
        cols = P[:, :3, list(self.joint_index), 2]  # (n, 3, k)
        W = np.swapaxes(cols, 1, 2) @ cols  # (n, k, k)
        Wt = np.ascontiguousarray(W.transpose(1, 2, 0))  # (k, k, n)
        C = self.covariance
        total = 0.0
        for a in range(k):
            total += float(
                np.vdot(
                    C[a * h2 : (a + 1) * h2, a * h2 : (a + 1) * h2],
                    self._diagonal_block(q, a, Wt[a, a], fade),
                )
            )
            for b in range(a + 1, k):
                G = (rows[a] * Wt[a, b][:, None]).T @ rows[b]  # (2H, 2H)
                total += 2.0 * float(np.vdot(C[a * h2 : (a + 1) * h2, b * h2 : (b + 1) * h2], G))
        if fade is not None:  # the faded-out angle errors (position_covariance's term)
            rms = np.asarray(self.amplitudes if self.angle_rms is None else self.angle_rms)
            missing = (1.0 - fade**2) * rms**2  # (n, k) rad²
            total += float(np.vdot(np.diagonal(W, axis1=1, axis2=2), missing))
        if J is not None and X is not None:  # 2 Σ_n tr(J_n X A_nᵀ) = 2 ⟨X, Σ_n J_nᵀ A_n⟩
            V = np.swapaxes(cols, 1, 2) @ J  # (n, k, p)
            Xk = np.asarray(X, dtype=float).reshape(len(X), k, h2)
            total += 2.0 * sum(float(np.vdot(Xk[:, a, :], V[:, a, :].T @ rows[a])) for a in range(k))
        return total / n

    def _diagonal_block(self, q: Array, a: int, w: Array, fade: Array | None) -> Array:
        """``B_aᵀ diag(w) B_a`` ``(2H, 2H)`` of joint ``a``'s faded basis rows at ``q`` from
        sums of harmonics (:func:`fourier_gram`): the global harmonics' columns unfaded, the
        others times the fade ``f`` (``(n, k)``; None: none), so the block is the grams of the
        weights ``w``, ``w f`` and ``w f²`` where the columns meet."""
        angles = q[:, self.joint_index[a]]
        if fade is None:
            return fourier_gram(angles, w, self.harmonics)
        f = fade[:, a]
        plain, once, twice = fourier_gram(angles, np.stack([w, w * f, w * f * f]), self.harmonics)
        g = 2 * self.global_harmonics
        out = twice
        out[:g, :g], out[:g, g:], out[g:, :g] = plain[:g, :g], once[:g, g:], once[g:, :g]
        return out

    def fade(self, q: ArrayLike) -> Array:
        """``(n, k)`` weight of each joint's learned angle error at ``q``: 1 on the covered
        angles, 0 from ``fade_width`` rad away (all ones without coverage)."""
        angles = np.atleast_2d(np.asarray(q, dtype=float))[:, list(self.joint_index)]
        if self.coverage is None:
            return np.ones_like(angles)
        outside = np.stack([_distance(angles[:, k], joint) for k, joint in enumerate(self.coverage)], axis=1)
        return np.cos(0.5 * np.pi * np.minimum(outside / self.fade_width, 1.0)) ** 2

    def covering(self, q: ArrayLike) -> JointAngleResidual:
        """This residual with the coverage of the calibration poses ``q`` ``(n, dof)``, its
        first :data:`GLOBAL_HARMONICS` harmonics kept everywhere and the rest faded over a
        width of its prior's correlation length (at least :data:`FADE`): the
        GP's posterior is supported about ``length_scale`` from its data (the spectral
        weights ``exp(-(h ℓ)²/2)`` are a Gaussian kernel of width ℓ on the circle)."""
        width = max(FADE, float(self.length_scale))
        angles = np.atleast_2d(np.asarray(q, dtype=float))
        cover = tuple(covered_intervals(angles[:, j], 2 * width) for j in self.joint_index)
        kept = min(GLOBAL_HARMONICS, self.harmonics)
        return dataclasses.replace(self, coverage=cover, fade_width=width, global_harmonics=kept)

    # ------------------------------------------------------------------ files
    def to_dict(self, covariance: bool = False) -> dict[str, Any]:
        """Plain lists and numbers (SI) for a model file; exact float round trip of what
        predictions use.  The coefficients' covariance (``covariance=True``: its upper
        triangle to 9 significant digits) is large (m(m+1)/2 numbers) and belongs with the
        calibration's other covariances in ``result.json``; a model file leaves it out."""
        out = {
            "kind": self.kind,
            "joints": list(self.joints),
            "harmonics": self.harmonics,
            "noise_std": float(self.noise_std),
            "amplitudes": [float(a) for a in self.amplitudes],
            "length_scale": float(self.length_scale),
            "coefficients": [float(v) for v in self.coefficients],
        }
        if self.coverage is not None:
            out["coverage"] = [[[lo, hi] for lo, hi in joint] for joint in self.coverage]
        if self.angle_rms is not None:
            out["angle_rms"] = [float(v) for v in self.angle_rms]
        if self.fade_width != FADE:  # older files: FADE
            out["fade_rad"] = float(self.fade_width)
        if self.global_harmonics:  # older files: 0, every harmonic fades
            out["global_harmonics"] = int(self.global_harmonics)
        if covariance:  # the upper triangle, row by row (the matrix is symmetric)
            out["covariance_upper"] = self.covariance_upper()
        return out

    def covariance_upper(self) -> list[float]:
        """The covariance's upper triangle, row by row, to 9 significant digits."""
        return [float(f"{v:.9g}") for v in self.covariance[np.triu_indices(self.size)]]

    def with_covariance_upper(self, upper: ArrayLike) -> JointAngleResidual:
        """This residual with the covariance given by its upper triangle (row by row)."""
        m = self.size
        upper = np.asarray(upper, dtype=float).reshape(-1)
        if len(upper) != m * (m + 1) // 2:
            raise ValueError(f"residual: the covariance needs {m * (m + 1) // 2} values, got {len(upper)}")
        C = np.zeros((m, m))
        C[np.triu_indices(m)] = upper
        return dataclasses.replace(self, covariance=C + np.triu(C, 1).T)

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], joint_names: tuple[str, ...] | list[str]
    ) -> JointAngleResidual:
        """The inverse of :meth:`to_dict` for a chain with joints ``joint_names``; raises
        ``ValueError`` naming what is wrong."""
        if data.get("kind", cls.kind) != cls.kind:
            raise ValueError(f"residual: unknown kind {data.get('kind')!r} (known: {cls.kind})")
        joints = tuple(str(j) for j in data["joints"])
        unknown = [j for j in joints if j not in joint_names]
        if unknown:
            raise ValueError(
                f"residual: joints {unknown} are not joints of the chain ({', '.join(joint_names)})"
            )
        coefficients = np.asarray(data["coefficients"], dtype=float)
        m = len(coefficients)
        learned = cls(
            joints=joints,
            joint_index=tuple(list(joint_names).index(j) for j in joints),
            harmonics=int(data["harmonics"]),
            coefficients=coefficients,
            covariance=np.zeros((m, m)),
            noise_std=float(data["noise_std"]),
            amplitudes=tuple(float(a) for a in data["amplitudes"]),
            length_scale=float(data["length_scale"]),
            coverage=None
            if data.get("coverage") is None
            else tuple(tuple(tuple(pair) for pair in joint) for joint in data["coverage"]),
            angle_rms=None if data.get("angle_rms") is None else tuple(float(v) for v in data["angle_rms"]),
            fade_width=float(data.get("fade_rad", FADE)),
            global_harmonics=int(data.get("global_harmonics", 0)),
        )
        upper = data.get("covariance_upper")
        return learned if upper is None else learned.with_covariance_upper(upper)
