"""The in-memory backend: whole clouds in this process, a second thread for the work beside (the
before epoch's heights and what the step runs on them, the registered cloud's writing)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from functools import partial
from pathlib import Path

from ..core.outputs import os_errors
from ..core.types import GridSpec
from ..dem import grid as gridmod
from ..dem.geotiff import write_grid
from ..inputs.io import write_las_chunked
from ..inputs.prepare import Prepared, prepare
from ..pipelines.pipeline import open_source
from ..registration.rigid import transform_points32
from .seam import Gridded, VolumeFn


class InMemory:
    """Whole clouds in memory; numpy's sorts and LAZ compression release the GIL, so a second
    thread does the before epoch's heights and writes the registered cloud meanwhile."""

    reading_note = " (cropping and thinning on the way)"
    raster_note = ""

    def __init__(self) -> None:
        self.pool: ThreadPoolExecutor | None = None
        self.cloud: Future | None = None
        self.cloud_path: Path | None = None

    @contextmanager
    def session(self, ctx) -> Iterator[InMemory]:
        with ThreadPoolExecutor(2) as self.pool:
            yield self

    def read(self, ctx) -> Prepared:
        """Both clouds streamed whole (:func:`inputs.prepare.prepare`)."""
        b, a = ctx.epochs
        check = ctx.hooks.ticker(*ctx.spans["prepare"], "reading")
        prep = prepare(open_source(b.path, b.pipeline), open_source(a.path, a.pipeline), ctx.options, check=check)
        ctx.timer.s["read"] = ctx.timer.s.get("read", 0.0) + prep.read_s  # the rest: frame, crop, thinning
        ctx.timer.s["crop"] = ctx.timer.s.get("crop", 0.0) - prep.read_s
        ctx.hooks.info(
            f"kept {len(prep.before):,} before points within {ctx.options.radius:g} m of the after "
            f"footprint and {len(prep.after):,} after points; registration subsets "
            f"{len(prep.before_thin):,} + {len(prep.after_thin):,} ({prep.voxel:.2f} m columns)"
        )
        return prep

    def dense(self, prep: Prepared) -> tuple:
        """The full-resolution points the fine registration's stable-ground refinement grids."""
        return prep.after.xyz, prep.before.xyz

    def grid(self, ctx, prep: Prepared, reg, grid: GridSpec, beside: Callable) -> Gridded:
        """The after epoch's heights here (moved block by block: no registered copy), the before
        epoch's on a second thread, then ``beside`` on them."""
        statistic = ctx.options.statistic
        heights = self.pool.submit(gridmod.epoch_dem, prep.before.xyz, grid, statistic, prep.before.nonsoil)
        later = self.pool.submit(lambda: beside(grid, heights.result()))
        move = partial(transform_points32, t=reg.transform)
        nonsoil = None if prep.after.nonsoil is None else prep.after.nonsoil.moved(reg.transform)
        dem_a = gridmod.epoch_dem(prep.after.xyz, grid, statistic, nonsoil, move)
        dems = (dem_a, heights.result())
        return Gridded(grid, dems, grid, dems, later)

    def volume(self, ctx, step: VolumeFn, gridded: Gridded, planes: tuple, moved) -> object:
        """``step`` on the whole grid."""
        return step(*gridded.dems, planes[2], gridded.grid)

    def write(self, ctx, layers: list, vols, grid, z0: float) -> None:
        """Each layer as one GeoTIFF (:func:`dem.geotiff.write_grid`); the registered cloud finished."""
        for name, key, desc in layers:
            array = getattr(vols, key)
            if key in gridmod.UINT8_LAYERS:
                write_grid(ctx.out.path(name), array.astype("uint8"), grid, desc, "", "uint8")
            else:
                write_grid(ctx.out.path(name), array + z0 if key.startswith("dem_") else array, grid, desc)
        if self.cloud is not None:
            with os_errors(self.cloud_path):
                self.cloud.result()

    def keep_cloud(self, prep: Prepared, reg, path: Path) -> None:
        """Start writing the after cloud (every point, all classes) moved by ``reg``, on the second thread."""
        if self.cloud is None:
            args = (path, prep.after_chunks(), prep.origin, prep.frame.wkt, reg.transform)
            self.cloud, self.cloud_path = self.pool.submit(write_las_chunked, *args), path

    def engine(self) -> None:
        return None
