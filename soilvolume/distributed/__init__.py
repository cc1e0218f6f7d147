"""The tiled Dask engine (its backend: :mod:`soilvolume.execution.tiled`): the in-process method with
the point work done as Dask tasks, so no process holds a survey's points.

1. A first pass of tasks (:mod:`scan`) returns column-thinning sums, counts and chunk boxes; the
   registration runs in the driver on the thinned subsets, as in-process.
2. The grid is cut into tiles (:mod:`tiletask`); each task streams only what meets its tile (VPC
   tiles, COPC nodes, chunks whose boxes the first pass recorded; VPC tiles kept on the workers,
   :mod:`pointcache`) and gives its cells the heights of :func:`grid.cell_heights` on the *global*
   grid's cells: a point belongs to one cell, so no halo is needed.
3. ``--volume-step whole``: the tiles' rasters (a few numbers per cell) are gathered and the volume
   step runs as in-process; ``tiles``: see :mod:`volumetiles`. Outputs are COGs written block by
   block. Finished tiles are kept after an interruption, keyed by what they were computed from
   (:mod:`tilestore`), so the same command resumes.
"""
