"""``python -m soilvolume.cli``: the command line without the console entry's start-up."""

import sys

from .app import main

sys.exit(main())
