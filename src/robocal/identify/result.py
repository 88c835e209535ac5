# long: one frozen result and its views (robot, tool, frame, uncertainty, summary), one concept
"""The result of a calibration: :class:`CalibrationResult`, frozen and typed.

A result is built once, by the calibration pipeline (:mod:`robocal.identify.pipeline`)
or read back from ``result.json`` (:mod:`robocal.identify.result_io`), and never changed
afterwards: what a caller adds — where the data came from, the validation on held-out
poses — makes a new result (:meth:`CalibrationResult.with_provenance`,
:meth:`~CalibrationResult.with_validation`, :meth:`~CalibrationResult.with_warnings`,
:meth:`~CalibrationResult.with_records`).  Units: SI (m, rad) unless a name says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.identify.effects import display_unit, effect_lines
from robocal.identify.noise_check import FitToNoise
from robocal.model.chain import Model
from robocal.model.dynamics import Payload
from robocal.model.flange_tool import split_tool
from robocal.model.joints import effect_of
from robocal.model.rank import Dropped
from robocal.model.steps import Role

if TYPE_CHECKING:
    from robocal.identify.provenance import Provenance
    from robocal.identify.residual.cv import CVTable

__all__ = ["CalibrationResult", "CalibrationWarning", "Diagnostics"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CalibrationWarning:
    """One warning of a calibration: a short ``code`` saying what kind (``"data"``,
    ``"rank"``, ``"parameterisation"``, ``"outliers"``, ``"fit-to-noise"``, ``"at-bounds"``,
    ``"few-equations"``, ``"solution"``, ``"residual"``...; ``"unknown"`` for results saved
    before warnings had codes) and the ``message`` a user reads."""

    code: str
    message: str

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class Diagnostics:
    """How the calibration went, beyond its estimates.

    Attributes:
        solve_seconds: time in the solver (s); evaluations: of all fits (residual, Jacobian).
        level: calibration level 1-3; effects: joint effects ``"none"``, ``"predict"`` or
            ``"identify"``; load_passes: passes of the joint loads (None: one, or none).
        outlier_poses: indices of poses with residuals far beyond the others.
        fit_to_noise: the residuals against the stated noise (None without one).
        cv: the learned residual's cross-validation table (``to_dict``; None: no residual
            considered); residual_rms_after_mm: RMS error with the learned residual (mm).
        at_bounds, objective: ``method="bounded"``: the parameters at a bound, and seed
            001's objective before and after; streaming: poses, subsample, chunk, passes of
            a large input's streamed fit (:mod:`robocal.identify.streaming_calibrate`), or None.
    """

    solve_seconds: float = 0.0
    evaluations: int = 0
    level: int = 2
    effects: str = "none"
    load_passes: int | None = None
    outlier_poses: tuple[int, ...] = ()
    fit_to_noise: FitToNoise | None = None
    cv: Mapping[str, Any] | None = None
    residual_rms_after_mm: float | None = None
    at_bounds: tuple[str, ...] | None = None
    objective: Mapping[str, Any] | None = None
    streaming: Mapping[str, Any] | None = None

    def cv_table(self) -> CVTable | None:
        """The cross-validation table as a :class:`~robocal.identify.residual.stage.CVTable`."""
        from robocal.identify.residual.cv import CVTable

        return None if self.cv is None else CVTable.from_dict(dict(self.cv))


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """A calibrated model with its uncertainty and the record of how it was obtained.

    Attributes:
        model: the calibrated robot with the measured tool appended (base frame: the
            robot's base), as saved in ``model.yaml``; :attr:`robot` and
            :attr:`T_flange_tool` are its two parts, :meth:`compose_measurement_chain`
            adds the device frame.
        T_device_base: (4, 4) the measuring device's frame identified (also ``frame``).
        names: estimated parameters (robot, ``frame_*`` corrections, ``tcp_*``).
        estimates, nominal, std: their values (SI), start values and standard deviations.
        covariance, correlation: ``(p, p)``.
        dropped: parameters not identified and why.
        residual_std: σ̂ of the weighted residuals (m for unit weights).
        rms_before, rms_after: RMS position error on the calibration data (m), with the
            start model (fitted frame and tool) and after calibration.
        condition_number: of the column-scaled Jacobian.
        residuals: ``(n, 3)`` or ``(n, 6)`` predicted minus measured at the solution
            (m, rad; device frame); None for results saved without them.
        warnings: what the user should know (:class:`CalibrationWarning`).
        diagnostics: :class:`Diagnostics`; provenance: where the data came from
            (:class:`~robocal.identify.provenance.Provenance`, None from the library);
            validation: the held-out statistics (``rc.validate(...).to_dict()``) when a
            caller added them; records: further facts a caller added (``data_file``,
            ``seed``...) and unknown entries of an older ``result.json``.
        run_id: the run id of the saved files this result was read from or saved as.
    """

    model: Model
    T_device_base: Array
    measure: str
    method: str
    names: tuple[str, ...]
    estimates: Array
    nominal: Array
    std: Array
    covariance: Array
    correlation: Array
    dropped: tuple[Dropped, ...]
    residual_std: float
    rms_before: float
    rms_after: float
    condition_number: float
    n: int
    success: bool
    message: str
    iterations: int
    seconds: float
    measurement_chain: Model | None = field(default=None, repr=False)
    compliance: Mapping[str, float] = field(default_factory=dict)  # joint -> rad per N·m
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    payload: Payload | None = None
    # (p, m) covariance of the estimated parameters with the learned residual's coefficients
    # (model.residual), from their joint fit; None without a residual
    residual_cross_covariance: Array | None = field(default=None, repr=False)
    residuals: Array | None = field(default=None, repr=False)
    warnings: tuple[CalibrationWarning, ...] = ()
    diagnostics: Diagnostics = Diagnostics()
    provenance: Provenance | None = None
    validation: Mapping[str, Any] | None = None
    records: Mapping[str, Any] = field(default_factory=dict)
    run_id: str | None = None

    # ------------------------------------------------------------------ new results from this one
    def replace(self, **changes: Any) -> CalibrationResult:
        """This result with some fields changed (as ``dataclasses.replace``, but the other
        fields are copied rather than passed through ``__init__`` again: a result has no
        checks to repeat, and a calibration derives several; TypeError for an unknown field)."""
        unknown = changes.keys() - _RESULT_FIELDS
        if unknown:
            raise TypeError(f"CalibrationResult has no field(s) {', '.join(sorted(unknown))}")
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__, **changes)
        return new

    def with_warnings(self, *warnings: CalibrationWarning | str, code: str = "unknown") -> CalibrationResult:
        """This result with more warnings (a text becomes a warning of ``code``)."""
        extra = tuple(
            w if isinstance(w, CalibrationWarning) else CalibrationWarning(code, w) for w in warnings
        )
        return self.replace(warnings=self.warnings + extra)

    def with_provenance(self, provenance: Provenance | None, **records: Any) -> CalibrationResult:
        """This result with where its data came from (and further ``records``)."""
        return self.replace(provenance=provenance, records={**self.records, **records})

    def with_validation(self, validation: Mapping[str, Any]) -> CalibrationResult:
        """This result with its held-out statistics (``rc.validate(...).to_dict()``)."""
        return self.replace(validation=dict(validation))

    def with_records(self, **records: Any) -> CalibrationResult:
        """This result with further facts (``source``, ``seed``... written to result.json)."""
        return self.replace(records={**self.records, **records})

    def with_diagnostics(self, **changes: Any) -> CalibrationResult:
        """This result with some :class:`Diagnostics` fields changed."""
        return self.replace(diagnostics=dataclasses.replace(self.diagnostics, **changes))

    # ------------------------------------------------------------------ views
    @property
    def frame(self) -> Array:
        """``T_device_base`` (4, 4) (the older name)."""
        return self.T_device_base

    # the calibrated robot = robot chain, T_flange_tool, T_device_base, residual (issue 32
    # item 5): ``model`` holds the first two joined; these split it (robocal.model.flange_tool)
    @property
    def robot(self) -> Model:
        """The calibrated robot to its flange: :attr:`model` without the measured tool's
        steps (its joint effects and learned residual kept)."""
        return split_tool(self.model).robot

    @property
    def T_flange_tool(self) -> Array | None:
        """``(4, 4)`` the measured tool in the flange frame (m); None when the calibration
        measured the flange itself (no tool steps)."""
        return split_tool(self.model).T_flange_tool

    def compose_measurement_chain(self) -> Model:
        """The chain predicting the device's measurements, composed from the parts: the
        device frame (:attr:`T_device_base`, fixed steps ``frame0_*``), :attr:`robot` and the
        measured tool's steps.  Its forward kinematics equal :attr:`measurement_chain`'s
        (the fit's own parameterisation, kept for the covariance's names); no joint effects
        or residual (pass their perturbations to ``fk``)."""
        from robocal.identify.problem import measurement_chain

        parts = split_tool(self.model)
        T_device_base = np.asarray(self.T_device_base, dtype=float)
        chain = measurement_chain(parts.robot, T_device_base, None, self.measure, fit_frame=False)
        return parts.on(chain)

    @property
    def warning_texts(self) -> list[str]:
        """The warnings' messages."""
        return [w.message for w in self.warnings]

    @property
    def metadata(self) -> Mapping[str, Any]:
        """A read-only view of the record in ``result.json``'s older layout (``warnings``
        as texts, ``residuals_mm``, ``fit_to_noise``, ``cv``, ``provenance``,
        ``validation``, ``saved_run_id``...): the typed fields say the same."""
        from robocal.identify.result_io import metadata_dict

        return MappingProxyType(metadata_dict(self))

    @property
    def fit_to_noise(self) -> FitToNoise | None:
        """The residuals against the stated measurement noise (None when the data gave
        no noise level)."""
        return self.diagnostics.fit_to_noise

    def joint_perturbations(
        self, q: ArrayLike, qd: ArrayLike | None = None, qdd: ArrayLike | None = None
    ) -> Array | None:
        """Joint perturbations ``(n, dof, 3)`` (δα, δβ, δθ) of every joint effect of the
        calibrated robot at ``q`` — identified, or predicted from the measured joint
        parameters — under the calibration's gravity and payload; ``qd``, ``qdd``
        (``(n, dof)``, rad/s, rad/s²) add the inertial loads of a motion.  None for a
        geometric calibration."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        physical = self.physical_perturbations(q, qd, qdd)
        if self.model.residual is None:
            return physical
        learned = self.model.residual.perturbations(q, self.model.dof)
        return learned if physical is None else physical + learned

    def physical_perturbations(
        self, q: ArrayLike, qd: ArrayLike | None = None, qdd: ArrayLike | None = None
    ) -> Array | None:
        """The joint perturbations ``(n, dof, 3)`` of the physical joint effects alone
        (:meth:`joint_perturbations` without the learned residual); None when there are none."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.model.joint_effects:
            from robocal.model.joints import joint_perturbations

            return joint_perturbations(
                self.robot, q, qd, qdd, gravity=np.asarray(self.gravity), payload=self.payload
            )
        if not self.compliance:
            return None
        from robocal.model.dynamics import gravity_torques  # results saved before joint effects

        tau = gravity_torques(self.model, q, np.asarray(self.gravity))
        pert = np.zeros((len(q), self.model.dof, 3))
        for name, c in self.compliance.items():
            j = self.model.joint_names.index(name)
            pert[:, j, 2] = -c * tau[:, j]
        return pert

    def predict(
        self,
        q: ArrayLike,
        frame: ArrayLike | None = None,
        qd: ArrayLike | None = None,
        qdd: ArrayLike | None = None,
    ) -> Array:
        """Tool frames ``(n, 4, 4)`` of the calibrated robot (with its joint effects) at
        ``q`` (``qd``, ``qdd``: along a motion), in the device frame (default: the
        calibrated one; identity for the base)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        T = self.model.fk(q, self.joint_perturbations(q, qd, qdd))
        return (self.frame if frame is None else np.asarray(frame, dtype=float)) @ T

    @property
    def high_correlations(self) -> list[tuple[str, str, float]]:
        """Parameter pairs with |correlation| > 0.9."""
        out = []
        p = len(self.names)
        for i in range(p):
            for j in range(i + 1, p):
                if abs(self.correlation[i, j]) > 0.9:
                    out.append((self.names[i], self.names[j], float(self.correlation[i, j])))
        return out

    @property
    def effect_names(self) -> tuple[str, ...]:
        """The identified joint-effect coefficients among :attr:`names` (``compliance_q2``...)."""
        return tuple(n for n in self.names if effect_of(n) is not None)

    def deltas(self) -> dict[str, float]:
        return {n: float(e - v) for n, e, v in zip(self.names, self.estimates, self.nominal, strict=True)}

    def position_covariance(self, q: ArrayLike, frame: Literal["device", "base"] = "device") -> Array:
        """Covariance ``(n, 3, 3)`` (m²) of the predicted tool position at joint values ``q``.

        ``frame="device"`` (default): the prediction of a measurement, in the device
        frame, with the uncertainty of every estimated parameter — geometric ones
        including the device frame's, and identified joint-effect coefficients (their
        patterns at ``q`` under the calibration's gravity and payload).  ``frame="base"``:
        the position in the robot's base frame, without the device frame's parameters.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        chain = self.measurement_chain if frame == "device" else self.model
        if chain is None:
            raise ValueError("this result has no measurement chain (saved by an older robocal?)")
        names = [
            n
            for n in self.names
            if n in set(chain.names) and not (frame == "base" and chain.roles[n] is Role.DEVICE)
        ]
        effects = [n for n in self.names if effect_of(n) is not None]
        perturbations = self.joint_perturbations(q)
        model = chain.with_free(None, free=False).with_free(names)
        J = model.jacobian(q, perturbations=perturbations).reshape(len(q), 3, -1)
        J = J[:, :, [model.free_names.index(n) for n in names]]
        if effects:  # d position / d coefficient = (d position / d joint perturbation) · pattern
            J = np.concatenate([J, self._effect_columns(chain, q, perturbations, effects)], axis=2)
        idx = [self.names.index(n) for n in names + effects]
        C = self.covariance[np.ix_(idx, idx)]
        # J C Jᵀ per pose, by matmuls (an einsum over both sums is 40x slower)
        cov = (J @ C) @ np.swapaxes(J, 1, 2)
        if self.model.residual is not None:  # the learned residual, fitted jointly with the parameters
            P = chain.perturbation_jacobian(q, "position", perturbations)
            cov = cov + self.model.residual.position_covariance(q, P)
            if self.residual_cross_covariance is not None:  # J X Aᵀ, A the residual's design
                W = self.model.residual.coefficient_map(q, P, self.residual_cross_covariance[idx])
                cross = J @ np.swapaxes(W, 1, 2)
                cov = cov + cross + np.swapaxes(cross, 1, 2)
        return cov

    def _effect_columns(
        self, chain: Model, q: Array, perturbations: Array | None, names: list[str], P: Array | None = None
    ) -> Array:
        """``(n, 3, m)`` derivatives of the tool position wrt the joint-effect coefficients
        ``names`` at ``q`` (the patterns the calibration identified them with); ``P``: the
        chain's position perturbation Jacobian at ``q`` when the caller has it."""
        from robocal.model.joints import EFFECT_KINDS, effect_basis, effect_of

        # the patterns of these kinds and joints only (all of them: 24 (n, dof, 3) arrays)
        wanted = [effect_of(n) for n in names]
        B, basis_names, _ = effect_basis(
            self.robot, q, kinds=[k for k in EFFECT_KINDS if any(w and w[0] == k for w in wanted)],
            joints=[j for j in self.robot.joint_names if any(w and w[1] == j for w in wanted)],
            gravity=np.asarray(self.gravity), payload=self.payload,
        )  # fmt: skip
        B = B[[basis_names.index(n) for n in names]]  # (m, n, dof, 3)
        if P is None:
            P = chain.perturbation_jacobian(q, "position", perturbations)  # (n, 3, dof, 3)
        return np.einsum("nrjc,knjc->nrk", P, B)

    def position_columns(
        self, q: ArrayLike, perturbations: Array | None = None, P: Array | None = None
    ) -> Array:
        """``(n, 3, p)`` derivatives of the predicted measurement (device frame, m) wrt the
        estimated parameters (:attr:`names`, SI) at ``q``; ``perturbations`` (this result's
        :meth:`joint_perturbations` at ``q``) and ``P`` (its measurement chain's position
        perturbation Jacobian there) when the caller has them."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        chain = self.measurement_chain
        if chain is None:
            raise ValueError("this result has no measurement chain (saved by an older robocal?)")
        if perturbations is None:
            perturbations = self.joint_perturbations(q)
        geometric = [n for n in self.names if n in set(chain.names)]
        effects = [n for n in self.names if effect_of(n) is not None]
        model = chain.with_free(None, free=False).with_free(geometric)
        J = model.jacobian(q, perturbations=perturbations).reshape(len(q), 3, -1)
        J = J[:, :, [model.free_names.index(n) for n in geometric]]
        if effects:
            J = np.concatenate([J, self._effect_columns(chain, q, perturbations, effects, P)], axis=2)
        order = [(geometric + effects).index(n) for n in self.names]
        return J[:, :, order]

    def position_uncertainty(self, q: ArrayLike, frame: Literal["device", "base"] = "device") -> Array:
        """1-σ radial position uncertainty ``sqrt(trace(cov))`` (m) at each pose, ``(n,)``."""
        return np.sqrt(np.trace(self.position_covariance(q, frame), axis1=1, axis2=2))

    def unexplained_rms(self) -> float:
        """RMS 3D position error of the robot that the calibrated model does not explain (m).

        With stated measurement noise: the part of the residuals beyond that noise (0 when the
        χ² test cannot tell the residuals from noise).  Without it: the learned residual's
        estimate of what remains per axis, or the residual σ — both include the device's
        noise, so they bound the robot's unexplained error from above.
        """
        noise = self.fit_to_noise
        if noise is not None:
            return noise.unmodelled_rms if noise.ratio > 1 and noise.warning() is not None else 0.0
        learned = self.model.residual
        if learned is not None:
            return math.sqrt(3.0) * float(learned.noise_std)
        return math.sqrt(3.0) * float(self.residual_std)

    def expected_position_error(self, q: ArrayLike) -> Array:
        """``(n,)`` RMS 3D position error (m) the calibrated model is expected to leave at
        commands ``q`` (base frame): its parameters' and learned residual's uncertainty
        (``position_uncertainty(q, "base")``) and the error it does not explain
        (:meth:`unexplained_rms`), added in quadrature."""
        return np.sqrt(self.position_uncertainty(q, "base") ** 2 + self.unexplained_rms() ** 2)

    def summary(self) -> str:
        """A plain-text report of the calibration."""
        message = self.message.removeprefix("converged: ")  # not "converged: converged: ..."
        lines = [
            f"calibration of {self.model.name!r}: {self.method}, {self.measure} measurements, {self.n} poses",
            f"  {'converged' if self.success else 'NOT CONVERGED'}: {message} "
            f"({self.iterations} iterations, {self.seconds * 1e3:.1f} ms)",
            f"  RMS position error on the calibration poses: {self.rms_before * 1e3:.4f} mm -> "
            f"{self.rms_after * 1e3:.4f} mm",
            f"  residual standard deviation {self.residual_std * 1e3:.4f} mm, "
            f"condition number {self.condition_number:.3g}",
            *([f"  {noise.summary()}"] if (noise := self.fit_to_noise) is not None else []),
            *[f"  {line}" for line in self.residual_lines()],
            "  parameter                nominal       estimate          delta           sigma",
        ]
        rot = {s.name: s.is_rotation for s in (self.measurement_chain or self.model).steps}
        for n, v0, v, s in zip(self.names, self.nominal, self.estimates, self.std, strict=True):
            f, unit = display_unit(n, rot.get(n, False))
            lines.append(
                f"  {n:<20} {v0 * f:>12.5f} {v * f:>14.5f} {(v - v0) * f:>14.5f} {s * f:>11.5f} {unit}"
            )
        effects = self.effect_estimates()
        if effects:
            lines.append(f"  joint effects ({self.diagnostics.effects}; values ± 1σ where identified):")
            lines += [f"    {line}" for line in effect_lines(effects)]
        if self.dropped:
            lines.append("  not identified:")
            lines += [f"    {d}" for d in self.dropped]
        for a, b, rho in self.high_correlations:
            lines.append(f"  warning: {a} and {b} are correlated ({rho:+.3f})")
        lines += [f"  warning: {w.message}" for w in self.warnings]
        return "\n".join(lines)

    def residual_lines(self) -> list[str]:
        """The model choice (CV table) and the learned residual, as text lines (empty when
        the calibration did not consider one)."""
        if self.diagnostics.cv is None:
            return []
        from robocal.identify.residual.cv import CVTable

        lines = CVTable.from_dict(dict(self.diagnostics.cv)).lines()
        learned = self.model.residual
        if learned is None:
            return [*lines, "learned residual: none (the physical model alone predicts best)"]
        amplitudes = ", ".join(
            f"{j} {a * 1e6:.0f}" for j, a in zip(learned.joints, learned.amplitudes, strict=True)
        )
        return [
            *lines,
            f"learned residual: joint angle errors, {learned.harmonics} harmonics per revolution on "
            f"{len(learned.joints)} joints (prior RMS µrad: {amplitudes}); RMS error on the calibration "
            f"poses {self.diagnostics.residual_rms_after_mm or float('nan'):.4f} mm, remaining σ "
            f"{learned.noise_std * 1e3:.4f} mm per axis",
        ]

    def effect_estimates(self) -> dict[str, dict[str, tuple[float, float | None]]]:
        """Every joint effect of the calibrated robot, ``{joint: {field: (value, σ)}}``
        (SI; σ None where the value was not identified but predicted or kept)."""
        from robocal.model.joints import EFFECT_PREFIXES

        sigma = dict(zip(self.names, self.std, strict=True))
        out: dict[str, dict[str, tuple[float, float | None]]] = {}
        for e in self.model.joint_effects:
            row = {}
            for prefix, attr in EFFECT_PREFIXES.values():
                value = getattr(e, attr)
                s = sigma.get(prefix + e.joint)
                if value or s is not None:
                    row[attr] = (value, None if s is None else float(s))
            if row:
                out[e.joint] = row
        return out

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The content of ``result.json`` (:mod:`robocal.identify.result_io`)."""
        from robocal.identify.result_io import result_dict

        return result_dict(self)

    def save(self, directory: str | Path, also: Callable[[Path], object] | None = None) -> CalibrationResult:
        """Write ``model.yaml`` (calibrated), ``measurement_model.yaml`` (the chain with
        the device frame and tool) and ``result.json`` to ``directory`` as one transaction
        (:mod:`robocal.outdir`); ``also(stage_dir)`` may write more files of the result
        into the staging directory.  Returns this result as saved (its :attr:`run_id`
        that of the files: a report written from it belongs to them).

        Raises:
            robocal.outdir.FolderBusyError: another process is writing ``directory``.
            OSError: the folder cannot be written (it is left as it was).
        """
        from robocal.identify.result_io import save_result

        return self.replace(run_id=save_result(self, directory, also))

    @classmethod
    def load(cls, directory: str | Path) -> CalibrationResult:
        """Read a result written by :meth:`save` (also by an older robocal).

        Raises:
            ValueError: the folder holds no complete, consistent result (the message names
                the file and what is wrong).
        """
        from robocal.identify.result_io import load_result_fields

        fields = load_result_fields(directory)  # result_io builds no result: no import circle
        fields["warnings"] = tuple(CalibrationWarning(code, text) for code, text in fields["warnings"])
        fields["diagnostics"] = Diagnostics(**fields["diagnostics"])
        return cls(**fields)


_RESULT_FIELDS = frozenset(f.name for f in dataclasses.fields(CalibrationResult))
