"""The ``robocal`` command (Typer + Rich), one module per step of a calibration.

Modules: :mod:`~robocal.cli.app` (the app, ``--version``, the registration of the others),
:mod:`~robocal.cli.options` (every shared option, defined once), :mod:`~robocal.cli.errors`
(no traceback reaches the user), and one module per command group: ``robots`` (robots, fk),
``model``, ``measure`` (data check, simulate), ``poses``, ``calibrate`` (calibrate, validate),
``experiments`` (reproduce), ``compensate``, ``export``, ``report``, ``iso9283``, ``study``
(study, fleet), ``gui``.

Start-up: these modules import only typer and rich at the top; each command imports what it
uses (tests/test_startup.py checks that ``robocal --help`` loads none of scipy.stats,
Pinocchio, plotly, Dask, scikit-learn).
"""

from robocal.cli.app import app, main

__all__ = ["app", "main"]
