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
    "TILT_MOUNT_HELP",
    "calibrate_constraint_command",
    "calibrate_constraint_file",
    "constraint_effect_kinds",
    "is_constraint_file",
    "placement_files",
    "plan_constraint_poses",
    "simulate_constraint_command",
    "simulate_constraint_file",
    "tilt_effect_kinds",
    "tracker_file",
    "validate_constraint_file",
]

CONSTRAINT_MEASURES = ("point", "plane", "distance", "tilt")
MAX_TRACKER_ROWS = 100_000  # --also-tracker: a comparison file, not a benchmark
RESULT_FILE = "constraints.json"  # robocal.workflow.constraints.CONSTRAINT_RESULT_FILE
TILT_MOUNT_HELP = (
    "--kind tilt: the sensors' mount on their links: joint (axes along the joint frame) or level "
    "(level at the home configuration, as the Katana thesis' sensors; written as mount_r*_deg columns)"
)
TILT_MOUNTS = ("joint", "level")


def is_constraint_file(path: Path, measure: str | None) -> bool:
    """Whether ``path`` holds constraint measurements (its columns, or ``--measure``)."""
    from robocal.measure.constraints.data import constraint_kind

    if measure in CONSTRAINT_MEASURES:
        return True
    return measure is None and path.is_file() and constraint_kind(path) is not None


def _sigma(noise: str | None) -> float:
    from robocal.measure.true_model import parse_quantity_option

    return 1e-4 if noise is None else parse_quantity_option(noise, "length", "--noise")


def calibrate_constraint_command(
    model, from_catalog: bool, chain: str | None, data_path: Path | list[Path], out: Path, *,
    angle_unit: AngleUnit, distances: list[str] | None, level: str | None, noise: str | None,
    force: bool = False, length_unit: LengthUnit = "m", effects: str | None = None,
) -> None:  # fmt: skip
    """``robocal calibrate`` of a constraint file (or several files: constraint files and
    tracker files, one fit): a catalog robot's complete position model, its link rotations
    freed when a file holds tilt rows (sensors read the angles a position model leaves to
    the tool: :func:`~robocal.identify.constraints.tilt_rows.link_rotations_free`; ``--chain
    catalog``: its published chain, for inclinometer files alone with its base tilt free:
    :func:`robocal.workflow.constraints.tilt_rows_only`), a model file's chain as it is.  ``effects``
    (``--effects``): the joint effects the tilt rows identify and the position rows carry
    (:func:`constraint_effect_kinds`)."""
    kinds, position_kinds = constraint_effect_kinds(effects)
    if (out / RESULT_FILE).exists() and not force:
        raise fail(f"{out} already holds a calibration result; use --force to overwrite it")
    from robocal.workflow.constraints import constraint_model

    paths = data_path if isinstance(data_path, list) else [data_path]
    try:
        model, frames = constraint_model(model, paths, from_catalog=from_catalog, chain=chain)
    except ValueError as err:
        raise fail(str(err)) from None
    _check_masses(model, position_kinds, effects)
    _check_sign_kinds(effects, paths)
    if effects is not None and effects.strip() == "none":  # as the tracker calibration's: the model's own too
        model = dataclasses.replace(model, joint_effects=())
    levels = {None: None, "1": 1, "offsets": 1, "2": 2, "kinematic": 2}
    if level not in levels:
        raise fail(
            f"--level {level}: constraint measurements identify level 1 (joint offsets) or 2 (kinematic)"
        )
    calibrate_constraint_file(model, data_path, out, angle_unit=angle_unit, distances=distances,
                              level=levels[level], noise=noise, length_unit=length_unit,
                              tilt_kinds=kinds, frames=frames, effects=position_kinds)  # fmt: skip


def _check_masses(model, kinds: tuple[str, ...], effects: str | None) -> None:
    """``--effects compliance`` on position rows needs the model's link masses: one line."""
    from robocal.identify.constraints.position_effects import check_effect_kinds

    try:
        check_effect_kinds(model, kinds)
    except ValueError as err:
        raise fail(f"--effects {safe(effects or '')}: {err}") from None


def _check_sign_kinds(effects: str | None, paths: list[Path]) -> None:
    """``--effects backlash`` (or clearance) named for files without tilt rows: one line, not
    a calibration that quietly leaves them out (``identify`` asks for what each row can see)."""
    from robocal.identify.constraints.position_effects import check_sign_kinds
    from robocal.measure.constraints.data import has_tilt_rows

    if effects is None or effects.strip() in ("none", "identify"):
        return
    try:
        check_sign_kinds(tuple(k.strip() for k in effects.split(",")), any(map(has_tilt_rows, paths)))
    except ValueError as err:
        raise fail(f"--effects {safe(effects)}: {err}") from None


def tilt_effect_kinds(effects: str | None) -> tuple[str, ...] | None:
    """``--effects`` for constraint files: the joint effects the tilt rows identify
    (:func:`constraint_effect_kinds`' first)."""
    return constraint_effect_kinds(effects)[0]


def constraint_effect_kinds(effects: str | None) -> tuple[tuple[str, ...] | None, tuple[str, ...]]:
    """``--effects`` for constraint files: ``(the joint effects the tilt rows identify,
    the joint effects the position rows carry)``.  Not given: the tilt rows' default
    (clearance, backlash, compliance; None) and no position effect (a model's stated
    compliances predict the position rows, held); ``none``: no joint effect (a model's
    stated ones left out too); ``identify``: the tilt rows' three and compliance on the
    position rows; or a list of
    ``clearance,backlash,compliance,radial``: the tilt rows identify those of the first three
    named, the position rows (fixed points, planes, distances, tracker points) carry
    ``compliance`` and ``radial`` (compliance about the axis, and tilting about the other
    two) when named, under the gravity loads of the model's link masses.  ``predict`` (the
    model's effects held) is the tracker calibration's only: refused."""
    from robocal.identify.constraints.position_effects import POSITION_EFFECT_KINDS
    from robocal.identify.constraints.tilt_rows import ALL_KINDS

    if effects is None:
        return None, ()
    if effects.strip() == "none":
        return (), ()
    if effects.strip() == "identify":
        return ALL_KINDS, ("compliance",)
    kinds = tuple(k.strip() for k in effects.split(",") if k.strip())
    known = ALL_KINDS + tuple(k for k in POSITION_EFFECT_KINDS if k not in ALL_KINDS)
    wrong = [k for k in kinds if k not in known]
    if not kinds or wrong:
        raise fail(
            f"--effects {safe(effects)}: a constraint file's rows take none, identify or some of "
            f"{', '.join(known)}"
        )
    return tuple(k for k in ALL_KINDS if k in kinds), tuple(k for k in POSITION_EFFECT_KINDS if k in kinds)


def _distances(items: list[str] | None) -> tuple[tuple[int, int, float], ...]:
    from robocal.workflow.constraints import parse_distances

    try:
        return parse_distances(items)
    except ValueError as err:
        raise fail(str(err)) from None


def _read(path: Path, dof: int, angle_unit: str, distances, sigma: float):
    from robocal.workflow.constraints import read_constraint_file

    try:
        return read_constraint_file(path, dof, angle_unit, distances, sigma)
    except ValueError as err:
        raise fail(_option_words(err)) from None


def _option_words(err: ValueError) -> str:
    """The use case's refusal with the command line's option named."""
    options = {
        "out": "--out",
        "distances": "--distance",
        "angle_unit": "--angle-unit",
        "effects": "--effects",
    }
    option = options.get(getattr(err, "field", ""))
    return f"{option} {err}" if option else str(err)


def calibrate_constraint_file(
    model, data_path: Path | list[Path], out: Path, *, angle_unit: AngleUnit, distances: list[str] | None,
    level: int | None, noise: str | None, length_unit: LengthUnit = "m",
    tilt_kinds: tuple[str, ...] | None = None, frames=None, effects: tuple[str, ...] = (),
) -> None:  # fmt: skip
    """Calibrate ``model`` (the complete position model of a catalog robot, or a model
    file's chain) from a constraint file; write ``out``/model.yaml and constraints.json
    (:func:`robocal.workflow.constraints.calibrate_constraint_files`, the GUI's too)."""
    from robocal.workflow.constraints import ConstraintRequest, calibrate_constraint_files

    paths = tuple(data_path) if isinstance(data_path, list) else (data_path,)
    stated, sigma = _distances(distances), _sigma(noise)
    request = ConstraintRequest(paths, model, out, angle_unit=angle_unit, length_unit=length_unit,
                                distances=stated, level=level or 2, noise_m=sigma, frames=frames,
                                effects=effects)  # fmt: skip
    if tilt_kinds is not None:
        request = dataclasses.replace(request, tilt_kinds=tilt_kinds)
    try:
        run = calibrate_constraint_files(request)
    except ValueError as err:
        raise fail(_option_words(err)) from None
    for line in run.summary_lines():
        console.print(safe(line), highlight=False, soft_wrap=True)
    for line in run.each_kind:
        console.print(safe(line), highlight=False, soft_wrap=True)
    console.print(f"wrote {out / 'model.yaml'} and {out / RESULT_FILE}", highlight=False)


def validate_constraint_file(
    directory: Path, data_path: Path, angle_unit: str, distances: list[str] | None, as_json: bool = False
) -> None:
    """The calibrated model of ``directory`` (and the model it started from, when it is a
    constraint calibration) on a constraint file: each kind's own figures, as text or
    (``as_json``) one JSON document on stdout."""
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
            stated = tuple((int(a), int(b), float(d)) for a, b, d in recorded)
        except (OSError, ValueError, TypeError) as err:
            raise fail(f"{directory / RESULT_FILE}: {err}") from None
    data = _read(data_path, model.dof, angle_unit, [s for s in stated if max(s[:2]) < 10**6], 1e-4)
    cal = None
    if (directory / RESULT_FILE).is_file():  # a constraint calibration: its joint effects, its start
        from robocal.cli.report_constraints import load_constraint_folder

        cal = load_constraint_folder(directory)
    from robocal.measure.constraints.mounts import mounts_in

    # sensors stated at home sit where the person put them: resolved against the start robot
    data = mounts_in(data, model if cal is None or cal.nominal is None else cal.nominal)
    from robocal.safe_output import strict_json

    figures = constraint_figures(model, data, tilt=None if cal is None else cal.tilt)
    nominal = None if cal is None else cal.nominal
    if as_json:  # the data's own strings go through json.dumps: escaped
        before = None if nominal is None else constraint_figures(nominal, data).as_dict()
        doc = {"model": model.name, "data": str(data_path), "poses": data.n, "kinds": list(data.kinds),
               "figures": figures.as_dict(), "nominal_figures": before}  # fmt: skip
        print(strict_json(doc, indent=2))  # NaN as null: a standard JSON document
        return
    console.print(f"{safe(model.name)} on {safe(data_path.name)} ({data.n} poses, {', '.join(data.kinds)}):",
                  highlight=False)  # fmt: skip
    for line in figures.lines():
        console.print("  " + safe(line), highlight=False)
    if nominal is not None:  # the robot a constraint calibration started from too
        console.print("before calibration (the nominal robot):", highlight=False)
        for line in constraint_figures(nominal, data).lines():
            console.print("  " + line, highlight=False)


def simulate_constraint_command(model_of, kind: str, poses, out, force: bool, options: tuple) -> None:
    """``robocal simulate ROBOT --kind KIND``: ``model_of()`` the robot; ``options``: ``--n``,
    ``--count``, ``--length``, ``--noise``, ``--seed``, ``--length-tol``, ``--angle-tol``,
    ``--placements``, ``--also-tracker``."""
    from robocal.console import refuse_overwrite
    from robocal.model.complete import calibration_model

    n, count, length, noise, seed, length_tol, angle_tol, placements, tracker, mount = options
    if out is None or poses is not None:
        raise fail("--kind makes its own configurations: give -o OUT.csv and no --poses")
    if mount not in TILT_MOUNTS or (mount != "joint" and kind != "tilt"):
        raise fail(f"--mount {safe(mount)}: joint or level, with --kind tilt")
    for path in placement_files(out, placements) + ([tracker_file(out)] if tracker else []):
        refuse_overwrite(path, force, "measurement file")
    own = model_of()  # the robot's own chain: the joint effects' moment points (simulate_tilt)
    model = calibration_model(own, "position")
    simulate_constraint_file(model, kind, out, n=n, count=count, length=length, noise=noise, seed=seed,
                             length_tol=length_tol, angle_tol=angle_tol, placements=placements,
                             tracker=tracker, level=mount == "level", frames=own)  # fmt: skip


def tracker_file(out: Path) -> Path:
    """``OUT``'s stem + ``.tracker`` + suffix: the tracker file of ``--also-tracker``."""
    return out.with_name(f"{out.stem}.tracker{out.suffix}")


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


def _simulated_noise(kind: str, noise: str | None) -> float:
    """``--noise``: the tool point's σ (m; 10 µm by default), an inclinometer's (rad, an
    angle such as 0.001deg; seed 003's resolution by default) for ``--kind tilt``."""
    from robocal.measure.constraints.data_set import TILT_SIGMA
    from robocal.measure.true_model import parse_quantity_option

    if kind == "tilt":
        return TILT_SIGMA if noise is None else parse_quantity_option(noise, "angle", "--noise")
    return 1e-5 if noise is None else parse_quantity_option(noise, "length", "--noise")


def simulate_tilt(model, true, n: int, sigma: float, seed: int | None, level: bool, frames=None):
    """``--kind tilt``: every link's sensor read on the ``true`` robot at ``n`` random
    configurations, along its joint frame or (``level``, ``--mount level``) level at the
    nominal ``model``'s home configuration; the joint effects' bending moments about
    ``frames``' joint frame origins (the robot's own chain, as ``calibrate`` takes them)."""
    from robocal.measure.constraints.sim import SceneTruth, level_mounts, simulate_tilt_rows

    mounts = level_mounts(model) if level else None
    data = simulate_tilt_rows(true, n, sigma=sigma, seed=seed, mounts=mounts, frames=frames)
    return data, SceneTruth(np.zeros((0, 3)), np.zeros((0, 4)), 0.0)


def simulate_constraint_file(
    model, kind: str, out: Path, *, n: int, count: int, length: str, noise: str | None, seed: int | None,
    length_tol: str, angle_tol: str, placements: int = 1, tracker: int = 0, level: bool = False,
    frames=None,
) -> None:  # fmt: skip
    """Simulate ``kind`` on a true robot drawn around ``model``; write ``out`` and
    ``out``.truth.json (the true parameters and scene); ``placements`` > 1: the same true
    robot at the scene moved rigidly (:func:`~robocal.measure.constraints.sim.moved_scene`),
    one file each (:func:`placement_files`), all in the one truth file: held-out data;
    ``tracker`` > 0: also that many tracker rows of the same true robot (random
    configurations, the tool point in the robot's base frame, 10 µm per axis) in
    :func:`tracker_file`, a plain tracker file (``q1..qN, x, y, z`` in m); ``frames``: the
    robot's own chain, whose joint frame origins the tilt rows' joint effects' bending
    moments are taken about (:func:`simulate_tilt`; None: the true robot's)."""
    from robocal.measure.constraints.data import write_constraints
    from robocal.measure.constraints.sim import moved_scene, simulate_constraints, simulate_tracker_rows
    from robocal.measure.true_model import draw_true_model, parse_quantity_option

    if kind not in CONSTRAINT_MEASURES:
        raise fail(f"--kind {kind!r}: one of {', '.join(CONSTRAINT_MEASURES)}")
    if n < 4 or count < 1:
        raise fail("--n must be >= 4 and --count >= 1")
    if tracker > MAX_TRACKER_ROWS:
        raise fail(f"--also-tracker {tracker}: at most {MAX_TRACKER_ROWS:,} rows")
    length_m = parse_quantity_option(length, "length", "--length")
    sigma = _simulated_noise(kind, noise)
    files, runs = placement_files(out, placements), []
    try:
        true = draw_true_model(model, length=length_tol, angle=angle_tol, seed=seed)
        if kind == "tilt":  # level: at home of the nominal robot (the mount a user states)
            data, scene = simulate_tilt(model, true, n, sigma, seed, level, frames)
        else:
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
        # the same true robot yields to gravity on the tracker as in its sockets (tilt rows: rigid)
        tracked = None
        if tracker:
            tracked = simulate_tracker_rows(true, tracker, sigma=1e-5, seed=rng, deflected=kind != "tilt")
    except ValueError as err:
        raise fail(str(err)) from None
    truth = {"kind": kind, "sigma_m": sigma,
             "true_parameters": dict(zip(true.names, true.values.tolist(), strict=True)),
             "length_m": scene.length} | _scene_doc(scene, out, data.n)  # fmt: skip
    truth |= _true_effects(true)
    if placements > 1:
        truth["placements"] = [_scene_doc(s, f, d.n) for (d, s), f in zip(runs, files, strict=True)]
    from robocal.outdir import write_together

    truth_path = out.with_name(out.name + ".truth.json")
    from robocal.measure.constraints.mounts import mounts_at_home

    # the sensors stated at home (home_r*_deg): the same sensors whichever chain calibrates them
    stated = [mounts_at_home(d, model) for d, _ in runs]
    texts = {f: write_constraints(d).encode() for d, f in zip(stated, files, strict=True)}
    if tracked is not None:  # the same true robot: a tracker calibration to compare with
        texts[tracker_file(out)] = write_constraints(tracked).encode()
        truth["tracker_file"] = {"file": tracker_file(out).name, "rows": tracked.n, "sigma_m": 1e-5,
                                 "T_device_base": np.eye(4).tolist()}  # fmt: skip
    write_together(texts | {truth_path: (json.dumps(truth, indent=1) + "\n").encode()})
    written = [f"{safe(str(f))} ({d.n} rows, {kind})" for (d, _), f in zip(runs, files, strict=True)]
    written += [f"{safe(str(tracker_file(out)))} ({tracker} rows, tracker)"] if tracker else []
    console.print(f"wrote {', '.join(written)} and the truth {safe(str(truth_path))}", highlight=False,
                  soft_wrap=True)  # fmt: skip


def _true_effects(true) -> dict:
    """The truth file's record of the joint compliances the true robot yields to gravity
    with (``compliance_<joint>``, ``radial_compliance_<joint>``, rad/(N·m); the model's
    ``joint_effects`` under its link masses' loads), none when it states none."""
    from robocal.identify.constraints.position_effects import stated_effects

    stated = stated_effects(true)
    if not stated:
        return {}
    loads = "the static gravity loads (9.81 m/s² along the base's -z) of the model's masses"
    return {"true_joint_effects_rad_per_Nm": stated, "joint_effect_loads": loads}


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
