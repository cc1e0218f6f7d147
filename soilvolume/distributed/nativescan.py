"""The first pass's scan of a whole LAS/LAZ file on the native chunk kernel
(:class:`~soilvolume.inputs.chunkwork.NativeChunks`, as :func:`soilvolume.inputs.stream.load`
streams one): decode, crop, labels, thinning and the points kept for the grid in one pass,
without the GIL (the driver scans tiles while the cluster starts; its imports share the cores).

It returns what :func:`.scan.scan_unit` computes in numpy: the same sums and counts, the same
kept chunks (one per ``CHUNK`` points) with soil points first, then the others, each in file
order: the grid takes them apart (:func:`.gridtile._epoch`), its sums byte-identical."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np

from .. import native
from ..core.types import SoilVolumeError
from ..inputs.chunkwork import Growing, NativeChunks, consume, native_work
from ..inputs.lasread import is_copc
from ..inputs.records import FileChunk, las_records
from ..inputs.stream import CHUNK, file_kernel, native_reads, open_source
from ..inputs.thinning import ColumnThinner, narrowed
from ..soil.points import PointRule

NOTHING = (np.full(2, np.inf), np.full(2, -np.inf))  # a box no point is in: no points kept


def native_scan(path: str, to_local, rule: PointRule, keep, thinning: tuple, kept: list | None) -> dict | None:
    """The scan of the file ``path`` (counts, the thinning ``sums`` as a
    :class:`.thinning.Block`; each chunk's kept points and labels appended to ``kept``, a list),
    or None where the kernel does not apply: no library, a frame not a plain shift, a crop not a
    lattice, a COPC, empty or unreadable file. Thinned on the columns meeting its header's box
    (points outside fail the reader's bounds check), not the epoch's, zeroed and swept per tile;
    if a point missed them, scanned again on all (its sums those of its columns with points)."""
    if is_copc(path):
        return None
    try:
        src = open_source(path)
    except SoilVolumeError:  # an empty or unreadable tile: the numpy scan says what it says of it
        return None
    if src.raw is not None or not native_reads(src, to_local, keep):
        return None
    pad = thinning[2]  # a column: the lattice adds one more on each side
    box = (src.lo[:2] - to_local.origin[:2] - pad, src.hi[:2] - to_local.origin[:2] + pad)
    tile = ColumnThinner(*narrowed(thinning, box))
    res, thinner, chunks = _scan(src, path, to_local, rule, keep, tile, kept is not None)
    if float(thinner.sums[3].sum()) == res["cropped"]:
        res["sums"] = thinner.block()
    else:  # a point off the header's box: on all the columns, the sums of those with points
        res, thinner, chunks = _scan(src, path, to_local, rule, keep, ColumnThinner(*thinning), kept is not None)
        res["sums"] = thinner.occupied()
    if kept is not None:
        kept.extend(chunks)
    return res


def _scan(src, path: str, to_local, rule: PointRule, keep, thinner: ColumnThinner, keeping: bool) -> tuple:
    """(the scan's counts, ``thinner`` fed, each chunk's kept points and labels if ``keeping``)."""
    out = Growing(src.count if keeping else 0), Growing(0), Growing(0, None, np.uint8)
    kernel = NativeChunks(native.kernels(), thinner, keep, None if keeping else NOTHING, to_local.origin, CHUNK)
    direct = (lambda has_class: rule.class_table(has_class)) if file_kernel() else None
    records = las_records(Path(path), src.count, CHUNK, lambda _cls: rule.signal_dims, direct=direct)
    items = ((rec, None if isinstance(rec, FileChunk) else rule.labels(cls, sig), rule) for rec, cls, sig in records)
    ends, labelled = [], False

    def work(item: tuple) -> tuple:
        nonlocal labelled
        rec, labels, _ = item
        labelled = labelled or labels is not None or (isinstance(rec, FileChunk) and rec.table is not None)
        got = native_work(kernel, item, out)
        if rec.flush:  # the end of a chunk of CHUNK points: of a kept chunk
            ends.append((out[0].n, out[1].n))
        return got

    try:
        points, used, cropped, _, _ = consume(items, work, None, None)
    finally:
        kernel.close()
    res = {"points": points, "used": used, "cropped": cropped, "index": []}
    chunks = []  # each kept chunk's (local float32 xyz, labels or None): its soil points, then its others
    if keeping:
        soil, other, labels = (g.result() for g in out)
        for (a0, b0), (a1, b1) in pairwise([(0, 0), *ends]):
            lab = np.concatenate([np.zeros(a1 - a0, np.uint8), labels[b0:b1]]) if labelled else None
            chunks.append((np.concatenate([soil[a0:a1], other[b0:b1]]), lab))
    return res, thinner, chunks
