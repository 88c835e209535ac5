"""The constraint kinds on the command line (fixed points, planes, distances: no tracker).

``robocal calibrate ROBOT --data FILE`` calibrates from them when the file has a ``point``,
``plane`` or ``pair``/``distance_mm`` column (or ``--measure point|plane|distance``;
:mod:`robocal.measure.constraints.data` documents the file); ``robocal simulate ROBOT --kind
KIND`` makes such a file with known truth; ``robocal validate DIR --data FILE`` reports a
constraint file's own figures (spread around each point, distance errors, plane residual).
A result folder holds ``model.yaml`` (the calibrated robot) and ``constraints.json``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
from rich.table import Table

from robocal.choices import AngleUnit, LengthUnit
from robocal.console import console, fail, safe

__all__ = [
    "CONSTRAINT_MEASURES",
    "RESULT_FILE",
    "calibrate_constraint_command",
    "calibrate_constraint_file",
    "is_constraint_file",
    "placement_files",
    "plan_constraint_poses",
    "print_each_kind",
    "read_mixed",
    "simulate_constraint_command",
    "simulate_constraint_file",
    "validate_constraint_file",
]

CONSTRAINT_MEASURES = ("point", "plane", "distance")
RESULT_FILE = "constraints.json"


def is_constraint_file(path: Path, measure: str | None) -> bool:
    """Whether ``path`` holds constraint measurements (its columns, or ``--measure``)."""
    from robocal.measure.constraints.data import constraint_kind

    if measure in CONSTRAINT_MEASURES:
        return True
    return measure is None and path.is_file() and constraint_kind(path) is not None


def _distances(items: list[str] | None) -> list[tuple[int, int, float]]:
    from robocal.measure.constraints.data import parse_distance

    try:
        return [parse_distance(item) for item in items or []]
    except ValueError as err:
        raise fail(str(err)) from None


def _read(path: Path, dof: int, angle_unit: str, distances, sigma: float):
    from robocal.measure.constraints.data import ConstraintFileError, read_constraints

    if angle_unit not in ("rad", "deg"):
        raise fail(f"--angle-unit {angle_unit!r}: rad or deg")
    try:
        return read_constraints(path, dof, angle_unit=angle_unit, distances=distances, sigma=sigma)
    except ConstraintFileError as err:
        raise fail(str(err)) from None


def _sigma(noise: str | None) -> float:
    from robocal.measure.true_model import parse_quantity_option

    return 1e-4 if noise is None else parse_quantity_option(noise, "length", "--noise")


def _read_tracker(path: Path, model, angle_unit: AngleUnit, length_unit: LengthUnit, sigma: float):
    """A tracker file's rows (joint values, x y z in the device frame) as constraint-set rows."""
    from robocal.measure.constraints.data_set import ConstraintSet
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.measurements import MeasurementFileError

    try:
        m = read_measurements(path, length_unit=length_unit, angle_unit=angle_unit, model=model)
    except MeasurementFileError as err:
        raise fail(str(err)) from None
    if m.position is None:
        raise fail(f"{path}: neither constraint columns (point, plane, pair) nor tracker positions (x, y, z)")
    none = -np.ones(len(m.q), dtype=np.intp)
    return ConstraintSet(m.q, none, none, position=m.position, sigma=sigma)


def read_mixed(
    paths: list[Path], model, angle_unit: AngleUnit, length_unit: LengthUnit, stated, sigma: float
):
    """The files of one fit: ``(first constraint file, tracker files, merged set)``.  The
    constraint files' points and planes are numbered in the order given (``--distance``
    names them so); the tracker files' rows have their own noise (estimated in the fit)."""
    from robocal.measure.constraints.data import constraint_kind
    from robocal.measure.constraints.data_set import merge_sets

    for path in paths:
        if not path.is_file():
            raise fail(f"--data {path}: no such file")
    constraint = [p for p in paths if constraint_kind(p) is not None]
    trackers = [p for p in paths if p not in constraint]
    if not constraint:
        raise fail("--data: several files calibrate together when one is a constraint file "
                   "(a point, plane or pair column)")  # fmt: skip
    one = stated if len(constraint) == 1 else []
    sets = [_read(p, model.dof, angle_unit, one, sigma) for p in constraint]
    sets += [_read_tracker(p, model, angle_unit, length_unit, sigma) for p in trackers]
    try:
        data = merge_sets(*sets)
    except ValueError as err:
        raise fail(f"--data: {err}") from None
    if stated and len(constraint) > 1:  # the merged numbering: the first file's points first
        if max(max(a, b) for a, b, _ in stated) >= data.n_points:
            raise fail(f"--distance: the files have points 0..{data.n_points - 1} only")
        pairs = np.array([(a, b) for a, b, _ in stated], dtype=np.intp)
        data = dataclasses.replace(data, point_pairs=pairs, point_length=np.array([d for *_, d in stated]))
    return constraint[0], trackers, data


def print_each_kind(model, data) -> None:
    """What each kind alone could identify beside what the union does (mixed data)."""
    from robocal.identify.constraints.fit import kind_identifiable

    union = set(kind_identifiable(model, data)[0])
    for kind, rows in (("constraint rows", data.constrained), ("tracker rows", data.tracked)):
        try:
            alone = set(kind_identifiable(model, data.select(rows))[0])
        except ValueError as err:  # too few rows of the kind for its start values
            console.print(f"{kind} alone: {safe(str(err))}", highlight=False, soft_wrap=True)
            continue
        missing = sorted(union - alone, key=list(model.names).index)
        line = f"{kind} alone ({int(rows.sum())} poses) identify {len(alone)} of the union's {len(union)}"
        line += f"; not {', '.join(missing)}" if missing else ""
        console.print(line, highlight=False, soft_wrap=True)


def calibrate_constraint_command(
    model, from_catalog: bool, chain: str | None, data_path: Path | list[Path], out: Path, *,
    angle_unit: AngleUnit, distances: list[str] | None, level: str | None, noise: str | None,
    force: bool = False, length_unit: LengthUnit = "m",
) -> None:  # fmt: skip
    """``robocal calibrate`` of a constraint file (or several files: constraint files and
    tracker files, one fit): a catalog robot's complete position model (``--chain
    catalog``: its published chain), a model file's chain as it is."""
    if (out / RESULT_FILE).exists() and not force:
        raise fail(f"{out} already holds a calibration result; use --force to overwrite it")
    from robocal.model.complete import calibration_model

    if chain == "complete" or (chain is None and from_catalog):
        try:
            model = calibration_model(model, "position")
        except ValueError as err:
            raise fail(f"no complete model of {model.name}: {err}") from None
    levels = {None: None, "1": 1, "offsets": 1, "2": 2, "kinematic": 2}
    if level not in levels:
        raise fail(
            f"--level {level}: constraint measurements identify level 1 (joint offsets) or 2 (kinematic)"
        )
    calibrate_constraint_file(model, data_path, out, angle_unit=angle_unit, distances=distances,
                              level=levels[level], noise=noise, length_unit=length_unit)  # fmt: skip


def calibrate_constraint_file(
    model, data_path: Path | list[Path], out: Path, *, angle_unit: AngleUnit, distances: list[str] | None,
    level: int | None, noise: str | None, length_unit: LengthUnit = "m",
) -> None:  # fmt: skip
    """Calibrate ``model`` (the complete position model of a catalog robot, or a model
    file's chain) from a constraint file; write ``out``/model.yaml and constraints.json.

    The fit is the MAP estimate under :class:`~robocal.identify.constraints.model.NominalPrior`'s
    default (lengths σ 0.3 mm, angles σ 5 mrad about the nominal geometry; the measurements
    weighted by σ̂ of a least-squares fit): on the real
    Panda's ball-in-socket recordings, leave-one-placement-out cross-validation put the
    held-out spread at 0.94 mm with it against 1.04 mm by least squares
    (benchmarks/bench_ball_in_socket.py)."""
    from robocal.identify.constraints.fit import calibrate_constraints
    from robocal.identify.constraints.model import NominalPrior
    from robocal.identify.options import Pruning

    stated = _distances(distances)
    paths = data_path if isinstance(data_path, list) else [data_path]
    first, trackers, data = read_mixed(paths, model, angle_unit, length_unit, stated, _sigma(noise))
    try:
        result = calibrate_constraints(model, data, level=level or 2, pruning=Pruning(), known_noise=False,
                                       prior=NominalPrior())  # fmt: skip
    except ValueError as err:
        raise fail(f"{', '.join(str(p) for p in paths)}: {err}") from None
    _save(result, out, first, stated, angle_unit, trackers)
    for line in result.summary_lines():
        console.print(safe(line), highlight=False, soft_wrap=True)
    if "tracker" in data.kinds and data.constrained.any():
        print_each_kind(model, data)
    console.print(f"wrote {out / 'model.yaml'} and {out / RESULT_FILE}", highlight=False)


def _result_doc(result, data_path: Path, stated) -> dict:
    from robocal.identify.result_io import file_hash

    return {
        "kind": "constraints",
        "measurements": list(result.kinds),
        "data": str(data_path),
        "data_sha256": file_hash(data_path),
        "distances_m": [[a, b, d] for a, b, d in stated],
        "success": result.success,
        "names": list(result.names),
        "estimates": result.estimates.tolist(),
        "start": result.start.tolist(),  # the nominal model: the report's and validate's "before"
        "std": result.std.tolist(),
        "not_identifiable": [{"name": d.name, "reason": d.reason} for d in result.dropped],
        "points_m": result.points.tolist(),
        "planes": result.planes.tolist(),
        "T_device_base": result.T_device_base.tolist(),
        "rms_before_m": result.rms_before,
        "rms_after_m": result.rms_after,
        "prior": None
        if result.prior is None
        else {"length_std_m": result.prior.length_std, "angle_std_rad": result.prior.angle_std},
        "summary": result.summary_lines(),
    }


def _save(result, out: Path, data_path: Path, stated, angle_unit: str = "rad", trackers=()) -> None:
    """model.yaml and constraints.json, all or nothing (``trackers``: the tracker files
    fitted with ``data_path``, recorded by name and SHA-256)."""
    from robocal.folder_lock import FolderBusyError
    from robocal.model.files import save_model
    from robocal.outdir import transaction

    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} is a file; give a directory")
    doc = _result_doc(result, data_path, stated) | {"angle_unit": angle_unit}  # how to read the file again
    if trackers:
        from robocal.identify.result_io import file_hash

        doc["tracker_data"] = [{"path": str(p), "sha256": file_hash(p)} for p in trackers]
        doc["noise_per_kind_m"] = dict(result.kind_sigma)
    try:
        with transaction(out, ("model.yaml", RESULT_FILE)) as stage:
            save_model(result.model, stage.path / "model.yaml", run_id=stage.run_id)
            (stage.path / RESULT_FILE).write_text(json.dumps(doc | {"run_id": stage.run_id}, indent=1) + "\n")
    except FolderBusyError as err:
        raise fail(str(err)) from None


def validate_constraint_file(
    directory: Path, data_path: Path, angle_unit: str, distances: list[str] | None
) -> None:
    """The calibrated model of ``directory`` (and the model it started from, when it is a
    constraint calibration) on a constraint file: each kind's own figures."""
    from robocal.identify.constraints.fit import constraint_figures
    from robocal.model.files import load_model

    if not (directory / "model.yaml").is_file():
        raise fail(f"{directory} holds no calibrated model (model.yaml)")
    try:
        model = load_model(directory / "model.yaml")
    except (OSError, ValueError) as err:
        raise fail(f"{directory / 'model.yaml'}: {err}") from None
    stated = _distances(distances)
    if not stated and (directory / RESULT_FILE).is_file():  # the calibration's stated distances
        try:
            recorded = json.loads((directory / RESULT_FILE).read_text()).get("distances_m", [])
            stated = [(int(a), int(b), float(d)) for a, b, d in recorded]
        except (OSError, ValueError, TypeError) as err:
            raise fail(f"{directory / RESULT_FILE}: {err}") from None
    data = _read(data_path, model.dof, angle_unit, [s for s in stated if max(s[:2]) < 10**6], 1e-4)
    figures = constraint_figures(model, data)
    console.print(f"{safe(model.name)} on {safe(data_path.name)} ({data.n} poses, {', '.join(data.kinds)}):",
                  highlight=False)  # fmt: skip
    for line in figures.lines():
        console.print("  " + line, highlight=False)
    if (directory / RESULT_FILE).is_file():  # a constraint calibration: the robot it started from too
        from robocal.cli.report_constraints import load_constraint_folder

        nominal = load_constraint_folder(directory).nominal
        if nominal is not None:
            console.print("before calibration (the nominal robot):", highlight=False)
            for line in constraint_figures(nominal, data).lines():
                console.print("  " + line, highlight=False)


def simulate_constraint_command(model_of, kind: str, poses, out, force: bool, options: tuple) -> None:
    """``robocal simulate ROBOT --kind KIND``: ``model_of()`` the robot; ``options``: ``--n``,
    ``--count``, ``--length``, ``--noise``, ``--seed``, ``--length-tol``, ``--angle-tol``,
    ``--placements``."""
    from robocal.console import refuse_overwrite
    from robocal.model.complete import calibration_model

    n, count, length, noise, seed, length_tol, angle_tol, placements = options
    if out is None or poses is not None:
        raise fail("--kind makes its own configurations: give -o OUT.csv and no --poses")
    for path in placement_files(out, placements):
        refuse_overwrite(path, force, "measurement file")
    model = calibration_model(model_of(), "position")
    simulate_constraint_file(model, kind, out, n=n, count=count, length=length, noise=noise, seed=seed,
                             length_tol=length_tol, angle_tol=angle_tol, placements=placements)  # fmt: skip


def placement_files(out: Path, placements: int) -> list[Path]:
    """``OUT`` and, for each further placement ``k``, ``OUT``'s stem + ``.placement<k>`` + suffix."""
    return [out] + [out.with_name(f"{out.stem}.placement{k}{out.suffix}") for k in range(2, placements + 1)]


def _scene_doc(scene, path: Path, n: int) -> dict:
    return {
        "file": path.name,
        "rows": n,
        "points_m": scene.points.tolist(),
        "planes": scene.planes.tolist(),
        "point_distances_m": [
            [a, b, float(np.linalg.norm(scene.points[a] - scene.points[b]))]
            for a in range(len(scene.points))
            for b in range(a + 1, len(scene.points))
        ],
    }


def simulate_constraint_file(
    model, kind: str, out: Path, *, n: int, count: int, length: str, noise: str | None, seed: int | None,
    length_tol: str, angle_tol: str, placements: int = 1,
) -> None:  # fmt: skip
    """Simulate ``kind`` on a true robot drawn around ``model``; write ``out`` and
    ``out``.truth.json (the true parameters and scene); ``placements`` > 1: the same true
    robot at the scene moved rigidly (:func:`~robocal.measure.constraints.sim.moved_scene`),
    one file each (:func:`placement_files`), all in the one truth file: held-out data."""
    from robocal.measure.constraints.data import write_constraints
    from robocal.measure.constraints.sim import moved_scene, simulate_constraints
    from robocal.measure.true_model import draw_true_model, parse_quantity_option

    if kind not in CONSTRAINT_MEASURES:
        raise fail(f"--kind {kind!r}: one of {', '.join(CONSTRAINT_MEASURES)}")
    if n < 4 or count < 1:
        raise fail("--n must be >= 4 and --count >= 1")
    length_m = parse_quantity_option(length, "length", "--length")
    sigma = 1e-5 if noise is None else parse_quantity_option(noise, "length", "--noise")
    files, runs = placement_files(out, placements), []
    try:
        true = draw_true_model(model, length=length_tol, angle=angle_tol, seed=seed)
        data, scene = simulate_constraints(
            true, kind, n, sigma=sigma, count=count, length=length_m, seed=seed
        )
        runs.append((data, scene))
        rng = np.random.default_rng(None if seed is None else [seed, 33])  # placements: their own draws
        for _ in files[1:]:
            moved = moved_scene(scene, rng)
            runs.append(
                simulate_constraints(true, kind, n, sigma=sigma, length=length_m, seed=rng, scene=moved)
            )
    except ValueError as err:
        raise fail(str(err)) from None
    truth = {"kind": kind, "sigma_m": sigma,
             "true_parameters": dict(zip(true.names, true.values.tolist(), strict=True)),
             "length_m": scene.length} | _scene_doc(scene, out, data.n)  # fmt: skip
    if placements > 1:
        truth["placements"] = [_scene_doc(s, f, d.n) for (d, s), f in zip(runs, files, strict=True)]
    from robocal.outdir import write_together

    truth_path = out.with_name(out.name + ".truth.json")
    texts = {f: write_constraints(d).encode() for (d, _), f in zip(runs, files, strict=True)}
    write_together(texts | {truth_path: (json.dumps(truth, indent=1) + "\n").encode()})
    written = [f"{safe(str(f))} ({d.n} rows, {kind})" for (d, _), f in zip(runs, files, strict=True)]
    console.print(f"wrote {', '.join(written)} and the truth {safe(str(truth_path))}", highlight=False,
                  soft_wrap=True)  # fmt: skip


def plan_constraint_poses(model, kind: str, out: Path, *, n: int, pool: int, index: str, seed: int) -> None:
    """``robocal poses --rows point|plane|distance``: ``n`` configurations (pairs for
    distances) of a seeded pool satisfying the constraint on the nominal robot (two sockets
    0.5 m apart, three planes, 300 mm pairs) maximising ``index`` on the kind's Jacobian;
    written as a constraint file (joint columns and labels) to record."""
    from robocal.identify.constraints.poses import select_constraint_poses
    from robocal.measure.constraints.data import write_constraints
    from robocal.measure.constraints.sim import simulate_constraints
    from robocal.model.complete import calibration_model

    if index not in ("O1", "O2", "O3", "O4", "O5"):
        raise fail(f"--index {index!r}: expected one of O1, O2, O3, O4, O5")
    complete = calibration_model(model, "position")
    size = 2 * pool if kind == "distance" else pool
    candidates, _ = simulate_constraints(complete, kind, size, sigma=1e-9, count=3 if kind == "plane" else 2,
                                         seed=seed)  # fmt: skip
    try:
        chosen = select_constraint_poses(complete, candidates, n, index=index)
    except ValueError as err:
        raise fail(str(err)) from None
    table = Table(title=f"observability of {n} {kind} candidates ({len(chosen.params)} unknowns)")
    for col in ("index", "chosen", f"first {n} of the pool"):
        table.add_column(col, justify="right")
    for name in ("O1", "O2", "O3", "O4", "O5"):
        table.add_row(name, f"{chosen.indices[name]:.4g}", f"{chosen.baseline[name]:.4g}")
    console.print(table)
    write_constraints(chosen.data, out)
    what = f"{chosen.data.n} configurations of {safe(complete.name)} ({kind})"
    console.print(f"wrote {what} to {safe(str(out))}", highlight=False)
