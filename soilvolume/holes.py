"""Unreliable and empty cells of a DEM of difference: find them and refill the difference.

Cells with few points have noisy or outlier-driven heights; dropping them and interpolating the
height *difference* from reliable neighbours keeps the volume (FINDINGS: +13 % -> -0.3 %).
Interpolation is harmonic (Laplace equation with the reliable cells as boundary values), which is
exact for planes, smooth, and solved as one sparse linear system.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve

_FOUR = ndimage.generate_binary_structure(2, 1)
_DIRECT_MAX = 600_000  # unknowns solved directly; larger systems use conjugate gradients


def sparse_cells(
    counts_before: np.ndarray, counts_after: np.ndarray, ratio: float = 0.5
) -> np.ndarray:
    """Cells with data in both epochs where either count is below ``ratio`` x that epoch's
    median count (median over its cells with data)."""
    both = (counts_before > 0) & (counts_after > 0)
    if ratio <= 0 or not both.any():
        return np.zeros(both.shape, bool)
    med_b = np.median(counts_before[counts_before > 0])
    med_a = np.median(counts_after[counts_after > 0])
    return both & ((counts_before < ratio * med_b) | (counts_after < ratio * med_a))


def enclosed_holes(valid: np.ndarray, max_cells: int | None) -> np.ndarray:
    """Empty cells in 4-connected components of at most ``max_cells`` cells that do not touch the
    grid border (so they are enclosed by valid cells). ``None``/0 -> none."""
    if not max_cells or max_cells <= 0:
        return np.zeros(valid.shape, bool)
    labels, n = ndimage.label(~valid, structure=_FOUR)
    if n == 0:
        return np.zeros(valid.shape, bool)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    keep = sizes <= max_cells
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    keep[border] = False
    keep[0] = False
    return keep[labels]


def harmonic_fill(values: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``values`` with the ``targets`` cells replaced by a harmonic interpolation of the finite,
    non-target cells; target components with no finite neighbour stay NaN."""
    known = np.isfinite(values) & ~targets
    out = np.where(known, values, np.nan)
    todo = _reachable(targets, known)
    if not todo.any():
        return out
    out[todo] = _solve_laplace(np.where(known, values, 0.0), known, todo)
    return out


def _reachable(targets: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Target cells in 4-connected components that touch at least one known cell."""
    labels, n = ndimage.label(targets, structure=_FOUR)
    if n == 0:
        return targets & False
    touching = np.unique(labels[ndimage.binary_dilation(known, _FOUR) & targets])
    ok = np.zeros(n + 1, bool)
    ok[touching] = True
    ok[0] = False
    return ok[labels]


def _neighbour_pairs(todo: np.ndarray, usable: np.ndarray):
    """For each of the 4 directions: (target cell, neighbour cell) flat indices where both the
    target is in ``todo`` and the neighbour is ``usable`` (inside the grid)."""
    rows, cols = todo.shape
    idx = np.arange(rows * cols).reshape(rows, cols)
    for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        src = idx[max(0, -dr): rows - max(0, dr), max(0, -dc): cols - max(0, dc)]
        dst = idx[max(0, dr): rows - max(0, -dr), max(0, dc): cols - max(0, -dc)]
        ok = todo.ravel()[src] & usable.ravel()[dst]
        yield src[ok], dst[ok]


def _solve_laplace(values: np.ndarray, known: np.ndarray, todo: np.ndarray) -> np.ndarray:
    """Solve deg_i u_i - sum_{unknown j} u_j = sum_{known k} v_k on the ``todo`` cells
    (Neumann at cells that are neither known nor todo)."""
    n_cells = todo.size
    unk = np.full(n_cells, -1, np.int64)
    flat_todo = np.flatnonzero(todo)
    unk[flat_todo] = np.arange(flat_todo.size)
    usable = known | todo
    diag = np.zeros(flat_todo.size)
    rhs = np.zeros(flat_todo.size)
    ri, ci = [], []
    vflat, kflat = values.ravel(), known.ravel()
    for src, dst in _neighbour_pairs(todo, usable):
        i = unk[src]
        np.add.at(diag, i, 1.0)
        k = kflat[dst]
        np.add.at(rhs, i[k], vflat[dst[k]])
        ri.append(i[~k])
        ci.append(unk[dst[~k]])
    ri, ci = np.concatenate(ri), np.concatenate(ci)
    a = sparse.csr_matrix(
        (np.concatenate([diag, -np.ones(ri.size)]),
         (np.concatenate([np.arange(diag.size), ri]), np.concatenate([np.arange(diag.size), ci]))),
        shape=(diag.size, diag.size),
    )
    if diag.size <= _DIRECT_MAX:
        return spsolve(a.tocsc(), rhs)
    from scipy.sparse.linalg import cg

    guess = _smooth_guess(values, known, todo)[todo]
    sol, _ = cg(a, rhs, x0=guess, tol=1e-9, maxiter=5000, M=sparse.diags(1.0 / diag))
    return sol


def _smooth_guess(values: np.ndarray, known: np.ndarray, todo: np.ndarray) -> np.ndarray:
    """Multi-scale normalized convolution: a fast first guess for the iterative solver."""
    out = np.where(known, values, 0.0)
    left = todo.copy()
    sigma = 1.0
    while left.any() and sigma < max(todo.shape):
        num = ndimage.gaussian_filter(np.where(known, values, 0.0), sigma)
        den = ndimage.gaussian_filter(known.astype(float), sigma)
        ok = left & (den > 1e-6)
        out[ok] = num[ok] / den[ok]
        left &= ~ok
        sigma *= 2.0
    return out


def fill_holes(diff: np.ndarray, max_cells: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Fill empty (NaN) holes of at most ``max_cells`` cells enclosed by valid cells.
    Returns (filled diff, mask of filled cells)."""
    holes = enclosed_holes(np.isfinite(diff), max_cells)
    filled = harmonic_fill(diff, holes)
    return filled, holes & np.isfinite(filled)


def refill_sparse(
    diff: np.ndarray,
    counts_before: np.ndarray,
    counts_after: np.ndarray,
    ratio: float = 0.5,
    max_hole_cells: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Drop cells whose point count in either epoch is below ``ratio`` x its median count and
    refill the difference there from reliable neighbours; with ``max_hole_cells`` also fill
    enclosed empty holes up to that size. Returns (filled diff, mask of refilled cells); cells
    that cannot be refilled (no reliable neighbour) become NaN."""
    weak = sparse_cells(counts_before, counts_after, ratio) & np.isfinite(diff)
    holes = enclosed_holes(np.isfinite(diff), max_hole_cells)
    targets = weak | holes
    filled = harmonic_fill(diff, targets)
    return filled, targets & np.isfinite(filled)


def summary(diff: np.ndarray, filled_mask: np.ndarray, cell_area: float) -> dict:
    """Counts, areas and the net volume contributed by refilled cells (for the report)."""
    d = np.where(filled_mask, diff, 0.0)
    n = int(filled_mask.sum())
    return {
        "filled_cells": n,
        "filled_area_m2": n * cell_area,
        "filled_net_m3": float(np.nansum(d) * cell_area),
    }
