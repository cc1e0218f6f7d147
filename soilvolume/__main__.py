import os
import signal
import sys


def _early(signum: int, _frame) -> None:
    """A signal while the program is still importing: nothing was written yet; leave at once."""
    name = "SIGINT" if signum == signal.SIGINT else "SIGTERM"
    sys.stderr.write(f"soilvolume: error: interrupted by {name}; nothing was written\n")
    os._exit(128 + signum)


for _sig in (signal.SIGINT, signal.SIGTERM):  # main() installs the run's own handlers
    signal.signal(_sig, _early)

from .cli import main  # noqa: E402 - after the handlers: imports take a moment

sys.exit(main())
