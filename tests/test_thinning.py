"""The streaming column thinner: the same centroids, to the bit, as the plain per-chunk formula."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.inputs.thinning import ColumnThinner


def reference_sums(chunks, lo, hi, voxel, within=None) -> np.ndarray:
    """Count and x/y/z sums per column, chunk by chunk, as the thinner defines them."""
    th = ColumnThinner(lo, hi, voxel, within)  # only for its lattice (first column, shape)
    rows, cols = th.shape
    sums = np.zeros((4, rows * cols))
    for xyz in chunks:
        with np.errstate(invalid="ignore"):
            ix = ((xyz[:, 0] - th.lo[0]) / th.voxel).astype(np.int64) - th.first[0]
            iy = ((xyz[:, 1] - th.lo[1]) / th.voxel).astype(np.int64) - th.first[1]
        ok = (ix >= 0) & (iy >= 0) & (ix < cols) & (iy < rows)
        ids = iy[ok] * cols + ix[ok]
        sums[3] += np.bincount(ids, minlength=rows * cols)
        for k in range(3):
            sums[k] += np.bincount(ids, weights=xyz[ok, k], minlength=rows * cols)
    return sums


def _chunks(dtype, seed=3):
    rng = np.random.default_rng(seed)
    out = []
    for c in range(5):
        n = 50_000
        xyz = np.column_stack([rng.uniform(-30, 430, n), rng.uniform(-30, 430, n), rng.normal(10, 2, n)])
        if c == 1:
            xyz[::37, 0] = np.nan  # undecodable coordinates fall outside
        if c == 2:  # all inside
            xyz = xyz[(xyz[:, :2] > 1).all(axis=1) & (xyz[:, :2] < 399).all(axis=1)]
        if c == 3:
            xyz = xyz[:0]
        out.append(xyz.astype(dtype))
    return out


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("within", [None, ((40.0, 55.0), (310.0, 390.0))])
def test_thinner_sums_match_the_formula_to_the_bit(dtype, within):
    chunks = _chunks(dtype)
    th = ColumnThinner(np.zeros(2), np.full(2, 400.0), 0.73, within)
    with np.errstate(invalid="ignore"):
        for xyz in chunks:
            th.add(xyz)
    ref = reference_sums(chunks, np.zeros(2), np.full(2, 400.0), 0.73, within)
    assert th.sums.tobytes() == ref.tobytes()
    filled = ref[3] > 0
    centroids, counts = th.columns()  # both in one pass, as the streaming takes them
    assert len(centroids) == int(filled.sum()) > 1000
    assert centroids.tobytes() == (ref[:3, filled] / ref[3, filled]).T.copy().tobytes()
    assert (counts == ref[3, filled]).all()


@pytest.mark.parametrize("within", [None, ((40.0, 55.0), (310.0, 390.0))])
def test_tiles_thinned_on_their_own_columns_add_up_to_the_epochs_bits(within):
    """Tiles thinned each on the columns its box meets (:func:`narrowed`), their blocks added in
    order to the epoch's thinner, give the bits of the epoch's thinner fed every tile's points,
    and of sparse adds of each tile's columns with points; a block off the columns is refused."""
    from soilvolume.inputs.thinning import narrowed

    thinning = (np.zeros(2), np.full(2, 400.0), 0.73, within)
    whole, blocks, sparse = (ColumnThinner(*thinning) for _ in range(3))
    rng = np.random.default_rng(5)
    for x0, y0 in [(0, 0), (200, 0), (0, 200), (200, 200), (150, 150)]:  # the last overlaps the others
        xyz = np.column_stack(
            [rng.uniform(x0, x0 + 200, 40_000), rng.uniform(y0, y0 + 200, 40_000), rng.normal(size=40_000)]
        )
        whole.add(xyz)
        tile = ColumnThinner(*narrowed(thinning, (np.array([x0, y0]) - 0.73, np.array([x0, y0]) + 200.73)))
        tile.add(xyz)
        assert tile.sums.shape[1] < whole.sums.shape[1] / 2  # its own columns, not the epoch's
        blocks.add_block(tile.block())
        has = np.flatnonzero(tile.sums[3])
        part = ColumnThinner(*thinning)
        part.add(xyz)
        cols = np.flatnonzero(part.sums[3])
        sparse.sums[:, cols] += part.sums[:, cols]
        assert len(has) == len(cols)
    assert blocks.sums.tobytes() == whole.sums.tobytes() == sparse.sums.tobytes()
    off = ColumnThinner(np.zeros(2), np.full(2, 400.0), 0.73, ((-50.0, -50.0), (500.0, 500.0)))
    if within is not None:  # a thinner of more columns than the epoch's: not a part of it
        with pytest.raises(ValueError, match="outside"):
            blocks.add_block(off.block())
