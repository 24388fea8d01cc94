"""``python -m vasim ...`` runs the ``vasim`` command."""

import sys

from vasim.cli import main

sys.exit(main())
