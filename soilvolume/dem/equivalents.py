"""Faster equivalents of SciPy calls the refill makes many times on small grids and systems,
giving the same arrays: CSR matrices taken straight from their rows (what ``scipy.sparse``
builds through coordinates, without the round trip) and the erosion by a disc (from the
distance transform: an erosion by a wide disc costs its area per cell)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse


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


SMALL_DISC = 6.0  # cells: up to this radius the erosion itself is quicker than the distance transform


def disc_erosion(mask: np.ndarray, radius: float) -> np.ndarray:
    """``ndimage.binary_erosion`` of ``mask`` by the disc of cells within ``radius`` (outside the
    grid is not ``mask``): the cells whose nearest cell off the mask lies beyond ``radius``, from
    the exact distance transform (squared distances are whole numbers of cells; an erosion by a
    wide disc costs its area per cell; a small one is quicker as it is)."""
    if radius <= SMALL_DISC:
        r = int(np.ceil(radius))
        yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
        return ndimage.binary_erosion(mask, xx * xx + yy * yy <= radius * radius)
    d = ndimage.distance_transform_edt(np.pad(mask, 1))[1:-1, 1:-1]
    return np.rint(d * d) > radius * radius
