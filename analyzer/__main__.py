"""``python -m analyzer``: the eg2scope command line."""

import sys

from .cli import main

sys.exit(main())
