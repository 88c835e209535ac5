"""Start-up of the ``robocal`` command: importing the CLI, ``--help`` and ``fk`` load none of the
heavy libraries (each command imports what it uses). Run in a fresh interpreter, since this
test session has long imported them all."""

import json
import subprocess
import sys

import pytest

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
print(json.dumps(sorted(m for m in {heavy} if m in sys.modules)))
"""


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["fk", "ur10", "--q", "0,-90,90,0,90,0", "--deg"], ["simulate", "--help"]],
    ids=["help", "fk", "simulate-help"],
)
def test_the_command_line_starts_without_heavy_libraries(argv):
    probe = _PROBE.format(heavy=repr(HEAVY))
    out = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


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
