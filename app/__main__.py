"""``python -m footnav.app`` runs the ``footnav`` command line."""

import sys

from footnav.app.cli import main

sys.exit(main())
