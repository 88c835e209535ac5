"""The one model representation: a chain of elementary transforms.

A robot model is an ordered tuple of :class:`Step` objects.  Each step is one
elementary motion ``Tx, Ty, Tz, Rx, Ry, Rz`` whose value is a named parameter
(constant, e.g. a DH link length) or a joint variable plus the joint's offset
parameter.  Every convention of the seeds (DH, modified DH, Hayati, Veitschegger,
Schröer's link sets, base and tool frames) is such a sequence, so one forward
kinematics routine and one analytic Jacobian serve them all.

Frames and shapes
-----------------
* ``q`` is ``(n, dof)`` (rad for revolute, m for prismatic joints); a 1-D ``q`` of
  length ``dof`` is one configuration and the leading ``n`` axis is dropped.
* ``T_base_tool = model.fk(q)`` is ``(n, 4, 4)``: the frame at the end of the chain
  expressed in the frame at its start.
* ``model.joint_frames(q)`` is ``(n, dof, 4, 4)``: for each joint the frame directly
  after its joint step (it moves with the joint's child link; its origin is on the
  joint axis).
* Joint perturbations ``(n, dof, 3) = (δα, δβ, δθ)`` model non-geometric effects
  (seed 003 eq. 5.9): δθ is added to the joint variable (rad, or m for a prismatic
  joint), then the child frame is tilted by δα about its first perpendicular axis and
  δβ about its second (x then y for a joint about z; y, z for x; z, x for y).  The
  tilt is expressed in the joint frame, the frame in which joint moments are
  computed.
* ``model.jacobian(q)`` is the identification Jacobian d(tool position)/d(free
  parameters), ``(3n, p)`` with rows ``[x, y, z]`` per pose; ``rows="pose"`` gives
  ``(6n, p)`` with rows ``[x, y, z, ωx, ωy, ωz]`` per pose, where ω is the
  small-rotation vector in the base frame (see :func:`robocal.spatial.pose_error`).
* ``model.joint_jacobian(q)`` is the geometric Jacobian ``(n, 6, dof)``, rows
  ``[v; ω]`` of the tool point in the base frame.

Analytic derivatives (DESIGN.md): for a rotation step about unit axis ``a`` whose
frame has origin ``o``, dp/dvalue = a × (p − o) and dω/dvalue = a; for a translation
step dp/dvalue = a and dω/dvalue = 0, with ``a`` and ``o`` in base coordinates.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.model import chain_batch, chain_plan
from robocal.model.chain_batch import to_homogeneous
from robocal.model.chain_compiled import (
    FK_ONE,
    FLOAT64,
    ChainData,
    Evaluation,
    chain_data,
    evaluate_compiled,
    fk_one_entry,
    into_data,
    joint_jacobian_one,
    kernel_data,
    kernel_evaluate,
    kernel_forward,
    load_kernels,
)
from robocal.model.chain_plan import Plan, check_perturbations, check_q, plan_of, read_only, segment_data
from robocal.model.steps import Body, Joint, JointEffects, JointType, Role, Step, check_chain

__all__ = ["Body", "Joint", "JointEffects", "Model", "Role", "Step"]

Array = NDArray[np.float64]
#: cached properties of a model that depend only on its steps' names, motions, joints and roles
_STRUCTURE = ("names", "roles", "_index", "_plan")
kernels_loader = load_kernels  # tests patch it (the numpy path throughout)


@dataclass(frozen=True)
class Model:
    """An immutable robot model: a named chain of elementary transforms.

    Build models with the helpers of :mod:`robocal.model.conventions`, load them
    with :func:`robocal.load_model` or take one from the catalog with
    :func:`robocal.robot`.  All values are SI (m, rad).
    """

    name: str
    steps: tuple[Step, ...]
    bodies: tuple[Body, ...] = ()
    title: str = ""
    source: str = ""
    notes: str = field(default="", compare=True)
    joint_effects: tuple[JointEffects, ...] = ()
    # the learned residual (robocal.model.residual.JointAngleResidual) or None
    residual: Any = field(default=None, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(self.steps))
        object.__setattr__(self, "bodies", tuple(self.bodies))
        object.__setattr__(self, "joint_effects", tuple(self.joint_effects))
        check_chain(self.name, self.steps, self.bodies, self.joint_effects)

    def __hash__(self) -> int:  # the dataclass's, kept: 48 steps take ~40 µs to hash
        if "_hash" not in self.__dict__:  # (caches keyed by the model hash it per call)
            fields = (self.name, self.steps, self.bodies, self.title, self.source, self.notes)
            object.__setattr__(self, "_hash", hash((*fields, self.joint_effects)))
        return self.__dict__["_hash"]

    # ------------------------------------------------------------------ parameters
    @property
    def dof(self) -> int:
        """Number of joint variables."""
        return len(self._plan.joint_steps)

    @property
    def joints(self) -> tuple[Joint, ...]:
        return tuple(s.joint for s in self.steps if s.joint is not None)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def joint_types(self) -> tuple[JointType, ...]:
        return tuple(t for s in self.steps if (t := s.joint_type) is not None)  # None: not a joint

    @property
    def joint_limits(self) -> Array:
        """``(dof, 2)`` lower/upper joint limits; ±inf where unknown."""
        out = np.tile([-np.inf, np.inf], (self.dof, 1))
        for j, joint in enumerate(self.joints):
            if joint.limits is not None:
                out[j] = joint.limits
        return out

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Names of all parameters, in chain order."""
        return tuple(s.name for s in self.steps)

    @cached_property
    def values(self) -> Array:
        """Values (SI) of all parameters, in chain order, shape ``(P,)`` (read-only)."""
        return read_only(np.array([s.value for s in self.steps]))

    @cached_property
    def free_mask(self) -> NDArray[np.bool_]:
        return read_only(np.array([s.free for s in self.steps], dtype=bool))

    @cached_property
    def roles(self) -> dict[str, Role]:
        """Each parameter's :class:`Role`, by name."""
        return {s.name: s.role for s in self.steps if s.role is not None}  # set by every Step

    def names_with_role(self, role: Role) -> tuple[str, ...]:
        """Names of the parameters with ``role``, in chain order."""
        return tuple(s.name for s in self.steps if s.role is role)

    @cached_property
    def free_names(self) -> tuple[str, ...]:
        """Names of the free parameters, in chain order (the Jacobian's columns)."""
        return tuple(s.name for s in self.steps if s.free)

    @property
    def free_values(self) -> Array:
        """Values (SI) of the free parameters, shape ``(p,)``."""
        return np.array([s.value for s in self.steps if s.free])

    def step(self, name: str) -> Step:
        """The step whose parameter is called ``name``."""
        try:
            return self.steps[self._index[name]]
        except KeyError:
            raise KeyError(f"model {self.name!r} has no parameter {name!r}") from None

    @cached_property
    def _index(self) -> dict[str, int]:
        return {s.name: i for i, s in enumerate(self.steps)}

    def with_free_values(self, x: ArrayLike) -> Model:
        """A new model whose free parameters take the values ``x`` (SI, shape ``(p,)``)."""
        x = np.asarray(x, dtype=float)
        if x.shape != (p := len(self.free_names),):
            raise ValueError(f"model {self.name!r} has {p} free parameters, got values shaped {x.shape}")
        if not np.isfinite(x).all():  # the checked copies name the first parameter that is not finite
            self.with_values(dict(zip(self.free_names, x.tolist(), strict=True)))
        # checked above: the copies need no checks of their own
        return chain_plan.with_free_values_copy(self, x, _STRUCTURE + ("free_mask", "free_names"))

    def with_values(self, values: Mapping[str, float]) -> Model:
        """A new model with the named parameters set to new values (SI)."""
        steps = list(self.steps)
        for name, value in values.items():
            i = self._index.get(name)
            if i is None:
                raise KeyError(f"model {self.name!r} has no parameter {name!r}")
            steps[i] = steps[i]._with_value(value)
        return self._derived(tuple(steps), "free")

    def with_free(self, names: Iterable[str] | None = None, free: bool = True) -> Model:
        """A new model with the named parameters (all when ``names`` is None) freed or fixed."""
        selected = set(self.names if names is None else names)
        index = self._index
        at = [index.get(name, -1) for name in selected]
        if -1 in at:
            unknown = [n for n in selected if n not in index]
            raise KeyError(f"model {self.name!r} has no parameter(s) {sorted(unknown)}")
        return chain_plan.with_free_copy(self, at, free, _STRUCTURE + ("values",))

    def _derived(self, steps: tuple[Step, ...], same: Literal["free", "values"]) -> Model:
        """This model with checked ``steps`` whose free flags or values (``same``) are its own:
        :func:`~robocal.model.chain_plan.derived_copy`, sharing what depends on them only."""
        shared = _STRUCTURE + (("free_mask", "free_names") if same == "free" else ("values",))
        return chain_plan.derived_copy(self, steps, shared)

    def fixed(self, names: Iterable[str]) -> Model:
        """A new model with the named parameters fixed (not identified)."""
        return self.with_free(names, free=False)

    # ------------------------------------------------------------------ kinematics
    @cached_property
    def _plan(self) -> Plan:
        return plan_of(self.steps)

    @cached_property
    def _segments(self) -> tuple[Array, Array]:
        """:func:`~robocal.model.chain_plan.segment_data` of this model's own values."""
        return segment_data(self._plan, self.values)

    def _forward(
        self,
        q: Array,
        perturbations: Array | None,
        keep_anchors: bool,
        values: Array | None = None,
        segments: tuple[Array, Array] | None = None,
    ) -> tuple[Array, Array | None]:
        """:func:`robocal.model.chain_batch.forward` for parameter ``values`` (default: the
        model's); ``segments``: :func:`segment_data` of ``values`` when the caller has it."""
        plan = self._plan
        if values is None:
            seg_T, _ = self._segments
            offsets = np.array([self.steps[i].value for i in plan.joint_steps])
        else:
            seg_T, _ = segment_data(self._plan, values) if segments is None else segments
            offsets = values[plan.joint_steps]
        return chain_batch.forward(plan, seg_T, offsets, q, perturbations, keep_anchors)

    def fk(
        self,
        q: ArrayLike,
        perturbations: ArrayLike | None = None,
        compiled: bool | None = None,
        data: ChainData | None = None,
    ) -> Array:
        """Tool frames ``T_base_tool`` shaped ``(n, 4, 4)`` for joint values ``q`` ``(n, dof)``.

        ``perturbations`` ``(n, dof, 3)`` are per-pose joint perturbations (δα, δβ, δθ).
        ``compiled``: use the compiled kernels (:mod:`robocal.model.kernels`; default: when
        numba is installed) or, with False, the numpy code (no numba import).  ``data``: this
        model's :meth:`data`; the frame of one configuration is then written into ``data.T``,
        which is returned (no allocation; overwritten by the next call).
        """
        if type(q) is np.ndarray and q.ndim == 1 and q.dtype is FLOAT64 and perturbations is None:
            # one configuration (the interactive case): the kernel called without dispatch
            one = FK_ONE[0] if FK_ONE else fk_one_entry(compiled)
            if compiled is not False and one is not None:
                if data is None:
                    T = np.empty((4, 4))
                    if one[0](q, self._fk_one_data, T):
                        return T
                elif data.model is self and one[2](q, data.data):
                    return data.T
            # else the general path says what is wrong
        q, single = check_q(q, self)
        d = check_perturbations(perturbations, len(q), self.dof)
        kernels = kernels_loader(compiled)
        if kernels is not None and d is None:
            plan = self._plan
            seg, _, offsets = self._kernel_segments
            qt = np.ascontiguousarray(q.T)
            T = kernels.forward_batch(qt, seg, offsets, plan.joint_axis_array, plan.joint_rot_array)
        elif kernels is not None:
            T = self._kernel_forward(kernels, q, d, keep_anchors=False)[0]
        else:
            F, _ = self._forward(q, d, keep_anchors=False)
            T = to_homogeneous(F)
        return into_data(data, self, "T", T[0] if single else T, single)

    def data(self) -> ChainData:
        """A new :class:`~robocal.model.chain_compiled.ChainData` of this model: the compiled
        work arrays and outputs, owned by the caller (numba required)."""
        return chain_data(self, self._kernel_segments)

    def joint_frames(
        self, q: ArrayLike, perturbations: ArrayLike | None = None, compiled: bool | None = None
    ) -> Array:
        """Frames after each joint step, ``(n, dof, 4, 4)`` in the base frame (``compiled``: as
        for :meth:`fk`)."""
        q, single = check_q(q, self)
        d = check_perturbations(perturbations, len(q), self.dof)
        kernels = kernels_loader(compiled)
        if kernels is not None:
            T = self._kernel_forward(kernels, q, d, keep_anchors=True)[1]
            return T[0] if single else T
        _, anchors = self._forward(q, d, keep_anchors=True)
        assert anchors is not None  # keep_anchors
        T = np.zeros((len(q), self.dof, 4, 4))
        T[:, :, :3, :] = anchors[1:].transpose(3, 0, 1, 2)
        T[:, :, 3, 3] = 1.0
        return T[0] if single else T

    # ------------------------------------------------------- compiled kernels (numba)
    @cached_property
    def _fk_one_data(self) -> Array:
        """:func:`robocal.model.kernels.pack_one` of this model: a constant of its values (as
        :attr:`_plan`), not a work array: the outputs are the caller's."""
        from robocal.model import kernels

        plan = self._plan
        seg, _, offsets = self._kernel_segments
        return kernels.pack_one(seg, offsets, plan.joint_axis_array, plan.joint_rot_array)

    @cached_property
    def _kernel_segments(self) -> tuple[Array, Array, Array]:
        """:meth:`_kernel_data` for this model's own values (models are immutable)."""
        from robocal.model import kernels

        return self._kernel_data(kernels, self.values)

    def _kernel_data(self, kernels, values: Array | None) -> tuple[Array, Array, Array]:
        """Segment transforms, local step frames and joint offsets for parameter ``values``."""
        if values is None:
            return self._kernel_segments
        return kernel_data(kernels, self._plan, self.dof, values)

    def _kernel_forward(
        self, kernels, q: Array, d: Array | None, keep_anchors: bool, values: Array | None = None
    ) -> tuple[Array, Array]:
        data = self._kernel_data(kernels, values)
        return kernel_forward(kernels, self._plan, data, q, d, keep_anchors)

    def _kernel_evaluate(
        self,
        kernels,
        q: Array,
        d: Array | None,
        steps: NDArray[np.intp],
        rows: int,
        values: Array | None = None,
        joint_columns: bool = False,
        perturbation_columns: bool = False,
    ) -> tuple[Array, Array, Array]:
        """:func:`robocal.model.chain_compiled.kernel_evaluate` for parameter ``values``."""
        data = self._kernel_data(kernels, values)
        return kernel_evaluate(self._plan, data, q, d, steps, rows, joint_columns, perturbation_columns)

    def _columns(
        self,
        q: Array,
        perturbations: Array | None,
        steps: Sequence[int] | NDArray[np.intp],
        orientation: bool = True,
        values: Array | None = None,
        tilt: bool = False,
        segments: tuple[Array, Array] | None = None,
    ) -> tuple[Array, ...]:
        """:func:`robocal.model.chain_batch.columns`: the tool frame and the derivative columns
        wrt the values of ``steps`` for parameter ``values`` (default: the model's)."""
        if segments is None:
            segments = self._segments if values is None else segment_data(self._plan, values)
        F, anchors = self._forward(q, perturbations, keep_anchors=True, values=values, segments=segments)
        assert anchors is not None  # keep_anchors
        return chain_batch.columns(
            self._plan, segments[1], F, anchors, perturbations, steps, orientation, tilt
        )

    def fk_jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
        compiled: bool | None = None,
    ) -> tuple[Array, Array]:
        """Tool frames ``(n, 4, 4)`` and the identification Jacobian in one pass.

        See :meth:`jacobian` for the Jacobian's layout, :meth:`fk` for ``compiled``.
        """
        if rows not in ("position", "pose"):
            raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
        q, single = check_q(q, self)
        d = check_perturbations(perturbations, len(q), self.dof)
        free = np.flatnonzero(self.free_mask)
        kernels = kernels_loader(compiled)
        if kernels is not None:
            T, J, _ = self._kernel_evaluate(kernels, q, d, free, 6 if rows == "pose" else 3)
            return (T[0] if single else T), J
        F, J = self._columns(q, d, free, orientation=rows == "pose")
        J = np.ascontiguousarray(J.transpose(2, 1, 0)).reshape(-1, len(free))
        T = to_homogeneous(F)
        return (T[0] if single else T), J

    def evaluate(
        self,
        q: ArrayLike,
        values: ArrayLike | None = None,
        rows: Literal["position", "pose"] = "position",
        jacobian: bool = True,
        perturbations: ArrayLike | None = None,
        joint_columns: bool = False,
        perturbation_columns: bool = False,
        compiled: bool | None = None,
    ) -> Evaluation:
        """Tool frames and identification Jacobian for other parameter values, without
        building a new model (the inner loop of the solvers).

        Args:
            q: ``(n, dof)`` joint values.
            values: all parameter values ``(P,)`` in chain order (default: the model's).
            rows, perturbations: as for :meth:`jacobian`.
            jacobian: whether to compute the Jacobian (columns: :attr:`free_names`).
            joint_columns: also return the joint Jacobian with the same rows
                (``(3n, dof)`` or ``(6n, dof)``): the derivatives with respect to the
                joint values, and so to the δθ joint perturbations.
            perturbation_columns: also return the derivatives with respect to all
                joint perturbations, ``(3n, dof, 3)`` or ``(6n, dof, 3)`` for (δα, δβ, δθ)
                (see :meth:`perturbation_jacobian`).
            compiled: as for :meth:`fk`.

        Returns:
            ``T (n, 4, 4)``, ``J`` (``(3n, p)`` or ``(6n, p)``) or ``None``, the joint
            columns when asked, and the perturbation columns when asked.
        """
        q, _ = check_q(q, self)
        d = check_perturbations(perturbations, len(q), self.dof)
        v = None if values is None else np.asarray(values, dtype=float)
        if v is not None and v.shape != (len(self.steps),):
            raise ValueError(f"values shaped {v.shape}; model {self.name!r} has {len(self.steps)} parameters")
        kernels = kernels_loader(compiled)
        if kernels is not None:
            free = np.flatnonzero(self.free_mask) if jacobian else np.zeros(0, dtype=np.intp)
            data = self._kernel_data(kernels, v)
            return evaluate_compiled(
                kernels, self._plan, data, q, d, free, rows, jacobian, joint_columns, perturbation_columns
            )
        return chain_batch.evaluate(self, q, d, v, rows, jacobian, joint_columns, perturbation_columns)

    def jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
    ) -> Array:
        """Identification Jacobian wrt the free parameters (SI units).

        Returns ``(3n, p)`` for ``rows="position"`` (rows x, y, z of pose 0, then pose
        1, ...) or ``(6n, p)`` for ``rows="pose"`` (x, y, z, ωx, ωy, ωz per pose).
        Columns follow :attr:`free_names`.
        """
        return self.fk_jacobian(q, rows, perturbations)[1]

    def perturbation_jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
    ) -> Array:
        """Derivatives of the tool pose wrt the joint perturbations (δα, δβ, δθ),
        ``(n, 3, dof, 3)`` for position rows or ``(n, 6, dof, 3)`` for pose rows
        ``[x, y, z, ωx, ωy, ωz]`` (ω: small rotation in the base frame), exact at the
        given ``perturbations`` ``(n, dof, 3)`` (default zero).  The δθ column is the
        joint Jacobian; the tilt columns turn the tool about the joint frame's
        perpendicular axes (x, y for a joint about z) through its origin."""
        if rows not in ("position", "pose"):
            raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
        q, single = check_q(q, self)
        out = self.evaluate(q, None, rows, False, perturbations, perturbation_columns=True)  # no J
        P = out[2].reshape(len(q), 3 if rows == "position" else 6, self.dof, 3)
        return P[0] if single else P

    def joint_jacobian(
        self, q: ArrayLike, perturbations: ArrayLike | None = None, data: ChainData | None = None
    ) -> Array:
        """Geometric Jacobian of the tool frame origin, ``(n, 6, dof)``, rows ``[v; ω]``
        in the base frame (the 6-vector of linear and angular velocity per unit joint rate);
        ``data``: as for :meth:`fk` (one configuration's Jacobian into ``data.J``)."""
        if type(q) is np.ndarray and q.ndim == 1 and q.dtype is FLOAT64 and perturbations is None:  # noqa: SIM102
            if (J := joint_jacobian_one(self, q, data)) is not None:  # one configuration: ~0.7 µs
                return J
        q, single = check_q(q, self)
        d = check_perturbations(perturbations, len(q), self.dof)
        kernels = kernels_loader(None)
        if kernels is not None:
            J = self._kernel_evaluate(kernels, q, d, self._plan.joint_steps, 6)[1].reshape(
                len(q), 6, self.dof
            )
        else:
            J = np.ascontiguousarray(self._columns(q, d, self._plan.joint_steps)[1].transpose(2, 1, 0))
        return into_data(data, self, "J", J[0] if single else J, single)
