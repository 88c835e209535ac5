"""Parameterisation singularities and model continuity (seed 000 eqs. 1-10).

A link parameterisation must be able to describe every nearby position of what it
places: the next joint's axis line (4 degrees of freedom for a revolute joint), the
next prismatic joint's direction (2), or the tool frame (6 for pose, 3 for position).
Seed 000 finds the singular manifolds symbolically (XYZ-ZYX frames at β = ±90°, DH
with parallel axes, Hayati with perpendicular axes or an axis through the origin,
Veitschegger); here the same question is answered numerically for any chain: the
rank of the map from the link's parameters to what it places.

Three checks, all at the nominal parameter values:

* per link, the rank and singular values of d(target)/d(link parameters), where a
  link is the parameters from one joint's offset up to the next joint step (the base
  link: everything before the first joint; the tool link: the last joint's offset and
  everything after it);
* the rank and condition number of the identification Jacobian (free parameters,
  columns scaled to unit norm) over sampled configurations;
* continuity: each joint axis is tilted by ``1e-6`` rad about two perpendicular
  directions and the smallest parameter change that follows it (least squares on the
  whole chain) must be of the same order; a DH model of parallel axes cannot follow a
  tilt at all (the common normal jumps to infinity), which the check reports.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from robocal.model.chain import Model

__all__ = ["ContinuityCheck", "LinkCheck", "ModelCheck", "check_model", "parameterisation_warnings"]

Verdict = Literal["ok", "near-singular", "singular"]


@dataclass(frozen=True)
class LinkCheck:
    """Rank of one link's parameterisation."""

    index: int  # 0 = base -> joint 1; j = joint j -> joint j+1 (or the tool for j = dof)
    parameters: tuple[str, ...]
    target: str
    needed: int
    rank: int
    singular_values: tuple[float, ...]
    verdict: Verdict

    @property
    def explanation(self) -> str:
        if self.verdict == "ok":
            return f"describes the {self.target} with full rank {self.needed}"
        return (
            f"rank {self.rank} < {self.needed}: cannot describe every nearby {self.target} "
            f"({self.verdict}; smallest relevant singular value {self.singular_values[self.needed - 1]:.2e})"
        )


@dataclass(frozen=True)
class ContinuityCheck:
    """How the chain's parameters follow a tiny tilt of one joint axis."""

    joint: str
    perturbation: float  # rad
    parameter_change: float  # largest scaled parameter change / perturbation
    residual: float  # part of the tilt the chain cannot represent / perturbation
    continuous: bool


@dataclass(frozen=True)
class ModelCheck:
    """The result of :func:`check_model`."""

    model: str
    links: tuple[LinkCheck, ...]
    identification_rank: int
    identification_columns: int
    condition_number: float
    continuity: tuple[ContinuityCheck, ...]

    @property
    def ok(self) -> bool:
        return (
            all(link.verdict == "ok" for link in self.links)
            and self.identification_rank == self.identification_columns
            and all(c.continuous for c in self.continuity)
        )


def _plucker(T: np.ndarray, axis: int, scale: float) -> np.ndarray:
    """Line (direction u, moment o × u / scale) of local axis ``axis`` of frames ``T``."""
    u = T[..., :3, axis]
    o = T[..., :3, 3]
    return np.concatenate([u, np.cross(o, u) / scale], axis=-1)


def _size(model: Model) -> float:
    T = model.joint_frames(np.zeros(model.dof)) if model.dof else np.eye(4)[None]
    tool = model.fk(np.zeros(model.dof))
    pts = np.concatenate([T[:, :3, 3], tool[None, :3, 3]])
    return max(float(np.abs(pts).max()), 0.1)


def _geometry(model: Model, values: np.ndarray, measure: str, scale: float) -> np.ndarray:
    """All joint axis lines at q = 0 (scaled Plücker) and the tool pose/position."""
    m = (
        model
        if np.array_equal(values, model.values)
        else model.with_values(dict(zip(model.names, values, strict=True)))
    )
    q = np.zeros((1, m.dof))
    parts = []
    if m.dof:
        frames = m.joint_frames(q)[0]
        for j, step in enumerate(s for s in m.steps if s.joint is not None):
            line = _plucker(frames[j], step.axis, scale)
            parts.append(line if step.is_rotation else line[:3])  # prismatic: direction only
    T = m.fk(q)[0]
    parts.append(T[:3, 3] / scale)
    if measure == "pose":
        parts.append(T[:3, :3].ravel())
    return np.concatenate(parts)


def _numeric_jacobian(f, x: np.ndarray, h: float = 1e-7) -> np.ndarray:
    cols = []
    for k in range(len(x)):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        cols.append((f(xp) - f(xm)) / (2 * h))
    return np.stack(cols, axis=1)


def _link_checks(model: Model, measure: str, scale: float, near: float) -> list[LinkCheck]:
    steps = model.steps
    joint_idx = [i for i, s in enumerate(steps) if s.joint is not None]
    bounds = [(0, joint_idx[0] if joint_idx else len(steps))]  # base link: before joint 1
    for k, start in enumerate(joint_idx):
        end = joint_idx[k + 1] if k + 1 < len(joint_idx) else len(steps)
        bounds.append((start, end))
    checks = []
    for index, (lo, hi) in enumerate(bounds):
        if hi <= lo:
            continue
        # the link's transform from the frame before step lo to the frame before step hi
        names = [s.name for s in steps[lo:hi]]
        f: Callable[[np.ndarray], np.ndarray]  # the link's parameter values -> what it must reach
        if hi < len(steps):
            nxt = steps[hi]
            assert nxt.joint is not None  # hi: a joint step's index
            target = (
                "axis line of joint " + nxt.joint.name
                if nxt.is_rotation
                else ("direction of prismatic joint " + nxt.joint.name)
            )
            needed = 4 if nxt.is_rotation else 2

            def to_axis(x, lo=lo, hi=hi, nxt=nxt):
                T = np.eye(4)
                for s, v in zip(steps[lo:hi], x, strict=True):
                    T = T @ _elem(s.motion, v)
                line = _plucker(T, nxt.axis, scale)
                return line if nxt.is_rotation else line[:3]

            f = to_axis
        else:
            target = "tool pose" if measure == "pose" else "tool position"
            needed = 6 if measure == "pose" else 3

            def to_tool(x, lo=lo, hi=hi):
                T = np.eye(4)
                for s, v in zip(steps[lo:hi], x, strict=True):
                    T = T @ _elem(s.motion, v)
                out = T[:3, 3] / scale
                return np.concatenate([out, T[:3, :3].ravel()]) if measure == "pose" else out

            f = to_tool

        x0 = np.array([s.value for s in steps[lo:hi]])
        J = _numeric_jacobian(f, x0)
        sv = np.linalg.svd(J, compute_uv=False)
        sv = np.concatenate([sv, np.zeros(max(0, needed - len(sv)))])
        top = sv[0] if sv[0] > 0 else 1.0
        rank = int(np.sum(sv > 1e-6 * top))
        if rank < needed:
            verdict: Verdict = "singular"
        elif sv[needed - 1] < near * top:
            verdict = "near-singular"
        else:
            verdict = "ok"
        checks.append(
            LinkCheck(index, tuple(names), target, needed, min(rank, needed), tuple(sv.tolist()), verdict)
        )
    return checks


def _elem(motion: str, value: float) -> np.ndarray:
    from robocal.spatial import elementary

    return elementary(motion, value)


def _geometry_jacobian(model: Model, measure: str, scale: float) -> np.ndarray:
    """d :func:`_geometry` / d(values), analytically at the nominal values: a rotation step
    turns everything after it about its axis line, a translation step shifts it along its
    axis (the identification Jacobian's rule, applied to the joint lines and the tool)."""
    from robocal.spatial import elementary

    frames, before = [], []
    T = np.eye(4)
    for s in model.steps:
        before.append(T)
        T = T @ elementary(s.motion, s.value)
        frames.append(T)
    joint_idx = [i for i, s in enumerate(model.steps) if s.joint is not None]
    columns = []
    for k, s in enumerate(model.steps):
        w = before[k][:3, s.axis]
        o_k = before[k][:3, 3]
        parts = []
        for i in joint_idx:
            F = frames[i]
            u, o = F[:3, model.steps[i].axis], F[:3, 3]
            if k > i:
                du, do = np.zeros(3), np.zeros(3)
            elif s.is_rotation:
                du, do = np.cross(w, u), np.cross(w, o - o_k)
            else:
                du, do = np.zeros(3), w.copy()
            if model.steps[i].is_rotation:
                parts.append(np.concatenate([du, (np.cross(do, u) + np.cross(o, du)) / scale]))
            else:
                parts.append(du)
        p = T[:3, 3]
        dp = np.cross(w, p - o_k) if s.is_rotation else w
        parts.append(dp / scale)
        if measure == "pose":
            dR = np.cross(w, T[:3, :3], axis=0) if s.is_rotation else np.zeros((3, 3))
            parts.append(dR.ravel())
        columns.append(np.concatenate(parts))
    return np.stack(columns, axis=1)


def _continuity(model: Model, measure: str, scale: float, eps: float) -> list[ContinuityCheck]:
    x0 = model.values
    angular = np.array([s.is_rotation for s in model.steps])
    # dimensionless parameters: lengths in units of the robot's size
    xs = np.where(angular, 1.0, scale)

    def g(xn):
        return _geometry(model, xn * xs, measure, scale)

    J = _geometry_jacobian(model, measure, scale) * xs  # per dimensionless parameter
    G0 = g(x0 / xs)
    out: list[ContinuityCheck] = []
    if model.dof == 0:
        return out
    frames = model.joint_frames(np.zeros(model.dof))
    offset = 0
    for j, (step, joint) in enumerate((s, s.joint) for s in model.steps if s.joint is not None):
        width = 6 if step.is_rotation else 3
        u = frames[j, :3, step.axis]
        o = frames[j, :3, 3]
        # two unit directions perpendicular to the axis
        w1 = np.cross(u, [1.0, 0, 0] if abs(u[0]) < 0.9 else [0, 1.0, 0])
        w1 /= np.linalg.norm(w1)
        w2 = np.cross(u, w1)
        worst_change, worst_residual = 0.0, 0.0
        for w in (w1, w2):
            dG = np.zeros_like(G0)
            du = eps * w
            block = np.concatenate([du, np.cross(o, du) / scale]) if step.is_rotation else du
            dG[offset : offset + width] = block
            # singular values below 1e-6 of the largest are finite-difference noise of a
            # rank-deficient map, not directions the chain can follow
            dx, *_ = np.linalg.lstsq(J, dG, rcond=1e-6)
            worst_change = max(worst_change, float(np.abs(dx).max()) / eps)
            worst_residual = max(worst_residual, float(np.linalg.norm(J @ dx - dG)) / eps)
        continuous = worst_residual < 1e-3 and worst_change < 1e3
        out.append(ContinuityCheck(joint.name, eps, worst_change, worst_residual, continuous))
        offset += width
    return out


def check_model(
    model: Model,
    measure: Literal["position", "pose"] = "pose",
    n_poses: int = 60,
    seed: int = 0,
    perturbation: float = 1e-6,
    near_singular: float = 1e-2,
) -> ModelCheck:
    """Check a chain for parameterisation singularities and discontinuities.

    Args:
        model: any chain.
        measure: whether the tool's orientation is measured (``"pose"``) or only its
            position; decides what the tool link must describe and the Jacobian's rows.
        n_poses: configurations sampled for the identification Jacobian.
        perturbation: axis tilt (rad) of the continuity check.
        near_singular: a link whose relevant singular value is below this fraction of
            its largest is reported as near-singular.
    """
    scale = _size(model)
    links = _link_checks(model, measure, scale, near_singular)
    rng = np.random.default_rng(seed)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n_poses, model.dof))
    p = len(model.free_names)
    if p:
        J = model.jacobian(q, rows="pose" if measure == "pose" else "position")
        norms = np.linalg.norm(J, axis=0)
        Jn = J / np.where(norms > 0, norms, 1.0)
        sv = np.linalg.svd(Jn, compute_uv=False)
        rank = int(np.sum(sv > 1e-8 * sv[0])) if sv[0] > 0 else 0
        cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    else:
        rank, cond = 0, float("nan")
    continuity = _continuity(model, measure, scale, perturbation)
    return ModelCheck(model.name, tuple(links), rank, p, cond, tuple(continuity))


def _as_calibrated(model: Model, measure: str) -> Model:
    """The chain as a calibration sees it: a free device frame before the base and a free
    tool after the end (what :func:`robocal.calibrate` adds), so that only the robot's own
    parameterisation is judged, not the missing base and tool parameters of a chain that
    starts at joint 1 or ends at the flange."""
    from robocal.model.steps import Step

    taken = set(model.names)

    def fresh(name: str) -> str:
        while name in taken:
            name += "_"
        taken.add(name)
        return name

    base = [Step(m, fresh(f"_check_base_{m}"), 0.0) for m in ("Tx", "Ty", "Tz", "Rz", "Ry", "Rx")]
    tool_motions = ("Tx", "Ty", "Tz", "Rz", "Ry", "Rx") if measure == "pose" else ("Tx", "Ty", "Tz")
    tool = [Step(m, fresh(f"_check_tool_{m}"), 0.0) for m in tool_motions]
    return Model(name=model.name, steps=(*base, *model.steps, *tool))


def parameterisation_warnings(model: Model, measure: Literal["position", "pose"] = "position") -> list[str]:
    """Why ``model`` is a poor chain to calibrate, as one warning (or ``[]`` when it is fine).

    Judges the chain at its nominal values as a calibration uses it (with a free device
    frame and a free tool added, as :func:`robocal.calibrate` does): the links whose
    parameters cannot describe every nearby position of the next joint axis (singular or
    near-singular, e.g. DH for parallel axes) and the joints whose small tilt the chain
    cannot follow continuously (:func:`check_model`'s link verdicts and continuity check;
    no identification Jacobian, so it takes a few milliseconds).  The warning names them
    and the fix: the complete model built from the robot's geometry.
    """
    if model.dof == 0:
        return []
    chain = _as_calibrated(model, measure)
    scale = _size(chain)
    links = [c for c in _link_checks(chain, measure, scale, 1e-2) if c.verdict != "ok"]
    broken = [c for c in _continuity(chain, measure, scale, 1e-6) if not c.continuous]
    if not links and not broken:
        return []
    names = model.joint_names

    def link_label(check: LinkCheck) -> str:
        own = [p for p in check.parameters if not p.startswith("_check_")]
        if check.index == 0:
            where = f"base → {names[0]}"
        elif check.index < model.dof:
            where = f"{names[check.index - 1]} → {names[check.index]}"
        else:
            where = f"{names[-1]} → tool"
        return f"link {check.index} ({where}: {', '.join(own)}) is {check.verdict}"

    parts = [link_label(c) for c in links]
    if broken:
        parts.append(
            "a small tilt of joint " + ", ".join(c.joint for c in broken) + " has no small parameter change"
        )
    from robocal.model.catalog import robots

    catalog = model.name if model.name in robots() else None
    target = repr(catalog) if catalog else "model"
    fixes = [f"rc.calibration_model({target}, {measure!r})"]
    if catalog:
        fixes.append(f"robocal calibrate {catalog} (its default, --chain complete)")
    fixes.append(f"robocal model build {catalog or 'MODEL.yaml'} -o complete.yaml")
    return [
        f"the {model.name} chain cannot describe every small deviation of the real robot at its nominal "
        f"values ({measure} measurements): {'; '.join(parts)}. Calibrate the complete model built from the "
        f"robot's joint geometry instead: {' / '.join(fixes)}"
    ]
