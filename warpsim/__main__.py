"""``python -m warpsim``: the ``warpsim`` command line."""

from .apps.cli import console

console()
