"""Inclinometer readings on the command line (seed 003's joint tilting set-up).

``robocal simulate ROBOT --device inclinometer --poses POSES.csv -o READINGS.csv`` reads a
dual-axis inclinometer on the link after every joint (level at the home configuration) at
the configurations of ``POSES.csv``, on a true robot with drawn geometric errors and the
model's joint effects (clearance, backlash, stiffness), and writes the readings CSV
(docs/inclinometer.md) with the truth beside it (``READINGS.truth.json``).

``robocal poses ROBOT --rows tilt -o POSES.csv`` (:func:`plan_tilt_poses`) chooses the
configurations to read by O1-O5 on the tilt Jacobian.

``robocal data tilt READINGS.csv ROBOT`` (:func:`identify_tilt_file`) identifies the joint
effects, the channels' zeros and the angles of the geometry that turn the sensed links
from such a file, and prints them with their 1σ and what the readings cannot see.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from robocal.console import console, fail, refuse_overwrite, safe

__all__ = ["identify_tilt_file", "plan_tilt_poses", "simulate_inclinometer"]

OFFSET_RANGE_DEG = 0.05  # the channels' zeros drawn within ±this (docs/inclinometer.md)


def _sensors(model, links: tuple[str, ...] | None = None) -> tuple[Any, ...]:
    from robocal.measure.inclinometer import Inclinometer

    return tuple(Inclinometer.level_at(model, j) for j in (links or model.joint_names))


def simulate_inclinometer(
    model, draw: Callable[[], Any], poses: Path, out: Path, noise: str | None, seed: int | None
) -> None:
    """Readings of the true robot ``draw()`` (geometry drawn as ``simulate`` draws it, the
    model's joint effects) at the poses of ``poses``, written to ``out`` with the truth
    beside it; bad input exits with one line."""
    from robocal.measure.measurements import MeasurementFileError

    try:
        _simulate(model, draw(), poses, out, noise, seed)
    except MeasurementFileError as err:
        raise fail(str(err)) from None
    except (ValueError, KeyError) as err:
        raise fail(str(err.args[0] if isinstance(err, KeyError) else err)) from None


def _simulate(model, true, poses: Path, out: Path, noise: str | None, seed: int | None) -> None:
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.inclinometer import simulate_readings
    from robocal.measure.tilt_csv import write_tilt_readings
    from robocal.measure.true_model import parse_quantity_option
    from robocal.outdir import atomic_write_text

    kwargs = {}
    if noise is not None:
        sigma = parse_quantity_option(noise, "angle", "--noise")
        if not 0 <= sigma <= math.radians(1.0):
            raise ValueError(f"--noise {noise}: an inclinometer's 1σ between 0 and 1 deg, e.g. 0.001deg")
        kwargs["sigma"] = sigma
    q = read_measurements(poses, model=model).q
    sensors = tuple(
        type(s)(link=s.link, mount=s.mount, **kwargs) for s in _sensors(model)
    )  # mounted level on the nominal robot: the set-up's, not the truth's
    rng = np.random.default_rng(None if seed is None else [seed, 2])
    span = math.radians(OFFSET_RANGE_DEG)
    offsets = {(s.link, a): float(rng.uniform(-span, span)) for s in sensors for a in s.axes}
    data = simulate_readings(true, q, sensors, rng, offsets)
    write_tilt_readings(out, data, model.joint_names)
    truth = {
        "command": "robocal simulate --device inclinometer",
        "poses": str(poses),
        "geometry_change": {
            n: b - a for n, a, b in zip(model.names, model.values, true.values, strict=True) if a != b
        },
        "joint_effects": [
            {
                "joint": e.joint,
                "clearance_tilt_deg": math.degrees(e.clearance_tilt),
                "backlash_deg": math.degrees(e.backlash),
                "compliance_rad_per_Nm": e.compliance,
            }
            for e in true.joint_effects
        ],
        "channel_zero_deg": {f"{k[0]}_{k[1]}": math.degrees(v) for k, v in offsets.items()},
        "sigma_deg": math.degrees(sensors[0].sigma),
        "seed": seed,
    }
    truth_path = out.with_name(out.stem + ".truth.json")
    atomic_write_text(truth_path, json.dumps(truth, indent=2) + "\n")
    console.print(
        f"wrote {safe(out)} ({data.n} readings: {len(q)} configurations x {len(data.channels())} channels) "
        f"and the truth {safe(truth_path)}",
        highlight=False,
        soft_wrap=True,
    )


def _rows(fit) -> list[tuple[str, str, str]]:
    """``(parameter, estimate ± 1σ, unit)`` in the thesis' units (deg, kgf·m/deg)."""
    from robocal.model.files import STIFFNESS_SCALE
    from robocal.model.joints import effect_of

    kgfm = STIFFNESS_SCALE["kgf*m/deg"]
    rows = []
    for name, v, s in zip(fit.names, fit.values, fit.sigma, strict=True):
        effect = effect_of(name)
        if effect is not None and effect[0] == "compliance":
            k = f"{1 / v / kgfm:.1f} ± {s / v**2 / kgfm:.1f}" if v > 2 * s else "not above zero"
            rows.append((f"stiffness_{effect[1]}", k, "kgf·m/deg"))
        else:
            rows.append((name, f"{math.degrees(v):.4f} ± {math.degrees(s):.4f}", "deg"))
    return rows


def identify_tilt_file(
    file: Path, robot: str, exact_geometry: bool, json_out: Path | None, force: bool
) -> None:
    """Identify clearance, backlash and stiffness from inclinometer readings (Katana thesis, seed 003)."""
    from rich.table import Table

    from robocal.cli.options import resolve_model
    from robocal.identify.tilt_identification import identify_tilt
    from robocal.measure.tilt_csv import read_tilt_readings

    model = resolve_model(robot)
    if json_out is not None:
        refuse_overwrite(json_out, force, "JSON file")
    try:
        data = read_tilt_readings(file, model)
        sensors = _sensors(model, tuple(dict.fromkeys(data.link)))
        fit = identify_tilt(model, data, sensors, geometry=not exact_geometry)
    except (ValueError, np.linalg.LinAlgError) as err:
        raise fail(str(err)) from None
    console.print(
        f"{safe(file)}: {fit.readings} readings, weighted RMS residual {fit.rms_residual:.2f}",
        highlight=False,
    )
    table = Table()
    for column in ("parameter", "estimate ± 1σ", "unit"):
        table.add_column(column)
    for row in _rows(fit):
        table.add_row(*row)
    console.print(table)
    for name, why in fit.not_identified.items():
        console.print(f"not identified: {name}: {why}", highlight=False, soft_wrap=True)
    if fit.rms_residual > 3:
        console.print(
            "note: the residual is far above 1: the readings' sigma is too small or the model misses an "
            "effect (sensors not level at home, a different robot)",
            highlight=False,
        )
    if json_out is not None:
        from robocal.outdir import atomic_write_text

        result = {
            "parameters": {
                n: {"value": float(v), "sigma": float(s)}
                for n, v, s in zip(fit.names, fit.values, fit.sigma, strict=True)
            },
            "not_identified": fit.not_identified,
            "rms_residual": fit.rms_residual,
            "readings": fit.readings,
            "units": "rad, rad/(N·m)",
        }
        atomic_write_text(json_out, json.dumps(result, indent=2) + "\n")


def plan_tilt_poses(model, out: Path, *, n: int, pool: int, index: str, seed: int) -> None:
    """``robocal poses ROBOT --rows tilt``: ``n`` configurations of a seeded pool of ``pool``
    random ones, read by a dual-axis inclinometer on the link after every joint (level at
    home, as ``simulate --device inclinometer`` places them), maximising ``index`` on the
    tilt Jacobian (:mod:`robocal.identify.tilt_poses`); written as a poses CSV."""
    from rich.table import Table

    from robocal.identify.tilt_poses import select_tilt_poses
    from robocal.measure.poses import random_poses, write_poses

    if pool < n:
        raise fail(f"--pool {pool} is smaller than --n {n}")
    try:
        sel = select_tilt_poses(model, random_poses(model, pool, seed=seed), n, _sensors(model), index=index)
    except (ValueError, np.linalg.LinAlgError) as err:
        raise fail(str(err)) from None
    table = Table(
        title=f"observability of {n} configurations for the inclinometers ({len(sel.params)} parameters)"
    )
    for col in ("index", "chosen", f"first {n} of the pool"):
        table.add_column(col, justify="right")
    for name in ("O1", "O2", "O3", "O4", "O5"):
        table.add_row(name, f"{sel.indices[name]:.4g}", f"{sel.baseline[name]:.4g}")
    console.print(table)
    for name, why in sel.not_seen.items():
        console.print(f"[dim]not identifiable: {safe(name)}: {safe(why)}[/]", highlight=False, markup=True)
    meta = {"robot": model.name, "method": "optimal", "rows": "tilt", "index": index, "pool": str(pool),
            "seed": str(seed), "value": repr(sel.value)}  # fmt: skip
    path = write_poses(out, sel.q, model=model, metadata=meta)
    what = f"{len(sel.q)} configurations of {safe(model.name)} (inclinometers)"
    console.print(f"wrote {what} to {safe(str(path))}", highlight=False)
