"""Python's cyclic garbage collector paused while the command loads its modules.

A run imports ~800 modules (numpy, SciPy, pyproj, laspy, rasterio and the engine's own); their
objects are long-lived and make no garbage cycles, yet the collector walks them again and again
as they are created: ~30 ms of start-up on the paper-sized pair, one full pass over every module
object among them. The command line pauses the collector before its imports (:func:`pause`) and
the run resumes it once its inputs are read (:func:`resume`), with everything loaded so far frozen
(``gc.freeze``: never walked again), or after its first step at the latest; a tiled run's driver
also once its cluster is up (an event loop makes cycles), and a local cluster's forkserver once it
has imported what its workers run (``distributed.forkpause`` and ``forkready``). A program that
imports the engine keeps its own collector as it is.
"""

from __future__ import annotations

import gc

_paused = False


def pause() -> None:
    """Pause the collector (once, when it is enabled), for :func:`resume` to restart."""
    global _paused
    if gc.isenabled():
        gc.disable()
        _paused = True


def resume() -> None:
    """Restart the collector if :func:`pause` stopped it, the objects so far frozen; else nothing."""
    global _paused
    if _paused:
        _paused = False
        gc.freeze()
        gc.enable()
