"""The seeds' experiments, reproduced: ``robocal reproduce seed000 | seed001 | seed003``.

Each experiment is a module ``robocal.experiments.<name>`` with a function

    run(out: Path | None = None, quick: bool = False, verbose: bool = True) -> dict

that runs the experiment, writes its report (and files) to ``out`` when given, prints
the seed's published numbers next to robocal's, and returns its numbers as plain data
(the ``--json`` output).

``robocal reproduce all --md docs/reproductions --readme README.md --force`` runs them all
and writes the comparison documents and the README's quoted numbers
(:mod:`robocal.experiments.reproductions`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["EXPERIMENTS", "get"]

#: experiment name -> (module, one-line description)
EXPERIMENTS: dict[str, tuple[str, str]] = {
    "seed000": ("robocal.experiments.seed000", "model construction for PUMA 560 / IRB 2400"),
    "seed001": ("robocal.experiments.seed001", "calibration-table workflow of the 3-DOF arm"),
    "seed003": ("robocal.experiments.seed003", "Katana 450 tables and trajectory with joint tilting"),
}


def get(name: str) -> Callable[..., dict[str, Any]]:
    """The ``run`` function of experiment ``name``."""
    if name not in EXPERIMENTS:
        raise KeyError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    module_name, _ = EXPERIMENTS[name]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name == module_name:
            raise NotImplementedError(f"experiment {name!r} is not available yet") from None
        raise
    return module.run
