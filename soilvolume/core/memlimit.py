"""A process under an address-space limit (``ulimit -v``) fails in one line naming it. OpenBLAS's
``blas_memory_alloc`` retries a failed 128 MiB buffer for ever (a series at 600 MB spun at its two
planes): :mod:`.watchdog` ends such a spin with :func:`out_of_memory`."""

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


def out_of_memory(keyed: bool = False) -> str:
    """The out-of-memory line, naming the limit (``keyed``: its option as a marker, else as a flag)."""
    limit = address_limit()
    under = f" under the address-space limit of {limit / 1e6:,.0f} MB (ulimit -v)" if limit else ""
    said = f"out of memory{under}: use a larger {wording.opt('cell')} or crop the clouds first"
    return said if keyed else wording.cli(said)


def short_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` is a MemoryError or a library that could not be mapped under a limit."""
    if isinstance(exc, MemoryError):
        return True
    text = str(exc).lower()
    return isinstance(exc, ImportError) and ("failed to map segment" in text or "cannot allocate memory" in text)
