"""The ``robocal`` command (Typer + Rich), one module per step of a calibration.

Modules: :mod:`~robocal.cli.app` (the app, ``--version``, the registration of the others),
:mod:`~robocal.cli.options` (every shared option, defined once), :mod:`~robocal.cli.errors`
(no traceback reaches the user), and one module per command group: ``robots`` (robots, fk),
``model``, ``measure`` (data check, simulate), ``poses``, ``calibrate`` (calibrate, validate),
``experiments`` (reproduce), ``compensate``, ``export``, ``report``, ``iso9283``, ``study``
(study, fleet), ``gui``.

Start-up: ``robocal --help`` lists the commands from :data:`robocal.cli.app.COMMANDS` without
importing a command module; a command's module is imported when the command runs, and it
imports at the top only typer, rich and the modules of :mod:`robocal.cli`, each command the
rest when it runs (tests/test_startup.py checks the modules ``--help``, ``robots``, ``fk``,
``validate`` and ``report`` load).
"""

from robocal.cli.app import app, main

__all__ = ["app", "main"]
