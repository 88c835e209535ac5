"""The calibration problem: a measurement model and the observations it must explain.

The measurement model is one chain (DESIGN.md: one representation):

    [device frame, fixed start] [device frame corrections] [robot] [tool]

* the device frame ``T_device_base`` starts from a closed-form Kabsch/Horn fit and is
  written as six fixed steps ``frame0_*`` plus six free corrections ``frame_*``
  (Tx Ty Tz Rz Ry Rx) that stay near zero, so the Euler parameterisation is never
  near its β = ±90° singularity (seed 000 eq. 2) whatever the device's placement;
* the tool is a point (``tcp_x, tcp_y, tcp_z``) for position measurements or a frame
  (plus ``tcp_rz, tcp_ry, tcp_rx``) for pose measurements.

Residuals are predicted minus measured, in the device frame, pose-major
(``x, y, z[, ωx, ωy, ωz]`` per pose), divided by the measurement uncertainty.

Joint effects (seed 003) enter as joint perturbations ``(n, dof, 3) = (δα, δβ, δθ)``
of the chain: known ones (``known_perturbations``, e.g. the tilting predicted from
measured joint parameters: the thesis' two-stage method) and patterns whose
coefficients are unknowns (``effect_basis``: clearance, backlash, compliance...,
:func:`robocal.model.joints.effect_basis`), identified with the geometric parameters.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.choices import Measure
from robocal.model.chain import Model
from robocal.model.chain_plan import derived_copy, read_only
from robocal.model.conventions import frame6, sequence
from robocal.model.steps import Role, Step

__all__ = [
    "FRAME_PREFIX",
    "TOOL_PREFIX",
    "Problem",
    "frame_steps",
    "measurement_chain",
    "measurement_chain_and_preference",
]

Array = NDArray[np.float64]
# the names of the steps measurement_chain adds; tell them by their Step.role, not by name
FRAME_PREFIX = "frame_"
TOOL_PREFIX = "tcp_"


def frame_steps(T: Array, prefix: str, free: bool, role: Role | None = None) -> list[Step]:
    """A rigid transform as six steps Tx Ty Tz Rz Ry Rx (intrinsic ZYX angles)."""
    return _valued(_frame_template(prefix, free, role), _frame_values(T))


def _frame_values(T: Array) -> list[float]:
    """The values of :func:`frame_steps` for ``T`` (4x4): x, y, z (m), rz, ry, rx (rad)."""
    return [*T[:3, 3].tolist(), *spatial.zyx_angles(T[:3, :3])]


@functools.lru_cache(maxsize=16)
def _frame_template(prefix: str, free: bool, role: Role | None) -> tuple[Step, ...]:
    """The six steps of :func:`frame6` at zero (steps are immutable: every calibration's
    measurement chain starts from the same ones and sets their values)."""
    return tuple(frame6(prefix, free=free, role=role))


@functools.lru_cache(maxsize=4)
def _tool_point_template() -> tuple[Step, ...]:
    names = [f"{TOOL_PREFIX}{c}" for c in "xyz"]
    return tuple(sequence(("Tx", "Ty", "Tz"), (0.0, 0.0, 0.0), names, role=Role.TOOL))


def _valued(template: tuple[Step, ...], values) -> list[Step]:
    return [step._with_value(v) for step, v in zip(template, values, strict=True)]


def measurement_chain(
    robot: Model, T_device_base: Array, tool: Array | None, measure: str, fit_frame: bool
) -> Model:
    """The chain predicting observations in the device frame (see the module docstring;
    ``tool`` None: no tool, the model's end is measured)."""
    return measurement_chain_and_preference(robot, T_device_base, tool, measure, fit_frame)[0]


def measurement_chain_and_preference(
    robot: Model, T_device_base: Array, tool: Array | None, measure: str, fit_frame: bool
) -> tuple[Model, NDArray[np.intp]]:
    """:func:`measurement_chain` and the rank test's preference order of its free
    parameters (:func:`robocal.identify.stages.preference_columns`; read-only), which
    depends on the robot and the layout only: worked out once for them."""
    fixed_frame = fit_frame or not np.allclose(T_device_base, np.eye(4))
    pose_tool = tool is not None and measure == "pose"
    template, preference = _chain_template(robot, (fixed_frame, fit_frame, tool is not None, pose_tool))
    steps = list(template.steps)
    values = template.values.copy()  # the template's, with the frame's and the tool's written in
    if fixed_frame:
        frame = _frame_values(T_device_base)
        steps[:6] = _valued(template.steps[:6], frame)
        values[:6] = frame
    if tool is not None:
        T_tool = np.asarray(tool, dtype=float)
        tool_values = _frame_values(T_tool) if pose_tool else T_tool[:3, 3].tolist()
        first = len(steps) - len(tool_values)
        steps[first:] = _valued(template.steps[first:], tool_values)
        values[first:] = tool_values
    chain = template._derived(tuple(steps), "free")
    # the floats the new steps hold (checked finite by _valued): the rank test reads them
    chain.__dict__["values"] = read_only(values)
    return chain, preference


# measurement chains at zero frame and tool values, by (robot, layout): keyed by the robot's
# value (its hash is cached; an id could be reused by another robot once this one is
# freed), equal robots share one; a few robots are calibrated in turn
_TEMPLATES: dict[tuple, tuple[Model, NDArray[np.intp]]] = {}


def _chain_template(robot: Model, layout: tuple[bool, bool, bool, bool]) -> tuple[Model, NDArray[np.intp]]:
    """The measurement chain of ``robot`` with, by ``layout``, the device frame's fixed
    steps, its free corrections, a tool and whether the tool is a frame (else a point),
    all at zero: every calibration of that robot sets the values of a copy, which shares
    the template's structure (plan, names, free flags) instead of working it out again;
    and the rank test's preference order of its free parameters."""
    from robocal.identify.stages import preference_columns  # (stages imports no problem)

    fixed_frame, fit_frame, has_tool, pose_tool = layout
    key = (robot, *layout)
    cached = _TEMPLATES.get(key)
    if cached is not None:
        return cached
    before: list[Step] = []
    if fixed_frame:
        before += _frame_template("frame0", False, Role.DEVICE)
    if fit_frame:
        before += _frame_template("frame", True, Role.DEVICE)
    after: list[Step] = []
    if has_tool:
        after += _frame_template("tcp", True, Role.TOOL) if pose_tool else _tool_point_template()
    clash = {s.name for s in before + after} & set(robot.names)
    if clash:
        raise ValueError(
            f"model {robot.name!r} already uses the reserved parameter name(s) {sorted(clash)}: frame_* and "
            "frame0_* name the measuring device's frame, tcp_* the tool.  A measurement_model.yaml holds "
            "the device frame: calibrate from the model.yaml next to it; otherwise rename those steps"
        )
    steps = (*before, *robot.steps, *after)
    # the robot's steps are checked, the added ones come from checked templates and their
    # names were checked against the robot's above: the chain's invariants hold
    template = derived_copy(robot, steps, (), name=robot.name + "+measurement", bodies=(), joint_effects=(),
                            residual=None)  # fmt: skip
    for name in ("names", "roles", "_index", "_plan", "free_mask", "free_names", "values"):
        getattr(template, name)  # worked out once, shared by every copy
    preference = read_only(preference_columns(template.free_names, template.roles))
    if len(_TEMPLATES) >= 16:
        _TEMPLATES.clear()
    _TEMPLATES[key] = template, preference
    return template, preference


@dataclass
class Problem:
    """Residuals and Jacobian of a calibration, as functions of the free values ``x``.

    Attributes:
        chain: the measurement chain; its free steps are the unknowns.
        q: ``(n, dof)`` joint values.
        position: ``(n, 3)`` measured positions (m, device frame).
        orientation: ``(n, 3, 3)`` measured rotations or None (position-only).
        weights: ``(n * rows,)`` residual weights (1/σ).
        length_scale: the robot's size (m), to compare rotations with lengths.
        effect_basis: ``(m, n, dof, 3)`` joint-perturbation patterns (δα, δβ, δθ) with
            unknown coefficients: the perturbation is Σ_k c_k B_k (e.g. B_k = the load
            moment about a joint's axis, c_k its compliance); ``(m, n, dof)`` means δθ
            patterns; ``None`` for a purely geometric calibration.
        effect_names: the ``m`` coefficient names.
        known_perturbations: ``(n, dof, 3)`` joint perturbations added to every
            evaluation (known joint effects), or None.
        effect_start: ``(m,)`` start values of the coefficients (default zero).
        preference: the rank test's order of the free parameters
            (:func:`measurement_chain_and_preference`, for a chain whose free parameters
            are its template's and no effect coefficients), or None: worked out when needed.
    """

    chain: Model
    q: Array
    position: Array
    orientation: Array | None
    weights: Array
    length_scale: float
    effect_basis: Array | None = None
    effect_names: tuple[str, ...] = ()
    known_perturbations: Array | None = None
    effect_start: Array | None = None
    preference: NDArray[np.intp] | None = None
    _cache: dict = dataclasses.field(default_factory=dict, repr=False)
    _tilts: bool = dataclasses.field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        n, dof = self.q.shape
        if self.effect_basis is not None:
            B = np.asarray(self.effect_basis, dtype=float)
            if B.ndim == 3:  # legacy: δθ patterns
                full = np.zeros(B.shape + (3,))
                full[..., 2] = B
                B = full
            if B.shape[1:] != (n, dof, 3) or len(B) != len(self.effect_names):
                raise ValueError(
                    f"effect_basis shaped {B.shape} does not fit {len(self.effect_names)} names, "
                    f"{n} poses and {dof} joints"
                )
            self.effect_basis = B if len(B) else None
        if self.effect_basis is None and self.effect_names:
            raise ValueError("effect_names given without effect_basis")
        if self.known_perturbations is not None:
            K = np.asarray(self.known_perturbations, dtype=float)
            if K.shape != (n, dof, 3):
                raise ValueError(f"known_perturbations shaped {K.shape}; expected ({n}, {dof}, 3)")
            self.known_perturbations = K
        m = self.n_effects
        start = np.zeros(m) if self.effect_start is None else np.asarray(self.effect_start, dtype=float)
        if start.shape != (m,):
            raise ValueError(f"effect_start shaped {start.shape}; expected ({m},)")
        self.effect_start = start
        self._tilts = self.effect_basis is not None and bool(np.any(self.effect_basis[..., :2]))

    @property
    def rows(self) -> int:
        return 3 if self.orientation is None else 6

    @property
    def measure(self) -> Measure:
        return "position" if self.orientation is None else "pose"

    @property
    def n_effects(self) -> int:
        return 0 if self.effect_basis is None else len(self.effect_basis)

    @property
    def patterns(self) -> Array:
        """``(m, n, dof, 3)`` :attr:`effect_basis`, for a problem with joint effects
        (:attr:`n_effects` > 0, which callers check first)."""
        assert self.effect_basis is not None, "a problem without joint effects has no patterns"
        return self.effect_basis

    @property
    def start_values(self) -> Array:
        """``(m,)`` :attr:`effect_start` (``__post_init__`` fills None with zeros)."""
        assert self.effect_start is not None
        return self.effect_start

    @property
    def free_names(self) -> tuple[str, ...]:
        names = self.chain.free_names
        return names + tuple(self.effect_names) if self.effect_names else names

    @functools.cached_property
    def free_scale(self) -> Array:
        """Tool displacement (m) per unit of each unknown: 1 for lengths, the robot's size
        for angles, size times the basis' largest value for effect coefficients."""
        rot = np.array([s.is_rotation for s in self.chain.steps if s.free], dtype=bool)
        scale = np.where(rot, self.length_scale, 1.0)
        if self.n_effects:
            peak = np.abs(self.patterns).reshape(self.n_effects, -1).max(axis=1)
            scale = np.concatenate([scale, self.length_scale * np.maximum(peak, 1e-300)])
        return scale

    def effect_scale(self, x: Array) -> Array:
        """``(p,)`` tool displacement (m) per unit of each unknown, to judge σ by.

        Geometric unknowns: the largest displacement of the measured point per unit over
        the measured poses, at ``x`` (position rows of the unweighted Jacobian): a rotation
        near the tool moves it by its short lever arm, not by the robot's size, and judging
        it by the size prunes wrist rotations whose partners then absorb their errors
        (biases of 20-124 σ on simulated robots with the probe near the flange axis).
        Joint-effect coefficients keep :attr:`free_scale` (the size times the pattern's
        peak): their patterns (joint loads) can be far larger at other poses than at the
        measured ones, where a poorly determined coefficient would extrapolate badly (real
        UR10 data: a kept wrist-2 compliance gave an 11 mm held-out maximum)."""
        from robocal.identify.stages import tool_displacement_scale

        J = self.jacobian(x, weighted=False).reshape(len(self.q), self.rows, -1)[:, :3]
        scale = tool_displacement_scale(J)
        if self.n_effects:
            scale[-self.n_effects :] = self.free_scale[-self.n_effects :]
        return scale

    @property
    def x0(self) -> Array:
        return np.concatenate([self.chain.free_values, self.effect_start])

    @property
    def tilts(self) -> bool:
        """Whether any effect pattern tilts a joint (needs the tilt columns)."""
        return self._tilts

    def values(self, x: Array) -> Array:
        """All chain parameter values for the unknowns ``x``."""
        v = self._chain_values.copy()
        v[self.chain.free_mask] = x[: len(x) - self.n_effects]
        return v

    @functools.cached_property
    def _chain_values(self) -> Array:
        return self.chain.values

    def perturbations(self, x: Array) -> Array | None:
        """Joint perturbations ``(n, dof, 3)``: the known ones plus the effect
        coefficients in ``x`` times their patterns (None when there are neither)."""
        if not self.n_effects:
            return self.known_perturbations
        pert = np.tensordot(x[len(x) - self.n_effects :], self.patterns, axes=1)
        if self.known_perturbations is not None:
            pert = pert + self.known_perturbations
        return pert

    def _evaluate(self, x: Array, jacobian: bool):
        key = (x.tobytes(), jacobian)
        if key not in self._cache:
            if len(self._cache) > 4:
                self._cache.clear()
            effects = jacobian and self.n_effects > 0
            tilts = effects and self.tilts
            out = self.chain.evaluate(
                self.q,
                self.values(x),
                rows=self.measure,
                jacobian=jacobian,
                perturbations=self.perturbations(x),
                joint_columns=effects and not tilts,
                perturbation_columns=tilts,
            )
            T, J = out[0], out[1]
            if effects:
                n, dof = self.q.shape
                if tilts:  # derivatives wrt (δα, δβ, δθ) of every joint
                    P = out[2].reshape(n, self.rows, dof, 3)
                    Jc = np.einsum("nrjc,knjc->nrk", P, self.patterns)
                else:
                    Jq = out[2].reshape(n, self.rows, dof)
                    Jc = np.einsum("nrj,knj->nrk", Jq, self.patterns[..., 2])
                J = np.concatenate([J, Jc.reshape(n * self.rows, -1)], axis=1)
            self._cache[key] = (T, J)
        return self._cache[key]

    def predicted(self, x: Array) -> Array:
        """Predicted tool frames ``(n, 4, 4)`` in the device frame.

        The Jacobian is computed in the same pass: solvers ask for it at nearly every
        point whose residual they evaluate, and one pass costs little more than FK."""
        return self._evaluate(x, jacobian=True)[0]

    def residual(self, x: Array, weighted: bool = True) -> Array:
        """Predicted minus measured, ``(n * rows,)``."""
        T = self.predicted(np.asarray(x, dtype=float))
        dp = T[:, :3, 3] - self.position
        if self.orientation is None:
            r = dp.reshape(-1)
        else:
            dw = spatial.matrix_to_rotvec(T[:, :3, :3] @ np.swapaxes(self.orientation, -1, -2))
            r = np.concatenate([dp, dw], axis=1).reshape(-1)
        return r * self.weights if weighted else r

    def jacobian(self, x: Array, weighted: bool = True) -> Array:
        """d residual / d x, ``(n * rows, p)``."""
        _, J = self._evaluate(np.asarray(x, dtype=float), jacobian=True)
        return J * self.weights[:, None] if weighted else J

    def scaled_jacobian(self, x: Array) -> Array:
        """The weighted Jacobian with every unknown as a tool displacement (:attr:`free_scale`)."""
        return self.jacobian(x) * self.free_scale

    def fix(self, names: list[str]) -> Problem:
        """The same problem with some unknowns fixed at their current start values
        (a fixed effect coefficient's perturbation joins the known perturbations)."""
        named = set(names)
        if not self.n_effects:  # the chain alone changes: a copy without __post_init__'s checks
            fixed = object.__new__(Problem)
            fixed.__dict__.update(self.__dict__)
            fixed.chain, fixed._cache, fixed.preference = self.chain.fixed(named), {}, None
            fixed.__dict__.pop("free_scale", None)
            fixed.__dict__.pop("_chain_values", None)
            return self._keep_start(fixed, named)
        effect_keep = [k for k, n in enumerate(self.effect_names) if n not in named]
        effect_drop = [k for k, n in enumerate(self.effect_names) if n in named]
        chain = self.chain.fixed(named & set(self.chain.names))
        known = self.known_perturbations
        start = self.start_values
        if effect_drop and np.any(start[effect_drop]):
            held = np.tensordot(start[effect_drop], self.patterns[effect_drop], axes=1)
            known = held if known is None else known + held
        basis = None if not effect_keep else self.patterns[effect_keep]
        fixed = dataclasses.replace(
            self,
            chain=chain,
            effect_basis=basis,
            effect_names=tuple(self.effect_names[k] for k in effect_keep),
            known_perturbations=known,
            effect_start=start[effect_keep],
            preference=None,
            _cache={},
        )
        return self._keep_start(fixed, named)

    def _keep_start(self, fixed: Problem, named: set[str]) -> Problem:
        """``fixed`` with this problem's evaluation at the start values, if cached: there
        the fixed problem predicts the same frames, and its Jacobian is this one's without
        the fixed columns (a solver starts there)."""
        if not self._cache:
            return fixed
        x0 = self.x0
        cached = self._cache.get((x0.tobytes(), True))
        if cached is not None:
            keep = np.array([name not in named for name in self.free_names], dtype=bool)
            fixed._cache[(x0[keep].tobytes(), True)] = (cached[0], cached[1][:, keep])
        return fixed
