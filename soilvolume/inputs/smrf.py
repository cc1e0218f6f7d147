"""The project's ground filters. The Simple Morphological Filter (Pingel et al. 2013) as PDAL's
filters.smrf implements it: ZImin, the lowest Z per ``cell``, empty cells the mean of the 8 nearest;
low outliers by the progressive filter on -ZImin (slope 5, one pixel); objects where openings of ZImin
by diamonds of radius 1..ceil(window/cell) differ by more than slope * cell * radius; ZIpro, ZImin
without those, refilled; ground where |ZIpro - z| <= threshold + scalar * slope(ZIpro) (last and
single returns only).

The Cloth Simulation Filter (Zhang et al. 2016) by the authors' ``CSF`` module (PyPI
``cloth-simulation-filter``, which PDAL's filters.csf wraps too): a cloth of ``resolution`` cells
dropped on the upturned cloud; points within ``threshold`` of it are ground. The earthworks
defaults, a fine cloth (0.5 m) of medium stiffness (``rigidness`` 2) with slope smoothing, follow
piles and pits yet bridge vehicles and bushes (rigidness 3 would bridge small piles too)."""

from __future__ import annotations

import math
import os
import sys

import numpy as np

from ..core.cells import cell_index
from ..core.types import SoilVolumeError

DEFAULTS = {"resolution": 0.5, "rigidness": 2, "threshold": 0.3, "smooth": True, "step": 0.65, "iterations": 500}
PACKAGE = "cloth-simulation-filter"  # DEFAULTS and PACKAGE: the cloth simulation's
CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


def morph(a: np.ndarray, radius: int, op: str) -> np.ndarray:
    """Grey "erosion" or "dilation" by the diamond of ``radius``: scipy.ndimage's with the 5-point cross,
    iterated; edges repeated, so neighbours outside the raster are ignored, as in PDAL's erodeDiamond and
    dilateDiamond (a zero's sign may differ: openings are only compared)."""
    from scipy import ndimage  # here, as cKDTree below

    for _ in range(radius):
        a = getattr(ndimage, f"grey_{op}")(a, footprint=CROSS, mode="nearest")
    return a


def knnfill(z: np.ndarray, cell: float) -> np.ndarray:
    """Fill NaN cells with the mean of the (up to) 8 nearest non-NaN cell centres."""
    from scipy.spatial import cKDTree  # here: a Dask worker imports this module, never filters

    empty = np.isnan(z)
    if not empty.any() or empty.all():
        return z
    rows, cols = np.indices(z.shape)
    full = ~empty
    tree = cKDTree(np.column_stack([cols[full], rows[full]]) * cell)
    k = min(8, int(full.sum()))
    _, idx = tree.query(np.column_stack([cols[empty], rows[empty]]) * cell, k=k, workers=-1)
    out = z.copy()
    out[empty] = z[full][idx.reshape(idx.shape[0], -1)].mean(axis=1)
    return out


def progressive(zi: np.ndarray, cell: float, slope: float, max_window: float) -> np.ndarray:
    """Object mask of the progressive morphological filter."""
    max_radius = int(math.ceil(max_window / cell))
    prev, erosion = zi, zi
    obj = np.zeros(zi.shape, dtype=bool)
    for radius in range(1, max_radius + 1):
        erosion = morph(erosion, 1, "erosion")
        opening = morph(erosion, radius, "dilation")
        obj |= np.abs(prev - opening) > slope * cell * radius
        prev = opening
    return obj


def _gradient(a: np.ndarray, axis: int) -> np.ndarray:
    if a.shape[axis] < 2:
        return np.zeros_like(a)
    return np.gradient(a, axis=axis)  # central inside, one-sided at the edges (MATLAB's)


def smrf_classify(x, y, z, *, cell=1.0, slope=0.15, window=18.0, threshold=0.5, scalar=1.25) -> np.ndarray:
    """Ground flags (True = ground) for the given points."""
    minx, miny = float(x.min()), float(y.min())
    cols = int((float(x.max()) - minx) / cell + 1)
    rows = int((float(y.max()) - miny) / cell + 1)
    c, r = cell_index(x, minx, cell), cell_index(y, miny, cell)
    flat = r * cols + c
    zimin = np.full(rows * cols, np.inf)
    np.minimum.at(zimin, flat, z)
    zimin[np.isinf(zimin)] = np.nan
    zimin = knnfill(zimin.reshape(rows, cols), cell)
    low = progressive(-zimin, cell, 5.0, cell)
    obj = progressive(zimin, cell, slope, window)
    zipro = knnfill(np.where(obj | low, np.nan, zimin), cell)
    scaled = zipro / cell
    gsurf = knnfill(np.hypot(_gradient(scaled, 1), _gradient(scaled, 0)), cell)
    thresh = threshold + scalar * gsurf
    zp, tp = zipro.ravel()[flat], thresh.ravel()[flat]
    return np.abs(zp - z) <= tp  # NaN comparisons are False: not ground, as PDAL skips them


def csf_classify(x: np.ndarray, y: np.ndarray, z: np.ndarray, **params) -> np.ndarray:
    """Ground mask of the points (metres) by the cloth simulation of ``params`` (:data:`DEFAULTS`)."""
    try:
        import CSF
    except ImportError as exc:
        raise SoilVolumeError(
            f"{{opt:ground=csf}} needs the '{PACKAGE}' package (pip install {PACKAGE}); it is not installed"
        ) from exc
    n = len(x)
    if n == 0:
        return np.zeros(0, bool)
    sim, q = CSF.CSF(), {**DEFAULTS, **params}
    p = sim.params
    p.bSloopSmooth, p.cloth_resolution, p.rigidness = bool(q["smooth"]), float(q["resolution"]), int(q["rigidness"])
    p.class_threshold, p.time_step, p.interations = float(q["threshold"]), float(q["step"]), int(q["iterations"])
    origin = np.array([x.min(), y.min(), z.min()])  # small coordinates: the module works in doubles
    sim.setPointCloud(np.column_stack([x, y, z]).astype(np.float64) - origin)
    ground, other = CSF.VecInt(), CSF.VecInt()
    # the module prints its progress on the process's stdout: file descriptor 1 to the null device for the
    # filtering; ``sys.stdout``, when it writes there, moved to a copy of it (the command line's progress
    # protocol writes on stdout)
    try:
        ours = sys.stdout.fileno() == 1
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both of the last two
        ours = False
    sys.stdout.flush()
    real = os.dup(1)
    python_stdout = sys.stdout
    if ours:
        sys.stdout = os.fdopen(os.dup(real), "w", buffering=1, encoding=python_stdout.encoding)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        sim.do_filtering(ground, other, exportCloth=False)
    finally:
        sys.stdout.flush()
        os.dup2(real, 1)
        os.close(real)
        os.close(null)
        if ours:
            sys.stdout.close()
            sys.stdout = python_stdout
    keep = np.zeros(n, bool)
    keep[np.asarray(ground, dtype=np.int64)] = True
    return keep
