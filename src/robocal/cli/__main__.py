"""``python -m robocal.cli``: the ``robocal`` command."""

from robocal.cli.app import main

main()
