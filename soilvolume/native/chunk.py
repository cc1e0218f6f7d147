"""ctypes side of ``sv_chunk`` (kernels.c): one chunk of point records streamed into the working
frame in one pass (decode, crop, labels, thinning, the kept points as float32)."""

from __future__ import annotations

import ctypes

import numpy as np

_D3, _D2, _D4 = ctypes.c_double * 3, ctypes.c_double * 2, ctypes.c_double * 4
_I3, _I2 = ctypes.c_int64 * 3, ctypes.c_int64 * 2
_P = ctypes.c_void_p


class ChunkArgs(ctypes.Structure):
    """``sv_chunk_t`` of kernels.c, field for field."""

    _fields_ = [
        ("rec", _P),
        ("n", ctypes.c_int64),
        ("stride", ctypes.c_int64),
        ("field", _I3),
        ("scale", _D3),
        ("offset", _D3),
        ("origin", _D3),
        ("labels", _P),
        ("framed", _P),
        ("plo", _D2),
        ("pres", ctypes.c_double),
        ("prows", ctypes.c_int64),
        ("pcols", ctypes.c_int64),
        ("tlo", _D2),
        ("voxel", ctypes.c_double),
        ("first", _I2),
        ("shape", _I2),
        ("ncols", ctypes.c_int64),
        ("sums", _P),
        ("mark", _P),
        ("side_ids", _P),
        ("side", _P),
        ("nside", ctypes.c_int64),
        ("chunk", ctypes.c_int64),
        ("flush", ctypes.c_int64),
        ("use_box", ctypes.c_int64),
        ("box", _D4),
        ("out", _P),
        ("others", _P),
        ("other_labels", _P),
        ("cropped", ctypes.c_int64),
        ("kept", ctypes.c_int64),
        ("other", ctypes.c_int64),
        ("soil", ctypes.c_int64),
        ("lo", _D3),
        ("hi", _D3),
    ]


def declare(lib: ctypes.CDLL) -> None:
    """The prototypes of the chunk kernels (``sv_file_chunk``: POSIX builds only)."""
    lib.sv_chunk.argtypes, lib.sv_chunk.restype = [ctypes.POINTER(ChunkArgs)], None
    if hasattr(lib, "sv_file_chunk"):
        i64 = ctypes.c_int64
        lib.sv_file_chunk.argtypes = [ctypes.POINTER(ChunkArgs), i64, i64, i64, _P, i64, _P, i64, i64]
        lib.sv_file_chunk.restype = i64


def address(a: np.ndarray | None) -> int | None:
    """The data address of a C-contiguous array (None for None)."""
    if a is None:
        return None
    assert a.flags.c_contiguous
    return a.ctypes.data
