"""Start-up of the ``robocal`` command: importing the CLI, ``--help``, ``robots`` and ``fk`` load
none of the heavy libraries (each command imports what it uses; ``--help`` not even numpy or a
command's module). Run in a fresh interpreter, since this test session has long imported them
all. Timings stay out of the tests: benchmarks/bench_startup.py measures them."""

import json
import subprocess
import sys

import pytest
import typer

HEAVY = (
    "scipy.stats",
    "scipy.optimize",
    "scipy.spatial",
    "pinocchio",
    "plotly",
    "dask",
    "distributed",
    "sklearn",
    "numba",
)

_PROBE = """
import contextlib, io, json, sys
from robocal.cli import app
with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):
    app(sys.argv[1:], standalone_mode=True)
print(json.dumps(sorted(m for m in sys.modules if m in {heavy} or m.startswith("robocal.cli."))))
"""


def _loaded(argv: list[str]) -> set[str]:
    """The heavy libraries and robocal.cli modules loaded by ``robocal argv`` in a fresh process."""
    probe = _PROBE.format(heavy=repr(HEAVY))
    out = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize(
    ("argv", "command_modules"),
    [
        (["--help"], set()),
        (["robots"], {"robocal.cli.robots"}),
        (["fk", "ur10", "--q", "0,-90,90,0,90,0", "--deg"], {"robocal.cli.robots"}),
        (["simulate", "--help"], {"robocal.cli.measure"}),
        (["validate", "--help"], {"robocal.cli.validate"}),
    ],
    ids=["help", "robots", "fk", "simulate-help", "validate-help"],
)
def test_the_command_line_starts_without_heavy_libraries(argv, command_modules):
    from robocal.cli.app import COMMANDS

    loaded = _loaded(argv)
    assert loaded & set(HEAVY) == set()
    registering = {f"robocal.cli.{module}" for module, _ in COMMANDS.values()}
    assert loaded & registering == command_modules  # only the module of the command that runs


def test_help_lists_the_commands_without_numpy():
    probe = (
        "import contextlib, io, sys\n"
        "from robocal.cli import app\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    app(['--help'])\n"
        "print(sorted(m for m in ('numpy', 'yaml', 'pydantic') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["[]"]


def test_the_help_summaries_are_the_commands_own():
    """``robocal --help`` lists COMMANDS' summaries without importing the commands: every
    command the modules register is listed, by its module, and its summary is the start of its
    own help (up to the summary's final full stop)."""
    from robocal.cli.app import COMMANDS, module_commands

    registered = {}
    for module in {module for module, _ in COMMANDS.values()}:
        for name, command in module_commands(module).items():
            registered[name] = (module, " ".join((command.help or "").split()))
    assert registered.keys() == COMMANDS.keys()
    for name, (module, summary) in COMMANDS.items():
        assert registered[name][0] == module
        assert registered[name][1].startswith(summary.rstrip(".")), name


def test_the_lazy_group_resolves_every_command_and_refuses_others():
    from typer.testing import CliRunner

    from robocal.cli import app
    from robocal.cli.app import COMMANDS

    group = typer.main.get_command(app)
    assert list(group.commands) == list(COMMANDS)  # the names, without importing a module
    assert all(group.commands[name].name == name for name in COMMANDS)
    result = CliRunner().invoke(app, ["calibrat"])
    assert result.exit_code == 2
    assert "calibrate" in result.output  # the close match suggested


def test_lazy_exports_keep_the_functions_named_like_modules():
    probe = (
        "import robocal.identify.calibrate, robocal.measure.simulate, robocal.cli.compensate\n"
        "import robocal as rc, types\n"
        "from robocal.identify import calibrate, validate\n"
        "from robocal.measure import simulate\n"
        "functions = (calibrate, validate, simulate, rc.compensate_targets, rc.calibrate)\n"
        "print(all(callable(f) for f in functions))\n"
        "package = rc.compensate\n"
        "print(isinstance(package, types.ModuleType) and package.__name__ == 'robocal.compensate')\n"
        "print(sorted(set(rc.__all__) - set(dir(rc))))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "True", "[]"]  # rc.compensate: the subpackage, not a function


def test_the_calibration_clock_stops_while_numba_compiles(monkeypatch):
    """A calibration's ``seconds`` (result.json, the report's calibration time) come from
    work_clock: a compilation between two readings is not counted, and first_use reports it
    apart."""
    import io
    import time

    import numba
    from rich.console import Console

    from robocal.identify import pipeline
    from robocal.identify.kernel_cache import compile_seconds, first_use, work_clock

    assert pipeline.work_clock is work_clock  # the clock the calibration times itself with
    out = io.StringIO()
    compiled_before = compile_seconds()
    with first_use(Console(file=out, width=200), min_seconds=0.0):
        square = numba.njit(lambda x: x * x + 1.0)  # a new function: compiled here, not cached
        assert square(3.0) == 10.0
    compiling = compile_seconds() - compiled_before
    assert compiling > 0.0
    # the work clock is the wall clock less every compilation so far (a fixed wall clock: the
    # relation is checked exactly, not against a machine's speed)
    monkeypatch.setattr(time, "perf_counter", lambda: 1000.0)
    assert work_clock() == 1000.0 - compile_seconds() <= 1000.0 - compiling
    monkeypatch.undo()
    assert "compiling robocal's kernels took" in out.getvalue()


def test_validate_and_report_of_a_folder_load_no_fitting_or_statistics_library(tmp_path):
    """Reading a calibration folder fits nothing: ``validate`` loads neither scipy.optimize (the
    solvers) nor scipy.stats (Student's t comes from scipy.special); ``report`` no scipy.stats
    (the learned residual's module still imports scipy.optimize at its top)."""
    from robocal.demo import run_demo

    folder = tmp_path / "calibration"
    run_demo(out=folder, quick=True, verbose=False)
    unused = {"scipy.optimize", "scipy.stats", "pinocchio", "dask", "distributed", "sklearn"}
    validate = _loaded(["validate", str(folder)])
    report = _loaded(["report", str(folder), "--out", str(tmp_path / "report.html")])
    assert validate & unused == set()
    assert report & (unused - {"scipy.optimize"}) == set()
    assert (tmp_path / "report.html").stat().st_size > 0  # the probe ran the command through
