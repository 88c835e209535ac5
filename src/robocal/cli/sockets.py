"""``robocal data sockets``: ball-in-socket recordings as they come -> a constraint CSV.

    robocal data sockets PLACEMENT/ -o front.csv
    robocal data sockets hole_0.csv hole_1.csv -o front.csv [--deg] [--force]

Each PATH is a headerless joint-angle file (the files in the order given are points 0, 1, …)
or a folder (its ``hole_<k>.csv`` by ``k``; ``*_pose.csv`` ignored):
:mod:`robocal.measure.constraints.sockets_import`.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Annotated

import typer

from robocal.cli.options import Force, out_option
from robocal.console import console, fail, refuse_overwrite, safe

__all__ = ["data_sockets"]


def data_sockets(
    paths: Annotated[
        list[Path],
        typer.Argument(
            metavar="PATH...",
            help="headerless joint-angle CSV per socket (points 0, 1, … in this order), or a "
            "placement folder: its hole_<k>.csv files (hole_<k>_pose.csv ignored)",
        ),
    ],
    out: Annotated[Path, out_option("constraint CSV to write (q1..qN, point)")],
    deg: Annotated[
        bool, typer.Option("--deg", help="the recorded angles are in degrees (default rad)")
    ] = False,
    force: Force = False,
) -> None:
    """Turn ball-in-socket recordings (MUKCa's layout) into a constraint CSV for calibrate."""
    from robocal.measure.constraints.data import ConstraintFileError, write_constraints
    from robocal.measure.constraints.sockets_import import read_socket_recordings

    refuse_overwrite(out, force)
    if out.is_dir():
        raise fail(f"-o {out}: a folder; give a file name")
    try:
        recording = read_socket_recordings(paths, angle_unit="deg" if deg else "rad")
    except ConstraintFileError as err:
        raise fail(str(err)) from None
    if any(out.resolve() == source.resolve() for source in recording.sources):
        raise fail(f"-o {out}: is one of the recordings read; write elsewhere")
    try:
        write_constraints(recording.data, out)
    except OSError as err:
        raise fail(f"-o {out}: cannot be written ({err.strerror or err})") from None
    _print_summary(recording, out)


def _print_summary(recording, out: Path) -> None:
    dof = recording.data.q.shape[1]
    for k, (source, rows) in enumerate(zip(recording.sources, recording.rows_per_point, strict=True)):
        # soft_wrap: a long path stays on one line (copyable), not broken at the console width
        console.print(
            f"point {k}: {rows} configurations from {safe(source)}", highlight=False, soft_wrap=True
        )
    console.print(f"wrote {safe(out)} ({recording.data.n} rows, {dof} joints, columns q1..q{dof}, point)",
                  highlight=False, soft_wrap=True)  # fmt: skip
    console.print(
        "next: robocal calibrate MODEL --data " + safe(shlex.quote(str(out))) + " --distance 0,1=50mm\n"
        "  (the distance between the sockets is your tool's: measure it and state it;"
        " 50 mm is MUKCa's plate)",
        highlight=False,
        soft_wrap=True,
    )
