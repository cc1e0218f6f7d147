"""The first pass's VPC tiles kept on the workers for the grid pass while they fit the memory
budget: the scan of a whole VPC tile (not COPC: its first pass reads a thinned level) also makes
its :class:`KeptTile`, which stays on its worker as a Dask future; the grid tasks meeting the
tile take it instead of decoding, labelling, shifting and cropping the file again. Tiles beyond
the budget are read again by the grid tasks."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, wait
from dataclasses import dataclass, replace

import numpy as np

from ..core import interrupt
from ..core.cells import rows
from ..core.types import SoilVolumeError, short_error
from ..inputs.lasread import is_copc
from ..inputs.stream import CHUNK, Source, file_chunks
from .waiting import in_thread

# a tile read ahead (xyz float64, classification, RGB, returns: 33 B and the chunk lists) while its
# kept form (float32 xyz and a label: 13 B) is made from it
CACHE_BYTES_PER_POINT = 40.0
CACHE_SHARE = 0.3  # of the budget: what the workers may hold beside their tasks (below Dask's spilling)
HELD_POINTS = 8_000_000  # points of the tiles the driver scans while the cluster starts (~100 MB kept)
SEND_S = 120.0  # the tiles the driver scanned must reach the workers within this

Key = tuple  # (tile path, PolygonMask.key() of the crop its kept points passed, or None: not cropped)


@dataclass(frozen=True)
class KeptTile:
    """A VPC tile as the grid needs it: per file chunk, the local float32 xyz the epoch's crop keeps,
    in file order, and their labels (None: all soil); ``points``: the tile's points."""

    chunks: tuple
    points: int


def kept_chunk(local: np.ndarray, labels: np.ndarray | None, inside: np.ndarray | None) -> tuple:
    """(local float32 xyz, labels) of the points of a chunk ``inside`` keeps (all when None), as
    the first pass keeps it and as a grid task makes it from the file."""
    if inside is None:
        return local.astype(np.float32), labels
    return rows(local, inside).astype(np.float32), None if labels is None else labels[inside]


def read_tile(path: str) -> tuple:
    """The chunks (xyz, classification, signals) of a whole LAS/LAZ file, as the grid reads them."""
    return tuple(file_chunks(path, None, CHUNK, signals=True))


class PointCache:
    """Futures of the VPC tiles kept in the workers' memory within ``budget_gb``; ``direct``: the
    tiles the driver scanned go straight to the workers (a cluster of this machine)."""

    def __init__(self, client, budget_gb: float, direct: bool = False) -> None:
        self.client, self.left, self.direct = client, budget_gb * CACHE_SHARE * 2**30, direct
        self.futures: dict[Key, object] = {}  # the kept tiles (a scan task's KeptTile), for the grid
        self.reads: dict[str, object] = {}  # tiles of an epoch to come read ahead, for its scan
        self.charged: set[str] = set()  # the tiles counted against the budget
        self.scanned: set[str] = set()  # tiles whose scan is done or on its way
        self.points = 0
        self.expected: list[Source] = []
        self.held: dict[Key, KeptTile] = {}  # tiles the driver scanned, until the workers are up
        self.sending: list[Future] = []  # the scatters of held tiles on their way

    def expect(self, src: Source) -> None:
        """Read the tiles of ``src`` (a VPC's region) ahead, behind the first tiles taken, so the later
        epoch's reads overlap the driver's work; only when all fit the budget."""
        if src.vpc is not None:
            self.expected.append(src)

    def take(self, src: Source, paths: list[str]) -> list[tuple]:
        """Per tile of ``paths`` (of ``src``) whose scan is submitted now: (the future of its chunks
        read ahead, or None; whether the scan keeps it, :meth:`admit`). :meth:`prefetch` follows."""
        self.send_held()
        return [(self.reads.pop(p, None), kept) for p, kept in zip(paths, self._begun(src, paths), strict=True)]

    def _begun(self, src: Source, paths: list[str]) -> list[bool]:
        """The scan of ``paths`` of ``src`` has begun (too late to read ``src`` ahead: only the tiles of
        its expected region it does not scan would be): whether each is kept (:meth:`admit`)."""
        self.expected = [e for e in self.expected if e.path != src.path]
        self.scanned.update(paths)
        return [self.admit(src, p) for p in paths]

    def admit(self, src: Source, path: str) -> bool:
        """Whether the tile ``path`` of ``src`` is kept: a VPC tile, not COPC, that fits what is
        left of the budget (counted once)."""
        if path in self.charged:
            return True
        count = _count(src, path)
        if count is None or is_copc(path) or count * CACHE_BYTES_PER_POINT > self.left:
            return False
        self.left -= count * CACHE_BYTES_PER_POINT
        self.points += count
        self.charged.add(path)
        return True

    def fits(self, src: Source, path: str) -> bool:
        """Whether the driver may scan and hold the tile ``path`` of the VPC ``src``: it fits the
        budget and what the driver holds (:data:`HELD_POINTS` at most, till the workers are up)."""
        count = _count(src, path)
        if count is None or (path not in self.charged and count * CACHE_BYTES_PER_POINT > self.left):
            return False
        return sum(k.points for k in self.held.values()) + count <= HELD_POINTS

    def hold(self, src: Source, key: Key, kept: KeptTile) -> None:
        """Keep a tile the driver scanned (see :meth:`fits`), sent to the workers at the next
        :meth:`take`."""
        self._begun(src, [key[0]])
        self.held[key] = kept

    def send_held(self) -> None:
        """Send the held tiles to the workers on a thread (the driver goes on with its next tasks
        and the registration); :meth:`sent` waits for them."""
        held, self.held = self.held, {}
        if not held:
            return
        resolve = getattr(self.client, "resolve", None)  # a cluster still starting: waited for here, in the driver
        client = resolve() if resolve else self.client
        self.sending.append(in_thread(self._send, client, held, name="soilvolume-send-tiles"))

    def _send(self, client, held: dict[Key, KeptTile]) -> None:
        """All of ``held`` in one scatter (one call per tile took twice as long: 17 tiles of
        3.8 M points, 0.10-0.15 s through the scheduler, 0.05 s straight and at once)."""
        futures = client.scatter(list(held.values()), hash=False, direct=self.direct)
        self.futures.update(zip(held, futures, strict=True))

    def sent(self) -> None:
        """Every held tile sent and its future here (waited for at most :data:`SEND_S`, a signal
        checked every 0.25 s); a failure to send them raised here, as one line."""
        self.send_held()
        while self.sending:
            sending, deadline = self.sending.pop(0), time.monotonic() + SEND_S
            while not wait([sending], 0.25).done:
                interrupt.check()
                if time.monotonic() > deadline:
                    raise SoilVolumeError(f"the Dask workers did not receive the tiles read here within {SEND_S:.0f} s")
            failed = sending.exception()  # the scatter's (the client was resolved in the driver: send_held)
            if failed is not None:
                raise SoilVolumeError(f"sending the tiles read here to the Dask workers failed ({short_error(failed)})")

    def prefetch(self) -> None:
        """Start the reads :meth:`expect` asked for, once, behind the tasks submitted so far (read
        first, they would take the workers before the scans that wait for them)."""
        expected, self.expected = self.expected, []
        todo = [(s, [p for p in s.tiles() if p not in self.scanned and p not in self.reads]) for s in expected]
        fresh = {p: _count(s, p) or 0 for s, paths in todo for p in paths if p not in self.charged}
        if sum(fresh.values()) * CACHE_BYTES_PER_POINT > self.left:
            return
        for s, paths in todo:
            for p in paths:
                if self.admit(s, p):  # after the scans of the tiles taken now
                    self.reads[p] = self.client.submit(read_tile, p, pure=False, priority=-1)

    def meeting(self, src: Source, crop: str | None) -> dict:
        """{path: future} of the tiles kept with the crop ``crop`` that a read of ``src`` opens."""
        self.sent()
        if src.vpc is None:
            return {}
        return {p: self.futures[(p, crop)] for p in src.tiles() if (p, crop) in self.futures}

    def release(self) -> None:
        """Free the workers' memory (the futures dropped)."""
        self.sent()
        self.futures.clear()
        self.reads.clear()


def _count(src: Source, path: str) -> int | None:
    """The point count of the tile ``path`` of the VPC ``src`` (None: not one of its tiles)."""
    if src.vpc is None:
        return None
    return next((t.count for t in src.vpc.tiles if t.path == path), None)


def chunks(src: Source, cached: dict | None, stats: dict, made: Callable[[Iterator], Iterator]) -> Iterator:
    """The chunks of ``src`` as the grid takes them: ``cached`` ({path: KeptTile}) from memory, the
    others made so by ``made``; the same chunks in the same order (byte-identical grid sums)."""
    if not cached or src.vpc is None:
        yield from made(src.chunks(signals=True))
        return
    for path in src.tiles():
        kept = cached.get(path)
        if kept is None:
            yield from made(file_chunks(path, src.region, CHUNK, signals=True))
            continue
        stats["cached"] += kept.points
        stats["read"] += kept.points
        yield from kept.chunks


def near_after(before: Source, after: Source, radius: float) -> Source:
    """The before VPC where the after's header box plus the crop radius reaches (the tiles its first
    pass reads), both in one projected CRS; else the before without its VPC (nothing expected)."""
    import pyproj

    same = before.crs_wkt is not None and before.crs_wkt == after.crs_wkt
    if before.vpc is None or not same or pyproj.CRS.from_wkt(before.crs_wkt).is_geographic:
        return replace(before, vpc=None)
    reach = 1.02 * radius + 1.0
    return before.within(after.lo[:2] - reach, after.hi[:2] + reach)
