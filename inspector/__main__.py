"""``python -m inspector``: the ``routefuse`` command."""

from inspector.cli.main import console

console()
