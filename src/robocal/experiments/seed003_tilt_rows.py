"""Tables 4.3 / 4.4 / 5.2 through ``robocal calibrate``: the thesis' set-up as a tilt file.

The thesis' virtual Katana of :mod:`robocal.experiments.seed003_inclinometer` (Table 3.2's
geometric errors, Table 5.2's joints), its sensors (a dual-axis inclinometer on every
link, level at the home configuration: the file's ``home_r*_deg`` columns), its
:data:`~robocal.experiments.seed003_inclinometer.N_CONFIGURATIONS` designed configurations,
zero offsets within ±0.05° and the 0.001° resolution (σ 0.001°, rounded to the count) are
written as one tilt file and calibrated by the command line (``robocal calibrate
katana450 --data FILE``: the one constraint fit,
geometry and joint effects together, in the default chain, the complete model with its
link rotations freed, :func:`robocal.identify.constraints.tilt_rows.link_rotations_free`;
the position model alone lacks the last joint's offset a sensor on link 5 reads and
fitted the same file to 0.025° RMS; ``--chain catalog`` gives the same tables,
tests/test_tilt_thesis.py).
:func:`tilt_rows_tables` sets the joint effects it saved in
``constraints.json`` beside the thesis' values and the old route's (``identify_tilt``,
orientation fitted); ``python -m robocal.experiments.seed003_tilt_rows`` prints the
markdown table docs/inclinometer.md holds.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["EFFECTS", "ROWS", "markdown_table", "thesis_tilt_file", "tilt_rows_tables"]

#: the options of the one fit: none (the default identifies clearance, backlash and compliance)
EFFECTS: tuple[str, ...] = ()
#: (table key, effect kind, the saved estimate's key) of the thesis' three tables
ROWS = (
    ("clearance_tilt_deg", "clearance", "estimate_rad"),
    ("backlash_deg", "backlash", "estimate_rad"),
    ("stiffness_kgfm_per_deg", "compliance", "estimate_rad_per_Nm"),
)


def thesis_tilt_file(path: Path, noise_seed: int = 1, n: int | None = None) -> np.ndarray:
    """Write the thesis' set-up's readings (module docstring) to ``path``; the configurations
    ``(n, dof)`` (rad).  ``n``: fewer designed configurations (None: the thesis' 30).  The
    sensors are written as a person states them: level at home, x along the base's x
    (``home_r*_deg`` = 0), whatever chain calibrates them."""
    from robocal.experiments.seed003_inclinometer import (
        N_CONFIGURATIONS,
        OFFSET_RANGE,
        design_configurations,
        katana_robots,
        katana_sensors,
    )
    from robocal.measure.constraints.data import write_constraints
    from robocal.measure.constraints.mounts import mounts_at_home
    from robocal.measure.constraints.sim import level_mounts, simulate_tilt_rows

    setup = katana_robots()
    q = design_configurations(setup.nominal, katana_sensors(setup.nominal), n or N_CONFIGURATIONS)
    rng = np.random.default_rng(noise_seed)
    zeros = {(k, a): float(rng.uniform(-OFFSET_RANGE, OFFSET_RANGE)) for k in range(5) for a in (0, 1)}
    count = math.radians(0.001)  # the thesis' resolution; σ one count
    noise = np.random.default_rng([noise_seed, 1])
    data = simulate_tilt_rows(setup.true, 0, configurations=q, mounts=level_mounts(setup.nominal),
                              zeros=zeros, sigma=count, resolution=count, seed=noise)  # fmt: skip
    write_constraints(mounts_at_home(data, setup.nominal), path)  # level at home: home_r*_deg = 0
    return q


def _one_fit(out: Path) -> dict[str, tuple[float, float]]:
    """``{name: (estimate, σ)}`` (SI) of the joint effects saved in ``out``/constraints.json."""
    doc = json.loads((out / "constraints.json").read_text())
    got = {}
    for e in doc["joint_effects"]:
        unit = "rad_per_Nm" if e["kind"] == "compliance" else "rad"
        got[e["name"]] = (float(e[f"estimate_{unit}"]), float(e[f"std_{unit}"] or math.nan))
    return got


def _display(kind: str, value: float, sigma: float) -> tuple[float, float]:
    """A saved value in the thesis' unit: deg, or a stiffness in kgf·m/deg from a compliance."""
    from robocal.model.files import STIFFNESS_SCALE

    if kind != "compliance":
        return math.degrees(value), math.degrees(sigma)
    kgfm = STIFFNESS_SCALE["kgf*m/deg"]
    return 1 / value / kgfm, sigma / value**2 / kgfm


def tilt_rows_tables(out: Path, old: dict[str, Any] | None = None) -> dict[str, list[dict[str, Any]]]:
    """Per table and joint: the thesis' value, the old route's (``old``: the
    ``orientation_fitted`` tables of :func:`~robocal.experiments.seed003_inclinometer.
    inclinometer_experiment`, or None) and the one fit's saved in ``out`` (estimate, σ;
    None where not identified or, for a stiffness, a compliance within 2σ of zero)."""
    from robocal.experiments.seed003_inclinometer import THESIS_TABLE_5_2

    got = _one_fit(out)
    tables: dict[str, list[dict[str, Any]]] = {}
    for key, kind, _ in ROWS:
        rows = []
        for j, thesis in enumerate(THESIS_TABLE_5_2[key]):
            name = f"{kind}_q{j + 1}"
            value = got.get(name)
            fit = None
            if value is not None and not (kind == "compliance" and value[0] <= 2 * value[1]):
                fit = _display(kind, *value)
            before = None if old is None else old[key][j]
            prior = (
                None
                if before is None or before["estimate"] is None
                else (before["estimate"], before["sigma"])
            )
            rows.append({"joint": f"q{j + 1}", "thesis": thesis, "old_route": prior, "one_fit": fit})
        tables[key] = rows
    return tables


def _cell(value: tuple[float, float] | None, digits: int) -> str:
    return "not identified" if value is None else f"{value[0]:.{digits}f} ± {value[1]:.{digits}f}"


def markdown_table(tables: dict[str, list[dict[str, Any]]]) -> str:
    """The side-by-side table (thesis / old route / one fit) as markdown."""
    lines = ["| parameter | joint | thesis | `robocal data tilt` | `robocal calibrate` (one fit) |",
             "|---|---|---|---|---|"]  # fmt: skip
    for key, rows in tables.items():
        digits = 1 if key.startswith("stiffness") else 4
        for r in rows:
            lines.append(f"| {key} | {r['joint']} | {r['thesis']:g} | {_cell(r['old_route'], digits)} | "
                         f"{_cell(r['one_fit'], digits)} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:  # pragma: no cover - the documentation's table
    import subprocess
    import sys
    import tempfile

    from robocal.experiments.seed003_inclinometer import inclinometer_experiment, katana_robots

    with tempfile.TemporaryDirectory() as tmp:
        path, out = Path(tmp) / "thesis_tilt.csv", Path(tmp) / "out"
        thesis_tilt_file(path)
        args = ["calibrate", "katana450", "--data", str(path), *EFFECTS]
        # the command as a user runs it (experiments sit below the CLI's layer: no import of it)
        result = subprocess.run([sys.executable, "-m", "robocal.cli", *args, "-o", str(out)],
                                capture_output=True, text=True, check=False)  # fmt: skip
        if result.returncode:
            raise SystemExit(result.stdout + result.stderr)
        old = inclinometer_experiment(katana_robots())["orientation_fitted"]["tables"]
        print(markdown_table(tilt_rows_tables(out, old)))


if __name__ == "__main__":  # pragma: no cover
    main()
