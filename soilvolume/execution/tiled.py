"""The tiled backend: the point work as Dask tasks of :mod:`soilvolume.distributed` (see there), so
no process holds a survey's points; finished tiles kept in the run's store."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..core.types import GridSpec, SoilVolumeError
from ..core.wording import opt
from ..dem.geotiff import grid_layout, write_cog
from ..dem.grid import UINT8_LAYERS
from ..distributed.cluster import checker
from ..distributed.pointcache import PointCache, near_after
from ..distributed.scan import dask_loader
from ..distributed.schedule import Schedule, budget_gb, client
from ..distributed.tilestore import input_identity, run_parts, run_store
from ..distributed.tiletask import Plan, coarse, plan_parts, run_tiles, tile_windows, volume_factor
from ..distributed.volumetiles import VolumeJob, grid_tiles, reader, tile_volumes
from ..distributed.waiting import in_thread
from ..inputs.footprint import PolygonMask, footprint
from ..inputs.io import write_las_chunked
from ..inputs.prepare import Prepared, prepare
from ..inputs.stream import open_source
from .seam import Gridded, VolumeFn, done

IDENTITY_S = 600.0  # at most this long for hashing the inputs (they are read from disk, as the first pass reads them)


class Tiled:
    """Point work as tile tasks on the cluster ``schedule`` names; tiles kept in the run's store."""

    reading_note = " (thinning for registration)"
    raster_note = " (COG)"

    def __init__(self, schedule: Schedule) -> None:
        self.schedule = schedule
        self.c = self.store = self.plan = self.cache = self.src_b = self.src_a = None
        self.k, self.stats, self.said, self.side, self.density, self.windows = 1, {}, None, 0, 0.0, []
        self.medians = self.identities = self.kept = self.cloud = None

    @contextmanager
    def session(self, ctx) -> Iterator[Tiled]:
        """The run's tile store and cluster, started in the background, waited for at its first use
        (``cluster_wait``), shut down in the background after its last."""
        if ctx.options.ground in ("filter", "csf"):
            raise SoilVolumeError(
                f"{opt('ground', ctx.options.ground)} needs whole clouds: use {opt('scheduler', 'none')} "
                "(or classify the tiles first)"
            )
        with run_store(ctx.out.final) as store, client(self.schedule, ctx.options.memory_limit, store.scratch) as c:

            def wait():
                with ctx.timer("cluster_wait"):
                    return c.result(checker(ctx.hooks))

            self.store, self.c, c.wait = store, c, wait
            yield self

    def read(self, ctx) -> Prepared:
        """The first pass: the thinned subsets (the inputs hashed beside it, for the tile store)."""
        hooks, options = ctx.hooks, ctx.options
        paths = [e.path for e in ctx.epochs]  # hashed by zlib's CRC, which releases the GIL
        self.identities = in_thread(
            lambda: {"before": input_identity(paths[0]), "after": input_identity(paths[1])}, name="soilvolume-ids"
        )
        self.src_b, self.src_a = (open_source(e.path) for e in ctx.epochs)
        direct = self.schedule.kind != "tcp"  # this machine's workers: sent straight to them
        self.cache = PointCache(self.c, budget_gb(options.memory_limit), direct)
        self.cache.expect(near_after(self.src_b, self.src_a, options.radius))
        loader = dask_loader(self.c, lambda m: hooks.step(ctx.at("prepare", 0.46), m), checker(hooks), self.cache)
        check = lambda: hooks.step(ctx.at("prepare", 0.23), "reading")  # noqa: E731
        prep = prepare(self.src_b, self.src_a, options, check=check, full=False, loader=loader)
        if self.c.ready():  # the tiles the driver read go out beside the registration, not before the grid
            self.cache.send_held()
        return prep

    def dense(self, prep: Prepared) -> None:
        return None  # no process holds the full-resolution points

    def grid(self, ctx, prep: Prepared, reg, grid: GridSpec, beside: Callable) -> Gridded:
        """The tiles gridded on the workers; ``beside`` on the overview's before DEM (``k`` > 1) or the grid's."""
        options, (b, a) = ctx.options, (str(e.path) for e in ctx.epochs)
        crs = prep.inputs["before"]["crs_wkt"], prep.inputs["after"]["crs_wkt"]
        ring = prep.crop if prep.crop is not None else footprint(prep.after_thin[:, :2], options.radius)
        # the sources opened here, so that no task opens them again (never whole clouds)
        opened = tuple(None if s is None or s.raw is not None else s for s in (self.src_b, self.src_a))
        parts = (prep.frame, prep.origin, grid, reg.transform, prep.ground, ring, options.statistic)
        self.plan = Plan(b, a, *crs, *parts, prep.index, prep.rules, opened, PolygonMask(ring))  # what each task needs
        self.windows, self.side, self.density = tile_windows(options, grid, prep, self.schedule, self.src_b)
        ctx.hooks.step(
            ctx.at("grid"), f"gridding {len(self.windows)} tiles of {self.side} x {self.side} cells on {self.schedule}"
        )
        self.k = volume_factor(options, grid)
        inputs = self.identities.result(IDENTITY_S)
        self.said = self.store.bind(run_parts(inputs, options, plan_parts(self.plan, self.windows, self.k)))
        if self.said:
            ctx.hooks.step(ctx.at("grid"), self.said)
        self.kept, self.stats = self.store.tiles(self.windows), {}
        if self.k > 1:  # the correction found on the overview
            at, dems = coarse(grid, self.k), ()
            at_dems, self.medians, self.stats = grid_tiles(self.c, self.plan, self.kept, self.k, ctx.hooks, self.cache)
        else:
            at, dems = grid, run_tiles(self.c, self.plan, ctx.hooks, self.kept, self.stats, self.cache)
            at_dems = dems
        self.cache.release()  # the workers' memory back for the volume step
        if self.k == 1:
            self.c.close_soon()  # the volume step runs here: the workers are done
        return Gridded(grid, dems, at, at_dems, done(beside(at, at_dems[1])))

    def volume(self, ctx, step: VolumeFn, gridded: Gridded, planes: tuple, moved) -> object:
        """``step`` on the whole grid, or on the overview, then tile by tile given its correction."""
        p_b, p_a, d_i = planes
        if self.k == 1:
            return step(*gridded.dems, d_i, gridded.grid)
        over = step(*gridded.correction_dems, d_i, gridded.correction_grid)
        parts = (over.offset, over.stable, over.params, self.medians, (p_b, p_a), moved, self.plan.rules)
        job = VolumeJob(self.kept, gridded.grid, ctx.options, self.k, *parts)
        vols = tile_volumes(self.c, job, over, ctx.hooks, (*ctx.spans["volume"], "volumes of"))
        self.c.close_soon()  # the rest reads the tile store
        return vols

    def write(self, ctx, layers: list, vols, grid, z0: float) -> None:
        """The rasters as COGs from memory or the tile store; the after cloud streamed through the driver."""
        get = reader(self.kept) if self.k > 1 else lambda key, r, c: getattr(vols, key)[r, c]  # heights local
        for name, key, desc in layers:  # the pair's layers (a surface as the reference runs in memory)
            if key in UINT8_LAYERS:
                layout = grid_layout(grid, desc, "", "uint8")
                write_cog(ctx.out.path(name), layout, lambda r, c, key=key: get(key, r, c).astype("uint8"))
            else:
                add = z0 if key.startswith("dem_") else 0.0
                piece = lambda r, c, key=key, add=add: get(key, r, c) + add  # noqa: E731
                write_cog(ctx.out.path(name), grid_layout(grid, desc), piece)
        if self.cloud is not None:
            prep, reg, path = self.cloud
            write_las_chunked(path, prep.after_chunks(), prep.origin, prep.frame.wkt, reg.transform)

    def keep_cloud(self, prep: Prepared, reg, path: Path) -> None:
        self.cloud = (prep, reg, path)

    def engine(self) -> dict:
        """report.json's ``engine``: where the tiles ran and what they cost."""
        k, stats = self.k, self.stats
        return {
            "scheduler": str(self.schedule),
            "tiles": len(self.windows),
            "tile_cells": self.side,
            "points_per_cell": round(self.density, 3),
            "volume_step": "whole grid" if k == 1 else f"tiles, overview of {k} x {k} cells",
            "tiles_resumed": stats["resumed"],
            "kept_tiles_discarded": self.said,
            "task_points_read": stats["read"],
            "task_points_from_memory": stats["cached"],
            "points_kept_in_memory": self.cache.points,
            "task_seconds": round(stats["seconds"], 3),
            "points_per_task_second": round(stats["read"] / max(stats["seconds"], 1e-9)),
        }
