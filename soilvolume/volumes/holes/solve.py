"""The biharmonic refill's least-squares solve: the normal equations' coupled groups each factorised
once (banded Cholesky batched by bandwidth, SuperLU if wider), refined, and ill-posed or wild groups
sent to the harmonic fill. CSR matrices are built from their rows (scipy's arrays, no COO trip)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy

TIKHONOV = 1e-10  # biharmonic normal matrix + eps I: factorisable even where the system is singular
_REFINE_MAX = 30  # iterative-refinement steps removing eps where the system is well posed
_BAND_EDGES = np.unique(np.ceil(8 * 1.25 ** np.arange(16)).astype(int))  # banded Cholesky up to ~230
_BIG_GROUP = 200_000  # coupled biharmonic unknowns beyond which a sub-system is filled harmonically


def rows_csr(rows: np.ndarray, cols: np.ndarray, data: np.ndarray, shape: tuple[int, int]) -> scipy.sparse.csr_matrix:
    """``csr_matrix((data, (rows, cols)))`` of entries row by row, columns increasing, built directly."""
    idx = np.int32 if max(shape[0], shape[1], data.size) < np.iinfo(np.int32).max else np.int64
    indptr = np.zeros(shape[0] + 1, idx)
    np.cumsum(np.bincount(rows, minlength=shape[0]), out=indptr[1:])
    return scipy.sparse.csr_matrix((data, cols.astype(idx), indptr), shape=shape)


def lower_triangle(a: scipy.sparse.csr_matrix) -> scipy.sparse.csr_matrix:
    """``scipy.sparse.tril(a, format="csr")``, taken from the rows directly when ``a`` is canonical."""
    a = a.tocsr()
    if not a.has_canonical_format:
        return scipy.sparse.tril(a, format="csr")
    row = np.repeat(np.arange(a.shape[0]), np.diff(a.indptr))
    keep = a.indices <= row
    indptr = np.zeros_like(a.indptr)
    np.cumsum(np.bincount(row[keep], minlength=a.shape[0]), out=indptr[1:])
    return scipy.sparse.csr_matrix((a.data[keep], a.indices[keep], indptr), shape=a.shape)


def least_squares(mat, rhs, k_rows, k_vals) -> tuple[np.ndarray, np.ndarray]:
    """(``mat x = rhs`` by one factorisation of ``normal + eps I`` refined, the unknowns to fill harmonically)."""
    normal = (mat.T @ mat).tocsr()
    g = mat.T @ rhs
    n_groups, group = scipy.sparse.csgraph.connected_components(normal, directed=False)
    solve, bad = group_solver(normal + TIKHONOV * scipy.sparse.identity(g.size, format="csr"), group, n_groups)
    x = refined(solve, normal, g)
    probe = 1.0 + np.random.default_rng(0).random(g.size)
    null = np.abs(solve(TIKHONOV * probe)) > 0.01  # directions only eps pins down: ill posed
    bad |= np.bincount(group, weights=null, minlength=n_groups) > 0
    has = np.diff(mat.indptr) > 0  # each row's group (its first unknown's): the range of the known values it holds
    row_group = np.full(mat.shape[0], -1)
    row_group[has] = group[mat.indices[mat.indptr[:-1][has]]]
    kg = row_group[k_rows]
    known = _group_range(kg[kg >= 0], k_vals[kg >= 0], n_groups)
    solved = _group_range(group, np.where(np.isfinite(x), x, np.inf), n_groups)
    bad |= beyond(known, solved, np.bincount(group, minlength=n_groups))  # wild: not finite, or far outside them
    return x, bad[group]


def refined(solve: Callable[[np.ndarray], np.ndarray], normal: scipy.sparse.csr_matrix, g: np.ndarray) -> np.ndarray:
    """``normal x = g`` by ``solve`` (of ``normal + eps I``), refined until converged or stalled at round-off."""
    x, last = solve(g), np.inf
    for _ in range(_REFINE_MAX):
        dx = solve(g - normal @ x)
        x += dx
        step = np.abs(dx).max()
        if not (step > 1e-9 * (1.0 + np.abs(x).max()) and step < 0.5 * last):
            break
        last = step
    return x


def group_solver(reg: scipy.sparse.spmatrix, group: np.ndarray, n_groups: int):
    """(solve, per-group skipped flags) of the block-diagonal SPD ``reg`` (blocks: ``group``): banded
    Cholesky batched by bandwidth, SuperLU if wider, blocks over ``_BIG_GROUP`` skipped (0)."""
    low = lower_triangle(reg)
    row = np.repeat(np.arange(low.shape[0]), np.diff(low.indptr))
    size = np.bincount(group, minlength=n_groups)
    order = np.argsort(group, kind="stable")
    pos = np.empty_like(order)
    pos[order] = np.arange(order.size)
    row_band = np.maximum.reduceat(pos[row] - pos[low.indices], low.indptr[:-1])  # diagonal in every row
    # each group's kind: its bandwidth's index in _BAND_EDGES, that size if wider (SuperLU), one more if over
    # _BIG_GROUP (skipped); the unknowns ordered by kind, group, grid order
    kind = np.searchsorted(_BAND_EDGES, np.maximum.reduceat(row_band[order], np.cumsum(size) - size))
    kind[size > _BIG_GROUP] = _BAND_EDGES.size + 1
    order = order[np.argsort(kind[group[order]], kind="stable")]
    pos[order] = np.arange(order.size)
    bounds = np.searchsorted(kind[group[order]], np.arange(_BAND_EDGES.size + 2))
    pr, pc = pos[row], pos[low.indices]
    by_row = np.argsort(pr, kind="stable")
    cut = np.searchsorted(pr[by_row], bounds)
    blocks, skipped = [], kind > _BAND_EDGES.size
    for k in range(_BAND_EDGES.size + 1):
        lo, hi = bounds[k], bounds[k + 1]
        if hi > lo:
            e = by_row[cut[k] : cut[k + 1]]
            try:
                blocks.append((lo, hi, _factor(k, pr[e] - lo, pc[e] - lo, low.data[e], hi - lo)))
            except (np.linalg.LinAlgError, RuntimeError):
                skipped[np.unique(group[order[lo:hi]])] = True

    def solve(b: np.ndarray) -> np.ndarray:
        y = b[order]
        y[bounds[-1] :] = 0.0
        for lo, hi, f in blocks:
            y[lo:hi] = f(y[lo:hi])
        x = np.empty_like(y)
        x[order] = y
        return x

    return solve, skipped


def _factor(kind: int, pi: np.ndarray, pj: np.ndarray, data: np.ndarray, n: int):
    """The solve of an SPD matrix's lower triangle: banded Cholesky of ``_BAND_EDGES[kind]``, else SuperLU."""
    if kind < _BAND_EDGES.size:
        ab = np.zeros((_BAND_EDGES[kind] + 1, n))
        ab[pi - pj, pj] = data
        chol = scipy.linalg.cholesky_banded(ab, lower=True, check_finite=False)
        return lambda b: scipy.linalg.cho_solve_banded((chol, True), b, check_finite=False)
    tri = scipy.sparse.csc_matrix((data, (pi, pj)), shape=(n, n))
    full = (tri + scipy.sparse.tril(tri, -1).T).tocsc()
    lu = scipy.sparse.linalg.splu(
        full, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    return lu.solve


def beyond(known: tuple, solved: tuple, size) -> np.ndarray:
    """Whether each group's solution (``solved``: min, max; +inf if not finite) is not finite or leaves
    its known stencil values' range (``known``: min, max) by a generous margin for ``size`` unknowns."""
    (lo, hi), (xlo, xhi) = known, solved
    with np.errstate(invalid="ignore"):  # groups without known values: NaN margin -> wild
        allow = (hi - lo) * np.maximum(4.0, np.sqrt(size)) + 1e-9 * (1.0 + np.abs(lo) + np.abs(hi))
        return ~np.isfinite(xhi) | ~(xlo >= lo - allow) | ~(xhi <= hi + allow)


def _group_range(groups: np.ndarray, vals: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-group min and max of ``vals`` (+inf/-inf for empty groups)."""
    order = np.argsort(groups, kind="stable")
    g, v = groups[order], vals[order]
    lo, hi = np.full(n, np.inf), np.full(n, -np.inf)
    if g.size:
        starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        lo[g[starts]] = np.minimum.reduceat(v, starts)
        hi[g[starts]] = np.maximum.reduceat(v, starts)
    return lo, hi
