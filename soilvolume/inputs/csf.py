"""The Cloth Simulation Filter (Zhang et al. 2016) by the authors' ``CSF`` module (PyPI
``cloth-simulation-filter``, which PDAL's filters.csf wraps too): a cloth of ``resolution`` cells
dropped on the upturned cloud; points within ``threshold`` of it are ground. The earthworks
defaults, a fine cloth (0.5 m) of medium stiffness (``rigidness`` 2) with slope smoothing, follow
piles and pits yet bridge vehicles and bushes (rigidness 3 would bridge small piles too)."""

from __future__ import annotations

import io
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from ..core.types import SoilVolumeError

DEFAULTS = {"resolution": 0.5, "rigidness": 2, "threshold": 0.3, "smooth": True, "step": 0.65, "iterations": 500}
PACKAGE = "cloth-simulation-filter"


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
    with _quiet_native_stdout():  # the module prints its progress on the process's stdout
        sim.do_filtering(ground, other, exportCloth=False)
    keep = np.zeros(n, bool)
    keep[np.asarray(ground, dtype=np.int64)] = True
    return keep


@contextmanager
def _quiet_native_stdout() -> Iterator[None]:
    """File descriptor 1 to the null device for the block; ``sys.stdout``, when it writes there,
    moved to a copy of it (the command line's progress protocol writes on stdout)."""
    try:
        ours = sys.stdout.fileno() == 1
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        ours = False
    sys.stdout.flush()
    real = os.dup(1)
    python_stdout = sys.stdout
    if ours:
        sys.stdout = os.fdopen(os.dup(real), "w", buffering=1, encoding=python_stdout.encoding)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(real, 1)
        os.close(real)
        os.close(null)
        if ours:
            sys.stdout.close()
            sys.stdout = python_stdout
