"""``python -m app`` runs the ``footnav`` command line."""

import sys

from app.cli import main

sys.exit(main())
