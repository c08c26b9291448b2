"""``python -m jwarp``: the command line interface."""

import sys

from jwarp.cli import main

sys.exit(main())
