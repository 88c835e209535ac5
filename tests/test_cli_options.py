"""Every command of ``robocal`` spells the same thing the same way (robocal.cli.options).

The test walks the whole Typer/Click command tree and fails on a second spelling of one
concept (``--output`` beside ``--out``, a ``--robot`` option beside the ROBOT argument,
``--unit`` beside ``--length-unit``), an option without help or metavar, a flag showing a
type, or one parameter name reached through different option names in different commands.
"""

from __future__ import annotations

from collections import defaultdict

import pytest
import typer
from typer.testing import CliRunner

from robocal.cli import app

#: spellings that are not robocal's: the concept, and the one spelling robocal uses for it
FORBIDDEN = {
    "--output": "-o/--out",
    "--robot": "the ROBOT argument",
    "--model": "the ROBOT argument",
    "--unit": "--length-unit / --angle-unit",
    "--units": "--length-unit / --angle-unit",
    "--html": "-o/--out",
    "--calibration": "the CALIBRATION argument",
    "--verbose": "(none)",
}


def _commands(command=None, path=()):
    """(path, click command) of every leaf command of the app."""
    command = command or typer.main.get_command(app)
    subcommands = getattr(command, "commands", None)
    if subcommands:
        for name, sub in subcommands.items():
            yield from _commands(sub, (*path, name))
    else:
        yield " ".join(path), command


def _argument_problems(where: str, p) -> list[str]:
    problems = []
    if not p.metavar:
        problems.append(f"{where}: an argument without a metavar")
    if not p.help:
        problems.append(f"{where}: an argument without help")
    if p.name == "robot" and p.metavar != "ROBOT":
        problems.append(f"{where}: the robot argument is spelled {p.metavar}, not ROBOT")
    return problems


def _option_problems(where: str, p, names: list[str]) -> list[str]:
    problems = [f"{where}: {n} (robocal spells it {FORBIDDEN[n]})" for n in names if n in FORBIDDEN]
    if not p.help:
        problems.append(f"{where}: {'/'.join(names)} has no help")
    if p.is_flag and p.metavar not in (None, ""):
        problems.append(f"{where}: the flag {names[-1]} shows a metavar")
    if not p.is_flag and not p.metavar:
        problems.append(f"{where}: {names[-1]} has no metavar saying what it takes")
    if p.name == "out" and sorted(p.opts) != ["--out", "-o"]:
        problems.append(f"{where}: an output is -o/--out, not {'/'.join(p.opts)}")
    if "-o" in p.opts and p.name != "out":
        problems.append(f"{where}: -o is the output, not {p.name}")
    if p.name == "robot":
        problems.append(f"{where}: the robot is the ROBOT argument, not an option")
    return problems


def _problems(commands) -> list[str]:
    problems: list[str] = []
    long_names: dict[str, set[str]] = defaultdict(set)
    for path, command in commands:
        for p in command.params:
            where = f"robocal {path}: {p.name}"
            if p.param_type_name == "argument":
                problems += _argument_problems(where, p)
                continue
            names = [*p.opts, *p.secondary_opts]
            problems += _option_problems(where, p, names)
            long_names[p.name].add("/".join(sorted(n for n in names if n.startswith("--"))))
    for dest, spellings in long_names.items():
        if len(spellings) > 1:
            problems.append(f"{dest}: spelled {' and '.join(sorted(spellings))} in different commands")
    return problems


def test_every_command_spells_every_option_one_way():
    commands = list(_commands())
    assert len(commands) >= 20  # the walk reaches the subcommands (robots show, model build ...)
    assert _problems(commands) == []


def test_the_walk_catches_a_second_spelling():
    """A command with ``--output`` (or a flag without help) makes the test above fail."""
    extra = typer.Typer()

    @extra.command("one")
    def one(out: str = typer.Option(..., "-o", "--out", metavar="FILE", help="x")) -> None: ...

    @extra.command("two")
    def two(
        out: str = typer.Option(..., "--output", metavar="FILE", help="x"),
        quiet: bool = typer.Option(False, "--quiet"),
    ) -> None: ...

    problems = _problems(_commands(typer.main.get_command(extra)))
    text = "\n".join(problems)
    assert "--output (robocal spells it -o/--out)" in text
    assert "--quiet has no help" in text
    assert "out: spelled --out and --output in different commands" in text


@pytest.mark.parametrize(
    "argv", [["-h"], ["calibrate", "-h"], ["model", "build", "-h"], ["robots", "show", "-h"]]
)
def test_h_is_help_everywhere(argv):
    result = CliRunner().invoke(app, argv)
    assert result.exit_code == 0 and "Usage:" in result.output
    assert "<bool>" not in result.output  # flags show no type


def test_version():
    from robocal import __version__

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"robocal {__version__}"


def test_reader_errors_name_the_option(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,2,3\n")
    result = CliRunner().invoke(app, ["data", "check", str(path), "--length-unit", "furlong"])
    assert result.exit_code == 2
    assert "--length-unit" in result.output and "length_unit" not in result.output
