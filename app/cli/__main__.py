"""`python -m wideprint.app.cli ...`: the `wideprint` command."""

import sys

from . import main

sys.exit(main())
