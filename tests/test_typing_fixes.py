"""Bugs that mypy found (issue 32 item 6), each held by a test of the behaviour."""

from __future__ import annotations

import dataclasses

import numpy as np

from robocal import spatial
from robocal.evaluate.iso9283.log import Iso9283Log
from robocal.evaluate.iso9283.report import evaluate_log


def _reorientation_log(cycles: int = 3, samples: int = 40) -> Iso9283Log:
    """A reorientation test along a line, each cycle turning the tool about z (m, rad)."""
    s = np.linspace(0.0, 0.3, samples)
    commanded = np.column_stack([0.5 + s, np.zeros(samples), 0.4 + 0.0 * s])
    turn = spatial.rotvec_to_matrix(np.column_stack([0 * s, 0 * s, np.linspace(0.0, 1.0, samples)]))
    n = cycles * samples
    rng = np.random.default_rng(0)
    return Iso9283Log(
        source="built",
        conditions={},
        time=np.arange(n) * 0.01,
        test=np.full(n, "reorientation"),
        cycle=np.repeat(np.arange(1, cycles + 1), samples),
        target=np.full(n, "line"),
        group=np.full(n, ""),
        position=np.tile(commanded, (cycles, 1)) + rng.normal(0.0, 1e-5, (n, 3)),
        commanded=np.tile(commanded, (cycles, 1)),
        rotation=np.tile(turn, (cycles, 1, 1)),
        commanded_rotation=np.tile(turn, (cycles, 1, 1)),
    )


def _row(log: Iso9283Log, number: int):
    return next(r for r in evaluate_log(log).rows if r.number == number)


def test_reorientation_needs_commanded_orientations_too():
    """A log with measured but no commanded orientations (an Iso9283Log built in Python) was
    passed on as ``None`` commanded frames; clause 8.4 now says the orientations are missing."""
    full = _reorientation_log()
    assert _row(full, 9).measured  # the same log with both orientations is evaluated
    half = dataclasses.replace(full, commanded_rotation=None)
    row = _row(half, 9)
    assert not row.measured
    assert "orientation" in row.summary and "shape" not in row.summary, row.summary


def test_a_per_robot_pose_set_without_n_is_refused_by_name(tmp_path):
    """mypy: ``random_poses(model, spec.n)`` with ``n: int | None``.  A per-robot random pose
    set without ``n`` used to pass the study's checks and fail every robot's row with a
    TypeError (``int() argument ... not 'NoneType'``); it is now refused before any work."""
    from typer.testing import CliRunner

    from robocal.cli import app

    cfg = tmp_path / "study.yaml"
    cfg.write_text(
        "name: t\nrobot: ur5\nrobots: 1\n"
        "pose_sets:\n  - {name: a, per_robot: true}\ndevices:\n  - {name: d}\n"
    )
    out = tmp_path / "o"
    result = CliRunner().invoke(app, ["study", str(cfg), "--out", str(out), "--workers", "0"])
    assert result.exit_code == 2, result.output
    assert "pose_sets[0]" in result.output and "'n'" in result.output, result.output
    assert not (out / "results.csv").exists()


def _cli_options():
    """``(command path, option)`` of every option of every ``robocal`` command (all modules)."""
    import typer

    from robocal.cli.app import COMMANDS, app, module_commands

    group = typer.main.get_group(app)
    commands = {
        name: command for module, _ in COMMANDS.values() for name, command in module_commands(module).items()
    }
    commands |= {name: c for name, c in group.commands.items() if name not in commands}
    stack = list(commands.items())
    while stack:
        path, command = stack.pop()
        stack += [(f"{path} {name}", sub) for name, sub in getattr(command, "commands", {}).items()]
        yield from ((path, p) for p in command.params)


def _choices(param) -> tuple[str, ...] | None:
    descriptor = getattr(param, "type_descriptor", None)
    if descriptor is None or not descriptor.is_choice:
        return None
    return tuple(descriptor.choices)


def test_every_choice_of_the_command_line_is_a_table_of_the_api():
    """One table of allowed choices (issue 32 item 6): an option with fixed choices offers
    exactly one of :mod:`robocal.choices`' tuples, the values of the ``Literal`` the API takes."""
    from typing import get_args, get_type_hints

    from robocal import choices
    from robocal.compensate.compensation import Frame
    from robocal.identify.observability_indices import IndexName
    from robocal.identify.options import RobustLoss
    from robocal.measure.dataset.columns import IncompleteMode
    from robocal.measure.ik_starts import TargetKind
    from robocal.measure.measurements import LimitsMode
    from robocal.model.geometry import Measure
    from robocal.study.config import StudyConfig

    tables = {getattr(choices, name) for name in choices.__all__ if name.isupper()}
    for alias, table in [
        (LimitsMode, choices.LIMITS_MODES),
        (IncompleteMode, choices.INCOMPLETE_MODES),
        (TargetKind, choices.TARGET_KINDS),
        (Frame, choices.FRAMES),
        (IndexName, choices.INDEX_NAMES),
        (Measure, choices.MEASURES),
        (get_type_hints(RobustLoss)["loss"], choices.LOSSES),
        (StudyConfig.model_fields["method"].annotation, choices.SOLVER_METHODS),
        (StudyConfig.model_fields["residual"].annotation, choices.RESIDUAL_CHOICES),
    ]:
        assert get_args(alias) == table  # the API's Literal is the table's
    found = {}
    for path, param in _cli_options():
        offered = _choices(param)
        if offered is not None:
            assert offered in tables, (
                f"robocal {path} {param.opts}: {offered} is not a table of robocal.choices"
            )
            found[(path, param.opts[0])] = offered
    # the options that used to spell their choices by hand are choices of the one table now
    for path, option, table in [
        ("data check", "--limits", choices.LIMITS_MODES),
        ("data check", "--incomplete", choices.INCOMPLETE_MODES),
        ("compensate", "--frame", choices.FRAMES),
        ("compensate", "--kind", choices.TARGET_KINDS),
        ("simulate", "--distribution", choices.DISTRIBUTIONS),
        ("poses", "--index", choices.INDEX_NAMES),
        ("poses", "--method", choices.POSE_METHODS),
        ("calibrate", "--residual", choices.RESIDUAL_CHOICES),
        ("calibrate", "--method", choices.SOLVER_METHODS),
        ("calibrate", "--length-unit", choices.LENGTH_UNIT_NAMES),
        ("calibrate", "--angle-unit", choices.ANGLE_UNIT_NAMES),
        ("data check", "--length-unit", choices.LENGTH_UNIT_NAMES),
        ("compensate", "--length-unit", choices.LENGTH_UNIT_NAMES),
        ("compensate", "--angle-unit", choices.ANGLE_UNIT_NAMES),
        ("calibrate", "--loss", choices.LOSSES),
        ("calibrate", "--bounds", choices.BOUNDS_NAMES),
        ("calibrate", "--chain", choices.CHAIN_CHOICES),
        ("fleet", "--chain", choices.CHAIN_CHOICES),
        ("fleet", "--residual", choices.RESIDUAL_CHOICES),
        ("fleet", "--method", choices.SOLVER_METHODS),
        ("poses", "--rows", choices.POSE_ROWS),
    ]:
        assert found.get((path, option)) == table, (path, option, sorted(found))


def test_a_choice_outside_the_table_is_refused_by_the_option(tmp_path):
    """The command line refuses a value outside the table before any work, naming the option."""
    from typer.testing import CliRunner

    from robocal.cli import app

    out = tmp_path / "p.csv"
    result = CliRunner().invoke(app, ["poses", "ur5", "--n", "6", "--kind", "elbow", "-o", str(out)])
    assert result.exit_code == 2 and "--kind" in result.output, result.output
    assert not out.exists()


def test_start_frames_of_data_without_measurements_are_refused_by_name():
    """mypy: ``data.position[None]`` with ``position: Array | None``.  A poses file (joint
    columns only) given to ``initial_frame_and_tool`` failed deep inside with
    ``'NoneType' object is not subscriptable``; it is a ValueError saying what is missing,
    and so are pose start values from position-only data."""
    import pytest

    from robocal.identify.calibrate import initial_frame_and_tool
    from robocal.measure.measurements import Measurements
    from robocal.model.catalog import robot

    ur5 = robot("ur5")
    q = np.random.default_rng(1).uniform(-1.0, 1.0, (12, 6))
    positions = Measurements(q=q, position=ur5.fk(q)[:, :3, 3])
    frame, _ = initial_frame_and_tool(ur5, positions, "position", None, True, False)
    assert frame.shape == (4, 4) and np.allclose(frame, np.eye(4), atol=1e-9)  # the data is in the base
    with pytest.raises(ValueError, match="position"):
        initial_frame_and_tool(ur5, Measurements(q=q), "position", None, True, False)
    with pytest.raises(ValueError, match="pose"):
        initial_frame_and_tool(ur5, positions, "pose", None, True, False)


def test_iso_poses_carry_their_cube_and_constraint():
    """mypy: ``IsoPoses.cube`` and ``.orientation`` were optional although
    :func:`iso9283_poses` always sets them (callers ignored the type or checked None); they
    are required now, with the constraint's ``kind`` as a field (was read from ``info``)."""
    import pytest

    from robocal.measure.poses import IsoPoses

    with pytest.raises(TypeError):  # a set without its cube cannot be built
        IsoPoses(
            q=np.zeros((5, 6)), positions=np.zeros((5, 3)), labels=("P1",) * 5, reachable=np.ones(5, bool)
        )


def test_unit_and_solver_tables_are_the_apis():
    """The unit names offered are the units robocal converts; the solver and residual
    choices are the ones :func:`robocal.calibrate` takes."""
    from typing import get_args

    from robocal import choices, units
    from robocal.identify.calibrate import RESIDUAL_CHOICES, Method, ResidualChoice
    from robocal.identify.solvers import METHODS

    assert set(choices.LENGTH_UNIT_NAMES) == set(units.LENGTH_UNITS)
    assert set(choices.ANGLE_UNIT_NAMES) <= set(units.ANGLE_UNITS)
    assert get_args(Method) == choices.SOLVER_METHODS and set(METHODS) == set(choices.SOLVER_METHODS)
    assert get_args(ResidualChoice) == RESIDUAL_CHOICES == choices.RESIDUAL_CHOICES


def test_a_unit_outside_the_table_is_refused_before_reading(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli import app

    data = tmp_path / "d.csv"
    data.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "0,0,0,0,0,0,0.1,0.2,0.3\n" * 3)
    out = tmp_path / "out"
    result = CliRunner().invoke(
        app, ["calibrate", "ur5", "--data", str(data), "--length-unit", "cm", "-o", str(out)]
    )
    assert result.exit_code == 2 and "--length-unit" in result.output, result.output
    assert not out.exists()


def _reader_file(tmp_path):
    path = tmp_path / "m.csv"
    rows = ["q1;q2;q3;q4;q5;q6;x;y;z"]
    rows += [f"{k};10;20;30;40;50;{100 + k},5;200;300" for k in range(6)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_reader_options_as_one_value_read_as_the_keywords(tmp_path):
    """``read_measurements(path, options=ReaderOptions(...))`` (what the CLI and the workflow
    pass) reads as the same keywords do; both at once is refused rather than one ignored."""
    import pytest

    import robocal as rc
    from robocal.measure.dataset.options import ReaderOptions
    from robocal.workflow import ReaderOptions as WorkflowReaderOptions

    assert WorkflowReaderOptions is ReaderOptions  # one type for the CLI, GUI and workflow
    path = _reader_file(tmp_path)
    keywords = {"length_unit": "mm", "angle_unit": "deg", "sep": ";", "decimal": ","}
    by_keywords = rc.read_measurements(path, **keywords)
    by_value = rc.read_measurements(path, options=ReaderOptions(**keywords))
    np.testing.assert_array_equal(by_value.q, by_keywords.q)
    np.testing.assert_array_equal(by_value.position, by_keywords.position)
    assert by_value.position[0, 0] == pytest.approx(0.1005)  # mm and the decimal comma applied
    with pytest.raises(TypeError, match="length_unit"):
        rc.read_measurements(path, options=ReaderOptions(**keywords), length_unit="um")
    with pytest.raises(TypeError):
        rc.read_measurements(path, options={"length_unit": "mm"})  # a dict is not the options
    options = ReaderOptions(extra=["x"])  # a list from a GUI or JSON
    assert options.extra == ("x",) and hash(options)
