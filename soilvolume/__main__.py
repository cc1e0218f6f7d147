"""``python -m soilvolume`` and the ``soilvolume`` command: a signal while still importing ends it in one
line, the process is settled (:mod:`soilvolume.process`), the command line run, the process left."""

import os
import signal
import sys

from . import process


def _early(signum: int, _frame) -> None:
    """A signal while the program is still importing: nothing was written yet; leave at once."""
    name = "SIGINT" if signum == signal.SIGINT else "SIGTERM"
    sys.stderr.write(f"soilvolume: error: interrupted by {name}; nothing was written\n")
    os._exit(128 + signum)


for _sig in (signal.SIGINT, signal.SIGTERM):  # main() installs the run's own handlers
    signal.signal(_sig, _early)
process.one_blas_thread()
process.hide_extras()

from .cli import main  # noqa: E402 - after the handlers and the settings: it loads numpy
from .native import OFF_THE_GIL  # noqa: E402


def run() -> int:
    """Run the command line and leave with its exit status."""
    process.import_ahead(sys.argv[1:], OFF_THE_GIL)
    return process.leave(main())


if __name__ == "__main__":
    sys.exit(run())
