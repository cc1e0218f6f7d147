"""The pair product (``soilvolume estimate BEFORE AFTER``, and ``register``): the method's steps
over two surveys, the first the reference, on any backend."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..core.record import RunRecord
from ..dem.grid import output_layers
from ..execution.seam import Backend
from . import steps
from .context import Context

#: the steps of a pair, in order (the progress table's)
PAIR = ("prepare", "register", "grid", "planes", "volume", "write", "report")
REGISTER = ("prepare", "register", "write")


def estimate(ctx: Context, backend: Backend, cloud: Path | None = None) -> tuple[dict, dict]:
    """Read, register, grid, planes, volume, write, report; ``cloud``: where the registered
    after cloud goes (``--registered-cloud``), else None."""
    with backend.session(ctx):
        prep = steps.read(ctx, backend)
        reg, options = steps.register(ctx, prep, backend.dense(prep))
        ctx = replace(ctx, options=options)
        if cloud is not None:
            backend.keep_cloud(prep, reg, cloud)
        gridded = steps.grid(ctx, backend, prep, reg)
        fitted = steps.planes(ctx, gridded)
        vols = steps.volume(ctx, backend, gridded, fitted, reg)
        extras = steps.write(ctx, backend, vols, gridded.grid, output_layers(ctx.options.correction))
        judged = steps.judged(vols, gridded.correction_grid, ctx.options)
        parts = (prep, reg, gridded.grid, fitted[:2], vols, ctx.options, judged, backend.engine())
        return steps.report(ctx, RunRecord(*parts), gridded, extras)


def register(ctx: Context, backend: Backend, cloud: Path) -> tuple:
    """Read, register and write the after cloud moved onto the before one: (Prepared, Registration)."""
    with backend.session(ctx):
        prep = steps.read(ctx, backend)
        reg, _ = steps.register(ctx, prep, backend.dense(prep))
        backend.keep_cloud(prep, reg, cloud)
        steps.write(ctx, backend, None, None, [])
        return prep, reg
