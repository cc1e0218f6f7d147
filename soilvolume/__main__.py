"""``python -m soilvolume`` and the ``soilvolume`` console command: a signal that arrives while
the program is still importing ends it with one line, like one during a run."""

import os
import signal
import sys


def _early(signum: int, _frame) -> None:
    """A signal while the program is still importing: nothing was written yet; leave at once."""
    name = "SIGINT" if signum == signal.SIGINT else "SIGTERM"
    sys.stderr.write(f"soilvolume: error: interrupted by {name}; nothing was written\n")
    os._exit(128 + signum)


def run() -> int:
    """Install the early handlers, import the command line (it takes a moment), run it;
    ``main`` installs the run's own handlers."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _early)
    from .cli import main

    return leave(main())


def leave(code: int) -> int:
    """End the process with ``code`` once the command returned, without the interpreter's teardown
    (0.4-0.6 s of freeing numpy, pyproj, rasterio and Open3D, which report.json's ``timings_s``
    cannot count): by then every output is written and closed, every pool and cluster shut."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said
            pass
    os._exit(code if isinstance(code, int) else 1)


if __name__ == "__main__":
    sys.exit(run())
