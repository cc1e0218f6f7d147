"""The in-process executor of :mod:`.run`: each step's point work on whole arrays in this
process (the tiled one, :mod:`soilvolume.distributed.executor`, does it as Dask tasks). An
executor implements how a step's work is done, never which steps run or in what order."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from functools import partial

import numpy as np

from ..core.types import SoilVolumeError
from ..dem import grid as gridmod
from ..dem.geotiff import write_grid


class InProcess:
    """Whole clouds in memory; the registered cloud written on a second thread meanwhile."""

    reading_note = " (cropping and thinning on the way)"
    raster_note = ""

    def __init__(self) -> None:
        self.pool: ThreadPoolExecutor | None = None
        self.cloud_job = None
        self.plane_job: Future | None = None

    @contextmanager
    def session(self, run):
        with ThreadPoolExecutor(2) as pool:  # numpy sorts and LAZ compression release the GIL
            self.pool = pool
            try:
                yield self
            finally:
                self.pool = None

    def prepare(self, run) -> None:
        if len(run.epochs) == 1:
            return _prepare_one(run)
        from .steps import prepare_pair

        b, a = run.epochs
        prep = run.prep = prepare_pair(b.path, a.path, run.options, run.hooks, b.pipeline, a.pipeline, run.spans)
        run.timer.s["read"] = prep.read_s  # the rest of streaming: frame, crop, thinning
        run.timer.s["crop"] = run.timer.s.get("crop", 0.0) - prep.read_s
        run.hooks.info(
            f"kept {len(prep.before):,} before points within {run.options.radius:g} m of the after "
            f"footprint and {len(prep.after):,} after points; registration subsets "
            f"{len(prep.before_thin):,} + {len(prep.after_thin):,} ({prep.voxel:.2f} m columns)"
        )

    def dense(self, run) -> tuple:
        """The full-resolution points the fine registration's stable-ground refinement grids."""
        return run.prep.after.xyz, run.prep.before.xyz

    def grid(self, run) -> None:
        if len(run.epochs) == 1:
            return _grid_one(run)
        from ..registration.rigid import CACHE_ROWS, transform_points, transform_points32
        from .steps import moved_nonsoil, shared_grid

        prep, reg, opts = run.prep, run.reg, run.options
        self._start_cloud(run)
        run.after_thin = transform_points(prep.after_thin, reg.transform)
        grid = run.grid = shared_grid(prep, run.after_thin, opts)
        before = self._before_then_planes(run)
        move = partial(transform_points32, t=reg.transform, chunk=CACHE_ROWS)  # block by block: no registered copy
        dem_a = gridmod.epoch_dem(prep.after.xyz, grid, opts.statistic, moved_nonsoil(prep, reg), move)
        run.dems = (dem_a, before.result())

    def _before_then_planes(self, run) -> Future:
        """The before cloud's heights on the pool beside the after cloud's, then on the same thread
        the planes step's two planes (their inputs are there by then; two threads at a time: the
        after cloud's heights keep a core); returns the heights' future (the planes': ``plane_job``)."""
        from .steps import after_plane, before_plane

        prep, opts, heights = run.prep, run.options, Future()

        def work() -> tuple:
            try:
                heights.set_result(gridmod.epoch_dem(prep.before.xyz, run.grid, opts.statistic, prep.before.nonsoil))
            except BaseException as err:
                heights.set_exception(err)
                raise
            return before_plane(prep, run.grid, heights.result(), opts), after_plane(run.after_thin, opts)

        self.plane_job = self.pool.submit(work)
        return heights

    def planes(self, run) -> tuple:
        """The planes step's (plane before, plane after, d_i), found on the pool since the grid step."""
        from .steps import with_offset

        return with_offset(*self.plane_job.result(), run.grid)

    def correction_grid(self, run) -> tuple:
        """(the grid, the (after, before) DEMs) the planes and the correction are found on."""
        return run.grid, run.dems

    def correction_note(self, run) -> str | None:
        return None

    def volume(self, run):
        from .steps import volume_step

        return volume_step(run.dems, run.planes[2], run.grid, run.options, run.reg)

    def write(self, run) -> None:
        if len(run.epochs) == 1:
            return _write_one(run)
        if run.vols is not None:
            _write_rasters(run)
        self._start_cloud(run)
        if self.cloud_job is not None:
            from ..core.outputs import os_errors

            with os_errors(run.cloud_out):
                self.cloud_job.result()

    def engine(self, run) -> dict | None:
        return None

    def html(self, run) -> tuple:
        """The arguments of :func:`steps.write_report_html` after ``report``."""
        return run.vols, run.grid, run.dems[0].heights + run.prep.origin[2]

    def _start_cloud(self, run) -> None:
        """Start writing the registered after cloud (every after point, all classes, moved by
        the registration) in the background, once, when the run writes it."""
        if run.cloud_out is None or self.cloud_job is not None:
            return
        from ..inputs.io import write_las_chunked

        prep = run.prep
        args = (run.cloud_out, prep.after_chunks(), prep.origin, prep.frame.wkt, run.reg.transform)
        self.cloud_job = self.pool.submit(write_las_chunked, *args)


def _write_rasters(run) -> None:
    vols, grid, out = run.vols, run.grid, run.out
    z0 = float(run.prep.origin[2])  # local -> absolute heights
    for name, key, desc in gridmod.output_layers(run.options.correction):
        array = getattr(vols, key)
        if key in gridmod.UINT8_LAYERS:
            write_grid(out.path(name), array.astype("uint8"), grid, desc, "", "uint8")
        else:
            write_grid(out.path(name), array + z0 if key.startswith("dem_") else array, grid, desc)


def _prepare_one(run) -> None:
    """One cloud (``dem``) streamed into its own working frame."""
    from ..inputs.prepare import prepare_single
    from ..pipelines.pipeline import open_source

    (epoch,) = run.epochs
    check = run.hooks.ticker(*run.spans["prepare"], "reading")
    run.prep = prepare_single(open_source(epoch.path, epoch.pipeline), run.crs, run.options, check=check)


def _grid_one(run) -> None:
    """The one cloud's grid (``bounds``, else its points' box) and heights at the cell centres."""
    from ..inputs.footprint import footprint, polygon_area
    from ..validate import check_grid_cells
    from ..volumes.compute import centred_heights

    one, options = run.prep, run.options
    xyz, origin, frame = one.xyz, one.origin, one.frame
    if run.bounds is not None:
        u, b = frame.xy_unit, run.bounds
        lo, hi = np.array([b[0] * u, b[1] * u, 0]) - origin, np.array([b[2] * u, b[3] * u, 0]) - origin
    else:
        lo, hi = xyz.min(axis=0).astype(float), xyz.max(axis=0).astype(float)
    cell = options.cell or gridmod.choose_cell(len(xyz), polygon_area(footprint(one.thin[:, :2])))
    grid = run.grid = gridmod.make_grid(lo, hi, cell, origin, frame.wkt, frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    run.hooks.step(run.at("grid", 0.1), f"gridding {len(xyz):,} points on {grid.rows} x {grid.cols} cells of {cell} m")
    h = centred_heights(gridmod.epoch_dem(xyz, grid, options.statistic), cell, options)
    if not np.isfinite(h).any():
        raise SoilVolumeError(f"{run.epochs[0].path}: no points inside the grid (check --bounds)")
    run.dems = (h,)


def _write_one(run) -> None:
    from ..core.outputs import os_errors

    desc = f"average height ({run.options.statistic}, cell centres) (m)"
    with os_errors(run.raster_out):
        write_grid(run.raster_out, run.dems[0] + run.prep.origin[2], run.grid, desc)
