"""Column scaling, singular values and the observability indices O1–O5 of a model's
identification Jacobian, and its identifiable parameters (the definitions and references:
:mod:`robocal.identify.observability`, which re-exports all of this module)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from robocal import choices
from robocal.model.chain import Model
from robocal.model.rank import IdentifiableSubset, identifiable_subset

__all__ = [
    "INDICES",
    "ObservabilityIndices",
    "column_scales",
    "identifiable_parameters",
    "observability",
    "observability_indices",
    "parameter_tolerances",
    "scaled_jacobian",
    "singular_values",
]

Array = NDArray[np.float64]
IndexName = choices.IndexName  # the one table of choices (robocal.choices)
Rows = Literal["position", "pose"]
INDICES: tuple[str, ...] = ("O1", "O2", "O3", "O4", "O5")

#: Default expected parameter errors: seed 003 §3.5 (0.1 mm on lengths, 0.05° on angles).
LENGTH_TOLERANCE = 1e-4
ANGLE_TOLERANCE = math.radians(0.05)


# ------------------------------------------------------------------------ scaling
def parameter_tolerances(
    model: Model,
    names: Sequence[str] | None = None,
    *,
    length: float = LENGTH_TOLERANCE,
    angle: float = ANGLE_TOLERANCE,
) -> Array:
    """Expected errors ``(p,)`` of the named (default: free) parameters: ``length`` (m)
    for translations, ``angle`` (rad) for rotations."""
    names = model.free_names if names is None else tuple(names)
    return np.array([angle if model.step(n).is_rotation else length for n in names])


def column_scales(
    J: ArrayLike,
    scale: Literal["norm", "tolerance"] | ArrayLike = "norm",
    *,
    tolerances: ArrayLike | None = None,
) -> Array:
    """Column scale factors ``(p,)`` for ``J`` ``(m, p)``: ``J_s = J * s``.

    Args:
        J: the Jacobian.
        scale: ``"norm"`` (``1/‖J_j‖``; columns without effect get 1), ``"tolerance"``
            (``s = tolerances``) or an explicit ``(p,)`` array.
        tolerances: ``(p,)`` expected parameter errors (SI) for ``"tolerance"``.
    """
    J = np.asarray(J, dtype=float)
    if J.ndim != 2:
        raise ValueError(f"Jacobian must be 2-D (m, p), got shape {J.shape}")
    p = J.shape[1]
    if isinstance(scale, str):
        if scale == "norm":
            norm = np.linalg.norm(J, axis=0)
            return np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 1.0)
        if scale == "tolerance":
            if tolerances is None:
                raise ValueError(
                    "scale='tolerance' needs the parameter tolerances (see parameter_tolerances)"
                )
            s = np.asarray(tolerances, dtype=float)
        else:
            raise ValueError(f"scale must be 'norm', 'tolerance' or an array, got {scale!r}")
    else:
        s = np.asarray(scale, dtype=float)
    if s.shape != (p,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"column scales must be {p} positive finite numbers, got shape {s.shape}")
    return s


def scaled_jacobian(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    scale: Literal["norm", "tolerance"] | ArrayLike = "tolerance",
) -> tuple[Array, Array, tuple[str, ...]]:
    """The column-scaled identification Jacobian of ``model`` at ``q`` ``(n, dof)``.

    Returns ``(J_s, s, names)``: ``J_s`` ``(3n, p)`` or ``(6n, p)``, the scale factors
    and the parameter names (``params``, default all free parameters, in that order).
    """
    J = model.jacobian(q, rows=rows)
    names = model.free_names
    if params is not None:
        index = {n: k for k, n in enumerate(names)}
        missing = [p for p in params if p not in index]
        if missing:
            raise KeyError(f"model {model.name!r} has no free parameter(s) {missing}")
        J = J[:, [index[p] for p in params]]
        names = tuple(params)
    tol = parameter_tolerances(model, names) if isinstance(scale, str) and scale == "tolerance" else None
    s = column_scales(J, scale, tolerances=tol)
    return J * s, s, names


# ------------------------------------------------------------------------ indices
def singular_values(J: ArrayLike) -> Array:
    """Singular values of ``J`` ``(m, p)``, largest first (``min(m, p)`` of them)."""
    J = np.asarray(J, dtype=float)
    if J.ndim != 2:
        raise ValueError(f"Jacobian must be 2-D (m, p), got shape {J.shape}")
    return scipy.linalg.svdvals(J)


@dataclass(frozen=True)
class ObservabilityIndices:
    """O1..O5 of a (scaled) Jacobian; see the module docstring for the definitions.

    Attributes:
        O1, O2, O3, O4, O5: the indices (0 when a parameter is unobservable).
        sigma: the singular values used, largest first.
        n_poses: number of poses ``n`` in O1's ``√n``.
    """

    O1: float
    O2: float
    O3: float
    O4: float
    O5: float
    sigma: Array
    n_poses: int

    def __getitem__(self, name: str) -> float:
        if name not in INDICES:
            raise KeyError(f"unknown observability index {name!r}; expected one of {INDICES}")
        return float(getattr(self, name))

    def as_dict(self) -> dict[str, float]:
        return {k: self[k] for k in INDICES}


def observability_indices(
    sigma: ArrayLike, n_poses: int, n_params: int | None = None
) -> ObservabilityIndices:
    """The indices O1..O5 from singular values ``sigma`` of a scaled Jacobian.

    Args:
        sigma: singular values (any order).
        n_poses: number of poses ``n`` (O1 divides by √n).
        n_params: number of parameters ``p``; when ``sigma`` has fewer values (fewer
            rows than columns) the missing ones are zero.
    """
    s = np.sort(np.asarray(sigma, dtype=float).reshape(-1))[::-1]
    p = len(s) if n_params is None else int(n_params)
    if len(s) > p:
        raise ValueError(f"{len(s)} singular values for {p} parameters")
    if len(s) < p:
        s = np.r_[s, np.zeros(p - len(s))]
    if p == 0 or n_poses < 1:
        raise ValueError(f"need at least one parameter and one pose, got p={p}, n={n_poses}")
    if np.any(s < 0) or not np.all(np.isfinite(s)):
        raise ValueError("singular values must be finite and >= 0")
    s1, sp = s[0], s[-1]
    if sp <= 0:
        o1 = o2 = o3 = o4 = o5 = 0.0
    else:
        o1 = math.exp(np.mean(np.log(s))) / math.sqrt(n_poses)
        o2, o3, o4 = sp / s1, sp, sp**2 / s1
        o5 = 1.0 / float(np.sum(1.0 / s))
    return ObservabilityIndices(o1, o2, o3, o4, o5, s, int(n_poses))


def observability(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    scale: Literal["norm", "tolerance"] | ArrayLike = "tolerance",
) -> ObservabilityIndices:
    """O1..O5 of the poses ``q`` ``(n, dof)`` for ``params`` (default: all free
    parameters — unidentifiable ones make every index 0; pass
    ``identifiable_parameters(...).kept``)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    Js, _, names = scaled_jacobian(model, q, rows=rows, params=params, scale=scale)
    return observability_indices(singular_values(Js), len(q), len(names))


# ------------------------------------------------------------------------ identifiable subset
# the rank test itself: robocal.model.rank (the model builder uses it too)


def identifiable_parameters(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    rtol: float = 1e-6,
    prefer: Sequence[str] | None = None,
    threshold: float = 0.05,
) -> IdentifiableSubset:
    """:func:`identifiable_subset` of the model's free parameters at poses ``q`` ``(n, dof)``."""
    J = model.jacobian(np.atleast_2d(np.asarray(q, dtype=float)), rows=rows)
    return identifiable_subset(J, model.free_names, rtol=rtol, prefer=prefer, threshold=threshold)


def index_from_eig(lam: Array, n: int, name: str) -> Array:
    """Index ``name`` from eigenvalues ``(..., p)`` (ascending) of ``J_sᵀ J_s``."""
    s = np.sqrt(np.maximum(lam, 0.0))
    smin, smax = s[..., 0], s[..., -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if name == "O1":
            out = np.exp(np.mean(np.log(np.maximum(s, 1e-300)), axis=-1)) / math.sqrt(n)
        elif name == "O2":
            out = smin / smax
        elif name == "O3":
            out = smin
        elif name == "O4":
            out = smin**2 / smax
        else:
            out = 1.0 / np.sum(1.0 / s, axis=-1)
    return np.where(smin > 0, out, 0.0)
