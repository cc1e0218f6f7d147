"""ctypes side of ``sv_chunk`` (kernels.c): one chunk of point records streamed into the working
frame in one pass (decode, crop, labels, thinning, the kept points as float32)."""

from __future__ import annotations

import ctypes

import numpy as np

#: the C types of the kernels' arguments and fields by letter: int64, double, float, a pointer (and
#: "c", an ``sv_chunk_t *``)
TYPES = {"i": ctypes.c_int64, "d": ctypes.c_double, "f": ctypes.c_float, "p": ctypes.c_void_p}
#: ``sv_chunk_t`` of kernels.c field for field: name, type letter and array length
FIELDS = (
    "rec p, n i, stride i, field i3, scale d3, offset d3, origin d3, labels p, framed p, plo d2, pres d, prows i, "
    "pcols i, tlo d2, voxel d, first i2, shape i2, ncols i, sums p, mark p, side_ids p, side p, nside i, chunk i, "
    "flush i, use_box i, box d4, out p, others p, other_labels p, cropped i, kept i, other i, soil i, lo d3, hi d3"
)


class ChunkArgs(ctypes.Structure):
    """``sv_chunk_t`` of kernels.c, field for field (:data:`FIELDS`)."""

    _fields_ = [
        (name, TYPES[kind[0]] * int(kind[1:]) if kind[1:] else TYPES[kind])
        for name, kind in (field.split() for field in FIELDS.split(", "))
    ]


TYPES["c"] = ctypes.POINTER(ChunkArgs)


def address(a: np.ndarray | None) -> int | None:
    """The data address of a C-contiguous array (None for None)."""
    if a is None:
        return None
    assert a.flags.c_contiguous
    return a.ctypes.data
