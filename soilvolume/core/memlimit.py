"""A process under an address-space limit (``ulimit -v``, RLIMIT_AS) fails in one line naming it.

OpenBLAS takes a work buffer (128 MiB of address space) for each thread that runs a matrix
product at the same time as another, and when that allocation fails it retries for ever in C
(its ``blas_memory_alloc`` loops until one succeeds): a series under a 600 MB limit spun at the
bias correction, its two planes on two threads. :mod:`.watchdog` sees such a spin and ends the
run with :func:`out_of_memory`."""

from __future__ import annotations

import resource

from . import wording

#: the address space OpenBLAS's buffer takes (its 128 MiB and glibc's arena around it), with margin
BLAS_BUFFER = 192 << 20


def address_limit() -> int | None:
    """The process's address-space limit in bytes (RLIMIT_AS's soft limit), None when unlimited."""
    try:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY else int(soft)


def limit_words() -> str:
    """How the out-of-memory line names the limit: `` under the address-space limit of N MB (ulimit
    -v)``, or nothing when there is none."""
    limit = address_limit()
    return f" under the address-space limit of {limit / 1e6:,.0f} MB (ulimit -v)" if limit else ""


def out_of_memory(keyed: bool = False) -> str:
    """The line of a run that ran out of memory, naming the limit when there is one (``keyed``: its
    option by key, :mod:`.wording`, else in the command line's words)."""
    said = f"out of memory{limit_words()}: use a larger {wording.opt('cell')} or crop the clouds first"
    return said if keyed else wording.cli(said)


def short_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` says the process ran out of memory: a MemoryError, or a library that could
    not be mapped (``failed to map segment``, ``cannot allocate memory``) under a limit."""
    if isinstance(exc, MemoryError):
        return True
    text = str(exc).lower()
    return isinstance(exc, ImportError) and ("failed to map segment" in text or "cannot allocate memory" in text)
