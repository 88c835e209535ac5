"""Does gear backlash under gravity explain the Kinova Gen3 lite's ball-in-socket spread? (issue 33)

MUKCa's README says its geometric calibration fails on the Gen3 lite because its joints have
no harmonic drives and "more backlash".  Backlash acts with the sign of the joint's load
(``δθ = sign(ηz)·b``, :mod:`robocal.model.joints`), so this study lets the ball-in-socket
rows carry it, as they carry compliance (:mod:`robocal.identify.constraints.position_effects`),
and asks the data:

* each series (``benchmarks/data/mukca/``: the two Gen3 lite ``dinova_1``, ``dinova_2`` with
  their URDF's ``<inertial>`` masses; the Pandas ``panda_3``, ``panda_6`` with Gaz et al.'s
  masses as controls; the iiwa 14, whose URDF has no inertials, geometry only) is fitted by
  the default (complete + prior) with no effect, compliance, backlash (with and without a
  deadband: a load within it puts the joint on no flank), compliance and backlash;
* figures, means over the training placements: the 5-fold CV within the training placement
  (RMS distance, mm, of a configuration from its socket as the other folds fitted it), the
  in-sample spread, and leave one placement out: the other placements' RMS spread and
  |socket distance - 50 mm|;
* the wrist-roll pairs: configurations of one socket whose joints 1..n-1 agree within 0.02
  rad and whose last joint turned more than 0.3 rad.  Their gravity loads on the other
  joints are the same, so no load-driven effect can separate them: their distance under the
  fitted robot is what such effects leave.

* then, per joint, a periodic angle error (``δθ_j = Σ_h a_h sin(h q_j) + b_h cos(h q_j)``,
  one or two harmonics: an encoder's or a gear's eccentricity, what a tracker fit's learned
  residual would take up) on the Kinovas' rows, the same figures.

robocal refuses backlash on position rows (``check_sign_kinds``); the study lets them carry
it by a context manager that swaps the position rows' effect kinds, the prediction's
deflections and the basis' deadband for the duration of a fit, and restores them.

Run: ``python benchmarks/bench_position_backlash.py [--robots dinova_1,panda_6]`` (all five:
about 5 min).  docs/tutorials/no-tracker.md quotes its table.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

import robocal.identify.constraints.figures as figures_module
import robocal.identify.constraints.fit as fit_module
import robocal.identify.constraints.position_effects as effects_module
from bench_ball_in_socket import DATA, SOCKET_DISTANCE, figures, kfold, with_masses
from robocal.identify.constraints.fit import calibrate_constraints, tool_points
from robocal.identify.constraints.model import NominalPrior
from robocal.identify.options import Pruning
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.joints import joint_perturbations, load_moments
from robocal.model.urdf.read import model_from_urdf

MUKCA = Path(__file__).resolve().parent / "data" / "mukca"
URDFS = {"dinova": MUKCA / "urdf" / "gen3lite.urdf", "kuka": MUKCA / "urdf" / "iiwa14.urdf"}
#: label -> (position-row effects, backlash deadband N·m)
VARIANTS = {
    "none": ((), 0.0),
    "compliance": (("compliance",), 0.0),
    "backlash": (("backlash",), 0.0),
    "backlash, deadband 0.5 N·m": (("backlash",), 0.5),
    "compliance + backlash": (("compliance", "backlash"), 0.0),
}
ROLL_SAME, ROLL_TURNED = 0.02, 0.3  # rad: the other joints within, the last joint turned beyond


def robot_model(series: str):
    """The series' model to ``ball_link`` with link masses (none for the iiwa: no inertials)."""
    if series.startswith("panda"):
        urdf = DATA / "urdf" / "panda.urdf"
        with tempfile.TemporaryDirectory() as folder:  # the finger's <mimic>, off the chain to the ball
            path = Path(folder) / "panda.urdf"
            path.write_text(re.sub(r"<mimic[^>]*/>", "", urdf.read_text()))
            model = model_from_urdf(path, measure="position", tip="ball_link")
        return with_masses(model, DATA)
    return model_from_urdf(URDFS[series.split("_")[0]], measure="position", tip="ball_link")


def placement_sets(series: str) -> dict[str, ConstraintSet]:
    """Each placement's two sockets (points 0 and 1, 50 mm apart), by name."""
    out = {}
    for folder in sorted(p for p in (MUKCA / series).iterdir() if (p / "hole_0.csv").is_file()):
        holes = [np.atleast_2d(np.loadtxt(folder / f"hole_{h}.csv", delimiter=",")) for h in (0, 1)]
        point = np.repeat([0, 1], [len(h) for h in holes])
        out[folder.name] = ConstraintSet(
            np.vstack(holes), point, -np.ones(len(point), dtype=int),
            point_pairs=[[0, 1]], point_length=[SOCKET_DISTANCE], sigma=1e-4,
        )  # fmt: skip
    return out


@contextlib.contextmanager
def backlash_on_position_rows(deadband: float) -> Iterator[None]:
    """Let position rows carry backlash for the duration (robocal refuses it): the kinds, the
    basis (a load within ``deadband`` N·m on no flank) and the prediction's deflections."""
    saved = (effects_module.POSITION_EFFECT_KINDS, fit_module.position_effects, figures_module.deflections)
    plain = saved[1]

    def basis(robot, chain, q, kinds=("compliance",), frames=None):
        found = plain(robot, chain, q, kinds, frames)
        if deadband <= 0 or "backlash" not in kinds:
            return found
        q = np.atleast_2d(q)
        eta = load_moments(robot, q)[:, :, 2]
        B = found.basis.copy()
        for k, name in enumerate(found.names):
            if name.startswith("backlash_"):
                B[k][np.abs(eta[:, robot.joint_names.index(name[len("backlash_") :])]) <= deadband] = 0.0
        patterns = np.linalg.norm(
            np.einsum("nrjc,knjc->nrk", chain.perturbation_jacobian(q, "position"), B), axis=1
        )
        scale = np.maximum(patterns.max(axis=0, initial=0.0), effects_module.DISPLACEMENT_FLOOR)
        return effects_module.PositionEffects(found.names, B, scale)

    def deflections(robot, q):
        if not robot.bodies or not robot.joint_effects:
            return None
        q = np.atleast_2d(q)
        elastic = joint_perturbations(robot, q, kinds=("compliance", "radial"))
        return elastic + joint_perturbations(robot, q, kinds=("backlash",), deadband=max(deadband, 1e-9))

    effects_module.POSITION_EFFECT_KINDS = ("compliance", "radial", "backlash")
    fit_module.position_effects, figures_module.deflections = basis, deflections
    try:
        yield
    finally:
        effects_module.POSITION_EFFECT_KINDS, fit_module.position_effects, figures_module.deflections = saved


def fit(model, data: ConstraintSet, effects: tuple[str, ...]):
    """The default constraint fit (complete + prior, pruning) with ``effects`` on the rows."""
    return calibrate_constraints(model, data, pruning=Pruning(), prior=NominalPrior(), effects=effects)


def roll_pairs(data: ConstraintSet) -> list[tuple[int, int]]:
    """Pairs of one socket's configurations that differ only by the last joint's turn."""
    q = data.q
    return [(a, b) for a in range(data.n) for b in range(a + 1, data.n)
            if data.point[a] == data.point[b] and np.abs(q[a, :-1] - q[b, :-1]).max() < ROLL_SAME
            and abs(q[a, -1] - q[b, -1]) > ROLL_TURNED]  # fmt: skip


def variant_row(model, sets: dict[str, ConstraintSet], effects: tuple[str, ...]) -> dict[str, float]:
    """The figures of one variant: means over the training placements (mm)."""
    cv, inside, held, apart, pairs = [], [], [], [], 0
    for train, data in sets.items():
        cv.append(kfold(model, data, effects))
        fitted = fit(model, data, effects).model
        inside.append(figures(fitted, data)[0])
        held += [figures(fitted, other) for name, other in sets.items() if name != train]
        p = tool_points(fitted, data.q)
        for a, b in roll_pairs(data):
            apart.append(float(np.sum((p[a] - p[b]) ** 2)))
            pairs += 1
    h = np.array(held)
    return {"cv": float(np.mean(cv)), "in": float(np.mean(inside)), "held": float(h[:, 0].mean()),
            "distance": float(h[:, 1].mean()), "pairs": pairs,
            "apart": 1e3 * math.sqrt(float(np.mean(apart))) if apart else float("nan")}  # fmt: skip


def load_lines(series: str, model, sets: dict[str, ConstraintSet]) -> list[str]:
    """How the wrist-roll pairs' loads differ, and each placement's load signs per joint."""
    if not model.bodies:
        return []
    diff = [np.abs(load_moments(model, d.q[[a]]) - load_moments(model, d.q[[b]]))[0, :-1, 2].max()
            for d in sets.values() for a, b in roll_pairs(d)]  # fmt: skip
    most = f", their largest load difference on joints 1..n-1 {max(diff):.3f} N*m" if diff else ""
    lines = [f"{series}: {len(diff)} wrist-roll pairs{most}"]
    for name, data in sets.items():
        eta = load_moments(model, data.q)[:, :, 2]
        positive = (eta > 0).sum(axis=0).tolist()
        median = np.round(np.median(np.abs(eta), axis=0), 2).tolist()
        lines.append(f"  {name}: positive load per joint {positive} of {data.n}; median |load| {median} N*m")
    return lines


# ---------------------------------------------------------------------- periodic angle errors
def periodic_basis(dof: int, q: np.ndarray, joint: int, harmonics: int) -> tuple[np.ndarray, tuple[str, ...]]:
    """``(m, n, dof, 3)`` angle-error patterns ``sin(h q_j)``, ``cos(h q_j)`` of ``joint`` and their names."""
    q = np.atleast_2d(q)
    basis, names = [], []
    for h in range(1, harmonics + 1):
        for label, wave in (("sin", np.sin), ("cos", np.cos)):
            B = np.zeros((len(q), dof, 3))
            B[:, joint, 2] = wave(h * q[:, joint])
            basis.append(B)
            names.append(f"{label}{h}_q{joint + 1}")
    return np.array(basis), tuple(names)


@contextlib.contextmanager
def periodic_rows(joint: int, harmonics: int, found: dict[str, float]) -> Iterator[None]:
    """Let position rows carry ``joint``'s periodic angle error for the duration (in place of
    the joint effects); the fitted coefficients land in ``found``."""
    saved = (fit_module.position_effects, fit_module.with_position_effects)

    def basis(robot, chain, q, kinds=(), frames=None):
        B, names = periodic_basis(robot.dof, q, joint, harmonics)
        columns = np.einsum("nrjc,knjc->nrk", chain.perturbation_jacobian(np.atleast_2d(q), "position"), B)
        scale = np.maximum(np.linalg.norm(columns, axis=1).max(axis=0), effects_module.DISPLACEMENT_FLOOR)
        return effects_module.PositionEffects(names, B, scale)

    def keep(robot, values):
        found.clear()
        found.update(values)
        return robot

    fit_module.position_effects, fit_module.with_position_effects = basis, keep
    try:
        yield
    finally:
        fit_module.position_effects, fit_module.with_position_effects = saved


def periodic_fit(model, data: ConstraintSet, joint: int | None, harmonics: int):
    """``(fitted model, fitted socket points, tool points of q)``; ``joint`` None: no error."""
    if joint is None:
        result = fit(model, data, ())
        return result.points, lambda q: tool_points(result.model, q)
    found: dict[str, float] = {}
    with periodic_rows(joint, harmonics, found):
        result = fit(model, data, ("compliance",))  # any kind: the basis is the periodic one

    def points(q):
        B, names = periodic_basis(model.dof, q, joint, harmonics)
        values = np.array([found.get(n, 0.0) for n in names])
        return result.model.fk(q, perturbations=np.einsum("k,knjc->njc", values, B))[:, :3, 3]

    return result.points, points


def spread(p: np.ndarray, data: ConstraintSet) -> tuple[float, float]:
    """RMS spread about each socket's centroid and |distance - 50 mm| (mm) of tool points ``p``."""
    centroids = np.array([p[data.point == k].mean(axis=0) for k in range(data.n_points)])
    rms = math.sqrt(float(np.mean(np.sum((p - centroids[data.point]) ** 2, axis=1))))
    return 1e3 * rms, 1e3 * abs(float(np.linalg.norm(centroids[0] - centroids[1])) - SOCKET_DISTANCE)


def periodic_row(
    model, sets: dict[str, ConstraintSet], joint: int | None, harmonics: int
) -> tuple[float, float]:
    """Mean 5-fold CV and mean held-out spread (mm) with ``joint``'s periodic angle error."""
    cv, held = [], []
    for train, data in sets.items():
        fold = np.random.default_rng(0).permutation(data.n) % 5
        err = []
        for f in range(5):
            sockets, points = periodic_fit(model, data.select(fold != f), joint, harmonics)
            test = data.select(fold == f)
            err.append(np.sum((points(test.q) - sockets[test.point]) ** 2, axis=1))
        cv.append(1e3 * math.sqrt(float(np.mean(np.concatenate(err)))))
        points = periodic_fit(model, data, joint, harmonics)[1]
        held += [spread(points(other.q), other)[0] for name, other in sets.items() if name != train]
    return float(np.mean(cv)), float(np.mean(held))


def periodic_lines(series: str) -> list[str]:
    model, sets = robot_model(series), placement_sets(series)
    lines = []
    for harmonics in (1, 2):
        for joint in (None, *range(model.dof)):
            cv, held = periodic_row(model, sets, joint, harmonics)
            which = "none" if joint is None else f"joint {joint + 1}"
            lines.append(f"| {series} | {which} | {harmonics} | {cv:.3f} | {held:.3f} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="dinova_1,dinova_2,panda_3,panda_6,kuka_14")
    parser.add_argument(
        "--periodic", default="dinova_1,dinova_2", help="series for the periodic errors ('' none)"
    )
    args = parser.parse_args()
    print("| series | effect | 5-fold CV (mm) | in sample (mm) | held-out spread (mm) | "
          "abs(distance - 50) (mm) | wrist-roll pairs | their RMS distance (mm) |")  # fmt: skip
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    notes = []
    for series in args.robots.split(","):
        model, sets = robot_model(series), placement_sets(series)
        for label, (effects, deadband) in VARIANTS.items():
            if effects and not model.bodies:
                continue  # no link masses: no loads to act under
            with backlash_on_position_rows(deadband) if "backlash" in effects else contextlib.nullcontext():
                row = variant_row(model, sets, effects)
            line = (f"| {series} | {label} | {row['cv']:.3f} | {row['in']:.3f} | {row['held']:.3f} | "
                    f"{row['distance']:.3f} | {row['pairs']} | {row['apart']:.3f} |")  # fmt: skip
            print(line.replace("nan", "-"), flush=True)
        notes += load_lines(series, model, sets)
    print("\n" + "\n".join(notes))
    if args.periodic:
        print("\n| series | periodic angle error | harmonics | 5-fold CV (mm) | held-out spread (mm) |")
        print("|---|---|---:|---:|---:|")
        for series in args.periodic.split(","):
            print("\n".join(periodic_lines(series)), flush=True)


if __name__ == "__main__":
    main()
