"""Faster equivalents of SciPy calls the refill makes many times on small grids and systems,
giving the same arrays: CSR matrices taken straight from their rows (what ``scipy.sparse``
builds through coordinates, without the round trip) and the erosion by a disc where only every
step-th cell of it is read."""

from __future__ import annotations

import numpy as np
from scipy import sparse


def rows_csr(rows: np.ndarray, cols: np.ndarray, data: np.ndarray, shape: tuple[int, int]) -> sparse.csr_matrix:
    """The CSR matrix of entries given row by row, each row's columns increasing (what
    ``csr_matrix((data, (rows, cols)))`` builds from them, without the conversion from
    coordinates: the same arrays and index type)."""
    idx = np.int32 if max(shape[0], shape[1], data.size) < np.iinfo(np.int32).max else np.int64
    indptr = np.zeros(shape[0] + 1, idx)
    np.cumsum(np.bincount(rows, minlength=shape[0]), out=indptr[1:])
    return sparse.csr_matrix((data, cols.astype(idx), indptr), shape=shape)


def lower_triangle(a: sparse.csr_matrix) -> sparse.csr_matrix:
    """``sparse.tril(a, format="csr")`` of a CSR matrix in canonical form (sorted, no duplicate
    entries), taken from its rows directly: the same arrays without the round trip through
    coordinates."""
    a = a.tocsr()
    if not a.has_canonical_format:
        return sparse.tril(a, format="csr")
    row = np.repeat(np.arange(a.shape[0]), np.diff(a.indptr))
    keep = a.indices <= row
    indptr = np.zeros_like(a.indptr)
    np.cumsum(np.bincount(row[keep], minlength=a.shape[0]), out=indptr[1:])
    return sparse.csr_matrix((a.data[keep], a.indices[keep], indptr), shape=a.shape)


def disc_erosion_every(mask: np.ndarray, radius: float, step: int) -> np.ndarray:
    """``ndimage.binary_erosion(mask, disc)[::step, ::step]`` for the disc of cells within
    ``radius`` (outside the grid is not ``mask``), looked up at those cells only: each is True
    when every cell within ``radius`` of it lies in the grid and in ``mask``."""
    r = int(np.ceil(radius))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    near = xx * xx + yy * yy <= radius * radius
    rows = np.arange(0, mask.shape[0], step)[:, None, None] + yy[near]
    cols = np.arange(0, mask.shape[1], step)[None, :, None] + xx[near]
    inside = (rows >= 0) & (rows < mask.shape[0]) & (cols >= 0) & (cols < mask.shape[1])
    looked = mask[np.clip(rows, 0, mask.shape[0] - 1), np.clip(cols, 0, mask.shape[1] - 1)]
    return (looked & inside).all(axis=-1)
