"""``python -m footnav.app`` runs the ``footnav`` command line."""

from footnav.app.cli import run

run()
