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

__all__ = [
    "FK_ONE",
    "Direct",
    "Evaluation",
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
    installed.  The module (and numba) is imported on first use only.
    """
    if compiled is False:
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


def fk_one_entry(compiled: bool | None) -> tuple[Any, Any] | None:
    """:func:`robocal.model.kernels.fk_one` ``(q, packed, T) -> bool`` and
    :func:`~robocal.model.kernels.fk_jacobian_one` ``(q, packed, T, J) -> bool`` for a float64
    ``q`` of one dimension (any strides or alignment), a packed model and C-ordered ``T``
    ``(4, 4)`` and ``J`` ``(6, dof)``, called without numba's dispatch (kept in
    :data:`FK_ONE`); None without the kernels (``compiled``: as for :func:`load_kernels`).

    Why: numba's dispatcher types every argument on every call (about 0.07 µs of the 0.4 µs
    of a one-configuration FK); the compiled wrapper of one explicit signature skips that.
    It checks no more than each array's item size (a float64 of another dtype, another
    number of dimensions or a subclass would be misread), so the caller lets through only
    ``type(q) is np.ndarray``, ``q.ndim == 1`` and ``q.dtype is FLOAT64``.
    """
    kernels = load_kernels(compiled)
    if kernels is None:
        if compiled is None:  # no numba (compiled=False: not looked up, nothing learnt)
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
    ):
        kernel.compile(signature)  # from numba's cache after the first time
        try:
            entries.append(kernel.overloads[signature].entry_point)
        except (AttributeError, KeyError):  # another numba's internals: its dispatcher then
            entries.append(kernel)
    FK_ONE.append((entries[0], entries[1]))
    return FK_ONE[-1]


def joint_jacobian_one(model: Any, q: Array) -> Array | None:
    """``Model.joint_jacobian`` ``(6, dof)`` of one configuration ``q`` (let through as for
    :func:`fk_one_entry`) by the compiled kernel; None without numba or when ``q`` does not
    fit (the general path then says why)."""
    one = FK_ONE[0] if FK_ONE else fk_one_entry(None)
    J = np.empty((6, model.dof))
    if one is not None and one[1](q, model._fk_one_data, np.empty((4, 4)), J):
        return J
    return None


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


@dataclass(frozen=True)
class Direct:
    """The compiled one-configuration entry points of a model, with its data and outputs in
    one preallocated array (as Pinocchio's ``model`` / ``data`` pair): no Python between the
    caller and the kernel, and two arguments (numba's dispatch costs per argument).

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

    >>> d = direct(rc.robot("ur10"))
    >>> fk, data, T = d.fk, d.data, d.T       # bind once, outside the loop
    >>> fk(q, data)                            # T now holds the tool frame of q
    True

    The model's values are copied when this is made: a model with other values needs its
    own :func:`direct`; two threads need two.
    """

    fk: Any  # numba dispatcher: (q, data) -> bool
    fk_jacobian: Any  # (q, data) -> bool
    fk_many: Any  # (Q, data, Ts, Js, jacobian) -> bool
    data: Array  # the model (robocal.model.kernels.pack_one), then T and J
    T: Array  # (4, 4) view into data: the output of fk / fk_jacobian
    J: Array  # (6, dof) view into data: the output of fk_jacobian


def direct(model: Any) -> Direct:
    """:class:`Direct` entry points of ``model`` (a :class:`robocal.model.chain.Model`; numba
    required: imports the kernels)."""
    kernels = load_kernels(True)
    plan = model._plan
    seg, _, offsets = model._kernel_segments
    data = kernels.pack_one(seg, offsets, plan.joint_axis_array, plan.joint_rot_array, outputs=True)
    out = int(data[1])
    return Direct(
        fk=kernels.fk_into,
        fk_jacobian=kernels.fk_jacobian_into,
        fk_many=kernels.fk_jacobian_many,
        data=data,
        T=data[out : out + 16].reshape(4, 4),
        J=data[out + 16 : out + 16 + 6 * model.dof].reshape(6, model.dof),
    )
