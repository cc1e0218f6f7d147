"""The engine's native kernels (:data:`SOURCES`): one-pass loops where numpy makes many passes,
loaded with ctypes when a build of these very sources is present (its name carries their
digest), else the numpy path runs (the same bits, slower; said under ``SOILVOLUME_DEBUG``).
``SOILVOLUME_NATIVE=0`` turns them off. Built by ``python -m soilvolume.native.build`` when the
environment is installed, never during a run. A ctypes call releases the GIL. :class:`ChunkArgs`: the
ctypes side of ``sv_chunk`` (one chunk of point records streamed into the working frame in one pass)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import sys
import threading
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCES = tuple(HERE / name for name in ("kernels.h", "chunks.c", "cells.c", "registration.c"))  # one library
ABI = 1  # sv_abi() of chunks.c
ENV = "SOILVOLUME_NATIVE"  # "0": the numpy path only
DIR_ENV = "SOILVOLUME_NATIVE_DIR"  # another folder holding the built library (the plugin's environment)

#: the C types of the kernels' arguments and fields by letter: int64, double, float, a pointer (and
#: "c", an ``sv_chunk_t *``)
TYPES = {"i": ctypes.c_int64, "d": ctypes.c_double, "f": ctypes.c_float, "p": ctypes.c_void_p}
#: ``sv_chunk_t`` of chunks.c field for field: name, type letter and array length
FIELDS = (
    "rec p, n i, stride i, field i3, scale d3, offset d3, origin d3, labels p, framed p, plo d2, pres d, prows i, "
    "pcols i, tlo d2, voxel d, first i2, shape i2, ncols i, sums p, mark p, side_ids p, side p, nside i, chunk i, "
    "flush i, use_box i, box d4, out p, others p, other_labels p, cropped i, kept i, other i, soil i, lo d3, hi d3"
)


class ChunkArgs(ctypes.Structure):
    """``sv_chunk_t`` of chunks.c, field for field (:data:`FIELDS`)."""

    _fields_ = [
        (name, TYPES[kind[0]] * int(kind[1:]) if kind[1:] else TYPES[kind])
        for name, kind in (field.split() for field in FIELDS.split(", "))
    ]


TYPES["c"] = ctypes.POINTER(ChunkArgs)
_lib: ctypes.CDLL | None | bool = False  # False: not looked for yet
#: set while the run's thread needs no interpreter for a while (a long kernel without the GIL, a whole
#: chunk of a file read and worked on; a tiled run's driver waiting for its tasks): another thread may
#: use it meanwhile without slowing this one
OFF_THE_GIL = threading.Event()
#: each kernel's result and arguments (:data:`TYPES`' letters; "-": no result)
PROTOTYPES = {
    "sv_chunk": ("-", "c"),
    "sv_file_chunk": ("i", "ciiipipii"),
    "sv_columns": ("i", "pppiidddiipppp"),
    "sv_cells": ("i", "pppiifffiiiipppp"),
    "sv_sort_keys": ("-", "pipiipp"),
    "sv_keys": ("-", "ppiidipp"),
    "sv_running_sum": ("-", "piip"),
    "sv_nearest_kept": ("i", "pippppppipiidpp"),
    "sv_cut_box": ("i", "pppiiddddpi"),
    "sv_bounds": ("-", "piiiipp"),
    "sv_grid_build": ("-", "piidddiipp"),
    "sv_grid_nearest2": ("-", "pipiidddiippdpp"),
    "sv_icp_terms": ("-", "pippipipidppp"),
    "sv_centroids": ("i", "pipp"),
}


def tag() -> str:
    """This platform's part of the library's name (``linux-x86_64``, ``darwin-arm64``, ``win32-amd64``)."""
    return f"{sys.platform}-{platform.machine().lower()}"


def library_name() -> str:
    """The file name of a build of these sources for this platform."""
    digest = hashlib.sha256(b"".join(path.read_bytes() for path in SOURCES)).hexdigest()[:16]
    suffix = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
    return f"_soilvolume_kernels-{digest}-{tag()}{suffix}"


def kernels() -> ctypes.CDLL | None:
    """The loaded library with its prototypes, or None (no build of these sources, or turned off)."""
    global _lib
    if _lib is False:
        _lib = _load()
    return _lib  # type: ignore[return-value]


def _load() -> ctypes.CDLL | None:
    if os.environ.get(ENV, "1") == "0" or not all(path.exists() for path in SOURCES):
        return None
    name = library_name()
    folders = [Path(os.environ[DIR_ENV])] if os.environ.get(DIR_ENV) else []  # then beside the sources
    path = next((f / name for f in [*folders, HERE] if (f / name).is_file()), None)
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
    for name, (result, args) in PROTOTYPES.items():
        if (fn := getattr(lib, name, None)) is not None:  # all but sv_file_chunk (POSIX builds only)
            fn.argtypes, fn.restype = [TYPES[kind] for kind in args], TYPES.get(result)
    return lib


_scratch = threading.local()


def zeros(name: str, size: int, dtype) -> np.ndarray:
    """A thread's kept array of at least ``size`` zeros, per ``name``, for kernels that leave it zero."""
    have = getattr(_scratch, name, None)
    if have is None or have.size < size:
        have = np.zeros(max(size, 1), dtype)
        setattr(_scratch, name, have)
    return have


def steps(points: np.ndarray, dtype) -> tuple[int, int] | None:
    """(values from one point to the next, from one axis to the next) of an (N, k) ``points`` array
    of ``dtype`` (or its transposed rows); None when a kernel cannot walk it so."""
    size = np.dtype(dtype).itemsize
    if points.dtype != dtype or points.ndim != 2 or min(points.strides) <= 0 or any(s % size for s in points.strides):
        return None
    return points.strides[0] // size, points.strides[1] // size


def axes(points: np.ndarray, dtype) -> tuple[np.ndarray, tuple[int, int, int], int]:
    """(the points as the kernels read them, their first x, y, z addresses, the step between
    points): walkable ones as they are (:func:`steps`), others copied (keep the array alive)."""
    if steps(points, dtype) is None:
        points = np.ascontiguousarray(points, dtype)
    (step, axis), at, size = steps(points, dtype), points.ctypes.data, np.dtype(dtype).itemsize
    return points, (at, at + size * axis, at + 2 * size * axis), step


def address(a: np.ndarray | None) -> int | None:
    """The data address of a C-contiguous array (None for None)."""
    if a is None:
        return None
    assert a.flags.c_contiguous
    return a.ctypes.data


def reset() -> None:
    """Look for the library again at the next :func:`kernels` (tests switch ``SOILVOLUME_NATIVE``)."""
    global _lib
    _lib = False
