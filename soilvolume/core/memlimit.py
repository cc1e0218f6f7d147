"""A process under an address-space limit (``ulimit -v``, RLIMIT_AS) fails in one line naming it,
never spins.

OpenBLAS takes its work buffer (128 MiB of address space) at the first matrix product large
enough to need it, and when that allocation fails it retries for ever in C (its
``blas_memory_alloc`` loops until an allocation succeeds): a series under a 600 MB limit spun at
the bias correction for minutes, deaf to signals. The buffer, once taken, is kept and reused by
every later product, so a process under such a limit takes it first (:func:`reserve_blas_buffer`),
while the address space is still free; a limit too small for it is refused at once."""

from __future__ import annotations

import mmap
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


def reserve_blas_buffer() -> None:
    """Under an address-space limit: one matrix product large enough for OpenBLAS to take its work
    buffer now (kept for the process's life), so no later product can find the limit reached and
    spin (see module); without a limit, nothing. MemoryError when the limit leaves no room for it."""
    if address_limit() is None:
        return
    try:  # room for the buffer, else the product itself would spin
        mmap.mmap(-1, BLAS_BUFFER).close()
    except OSError:
        raise MemoryError from None
    import numpy as np

    a = np.ones((256, 256))
    if not np.isfinite(float((a @ a)[0, 0])):  # the product is what takes the buffer
        raise MemoryError
