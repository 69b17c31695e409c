"""``python -m coassist.cli``: the ``coassist`` command."""

from coassist.cli import app

app()
