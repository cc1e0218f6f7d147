"""Cell heights at the cell centres: a cell whose points cover one side only (a hole's edge, the
survey's edge) is moved along the local slope to its centre."""

from __future__ import annotations

import numpy as np

from soilvolume.dem.grid import OffsetSums, cell_coords, epoch_dem, flat_ids, make_grid, slopes


def _plane_points(seed: int = 0) -> tuple[np.ndarray, object]:
    """A 0.6-slope plane sampled at ~400 points/m2 on a 20 x 20 m grid of 0.5 m cells, with a
    disc of 3 m radius and the east half of one row of cells left without points."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 20, (160_000, 2))
    hole = np.hypot(xy[:, 0] - 10, xy[:, 1] - 10) < 3.0
    half = (xy[:, 1] >= 4.0) & (xy[:, 1] < 4.5) & (xy[:, 0] % 0.5 > 0.25)
    xy = xy[~hole & ~half]
    z = 0.6 * xy[:, 0] - 0.3 * xy[:, 1]
    grid = make_grid(np.zeros(3), np.array([20.0, 20.0, 0.0]), 0.5, np.zeros(3), None)
    return np.c_[xy, z], grid


def test_centred_heights_are_the_plane_at_the_cell_centres():
    xyz, grid = _plane_points()
    dem = epoch_dem(xyz, grid)
    x, y = grid.centers_local()
    truth = 0.6 * x - 0.3 * y
    partial = (y >= 4.0) & (y < 4.5)
    err_mean = np.abs(dem.heights - truth)[partial]
    err_centred = np.abs(dem.centred(grid.cell) - truth)[partial]
    assert np.nanmedian(err_mean) > 0.06  # a half-covered cell: 0.6 x 0.125 m off
    assert np.nanmax(err_centred) < 0.01
    cut = np.hypot(dem.dx, dem.dy) > 0.05  # points on one side
    ring = np.isfinite(dem.heights) & (np.hypot(x - 10, y - 10) < 3.6) & cut  # cells cut by the disc
    e_mean, e_centred = (dem.heights - truth)[ring], (dem.centred(grid.cell) - truth)[ring]
    assert np.median(np.abs(e_mean)) > 0.04 and np.median(np.abs(e_centred)) < 0.01
    assert abs(e_centred.sum()) < 0.1 * abs(e_mean.sum())  # the volume of the ring


def test_offsets_are_zero_on_evenly_covered_cells_and_chunking_does_not_matter():
    xyz, grid = _plane_points(1)
    dem = epoch_dem(xyz, grid)
    dx, dy = dem.dx, dem.dy
    sums = OffsetSums(grid.rows * grid.cols)  # as a tile task gathers them, chunk by chunk
    for part in np.array_split(xyz, 7):
        col, row, ok = cell_coords(part, grid)
        sums.add(flat_ids(col[ok], row[ok], grid.cols), col[ok], row[ok])
    dx2, dy2 = sums.means(dem.counts, grid.cell)
    assert np.allclose(dx, dx2, atol=1e-6) and np.allclose(dy, dy2, atol=1e-6)
    x, y = grid.centers_local()
    inner = (np.hypot(x - 10, y - 10) > 4.5) & ((y < 3.5) | (y > 5.0))
    assert np.abs(dx[inner]).max() < 0.06 and np.abs(dy[inner]).max() < 0.06  # ~400 points a cell
    half = (y >= 4.0) & (y < 4.5)
    assert np.allclose(dx[half], -0.125, atol=0.03)  # points on the west half only


def test_slopes_central_one_sided_and_missing():
    h = np.array([[0.0, 1.0, 2.0, np.nan, np.nan], [0.0, 1.0, 2.0, 3.0, 4.0]])
    gx, gy = slopes(h, 0.5)
    assert np.allclose(gx[1], 2.0) and np.allclose(gx[0, :3], 2.0)  # one-sided at the NaN
    assert np.isnan(gx[0, 3]) and np.allclose(gy[0, :3], 0.0)


def test_the_dem_command_writes_heights_at_the_cell_centres(tmp_path):
    """`soilvolume dem` gives the same cell-centre heights as an estimate's DEMs."""
    import pyproj
    import rasterio

    from soilvolume.api import cloud_to_dem
    from soilvolume.inputs.io import write_las
    from soilvolume.options import Options

    xyz, _ = _plane_points(2)
    origin = np.array([500_000.0, 3_900_000.0, 0.0])
    write_las(tmp_path / "plane.las", xyz + origin, pyproj.CRS.from_epsg(32654).to_wkt())
    out = tmp_path / "dem.tif"
    cloud_to_dem(
        tmp_path / "plane.las", out, Options(cell=0.5, ground="none"), bounds=(500_000, 3_900_000, 500_020, 3_900_020)
    )
    with rasterio.open(out) as ds:
        h = ds.read(1, masked=True).filled(np.nan)
        t = ds.transform
    cols, rows = np.meshgrid(np.arange(h.shape[1]) + 0.5, np.arange(h.shape[0]) + 0.5)
    x, y = t.c + cols * t.a - origin[0], t.f + rows * t.e - origin[1]
    err = np.abs(h - (0.6 * x - 0.3 * y))
    assert np.nanmedian(err) < 0.005 and np.nanpercentile(err, 99) < 0.03, np.nanmax(err)


def test_a_cell_at_a_hole_is_not_moved_by_the_bush_beside_it():
    """Flat ground with a hole west of a cell whose points sit on its east side, and a bush (a
    dome of cells 0.4-0.7 m high) east of it: the step onto the bush is no slope of the ground
    (the next step disagrees), so the cell keeps the ground's height; on a steady one-sided
    slope the cell is still moved to its centre."""
    h = np.zeros((3, 7))
    h[:, 1] = np.nan  # the hole
    h[:, 3:6] = [0.45, 0.55, 0.3]  # the bush
    dx = np.zeros_like(h)
    dx[:, 2] = 0.15  # the cell's points: its east side
    base = np.zeros_like(h)
    from soilvolume.dem.grid import EpochDEM

    dem = EpochDEM(h, np.full(h.shape, 50), np.full(h.shape, 0.03), dx, np.zeros_like(h))
    assert abs(dem.centred(0.5)[1, 2] - base[1, 2]) < 0.065  # was -0.27: moved down the bush's flank
    wall = np.tile(0.6 * 0.5 * np.arange(7.0), (3, 1))  # a pit's wall at 0.6 m/m
    wall[:, 1] = np.nan
    wall[:, 2] += 0.6 * 0.15  # the points' mean lies 0.15 m east of the centre
    dem = EpochDEM(wall, np.full(h.shape, 50), np.full(h.shape, 0.03), dx, np.zeros_like(h))
    assert abs(dem.centred(0.5)[1, 2] - 0.6) < 0.005


def test_offset_sums_block_by_block_have_the_bits_of_one_pass_point_by_point():
    """OffsetSums.add_at (the in-process grid's blocks): a bincount for the cells a block brings
    first, one-by-one adds for the cells earlier blocks gave points, the same bits as adding every
    point in order into empty sums (np.add.at over all of them), for one block and several."""
    rng = np.random.default_rng(3)
    for n_cells, n, blocks in ((50, 1000, 1), (50, 1000, 7), (5000, 200_000, 5), (1_000_000, 300_000, 3)):
        ids = rng.integers(0, n_cells, n)
        col, row = ((rng.random(n) * 100).astype(np.float32) for _ in range(2))
        col[:10] = np.floor(col[:10])  # on a cell's edge: an offset of zero
        ref = OffsetSums(n_cells)
        for sums, c in ((ref.sx, col), (ref.sy, row)):
            np.add.at(sums, ids, (c - np.floor(c)).astype(np.float64))
        got = OffsetSums(n_cells)
        edges = np.linspace(0, n, blocks + 1).astype(int)
        for a, b in zip(edges, edges[1:], strict=False):
            got.add_at(ids[a:b], col[a:b], row[a:b])
        assert got.sx.tobytes() == ref.sx.tobytes() and got.sy.tobytes() == ref.sy.tobytes(), (n_cells, blocks)
