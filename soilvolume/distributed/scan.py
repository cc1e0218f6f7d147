"""The tiled engine's first pass as Dask tasks, each streaming one unit of a source (a range of a
LAS/LAZ file's points, or a VPC tile) and returning its column-thinning sums, counts and chunk
boxes: a drop-in for :func:`stream.load` keeping no full-resolution points, for :func:`prepare.prepare`.

A whole LAS/LAZ file is scanned on the native chunk kernel (:class:`~soilvolume.inputs.chunkwork.NativeChunks`,
as :func:`stream.load` streams one): decode, crop, labels, thinning and the points kept for the grid in one
pass, without the GIL (the driver scans tiles while the cluster starts; its imports share the cores): numpy's
sums and counts, the same kept chunks (one per ``CHUNK`` points) with soil points first, then the others,
each in file order: the grid takes them apart (:func:`.gridtile._epoch`), its sums byte-identical."""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import replace
from itertools import chain, pairwise
from pathlib import Path

import numpy as np

from .. import native
from ..core.cells import bounds, rows
from ..core.types import SoilVolumeError
from ..inputs import stream
from ..inputs.chunkwork import NOTHING, Growing, NativeChunks, consume, native_work
from ..inputs.lasread import is_copc, read_fraction
from ..inputs.records import FileChunk, las_records
from ..inputs.stream import CHUNK, Loaded, Source, epoch_rule, file_chunks, file_kernel, las_ranges, load, native_reads
from ..inputs.thinning import Block, ColumnThinner, narrowed
from ..soil.points import SOIL, NonSoil, PointRule
from .pointcache import KeptTile, kept_chunk, read_tile
from .waiting import completed

UNIT = 8_000_000  # points per task of a single file
# COPC files are read for registration only down to the octree level whose spacing puts about
# this many points squared in a registration column (a column centroid of ~16 points instead of
# all of them: ~4x less noise than one point, a fraction of the reading)
COPC_POINTS_PER_COLUMN_SIDE = 4.0
Unit = tuple[str, int | None, int | None]  # path, first point, point count (None: the whole file)


def units(src: Source) -> list[Unit]:
    """The pieces of ``src`` one task each streams."""
    if src.vpc is not None:
        return [(p, None, None) for p in src.tiles()]
    if is_copc(src.path):
        return [(src.path, None, None)]
    return [(src.path, s, min(UNIT, src.count - s)) for s in range(0, src.count, UNIT)]


def scan_unit(
    unit: Unit, region, to_local, rule: PointRule, keep, thinning: tuple, indexed: bool, cached=None, kept=None
) -> dict:
    """Thinning sums, counts and chunk boxes of one unit's soil points; ``cached``: its chunks read
    already, left intact; ``kept`` (a list): each chunk's kept points and labels appended."""
    path, start, count = unit
    voxel = thinning[2]  # (lo, hi, voxel[, within]) of the driver's ColumnThinner
    resolution = voxel / COPC_POINTS_PER_COLUMN_SIDE if start is None and is_copc(path) else None
    if cached is None and resolution is None and start is None:
        done = native_scan(path, to_local, rule, keep, thinning, kept)
        if done is not None:
            return {"unit": tuple(unit), **done}
    shift = to_local if cached is not None else getattr(to_local, "inplace", to_local)
    if cached is not None:
        chunks = iter(cached)
    elif start is None:
        chunks = file_chunks(path, region, CHUNK, resolution, signals=True)
    else:
        chunks = las_ranges(path, [(start, count)], CHUNK, signals=True)
    thinner = ColumnThinner(*thinning)
    out = {"unit": tuple(unit), "points": 0, "used": 0, "cropped": 0, "index": []}
    for xyz, cls, sig in chunks:
        if indexed and start is not None:  # a range of a single file: its chunks' boxes bound the grid's reads
            out["index"].append((start + out["points"], len(xyz), *bounds(xyz, 2)))
        out["points"] += len(xyz)
        local = shift(xyz)  # a chunk the reader allocated: shifted in place (a cached one: copied)
        labels = rule.labels(cls, sig)
        inside = None if keep is None else keep(local)
        if kept is not None:
            kept.append(kept_chunk(local, labels, inside))
        mask = None if labels is None else labels == SOIL
        out["used"] += len(xyz) if mask is None else int(mask.sum())
        if inside is not None:
            mask = inside if mask is None else mask & inside
        if mask is not None:
            local = rows(local, mask)
        thinner.add(local)
        out["cropped"] += len(local)
    if resolution is not None:  # a thinned read: counts back to the survey's density
        scale = 1.0 / read_fraction(path, *(region if region is not None else (None, None)), resolution)
        thinner.sums *= scale  # centroids unchanged, counts scaled
        out.update({k: round(out[k] * scale) for k in ("points", "used", "cropped")})
    out["sums"] = thinner.occupied()
    return out


def scan_keeping(unit: Unit, region, to_local, rule: PointRule, keep, thinning: tuple, indexed: bool, cached=None):
    """(:func:`scan_unit`'s summary, the unit's :class:`.pointcache.KeptTile` for the grid pass)."""
    kept: list = []
    out = scan_unit(unit, region, to_local, rule, keep, thinning, indexed, cached, kept)
    return out, KeptTile(tuple(kept), out["points"])


def dask_loader(
    client, progress: Callable[[str], None], wait_check: Callable[[], None], cache
) -> Callable[..., Loaded]:
    """A :func:`stream.load` running its units on ``client`` (sources in memory and reads keeping the
    points stream here); ``wait_check`` runs while waiting; ``cache``: a :class:`.pointcache.PointCache`."""

    def loader(src: Source, to_local, mode: str, keep, thinner: ColumnThinner, check, box, indexed, exclude) -> Loaded:
        if src.raw is not None or box is None or (box[1] >= box[0]).all():  # a read keeping the points
            return load(src, to_local, mode, keep, thinner, check, box, indexed, exclude)
        todo, ready = units(src), client.ready
        crop = None if keep is None else getattr(keep, "key", lambda: False)()  # False: not a lattice, not kept
        kept = cache if crop is not False else None
        rule, pre = _rule(client, src, todo, kept, ready, (mode, exclude), wait_check)
        thinning = (thinner.lo, thinner.hi, thinner.voxel, thinner.within)
        args = (src.region, to_local, rule, keep, thinning, indexed)
        here, left = _scan_here(src, todo, args, (kept, crop, pre), ready, wait_check)
        send = kept is not None and (left or client.ready())  # the tiles read here go to the workers once up
        taken = kept.take(src, [u[0] for u in left]) if send else [(None, False)] * len(left)
        futures = _submit(client, left, args, taken, kept, crop)
        if send:
            kept.prefetch()
        done = chain(here, completed(client, futures, f"reading {src.path}", wait_check))
        parts, position, waiting = [], {u: k for k, u in enumerate(todo)}, {}
        for k, part in enumerate(done, 1):  # the units' sums added in the units' order as they arrive
            waiting[position[part.pop("unit")]] = part.pop("sums")
            _add_in_order(thinner, waiting, k - len(waiting))
            parts.append(part)
            progress(f"scanned {k}/{len(todo)} pieces of {src.path}")
        single = indexed and src.vpc is None and not is_copc(src.path)  # a single file's chunk index
        index = tuple(sorted((e for p in parts for e in p["index"]), key=lambda e: e[0])) if single else None
        points, used, cropped = (sum(p[k] for p in parts) for k in ("points", "used", "cropped"))
        thin, counts = thinner.columns()
        extra = {"read_s": 0.0, "cropped": cropped, "counts": counts, "index": index}
        empty = np.empty((0, 3), np.float32)  # stream.load's result without points: columns, counts, totals
        nothing = NonSoil(empty, np.empty(0, np.uint8), rule) if rule.active else None
        note = "class 2 (ground)" if rule.use_class else "all points"
        return Loaded(empty, thin, points, used, note, extra, nothing)

    return loader


def _add_in_order(thinner: ColumnThinner, waiting: dict, added: int) -> None:
    """Add the units' sums ({position: (columns, sums) or a :class:`Block`}) to ``thinner`` in the
    units' order, however the tasks finish (the same bits every run); ``added``: how many were
    added before; later ones wait for those before them."""
    while added in waiting:
        part = waiting.pop(added)
        if isinstance(part, Block):
            thinner.add_block(part)
        else:
            cols, sums = part
            thinner.sums[:, cols] += sums
        added += 1


def _submit(client, left: list[Unit], args: tuple, taken: list[tuple], cache, crop) -> list:
    """Futures of ``left``'s scans (``taken``: per unit, its chunks read ahead or None, whether kept);
    a kept unit's :class:`.pointcache.KeptTile` split off on its worker, its future to ``cache``."""

    def submit(fn, ks: list[int]) -> list:
        reads = [taken[k][0] for k in ks]
        return client.map(fn, [left[k] for k in ks], *[[a] * len(ks) for a in args], reads, pure=False) if ks else []

    keeping = [k for k, t in enumerate(taken) if t[1]]
    plain = [k for k, t in enumerate(taken) if not t[1]]
    futures = dict(zip(plain, submit(scan_unit, plain), strict=True))
    both = submit(scan_keeping, keeping)
    if both:
        parts = client.map(operator.getitem, both, [0] * len(both), pure=False)
        tiles = client.map(operator.getitem, both, [1] * len(both), pure=False)
        for k, part, tile in zip(keeping, parts, tiles, strict=True):
            futures[k] = part
            cache.futures[(left[k][0], crop)] = tile
    return [futures[k] for k in range(len(left))]


def _rule(client, src: Source, todo: list[Unit], cache, ready: Callable[[], bool], how: tuple, check) -> tuple:
    """(the epoch's rule, {path: chunks} of its first tile if read whole for it), decided on the
    source's first chunk (:func:`stream.epoch_rule`; ``how``: mode, exclude): by the driver when it
    scans that tile (decoded once), by the worker that read it ahead."""
    path = todo[0][0] if todo and src.vpc is not None else None
    if path is not None and cache is not None and not is_copc(path):
        if not ready() and cache.fits(src, path):
            chunks = read_tile(path)
            if chunks:
                return epoch_rule(src, chunks[0][1], chunks[0][2], *how), {path: chunks}
        elif (read := cache.reads.get(path)) is not None:
            named = replace(src, vpc=None)  # what the rule's messages name, without the tile list
            decided = client.submit(_first_rule, read, named, how, pure=False)
            rule = next(completed(client, [decided], f"reading {src.path}", check))
            if rule is not None:
                return rule, {}
    stream = src.chunks(signals=True)
    _, first, sig = next(stream, (None, None, None))
    stream.close()
    return epoch_rule(src, first, sig, *how), {}


def _first_rule(chunks: tuple, src: Source, how: tuple) -> PointRule | None:
    """:func:`stream.epoch_rule` on the first of a tile's ``chunks`` (None when it has none)."""
    return epoch_rule(src, chunks[0][1], chunks[0][2], *how) if chunks else None


def _scan_here(src: Source, todo: list[Unit], args: tuple, kept: tuple, ready: Callable[[], bool], check) -> tuple:
    """(parts, units left): the VPC tiles of ``todo`` scanned here in order while the cluster starts
    and they fit the cache of ``kept`` (cache, crop key, {path: chunks} read), held for the workers."""
    cache, crop, pre = kept
    parts = []
    while todo and cache is not None and src.vpc is not None and not ready():
        path = todo[0][0]
        if is_copc(path) or not cache.fits(src, path):
            break
        part, tile = scan_keeping(todo[0], *args, cached=pre.pop(path, None))  # None: the scan reads it
        parts.append(part)
        cache.hold(src, (path, crop), tile)
        todo = todo[1:]
        check()
    return parts, todo


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
        src = stream.open_source(path)
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
