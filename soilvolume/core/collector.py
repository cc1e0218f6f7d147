"""Left for one merge (issue 52): the command no longer pauses Python's garbage collector (it
gained under 5 % of the wall time, ``bench/README.md``), so :func:`resume` has nothing to do.
Delete this module with its last callers, ``workflow/run.drive`` and ``distributed/executor``."""


def resume() -> None:
    """Nothing: the collector is never paused."""
