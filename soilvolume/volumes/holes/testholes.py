"""The refill's error on known ground: test discs cut out of known cells, refilled and compared with
what was there; apart and surrounded, every disc's biharmonic system is one matrix, solved at once."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy

from .interpolate import fill, harmonic_instead, stencil_system
from .solve import TIKHONOV, beyond, group_solver, refined

MAX_TEST_RADIUS = 32.0  # cells: the largest test hole of the refill error


def fill_error(
    h: np.ndarray, usable: np.ndarray, method: str = "biharmonic", radius: float = 3.0, seed: int = 0
) -> tuple[float, float]:
    """(RMS, one-sigma error of a hole's MEAN height) of the fill (m), on discs of ``radius`` cut from ``usable`` ``h``
    (NaN if no room)."""
    step = 2 * int(np.ceil(radius)) + 5
    cand = np.argwhere(disc_erosion_every(usable & np.isfinite(h), radius + 2, step)) * step
    if len(cand) < 5:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    centres = cand[rng.choice(len(cand), min(40, len(cand)), replace=False)]  # 40 test holes
    mean_err, err = disc_errors(h, centres, radius, method)
    return float(np.sqrt(np.mean(np.square(err)))), float(np.sqrt(np.mean(np.square(mean_err))))


def disc_errors(h: np.ndarray, centres: np.ndarray, radius: float, method: str) -> tuple[np.ndarray, np.ndarray]:
    """(each disc's mean error, every disc cell's error) (m) of ``method``'s refill of apart discs of ``radius`` on
    ``centres`` cut from ``h``."""
    r = int(np.ceil(radius))
    yy, xx = np.mgrid[-r - 2 : r + 3, -r - 2 : r + 3]
    labels = np.zeros(h.shape, np.int32)
    disc = np.argwhere(xx * xx + yy * yy <= radius * radius) - (r + 2)
    labels[centres[:, :1] + disc[:, 0], centres[:, 1:] + disc[:, 1]] = np.arange(1, len(centres) + 1)[:, None]
    targets = labels > 0
    values = np.where(targets, np.nan, h)
    filled = discs_filled(values, targets, centres, disc) if method == "biharmonic" else None
    err = (fill(values, targets, method) if filled is None else filled) - h
    mean_err = scipy.ndimage.mean(np.nan_to_num(err), labels, np.arange(1, len(centres) + 1))
    return np.asarray(mean_err), np.nan_to_num(err[targets])


def error_where(
    h: np.ndarray, usable: np.ndarray, where: np.ndarray, method: str, radius: np.ndarray, seed: int
) -> np.ndarray | None:
    """One-sigma error (m) of a hole's mean height at each ``radius``, on test discs centred in ``where`` (the change
    itself: a trench's floor is not its rim's) of 1, 2, 4 ... cells, up to the first at least the largest ``radius``
    or the largest with room; beyond that, on the log-log trend of the last two (at least as the square root of the
    radius). None without room for the smallest."""
    known = np.pad(usable & np.isfinite(h), 1)
    room = scipy.ndimage.distance_transform_edt(known)[1:-1, 1:-1]
    rows = []
    for r in 2.0 ** np.arange(int(np.ceil(np.log2(min(max(radius.max(), 1.0), MAX_TEST_RADIUS)))) + 1):
        centres = _apart(np.argwhere(where & (room > r + 2)), 2 * int(np.ceil(r)) + 5, seed)
        if len(centres) < 5:
            break
        rows.append((r, float(np.sqrt(np.mean(np.square(disc_errors(h, centres, r, method)[0]))))))
    if not rows:
        return None
    r_m, e_m = np.log(np.array(rows)).T
    at = np.log(np.maximum(radius, 1.0))
    slope = float(np.clip((e_m[-1] - e_m[-2]) / (r_m[-1] - r_m[-2]), 0.5, 2.0)) if len(rows) > 1 else 1.0
    return np.exp(np.interp(at, r_m, e_m) + slope * np.maximum(at - r_m[-1], 0.0))  # beyond: on the last rungs' trend


def _apart(cand: np.ndarray, step: int, seed: int, n: int = 40) -> np.ndarray:
    """Up to ``n`` of the ``cand`` cells (rows, cols) drawn at random, each ``step`` cells from the others."""
    cand = cand[np.random.default_rng(seed).permutation(len(cand))]
    block = cand // step
    _, first = np.unique(
        block[:, 0] * (int(block[:, 1].max(initial=0)) + 1) + block[:, 1], return_index=True
    )  # one per block
    picked: list[tuple[int, int]] = []
    for r, c in cand[np.sort(first)].tolist():  # Python ints: a few numbers per test, no arrays
        if all(max(abs(r - pr), abs(c - pc)) >= step for pr, pc in picked):
            picked.append((r, c))
            if len(picked) == n:
                break
    return np.array(picked, int).reshape(-1, 2)


def error_by_radius(
    h: np.ndarray, usable: np.ndarray, method: str, radius: np.ndarray, seed: int, floor=0.0
) -> np.ndarray | None:
    """:func:`fill_error` at radii 1, 2, 4 ... up to :data:`MAX_TEST_RADIUS`, interpolated in log radius at each
    ``radius`` (at least ``floor``): (radii, 2); None without room."""
    ladder = 2.0 ** np.arange(int(np.log2(min(max(radius.max(), 1.0), MAX_TEST_RADIUS))) + 1)
    rows = [(r, *e) for r in ladder if np.isfinite(e := fill_error(h, usable, method, r, seed=seed)).all()]
    if not rows:
        return None
    r_m, *e_m = np.log(np.maximum(np.array(rows), floor)).T
    at = np.log(np.maximum(radius, 1.0))
    return np.exp(np.stack([np.interp(at, r_m, e) for e in e_m], axis=1))


def discs_filled(values: np.ndarray, targets: np.ndarray, centres: np.ndarray, disc: np.ndarray) -> np.ndarray | None:
    """:func:`.interpolate.biharmonic_fill` of apart, surrounded test discs (else None): one matrix factorised once,
    solved for all."""
    reach = int(np.abs(disc).max()) + 2  # the stencils touching a disc stay within 2 cells of it
    if (centres.min(axis=0) < reach).any() or (centres.max(axis=0) + reach >= values.shape).any():
        return None
    size, flat, mat, normal, (k_rows, k_cells, k_coef), solve = _disc_system(disc.astype(np.int64).tobytes(), reach)
    k_vals = values[_around(centres, k_cells, size)]  # (discs, known terms)
    if solve is None or not np.isfinite(k_vals).all():
        return None
    n_rows = mat.shape[0]
    at_row = (k_rows + n_rows * np.arange(len(centres))[:, None]).ravel()
    rhs = -np.bincount(at_row, weights=(k_coef * k_vals).ravel(), minlength=n_rows * len(centres))
    x = refined(solve, normal, mat.T @ rhs.reshape(len(centres), n_rows).T)  # (disc cells, discs)
    cells = np.ravel_multi_index(_around(centres, flat, size), values.shape)  # (discs, disc cells)
    rank = np.empty(cells.size, np.int64)
    rank[np.argsort(cells.ravel())] = np.arange(cells.size)  # the whole system's unknowns: in grid order
    probe = (1.0 + np.random.default_rng(0).random(cells.size))[rank].reshape(cells.shape).T
    bad = (np.abs(solve(TIKHONOV * probe)) > 0.01).any(axis=0)  # directions only eps pins down
    solved = np.where(np.isfinite(x), x, np.inf)
    bad |= beyond((k_vals.min(axis=1), k_vals.max(axis=1)), (solved.min(axis=0), solved.max(axis=0)), flat.size)
    out = values.copy()
    out.ravel()[cells.ravel()] = x.T.ravel()
    return harmonic_instead(out, values, targets, cells[bad].ravel())  # as biharmonic_fill


@lru_cache(maxsize=16)
def _disc_system(disc: bytes, reach: int):
    """One test disc's system (offsets' bytes; stencils within ``reach``): (patch size, its flat cells,
    matrix, normal matrix, :func:`stencil_system`'s known terms, solve of normal + eps I or None)."""
    size = 2 * reach + 1
    offsets = np.frombuffer(disc, np.int64).reshape(-1, 2)
    todo = np.zeros((size, size), bool)
    todo[offsets[:, 0] + reach, offsets[:, 1] + reach] = True
    flat = np.flatnonzero(todo)
    mat, known, _ = stencil_system(np.ones_like(todo), todo, flat)
    normal = (mat.T @ mat).tocsr()
    n_groups, group = scipy.sparse.csgraph.connected_components(normal, directed=False)
    solve = None
    if n_groups == 1:
        solve, skipped = group_solver(normal + TIKHONOV * scipy.sparse.identity(flat.size, format="csr"), group, 1)
        solve = None if skipped[0] else solve
    return size, flat, mat, normal, known, solve


def _around(centres: np.ndarray, cells: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols), each (discs, cells): the flat ``cells`` of a ``size``-wide patch on each centre."""
    r, c = np.divmod(cells, size)
    half = size // 2
    return centres[:, :1] - half + r, centres[:, 1:] - half + c


def disc_erosion_every(mask: np.ndarray, radius: float, step: int) -> np.ndarray:
    """``scipy.ndimage.binary_erosion(mask, disc)[::step, ::step]`` (outside the grid is not ``mask``), at those cells
    only."""
    r = int(np.ceil(radius))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    near = xx * xx + yy * yy <= radius * radius
    rows = np.arange(0, mask.shape[0], step)[:, None, None] + yy[near]
    cols = np.arange(0, mask.shape[1], step)[None, :, None] + xx[near]
    inside = (rows >= 0) & (rows < mask.shape[0]) & (cols >= 0) & (cols < mask.shape[1])
    looked = mask[np.clip(rows, 0, mask.shape[0] - 1), np.clip(cols, 0, mask.shape[1] - 1)]
    return (looked & inside).all(axis=-1)
