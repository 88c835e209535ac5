"""Seed 003's inclinometer set-up (Figs. 4.6, 5.4; Tables 4.3, 4.4, 5.2) in simulation.

The thesis fixes inclinometers (resolution 0.001°) on the Katana's links and reads them
at configurations chosen one joint at a time so that the moment about X flips (clearance
tilt), the moment about Z changes (stiffness) or flips with a small magnitude (backlash)
— Fig. 5.4's configurations 1-6 per joint; it measured joint 1's backlash and stiffness
with end-effector poses instead, "as inclinometers cannot work without gravity
component" (§4.4.1).  The configurations themselves are only drawn (the figures), so
this reproduction lets the readings choose them: :func:`design_configurations` picks,
from random configurations whose readings stay within the sensors' range, the
:data:`N_CONFIGURATIONS` that determine the joint parameters best (greedy D-optimal, the
same count as the thesis' three pairs per joint).

The virtual Katana is that of :func:`robocal.experiments.seed003_setup.katana_setup`:
Table 3.2's geometric errors and Table 5.2's joint parameters.  A dual-axis sensor sits
on each link (level at the home configuration, zero offsets drawn within ±0.05°); the
parameters are identified from the readings with the nominal geometry
(:func:`robocal.identify.tilt_identification.identify_tilt`) and printed next to the
thesis' tables.  A second run on a robot without geometric errors shows what the
thesis' claim "a relative change in orientation is not affected by the geometric
errors" costs: the identification's bias from the Table 3.2 errors; a third fits the
angles of the geometry that turn the sensed links with the joint parameters and
removes that bias (:func:`robocal.identify.tilt_identification.orientation_parameters`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.experiments.seed003_setup import KatanaSetup

__all__ = ["N_CONFIGURATIONS", "design_configurations", "inclinometer_experiment", "katana_sensors"]

Array = NDArray[np.float64]

#: configurations read: the thesis' three pairs per joint, five joints
N_CONFIGURATIONS = 30
OFFSET_RANGE = math.radians(0.05)  # sensors' zero offsets drawn within this (an assumption)

#: Tables 4.3 / 4.4 / 5.2 (deg, deg, kgf·m/deg), joints 1-5
THESIS_TABLE_5_2: dict[str, tuple[float, ...]] = {
    "clearance_tilt_deg": (0.022, 0.024, 0.017, 0.015, 0.018),
    "backlash_deg": (0.063, 0.061, 0.057, 0.046, 0.051),
    "stiffness_kgfm_per_deg": (122.0, 90.0, 75.0, 78.0, 80.0),
}


def katana_robots() -> KatanaSetup:
    """The virtual Katana's models (nominal, geometric, true) without its poses: what
    :func:`inclinometer_experiment` uses of :func:`~robocal.experiments.seed003_setup.katana_setup`."""
    from robocal.experiments.seed003_setup import THESIS_GEOMETRIC_ERRORS
    from robocal.model.catalog import robot

    nominal = robot("katana450")
    true = nominal.with_values({k: nominal.step(k).value + v for k, v in THESIS_GEOMETRIC_ERRORS.items()})
    geometric = dataclasses.replace(nominal, joint_effects=())
    empty = np.zeros((0, nominal.dof))
    return KatanaSetup(nominal, geometric, true, None, empty, empty)


def katana_sensors(model) -> tuple[Any, ...]:
    """A dual-axis inclinometer on the link after each joint, level at ``q = 0``."""
    from robocal.measure.inclinometer import Inclinometer

    return tuple(Inclinometer.level_at(model, j) for j in model.joint_names)


def _candidates(model, sensors, n: int, rng: np.random.Generator) -> Array:
    """Random configurations within the joint limits whose readings all stay in range."""
    from robocal.measure.inclinometer import channel_rows, readings

    lim = model.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n, model.dof))
    rows, link, axis, mounts = channel_rows(model, q, sensors)
    r = np.abs(readings(model, rows, link, axis, mounts)).reshape(n, -1)
    limit = min(s.max_tilt for s in sensors)
    return q[np.all(r < 0.9 * limit, axis=1)]


def design_configurations(
    model, sensors, n: int = N_CONFIGURATIONS, candidates: int = 1500, seed: int = 0
) -> Array:
    """``n`` configurations ``(n, dof)`` picked greedily from random ones to maximise
    ``log det`` of the identifiable parameters' information at the model's own joint
    effects (the "measured" Table 5.2 values)."""
    from robocal.identify.tilt_identification import parameter_names, tilt_jacobian, visible
    from robocal.measure.inclinometer import TiltReadings, channel_rows

    q = _candidates(model, sensors, candidates, np.random.default_rng(seed))
    rows, link, axis, _ = channel_rows(model, q, sensors)
    dummy = TiltReadings(rows, link, axis, np.zeros(len(rows)), np.full(len(rows), sensors[0].sigma_reading))
    names = parameter_names(model, dummy)
    prior = {
        f"{kind}_{e.joint}": getattr(e, field)
        for e in model.joint_effects
        for kind, field in (
            ("clearance", "clearance_tilt"),
            ("backlash", "backlash"),
            ("compliance", "compliance"),
        )
    }
    x = np.array([prior.get(n_, 0.0) for n_ in names])
    J = tilt_jacobian(model, dummy, sensors, names, x)
    keep, _ = visible(J, names)
    J = J[:, keep] / np.linalg.norm(J[:, keep], axis=0)
    per = J.reshape(len(q), -1, J.shape[1])  # (configurations, channels, parameters)
    info = 1e-6 * np.eye(J.shape[1])
    chosen: list[int] = []
    for _ in range(min(n, len(q))):
        scores = [
            -np.inf if c in chosen else np.linalg.slogdet(info + per[c].T @ per[c])[1] for c in range(len(q))
        ]
        best = int(np.argmax(scores))
        chosen.append(best)
        info = info + per[best].T @ per[best]
    return q[chosen]


def _tables(fit, true_effects) -> dict[str, list[dict[str, Any]]]:
    """Identified values with 1σ and the truth, per joint, in the thesis' units."""
    from robocal.model.files import STIFFNESS_SCALE

    kgfm = STIFFNESS_SCALE["kgf*m/deg"]
    true = {e.joint: e for e in true_effects}
    out: dict[str, list[dict[str, Any]]] = {k: [] for k in THESIS_TABLE_5_2}
    for joint, e in true.items():
        for key, kind, conv in (
            ("clearance_tilt_deg", "clearance", lambda v, s: (math.degrees(v), math.degrees(s))),
            ("backlash_deg", "backlash", lambda v, s: (math.degrees(v), math.degrees(s))),
            ("stiffness_kgfm_per_deg", "compliance", lambda v, s: (1 / v / kgfm, s / v**2 / kgfm)),
        ):
            name = f"{kind}_{joint}"
            got = fit.value(name)
            tv = getattr(e, dict(clearance="clearance_tilt").get(kind, kind))
            truth = conv(tv, 0.0)[0]
            row = {"joint": joint, "true": truth, "estimate": None, "sigma": None}
            if got is None:
                row["not_identified"] = fit.not_identified.get(name, "not identified")
            elif kind == "compliance" and got[0] <= 2 * got[1]:  # no stiffness within 2σ of infinity
                row["not_identified"] = f"compliance {got[0]:.3g} ± {got[1]:.3g} rad/(N·m): not above zero"
            else:
                row["estimate"], row["sigma"] = conv(*got)
            out[key].append(row)
    return out


def _geometry_rows(fit, setup: KatanaSetup) -> dict[str, Any]:
    """The angles of the geometry the fit estimated (deg, ± 1σ, the truth's change from
    nominal) and those it could not see, with the reason."""
    from robocal.identify.tilt_identification import GEOM

    rows = []
    for name, value, sigma in zip(fit.names, fit.values, fit.sigma, strict=True):
        if name.startswith(GEOM):
            step = name[len(GEOM) :]
            true = setup.true.step(step).value - setup.nominal.step(step).value
            rows.append(
                {
                    "step": step,
                    "estimate": math.degrees(value),
                    "sigma": math.degrees(sigma),
                    "true": math.degrees(true),
                }
            )
    unseen = {k[len(GEOM) :]: v for k, v in fit.not_identified.items() if k.startswith(GEOM)}
    return {"estimated": rows, "not_identified": unseen}


def inclinometer_experiment(
    setup: KatanaSetup, noise_seed: int = 1, n: int = N_CONFIGURATIONS
) -> dict[str, Any]:
    """Readings of the virtual Katana at the designed configurations; the joint parameters
    identified from them, with and without the Table 3.2 geometric errors in the robot."""
    from robocal.identify.tilt_identification import identify_tilt
    from robocal.measure.inclinometer import simulate_readings

    sensors = katana_sensors(setup.nominal)
    q = design_configurations(setup.nominal, sensors, n)
    rng = np.random.default_rng(noise_seed)
    offsets = {(s.link, a): float(rng.uniform(-OFFSET_RANGE, OFFSET_RANGE)) for s in sensors for a in s.axes}
    out: dict[str, Any] = {"configurations": len(q), "readings_per_configuration": 2 * len(sensors)}
    effects_only = dataclasses.replace(setup.nominal, joint_effects=setup.true.joint_effects)
    runs = {  # key: (the robot read, angles of the geometry fitted with the joints)
        "with_geometric_errors": (setup.true, False),
        "joint_effects_only": (effects_only, False),
        "orientation_fitted": (setup.true, True),
    }
    for key, (true, geometry) in runs.items():
        data = simulate_readings(true, q, sensors, np.random.default_rng([noise_seed, 1]), offsets)
        fit = identify_tilt(setup.geometric, data, sensors, geometry=geometry)
        out[key] = {"tables": _tables(fit, setup.true.joint_effects), "rms_residual": fit.rms_residual}
        if geometry:
            out[key]["geometry"] = _geometry_rows(fit, setup)
    out["resolution_deg"] = math.degrees(sensors[0].resolution)
    out["sigma_deg"] = math.degrees(sensors[0].sigma)
    out["q_deg"] = np.degrees(q).round(3).tolist()
    return out


def print_inclinometer(inc: dict[str, Any]) -> None:
    """Tables 4.3 / 4.4 / 5.2: the thesis' values (the virtual robot's truth) beside the
    identified ones (± 1σ), joint effects only and with Table 3.2's geometry."""
    from rich import box
    from rich.table import Table

    from robocal.console import console

    table = Table(
        title="Tables 4.3 / 4.4 / 5.2 from simulated inclinometer readings",
        title_justify="left",
        box=box.SIMPLE_HEAD,
    )
    for c in ("parameter", "joint", "thesis", "robocal (effects only)", "robocal (with Table 3.2 geometry)"):
        table.add_column(c, justify="left" if c in ("parameter", "joint") else "right", no_wrap=True)
    for key, rows in inc["joint_effects_only"]["tables"].items():
        digits = 1 if key.startswith("stiffness") else 4
        for a, b in zip(rows, inc["with_geometric_errors"]["tables"][key], strict=True):
            cells = [
                "not identified"
                if r["estimate"] is None
                else f"{r['estimate']:.{digits}f} ± {r['sigma']:.{digits}f}"
                for r in (a, b)
            ]
            table.add_row(key, a["joint"], f"{a['true']:g}", *cells)
    console.print(table)
