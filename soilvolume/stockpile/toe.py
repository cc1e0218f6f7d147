"""A pile's toe: heights along its polygon's boundary, each from a robust plane fitted to the
ground cells around it outside the polygon (the toe line is drawn on the ground, the pile inside
it; cells standing off the plane are trimmed), so that neither the noise of one cell nor the
pile's skirt moves it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from .survey import NOISE_FLOOR, Survey

HALF_WINDOW = 5  # cells each side of a toe point whose heights (those outside) its plane is fitted to
FEWEST = 6  # cells outside the polygon a toe point's fit needs, else it takes the inside ones too
TRIM = 2.5  # cells this many robust deviations off a toe point's plane are left out (a skirt: above it)
PASSES = 3  # fits of a toe point's plane, each without the cells the last one found off it


@dataclass(frozen=True)
class Toe:
    """Toe points ``x``, ``y`` (local m) along the polygon's exterior rings with their heights
    ``z`` (m), each point's share ``weight`` (m) of the toe's length (trapezoid rule: the ring's
    vertices are points, so the mean of any height linear along each edge is exact), the noise
    of each toe height ``sigma`` (m) and of a cell ``noise`` (m), and ``reach`` (m) the side of the
    window of cells each toe height is fitted to (heights closer than it share cells); ``missing``
    (m) the length of toe without any measured cell near it (left out)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    weight: np.ndarray
    sigma: np.ndarray
    noise: float
    reach: float
    missing: float = 0.0

    def plane(self) -> np.ndarray:
        """The least-squares plane ``(a, b, c)`` of ``z = a + b x + c y`` through the toe heights
        (weighted by their share of the toe)."""
        a = np.column_stack([np.ones_like(self.x), self.x, self.y])
        w = np.sqrt(self.weight)
        return np.linalg.lstsq(a * w[:, None], self.z * w, rcond=None)[0]

    def mean(self) -> float:
        """The toe's mean height along its length."""
        return float(np.sum(self.z * self.weight) / np.sum(self.weight))


def toe_points(polygon: BaseGeometry, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, weight) of points along each exterior ring of ``polygon``: its vertices and points
    at most ``spacing`` apart, each weighted by half the distance to its neighbours; the same
    points whichever vertex a ring starts at and whichever way it runs (normalised first)."""
    xs, ys, ws = [], [], []
    for part in shapely.get_parts(shapely.normalize(polygon)):
        ring = part.exterior
        verts = np.asarray(ring.coords)[:-1]
        at = np.array([ring.project(shapely.Point(v)) for v in verts])
        n = max(8, int(np.ceil(ring.length / spacing)))
        along = np.unique(np.concatenate([at, np.linspace(0.0, ring.length, n, endpoint=False)]))
        pts = shapely.get_coordinates(shapely.line_interpolate_point(ring, along))
        gaps = np.diff(np.concatenate([along, [along[0] + ring.length]]))
        ws.append(0.5 * (gaps + np.roll(gaps, 1)))
        xs.append(pts[:, 0])
        ys.append(pts[:, 1])
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(ws)


def toe_of(polygon: BaseGeometry, survey: Survey) -> Toe | None:
    """The :class:`Toe` of ``polygon`` on ``survey``: heights at points one cell apart (those
    without any measured cell near them left out); None without 3 toe heights."""
    grid = survey.grid
    x, y, w = toe_points(polygon, grid.cell)
    z, resid, used, factor = local_planes(survey, x, y, polygon)
    ok = used > 0
    if ok.sum() < 3:
        return None
    n = max(4.0, float(np.median(used[ok])))  # a plane's 3 terms fitted: residuals have n - 3 degrees of freedom
    noise = max(NOISE_FLOOR, 1.4826 * float(np.nanmedian(np.abs(resid[ok]))) * np.sqrt(n / (n - 3)))
    sigma = noise * np.sqrt(factor[ok])  # the fitted plane's height at the toe point
    reach = (2 * HALF_WINDOW + 1) * grid.cell
    return Toe(x[ok], y[ok], z[ok], w[ok], sigma, noise, reach, float(w[~ok].sum()))


def _windows(survey: Survey, x: np.ndarray, y: np.ndarray, polygon: BaseGeometry) -> tuple[np.ndarray, ...]:
    """For each point: the offsets (dx, dy, m) of the cells of its window and their heights and
    whether each is a measured cell of the grid outside ``polygon`` (inside too where fewer than
    :data:`FEWEST` are outside), each (points, window cells)."""
    g = survey.grid
    col = np.floor((x + g.origin[0] - g.xmin) / g.cell).astype(np.int64)
    row = np.floor((g.ymax - g.origin[1] - y) / g.cell).astype(np.int64)
    k = np.arange(-HALF_WINDOW, HALF_WINDOW + 1)
    dr, dc = (a.ravel() for a in np.meshgrid(k, k, indexing="ij"))
    rr, cc = row[:, None] + dr[None, :], col[:, None] + dc[None, :]
    ok = (rr >= 0) & (rr < g.rows) & (cc >= 0) & (cc < g.cols)
    rr, cc = np.clip(rr, 0, g.rows - 1), np.clip(cc, 0, g.cols - 1)
    h = survey.heights[rr, cc]
    ok &= np.isfinite(h)
    cx = g.xmin - g.origin[0] + (cc + 0.5) * g.cell
    cy = g.ymax - g.origin[1] - (rr + 0.5) * g.cell
    out = ok & ~shapely.contains_xy(polygon, cx, cy)
    ok = np.where(out.sum(axis=1, keepdims=True) >= FEWEST, out, ok)
    return cx - x[:, None], cy - y[:, None], np.where(ok, h, 0.0), ok


def local_planes(survey: Survey, x: np.ndarray, y: np.ndarray, polygon: BaseGeometry) -> tuple[np.ndarray, ...]:
    """(height at each point, the final fits' residuals of their cells (NaN where unused), the
    cells each fit used, the variance of each height per unit cell variance): planes fitted to
    each point's window, :data:`PASSES` times, each time without the cells more than :data:`TRIM`
    robust deviations off the last plane."""
    dx, dy, h, use = _windows(survey, x, y, polygon)
    coef = np.zeros((len(x), 3))
    for _ in range(PASSES):
        coef, _ = _fit(dx, dy, h, use)
        resid = h - (coef[:, :1] + coef[:, 1:2] * dx + coef[:, 2:] * dy)
        masked = np.where(use, np.abs(resid), np.nan)
        masked[~use.any(axis=1)] = 0.0  # a toe point without any cell: no all-NaN median (and its warning)
        s = np.maximum(1.4826 * np.nanmedian(masked, axis=1, keepdims=True), NOISE_FLOOR)
        keep = use & (np.abs(resid) < TRIM * s)
        keep |= keep.sum(axis=1, keepdims=True) < 3  # too few left: keep what there is
        use = keep & use
    coef, factor = _fit(dx, dy, h, use)
    resid = h - (coef[:, :1] + coef[:, 1:2] * dx + coef[:, 2:] * dy)
    return coef[:, 0], np.where(use, resid, np.nan), use.sum(axis=1), factor


def _fit(dx: np.ndarray, dy: np.ndarray, h: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point, the plane (height at the point, x slope, y slope) least-squares fitted to the
    cells ``use`` marks (a tiny ridge keeps fits on too few cells defined: they go flat), and the
    variance of its height per unit variance of a cell."""
    w = use.astype(np.float64)
    a = np.stack([np.ones_like(dx), dx, dy], axis=-1) * w[..., None]
    ata = np.einsum("pki,pkj->pij", a, a) + np.diag([1e-9, 1e-6, 1e-6])
    atb = np.einsum("pki,pk->pi", a, h * w)
    inv = np.linalg.inv(ata)
    return np.einsum("pij,pj->pi", inv, atb), inv[:, 0, 0]
