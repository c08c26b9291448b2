"""``python -m jwarp.cli ...`` runs the command line."""

import sys

from jwarp.cli.main import main

sys.exit(main())
