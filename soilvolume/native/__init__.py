"""The engine's native kernels (``kernels.c``): one-pass loops over the points where numpy makes
many passes over memory, loaded with ctypes when a build of this very source is present (its
file name carries the source's digest: a library built from other code is never used), else the
numpy path runs (the same bits, slower). ``SOILVOLUME_NATIVE=0`` turns them off.

Built by ``python -m soilvolume.native.build`` when the environment is installed (``make setup``;
the plugin's installer when the machine has a C compiler; ``make package`` ships the source only,
no binary), never during a run: without a build the numpy path runs, said only under
``SOILVOLUME_DEBUG``. A ctypes call releases the GIL: a kernel on the reading thread runs beside
Python on the other."""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import sys
import threading
from pathlib import Path

import numpy as np

from .chunk import declare

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "kernels.c"
ABI = 1  # sv_abi() of kernels.c
ENV = "SOILVOLUME_NATIVE"  # "0": the numpy path only
DIR_ENV = "SOILVOLUME_NATIVE_DIR"  # another folder holding the built library (the plugin's environment)

_lib: ctypes.CDLL | None | bool = False  # False: not looked for yet


def tag() -> str:
    """This platform's part of the library's name (``linux-x86_64``, ``darwin-arm64``, ``win32-amd64``)."""
    return f"{sys.platform}-{platform.machine().lower()}"


def library_name() -> str:
    """The file name of a build of this source for this platform."""
    digest = hashlib.sha256(SOURCE.read_bytes()).hexdigest()[:16]
    suffix = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
    return f"_soilvolume_kernels-{digest}-{tag()}{suffix}"


def folders() -> list[Path]:
    """Where a built library is looked for: ``SOILVOLUME_NATIVE_DIR``, then beside the source."""
    extra = os.environ.get(DIR_ENV)
    return ([Path(extra)] if extra else []) + [HERE]


def kernels() -> ctypes.CDLL | None:
    """The loaded library with its prototypes, or None (no build of this source, or turned off)."""
    global _lib
    if _lib is False:
        _lib = _load()
    return _lib  # type: ignore[return-value]


def _load() -> ctypes.CDLL | None:
    if os.environ.get(ENV, "1") == "0" or not SOURCE.exists():
        return None
    name = library_name()
    path = next((f / name for f in folders() if (f / name).is_file()), None)
    if path is None:
        if os.environ.get("SOILVOLUME_DEBUG"):
            sys.stderr.write(f"soilvolume: no {name} (python -m soilvolume.native.build): the numpy path runs\n")
        return None
    try:
        lib = ctypes.CDLL(str(path))
        lib.sv_abi.restype = ctypes.c_int64
        if lib.sv_abi() != ABI:
            return None
    except (OSError, AttributeError):
        return None
    declare(lib)
    _declare(lib)
    return lib


def _declare(lib: ctypes.CDLL) -> None:
    """The prototypes of the kernels other than the chunk's."""
    i64, f64, ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_void_p
    lib.sv_columns.argtypes = [ptr, ptr, ptr, i64, i64, f64, f64, f64, i64, i64, ptr, ptr, ptr, ptr]
    lib.sv_columns.restype = i64
    f32 = ctypes.c_float
    lib.sv_cells.argtypes = [ptr, ptr, ptr, i64, i64, f32, f32, f32, i64, i64, i64, i64, ptr, ptr, ptr, ptr]
    lib.sv_cells.restype = i64
    lib.sv_sort_keys.argtypes = [ptr, i64, ptr, i64, i64, ptr, ptr]
    lib.sv_sort_keys.restype = None
    lib.sv_keys.argtypes = [ptr, ptr, i64, i64, f64, i64, ptr, ptr]
    lib.sv_keys.restype = None
    lib.sv_running_sum.argtypes = [ptr, i64, i64, ptr]
    lib.sv_running_sum.restype = None
    lib.sv_nearest_kept.argtypes = [ptr, i64, ptr, ptr, ptr, ptr, ptr, ptr, i64, ptr, i64, i64, f64, ptr, ptr]
    lib.sv_nearest_kept.restype = i64
    lib.sv_cut_box.argtypes = [ptr, ptr, ptr, i64, i64, f64, f64, f64, f64, ptr, i64]
    lib.sv_cut_box.restype = i64
    lib.sv_bounds.argtypes = [ptr, i64, i64, i64, i64, ptr, ptr]
    lib.sv_bounds.restype = None
    lib.sv_grid_build.argtypes = [ptr, i64, i64, f64, f64, f64, i64, i64, ptr, ptr]
    lib.sv_grid_build.restype = None
    lib.sv_grid_nearest2.argtypes = [ptr, i64, ptr, i64, i64, f64, f64, f64, i64, i64, ptr, ptr, f64, ptr, ptr]
    lib.sv_grid_nearest2.restype = None
    lib.sv_icp_terms.argtypes = [ptr, i64, ptr, ptr, i64, ptr, i64, ptr, i64, f64, ptr, ptr, ptr]
    lib.sv_icp_terms.restype = None
    lib.sv_centroids.argtypes = [ptr, i64, ptr, ptr]
    lib.sv_centroids.restype = i64


_scratch = threading.local()


def zeros(name: str, size: int, dtype) -> np.ndarray:
    """A thread's array of at least ``size`` zeros kept for the kernels that leave it zero (one
    per ``name``: no fresh pages to fault in at every call)."""
    have = getattr(_scratch, name, None)
    if have is None or have.size < size:
        have = np.zeros(max(size, 1), dtype)
        setattr(_scratch, name, have)
    return have


def steps(points: np.ndarray, dtype) -> tuple[int, int] | None:
    """(values from one point to the next, from one axis to the next) of ``points``, an (N, k)
    array of ``dtype`` or its transposed (k, N) rows, as a kernel walks them; None when the
    kernels cannot walk it so (another dtype, strides not whole values, or not positive)."""
    size = np.dtype(dtype).itemsize
    if points.dtype != dtype or points.ndim != 2 or min(points.strides) <= 0 or any(s % size for s in points.strides):
        return None
    return points.strides[0] // size, points.strides[1] // size


def axes(points: np.ndarray, dtype) -> tuple[np.ndarray, tuple[int, int, int], int]:
    """(the points as the kernels read them, the addresses of their first x, y and z, the values
    from one point's to the next's): an (N, 3) array of ``dtype`` or its transposed (3, N) rows as
    they are (:func:`steps`), any other copied into a C-ordered one of ``dtype`` (keep the array
    while the addresses are used)."""
    walk = steps(points, dtype)
    if walk is None:
        points = np.ascontiguousarray(points, dtype)
        walk = steps(points, dtype)
    (step, axis), at, size = walk, points.ctypes.data, np.dtype(dtype).itemsize
    return points, (at, at + size * axis, at + 2 * size * axis), step


def reset() -> None:
    """Look for the library again at the next :func:`kernels` (tests switch ``SOILVOLUME_NATIVE``)."""
    global _lib
    _lib = False
