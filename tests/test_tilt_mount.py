"""A sensor mount in the tilt rows (issue 33): the file states it, the fit uses it, and with
the thesis' level-at-home sensors the clearances of the Katana's parallel joints are told apart;
clearance reaches the command line (--effects)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocal.experiments.seed003_inclinometer import design_configurations, katana_robots, katana_sensors
from robocal.identify.constraints.fit import calibrate_constraints
from robocal.identify.constraints.tilt_rows import ALL_KINDS
from robocal.measure.constraints.data import ConstraintFileError, read_constraints, write_constraints
from robocal.measure.constraints.sim import level_mounts, simulate_tilt_rows


@pytest.fixture(scope="module")
def katana():
    setup = katana_robots()
    return setup, design_configurations(setup.nominal, katana_sensors(setup.nominal), 30)


def test_mount_columns_round_trip_and_one_mount_per_link(tmp_path, katana):
    setup, q = katana
    data = simulate_tilt_rows(setup.true, 0, configurations=q[:3], mounts=level_mounts(setup.nominal), seed=1)
    path = tmp_path / "t.csv"
    write_constraints(data, path)
    back = read_constraints(path, 5)
    assert np.allclose(back.tilt_mount, data.tilt_mount, atol=1e-12) and back.mounted
    lines = path.read_text().splitlines()
    cells = lines[4].split(",")
    cells[-3] = "12.5"  # link 2's second row (file row 5): another mount
    lines[4] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConstraintFileError, match="row 5"):
        read_constraints(path, 5)


def test_level_mount_separates_the_parallel_joints_clearances(katana):
    """Joint-frame sensors see only the sum of joints 2-4's clearance (σ ~0.1°); level at
    home (the thesis') each is within 4σ of the truth with σ below 0.001°."""
    setup, q = katana
    truth = {f"clearance_{e.joint}": e.clearance_tilt for e in setup.true.joint_effects}
    sigma = math.radians(0.001)
    for mounts, small in ((None, False), (level_mounts(setup.nominal), True)):
        data = simulate_tilt_rows(setup.true, 0, configurations=q, mounts=mounts, sigma=sigma, seed=2)
        fit = calibrate_constraints(setup.geometric, data, known_noise=True, tilt_kinds=ALL_KINDS)
        for name in ("clearance_q2", "clearance_q3", "clearance_q4"):
            k = fit.names.index(name)
            assert (fit.std[k] < math.radians(0.001)) == small, (name, math.degrees(fit.std[k]))
            if small:
                assert abs(fit.estimates[k] - truth[name]) < 4 * fit.std[k]


def test_effects_option_for_tilt_files(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli import app

    run = CliRunner().invoke
    out = tmp_path / "t.csv"
    args = ["simulate", "katana450", "--kind", "tilt", "--mount", "level", "--n", "30", "-o", str(out)]
    assert run(app, [*args, "--seed", "2"]).exit_code == 0
    header = out.read_text().splitlines()[0]  # the sensors stated at home, level: chain-independent
    assert "home_rx_deg" in header and "mount_rx_deg" not in header
    bad = run(
        app, ["calibrate", "katana450", "--data", str(out), "--effects", "predict", "-o", str(tmp_path / "a")]
    )
    assert bad.exit_code != 0 and "--effects" in bad.output and not (tmp_path / "a").exists()
    ok = run(app, ["calibrate", "katana450", "--data", str(out), "--effects", "clearance,backlash,compliance",
                   "-o", str(tmp_path / "b")])  # fmt: skip
    assert ok.exit_code == 0, ok.output
    import json

    saved = {
        e["name"] for e in json.loads((tmp_path / "b" / "constraints.json").read_text())["joint_effects"]
    }
    assert {"clearance_q2", "clearance_q3"} <= saved
