"""The compiled (numba) path of a chain's kinematics: loading :mod:`robocal.model.kernels` on
first use and packing a chain's plan and values for its functions.

The kernels compute what :mod:`robocal.model.chain_batch` computes with numpy (same shapes
and units: m, rad).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain_plan import Plan
from robocal.model.kernel_mode import compiled_wanted

__all__ = [
    "FK_ONE",
    "ChainData",
    "Evaluation",
    "chain_data",
    "direct",
    "evaluate_compiled",
    "fk_one_entry",
    "joint_jacobian_one",
    "kernel_data",
    "kernel_evaluate",
    "kernel_forward",
    "load_kernels",
]

Array = NDArray[np.float64]
#: What :meth:`robocal.model.chain.Model.evaluate` returns: the tool frames ``T``
#: ``(n, 4, 4)``, the identification Jacobian (None when not asked for), then the joint
#: columns and the perturbation columns, each when asked for.  Its length and the Jacobian's
#: None depend on the flags, which a tuple type cannot say (``tuple[Array, Array | None,
#: *tuple[Array, ...]]`` makes every ``out[2]`` an error): the items are ``Any`` until the
#: kernels' results become named records (issue 32 item 2).
Evaluation = tuple[Any, ...]
FLOAT64 = np.dtype(np.float64)
KERNELS: list = []  # the kernels module once imported (a list: no `global` statement needed)
#: :func:`fk_one_entry` once looked up (None: no numba).  One entry point for every model,
#: each model's data being its ``_fk_one_data`` (a constant of its values, as its ``_plan``):
#: a cache keyed by the model would hash it in Python (~0.1 µs) on every call.
FK_ONE: list = []


def load_kernels(compiled: bool | None):
    """The compiled kernels module when they are to be used, else None (numpy).

    ``compiled``: True requires them, False never uses them, None uses them when numba is
    installed and the process has not chosen the numpy path
    (:func:`robocal.model.kernel_mode.compiled_wanted`).  The module (and numba) is imported
    on first use only.
    """
    if compiled is False or (compiled is None and not compiled_wanted()):
        return None
    if KERNELS:
        return KERNELS[0]
    try:
        from robocal.model import kernels
    except ImportError:
        if compiled:
            raise
        return None
    KERNELS.append(kernels)
    return kernels


def fk_one_entry(compiled: bool | None) -> tuple[Any, Any, Any, Any] | None:
    """The one-configuration kernels called without numba's dispatch (kept in :data:`FK_ONE`):
    :func:`robocal.model.kernels.fk_one` ``(q, packed, T) -> bool``,
    :func:`~robocal.model.kernels.fk_jacobian_one` ``(q, packed, T, J) -> bool``,
    :func:`~robocal.model.kernels.fk_into` and :func:`~robocal.model.kernels.fk_jacobian_into`
    ``(q, data) -> bool`` (a :class:`ChainData`'s ``data``), for a float64 ``q`` of one
    dimension (any strides or alignment), a packed model and C-ordered ``T`` ``(4, 4)`` and
    ``J`` ``(6, dof)``; None without the kernels (``compiled``: as for :func:`load_kernels`).

    Why: numba's dispatcher types every argument on every call (about 0.07 µs of the 0.4 µs
    of a one-configuration FK); the compiled wrapper of one explicit signature skips that.
    It checks no more than each array's item size (a float64 of another dtype, another
    number of dimensions or a subclass would be misread), so the caller lets through only
    ``type(q) is np.ndarray``, ``q.ndim == 1`` and ``q.dtype is FLOAT64``.
    """
    kernels = load_kernels(compiled)
    if kernels is None:
        if compiled is None and compiled_wanted():  # no numba (else: nothing learnt)
            FK_ONE.append(None)
        return None
    from numba import types

    f64 = types.float64
    q, packed, out = (
        types.Array(f64, 1, "A", aligned=False),
        types.Array(f64, 1, "C"),
        types.Array(f64, 2, "C"),
    )
    entries = []
    for kernel, signature in (
        (kernels.fk_one, (q, packed, out)),
        (kernels.fk_jacobian_one, (q, packed, out, out)),
        (kernels.fk_into, (q, packed)),
        (kernels.fk_jacobian_into, (q, packed)),
    ):
        kernel.compile(signature)  # from numba's cache after the first time
        try:
            entries.append(kernel.overloads[signature].entry_point)
        except (AttributeError, KeyError):  # another numba's internals: its dispatcher then
            entries.append(kernel)
    FK_ONE.append(tuple(entries))
    return FK_ONE[-1]


def joint_jacobian_one(model: Any, q: Array, data: ChainData | None) -> Array | None:
    """``Model.joint_jacobian`` ``(6, dof)`` of one configuration ``q`` (let through as for
    :func:`fk_one_entry`) by the compiled kernel, into ``data.J`` when given (this model's);
    None without numba or when ``q`` or ``data`` does not fit (the general path then says
    why)."""
    one = FK_ONE[0] if FK_ONE else fk_one_entry(None)
    if one is None:
        return None
    if data is not None:
        return data.J if data.model is model and one[3](q, data.data) else None
    J = np.empty((6, model.dof))
    return J if one[1](q, model._fk_one_data, np.empty((4, 4)), J) else None


def into_data(data: ChainData | None, model: Any, name: str, value: Array, single: bool) -> Array:
    """``value`` (the general path's result), or with ``data`` and one configuration
    (``single``) ``value`` copied into ``data``'s output ``name`` (``"T"`` or ``"J"``), which is
    returned; ValueError when ``data`` was made for another model (its frame would be
    another robot's)."""
    if data is None:
        return value
    if data.model is not model and data.model != model:
        raise ValueError(
            f"data was made for model {data.model.name!r}, not for {model.name!r}: use model.data()"
        )
    if not single:
        return value
    out: Array = getattr(data, name)
    out[...] = value
    return out


def kernel_data(kernels, plan: Plan, dof: int, values: Array) -> tuple[Array, Array, Array]:
    """Segment transforms, local step frames and joint offsets for parameter ``values``."""
    values = np.ascontiguousarray(values, dtype=float)
    seg, local = kernels.segment_data(values, plan.step_axis, plan.step_rot, plan.step_joint, dof)
    return seg, local, values[plan.joint_steps]


def _perturbations(d: Array | None, dof: int) -> tuple[Array, bool]:
    if d is None:
        return np.zeros((1, dof, 3)), False
    return np.ascontiguousarray(d, dtype=float), True


def kernel_forward(
    kernels, plan: Plan, data: tuple[Array, Array, Array], q: Array, d: Array | None, keep_anchors: bool
) -> tuple[Array, Array]:
    """:func:`robocal.model.kernels.forward` of ``q`` ``(n, dof)`` with :func:`kernel_data`
    ``data``: the tool frames ``(n, 4, 4)`` and, with ``keep_anchors``, the joint frames."""
    seg, _, offsets = data
    pert, has_pert = _perturbations(d, len(plan.joint_steps))
    return kernels.forward(
        np.ascontiguousarray(q),
        pert,
        has_pert,
        seg,
        offsets,
        plan.joint_axis_array,
        plan.joint_rot_array,
        keep_anchors,
    )


def kernel_evaluate(
    plan: Plan,
    data: tuple[Array, Array, Array],
    q: Array,
    d: Array | None,
    steps: NDArray[np.intp],
    rows: int,
    joint_columns: bool = False,
    perturbation_columns: bool = False,
) -> tuple[Array, Array, Array]:
    """:func:`robocal.model.kernels_evaluate.evaluate`: ``T (n, 4, 4)``, the columns of
    ``steps`` ``(n * rows, m)`` and the joint/perturbation columns ``(n * rows, dof, 3)``."""
    from robocal.model.kernels_evaluate import evaluate as fused  # numba: loaded by load_kernels

    seg, local, offsets = data
    pert, has_pert = _perturbations(d, len(plan.joint_steps))
    return fused(
        np.ascontiguousarray(q),
        pert,
        has_pert,
        seg,
        local,
        offsets,
        plan.joint_axis_array,
        plan.joint_rot_array,
        plan.anchor_of,
        plan.step_axis,
        plan.step_rot,
        np.ascontiguousarray(steps, dtype=np.intp),
        plan.joint_steps,
        rows,
        joint_columns or perturbation_columns,
        perturbation_columns,
    )


def evaluate_compiled(
    kernels,
    plan: Plan,
    data: tuple[Array, Array, Array],
    q: Array,
    d: Array | None,
    free: NDArray[np.intp],
    rows: str,
    jacobian: bool,
    joint_columns: bool,
    perturbation_columns: bool,
) -> Evaluation:
    """:meth:`robocal.model.chain.Model.evaluate` by the compiled kernels (same returns);
    ``free``: the step indices of the Jacobian's columns (empty without ``jacobian``)."""
    if not jacobian and not joint_columns and not perturbation_columns:
        return kernel_forward(kernels, plan, data, q, d, keep_anchors=False)[0], None
    T, J, P = kernel_evaluate(
        plan, data, q, d, free, 6 if rows == "pose" else 3, joint_columns, perturbation_columns
    )
    out: Evaluation = (T, J if jacobian else None)
    if joint_columns:
        out += (np.ascontiguousarray(P[:, :, 2]),)
    if perturbation_columns:
        out += (P,)
    return out


@dataclass(frozen=True, eq=False)
class ChainData:
    """A model's compiled work arrays, owned by the caller (Pinocchio's ``data`` to the
    model's ``model``): what :meth:`robocal.model.chain.Model.data` makes, a new one per call.

    The model stays an immutable value; what the kernels write (the outputs ``T`` and ``J`` and
    the joints' sines and cosines) lives here, so a hot loop allocates nothing and two threads
    with two of these never share a buffer.  ``Model.fk(q, data=d)`` and
    ``Model.joint_jacobian(q, data=d)`` of one configuration write into ``d.T`` / ``d.J`` and
    return them (checked arguments, no allocation); the direct entry points below skip even
    the checks.

    ``fk(q, data)`` writes the tool frame ``T_base_tool`` of ``q`` ``(dof,)`` (float64; rad for
    revolute joints, m for prismatic) into ``T`` ``(4, 4)`` (m), a view into ``data``;
    ``fk_jacobian(q, data)`` also writes the geometric Jacobian of the tool frame's origin into
    ``J`` ``(6, dof)`` (rows ``[v; ω]`` in the base frame per unit joint rate, as
    ``Model.joint_jacobian``).  ``fk_many(Q, data, Ts, Js, jacobian)`` does it for each row of
    ``Q`` ``(n, dof)`` into the caller's ``Ts`` ``(n, 4, 4)`` and (with ``jacobian``) ``Js``
    ``(n, 6, dof)``.  Each returns True, or False with the outputs unset when ``q`` is not
    ``(dof,)`` or holds NaN/inf or an output has another shape (only those checks: the
    general ``Model.fk`` says what is wrong).  ``T`` and ``J`` are overwritten by the next
    call: copy what is kept.

    >>> d = rc.robot("ur10").data()
    >>> fk, data, T = d.fk, d.data, d.T       # bind once, outside the loop
    >>> fk(q, data)                            # T now holds the tool frame of q
    True

    The model's values are copied when this is made: a model with other values needs its
    own; two threads need two.
    """

    model: Any  # the robocal.model.chain.Model this was made for (Model.fk checks it)
    plan: Plan  # the chain's structure (shared by the models of the same structure)
    segments: tuple[Array, Array, Array]  # kernel_data: segments, local frames, joint offsets
    fk: Any  # numba dispatcher: (q, data) -> bool
    fk_jacobian: Any  # (q, data) -> bool
    fk_many: Any  # (Q, data, Ts, Js, jacobian) -> bool
    data: Array  # the model packed (robocal.model.kernels.pack_one), then T, J and the scratch
    T: Array  # (4, 4) view into data: the output of fk / fk_jacobian
    J: Array  # (6, dof) view into data: the output of fk_jacobian


def chain_data(model: Any, segments: tuple[Array, Array, Array]) -> ChainData:
    """A new :class:`ChainData` of ``model`` (a :class:`robocal.model.chain.Model`) whose
    :func:`kernel_data` is ``segments`` (numba required: imports the kernels)."""
    kernels = load_kernels(True)
    plan = model._plan
    seg, _, offsets = segments
    data = kernels.pack_one(seg, offsets, plan.joint_axis_array, plan.joint_rot_array, outputs=True)
    out = int(data[1])
    return ChainData(
        model=model,
        plan=plan,
        segments=segments,
        fk=kernels.fk_into,
        fk_jacobian=kernels.fk_jacobian_into,
        fk_many=kernels.fk_jacobian_many,
        data=data,
        T=data[out : out + 16].reshape(4, 4),
        J=data[out + 16 : out + 16 + 6 * model.dof].reshape(6, model.dof),
    )


def direct(model: Any) -> ChainData:
    """``model.data()``: the :class:`ChainData` of ``model`` (numba required)."""
    return model.data()
