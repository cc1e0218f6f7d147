"""The tiled executor of :mod:`soilvolume.workflow.run`: the same steps, with the point work as
Dask tasks (see :mod:`.tiled`), so no process holds a survey's points. Registration runs in the
driver on the thinned subsets a first pass of tasks returns; the grid is cut into tiles; with
``--volume-step tiles`` the volume step runs tile by tile too (:mod:`.volumestep`)."""

from __future__ import annotations

import importlib
import threading
from contextlib import contextmanager

from ..core.types import SoilVolumeError
from ..core.wording import opt
from .schedule import Schedule


def _import_steps() -> None:
    """The driver's next steps imported while it waits for the first pass's tasks (~0.2 s that
    came between the reading and the registration)."""
    try:
        importlib.import_module("..workflow.steps", __package__)
    except Exception:  # noqa: BLE001 - the step that needs it reports what is missing
        pass


IDENTITY_S = 600.0  # at most this long for hashing the inputs (they are read from disk, as the first pass reads them)


def _identify(future, epochs) -> None:
    """The inputs' identities (:func:`.fingerprint.input_identities`: zlib's CRC releases the GIL)
    into ``future``."""
    from .fingerprint import input_identities

    try:
        future.set_result(input_identities(*(e.path for e in epochs)))
    except BaseException as exc:  # noqa: BLE001 - raised where the result is taken
        future.set_exception(exc)


class Tiled:
    """Point work as tile tasks on the cluster ``schedule`` names; tiles kept in the run's store."""

    reading_note = " (thinning for registration)"
    raster_note = " (COG)"

    def __init__(self, schedule: Schedule) -> None:
        self.schedule = schedule
        self.c = self.store = self.plan = self.cache = self.starting = self.src_a = None
        self.k, self.stats, self.said, self.side, self.density, self.windows = 1, {}, None, 0, 0.0, []
        self.coarse = self.over_epochs = self.medians = self.identities = None

    @contextmanager
    def session(self, run):
        """The run's tile store and cluster; the cluster starts in the background and is waited
        for at its first use (``cluster_wait``), shut down in the background after its last."""
        from ..core.collector import resume
        from .cluster import LazyClient, checker
        from .schedule import client
        from .tilestore import run_store

        if run.options.ground in ("filter", "csf"):
            raise SoilVolumeError(
                f"{opt('ground', run.options.ground)} needs whole clouds: use {opt('scheduler', 'none')} "
                "(or classify the tiles first)"
            )
        with run_store(run.out.final) as store, client(self.schedule, run.options.memory_limit, store.scratch) as s:
            self.store, self.starting = store, s
            s.future.add_done_callback(lambda _: resume())  # the garbage collector, once the cluster is up

            def wait():
                with run.timer("cluster_wait"):
                    return s.result(checker(run.hooks))

            # the driver reads tiles itself while a local cluster starts (a remote one's workers read theirs)
            self.c = LazyClient(wait, s.future.done if self.schedule.kind != "tcp" else lambda: True)
            yield self

    def prepare(self, run) -> None:
        from concurrent.futures import Future

        from ..inputs.prepare import prepare
        from ..inputs.stream import open_source
        from .cluster import checker
        from .pointcache import PointCache, near_after
        from .scan import dask_loader
        from .schedule import budget_gb

        hooks = run.hooks
        threading.Thread(target=_import_steps, daemon=True, name="soilvolume-steps").start()
        self.identities = Future()  # the inputs as the run starts reading them, hashed beside the first pass
        threading.Thread(
            target=_identify, args=(self.identities, run.epochs), daemon=True, name="soilvolume-ids"
        ).start()
        self.src_b, self.src_a = (open_source(e.path) for e in run.epochs)
        src_a = self.src_a
        direct = self.schedule.kind in ("local", "threads")  # this machine's workers: sent straight to them
        self.cache = PointCache(self.c, budget_gb(run.options.memory_limit), direct)
        self.cache.expect(near_after(self.src_b, src_a, run.options.radius))
        loader = dask_loader(self.c, lambda m: hooks.step(run.at("prepare", 0.46), m), checker(hooks), self.cache)
        check = lambda: hooks.step(run.at("prepare", 0.23), "reading")  # noqa: E731
        run.prep = prepare(self.src_b, src_a, run.options, check=check, full=False, loader=loader)
        if self.c.ready():  # the tiles the driver read go out beside the registration, not before the grid
            self.cache.send_held()

    def dense(self, run) -> None:
        return None  # no process holds the full-resolution points

    def grid(self, run) -> None:
        from ..inputs.footprint import footprint
        from ..registration.rigid import transform_points
        from ..workflow.steps import shared_grid
        from .fingerprint import run_parts
        from .tiled import cell_from_columns, plan_for, volume_factor
        from .tiletask import plan_parts

        prep, reg, options = run.prep, run.reg, run.options
        run.after_thin = transform_points(prep.after_thin, reg.transform)
        poly = footprint(run.after_thin[:, :2])  # the registered after footprint
        cell = options.cell if options.cell else cell_from_columns(prep, poly)
        run.grid = shared_grid(prep, run.after_thin, options.with_(cell=cell), poly)
        self.plan = plan_for(run, cell, (self.src_b, self.src_a))
        self.windows, self.side, self.density = self._tiles(run, cell)
        run.hooks.step(
            run.at("grid"), f"gridding {len(self.windows)} tiles of {self.side} x {self.side} cells on {self.schedule}"
        )
        self.k = volume_factor(options, run.grid, self.schedule)
        inputs = self.identities.result(IDENTITY_S)
        self.said = self.store.bind(run_parts(inputs, options, plan_parts(self.plan, self.windows, self.k)))
        if self.said:
            run.hooks.step(run.at("grid"), self.said)
        self.kept = self.store.tiles(self.windows)
        if self.k > 1:
            from . import overview
            from .volumestep import grid_tiles

            self.over_epochs, self.medians, self.stats = grid_tiles(
                self.c, self.plan, self.kept, self.k, run.hooks, self.cache
            )
            self.coarse = overview.coarse(run.grid, self.k)
        else:
            from .tiletask import epoch_dems, run_tiles

            self.stats = {}
            arrays = run_tiles(self.c, self.plan, self.windows, run.hooks, self.kept, self.stats, self.cache)
            run.dems = epoch_dems(arrays, self.plan.rules)
        self.cache.release()  # the workers' memory back for the volume step
        if self.k == 1:
            self.starting.close_soon()  # the volume step runs here: the workers are done

    def _tiles(self, run, cell: float) -> tuple:
        """(the tile windows, their side in cells, points per cell) for the run's grid."""
        from .schedule import check_tiles, worker_gb
        from .tiled import data_tiling, fits, points_per_cell, tile_side
        from .tiletask import tiles

        options, grid = run.options, run.grid
        task_gb, density = worker_gb(self.schedule, options.memory_limit), points_per_cell(run.prep, cell)
        side = tile_side(options, grid, density, task_gb, self.schedule.workers)
        tiling = None if options.tile_cells else data_tiling(self.src_b, cell, 2 * side)
        if tiling and not fits(density * (tiling[0] / cell) ** 2, task_gb):
            tiling = None  # a data tile too dense for one task's memory: smaller tiles, read more than once
        windows = tiles(grid, side)
        if tiling:  # snap to the input's tiles (one grid tile per data tile) when that keeps the workers busy
            pitch = max(1, round(tiling[0] / cell))
            aligned = tiles(grid, pitch, tiling[0], tiling[1:])
            if len(aligned) >= min(len(windows), 2 * self.schedule.workers):
                windows, side = aligned, pitch
        check_tiles(windows, density, task_gb, options)
        return windows, side, density

    def correction_grid(self, run) -> tuple:
        """(the grid, the (after, before) DEMs) the planes and the correction are found on: the
        overview's with the volume step in tiles."""
        return (self.coarse, self.over_epochs) if self.k > 1 else (run.grid, run.dems)

    def planes(self, run) -> tuple:
        """The planes step's (plane before, plane after, d_i), on the correction's grid."""
        from ..workflow.steps import planes_step

        grid, dems = self.correction_grid(run)
        return planes_step(run.prep, grid, dems[1], run.after_thin, run.options)

    def correction_note(self, run) -> str | None:
        k = self.k
        return f"estimating the vertical bias correction on a {k} x {k} overview of the grid" if k > 1 else None

    def volume(self, run):
        from ..workflow.steps import volume_step

        if self.k == 1:
            return volume_step(run.dems, run.planes[2], run.grid, run.options, run.reg)
        from .volumestep import tile_volumes

        over = volume_step(self.over_epochs, run.planes[2], self.coarse, run.options, run.reg)
        vols = tile_volumes(self.c, self.kept, self.k, over, run, self.medians)
        self.starting.close_soon()  # the rest reads the tile store
        return vols

    def write(self, run) -> None:
        from .cog import write_outputs

        if self.k > 1:
            from .volumestep import reader

            get = reader(self.kept)
        else:
            v = run.vols
            arrays = {"dem_out_b": v.dem_out_b, "dem_out_a": v.dem_out_a, "diff": v.diff, "offset": v.offset}
            arrays.update(filled_mask=v.filled_mask, classes=v.classes)
            get = lambda key, r, c: arrays[key][r, c]  # noqa: E731
        write_outputs(run.out, get, run.grid, float(run.prep.origin[2]), run.options.correction)
        if run.cloud_out is not None:  # --registered-cloud: the after cloud streamed through the driver
            from ..inputs.io import write_las_chunked

            prep = run.prep
            write_las_chunked(run.cloud_out, prep.after_chunks(), prep.origin, prep.frame.wkt, run.reg.transform)

    def engine(self, run) -> dict:
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
            "task_points_from_memory": stats.get("cached", 0),
            "points_kept_in_memory": self.cache.points if self.cache is not None else 0,
            "task_seconds": round(stats["seconds"], 3),
            "points_per_task_second": round(stats["read"] / max(stats["seconds"], 1e-9)),
        }

    def html(self, run) -> tuple:
        z0 = run.prep.origin[2]
        if self.k > 1:
            return run.vols, self.coarse, self.over_epochs[0].heights + z0
        return run.vols, run.grid, run.dems[0].heights + z0
