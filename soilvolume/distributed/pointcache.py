"""The first pass's points kept on the workers for the grid pass, when they fit the memory
budget: a whole VPC tile (not COPC: its first pass reads a thinned level) is read once, by a
task whose result stays on the worker that read it (a Dask future); the scan task and the
grid tasks whose boxes meet the tile consume that future instead of decoding the file again.
Tiles that do not fit the budget are read again by the grid tasks, as without the cache."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

from ..core import interrupt
from ..core.types import SoilVolumeError, short_error
from ..inputs.copc import is_copc
from ..inputs.stream import CHUNK, Source, file_chunks

CACHE_BYTES_PER_POINT = 40.0  # xyz float64, classification, RGB, returns (33 B) and the chunk lists
CACHE_SHARE = 0.3  # of the budget: what the workers may hold beside their tasks (below Dask's spilling)
HELD_POINTS = 8_000_000  # points of the tiles the driver reads while the cluster starts (~320 MB)
SEND_S = 120.0  # the tiles the driver read must reach the workers within this


def read_tile(path: str) -> tuple:
    """The chunks (xyz, classification, signals) of one whole LAS/LAZ file, as the grid tasks'
    reads yield them (:func:`stream.file_chunks`): the cached form of a VPC tile."""
    return tuple(file_chunks(path, None, CHUNK, signals=True))


class PointCache:
    """Futures of the VPC tiles read into the workers' memory, within ``budget_gb``."""

    def __init__(self, client, budget_gb: float) -> None:
        self.client, self.left = client, budget_gb * CACHE_SHARE * 2**30
        self.futures: dict[str, object] = {}
        self.points = 0
        self.expected: list[Source] = []
        self.held: dict[str, tuple] = {}  # tiles read by the driver, until the workers are up
        self.sending: set[str] = set()  # held tiles on their way to the workers
        self.senders: list[threading.Thread] = []
        self.failed: BaseException | None = None

    def expect(self, src: Source) -> None:
        """Read the tiles of ``src`` (a VPC, within its region) as soon as the first tiles are
        taken, behind them: the later epoch's reads then overlap the driver's work between the
        epochs and the first epoch's last tasks. Only when every tile expected fits the budget;
        a tile read but not scanned is merely not needed (the grid reads what it meets)."""
        if src.vpc is not None:
            self.expected.append(src)

    def take(self, src: Source, paths: list[str], priority: int = 0) -> list:
        """A future of each of ``paths`` (tiles of ``src``) kept in memory, or None for those
        read by streaming (not a VPC tile, COPC, or beyond the budget)."""
        self.send_held()
        if priority >= 0 and self.sending.intersection(paths):
            self.sent()  # a tile on its way: its future, not a second read
        if src.vpc is None:
            return [None] * len(paths)
        counts = {t.path: t.count for t in src.vpc.tiles}
        out = []
        for p in paths:
            need = counts.get(p, 0) * CACHE_BYTES_PER_POINT
            if p not in counts or is_copc(p) or p in self.sending or (p not in self.futures and need > self.left):
                out.append(None)  # (on its way: a prefetch does not wait for it)
                continue
            if p not in self.futures:
                self.futures[p] = self.client.submit(read_tile, p, pure=False, priority=priority)
                self.left -= need
                self.points += counts[p]
            out.append(self.futures[p])
        self._prefetch()
        return out

    def fits(self, src: Source, path: str) -> bool:
        """Whether the tile ``path`` of ``src`` (a VPC) fits what is left of the budget, and
        the driver may hold it (:data:`HELD_POINTS` at most, till the workers are up)."""
        count = next((t.count for t in src.vpc.tiles if t.path == path), None)
        held = sum(len(c[0]) for chunks in self.held.values() for c in chunks)
        return count is not None and count * CACHE_BYTES_PER_POINT <= self.left and held + count <= HELD_POINTS

    def hold(self, src: Source, path: str, chunks: tuple) -> None:
        """Keep the chunks of a tile the driver read (see :meth:`fits`) for the workers: sent to
        them at the next :meth:`take` (the same chunks a worker's read gives)."""
        count = next(t.count for t in src.vpc.tiles if t.path == path)
        self.left -= count * CACHE_BYTES_PER_POINT
        self.points += count
        self.held[path] = chunks

    def send_held(self) -> None:
        """The tiles the driver holds (:meth:`hold`) sent to the workers, by a thread: the driver
        goes on with its next tasks and the registration while they go out (~0.2 s for the paper
        pair's 3.5 M points); :meth:`sent` waits for them."""
        held, self.held = self.held, {}
        self.sending.update(held)
        if not held:
            return
        resolve = getattr(self.client, "resolve", None)  # a cluster still starting: waited for here, in the driver
        client = resolve() if resolve else self.client
        sender = threading.Thread(target=self._send, args=(client, held), daemon=True, name="soilvolume-send-tiles")
        self.senders.append(sender)
        sender.start()

    def _send(self, client, held: dict[str, tuple]) -> None:
        try:
            for path, chunks in held.items():
                self.futures[path] = client.scatter([chunks], hash=False)[0]
                self.sending.discard(path)
        except BaseException as exc:  # noqa: BLE001 - raised in the driver by sent()
            self.failed = exc

    def sent(self) -> None:
        """Wait (at most :data:`SEND_S`, a signal checked every 0.25 s) until the tiles being sent
        have their futures; a failure to send them is raised here, as one line."""
        while self.senders:
            sender, deadline = self.senders.pop(0), time.monotonic() + SEND_S
            while sender.is_alive() and time.monotonic() < deadline:
                sender.join(0.25)
                interrupt.check()
            if sender.is_alive():
                raise SoilVolumeError(f"the Dask workers did not receive the tiles read here within {SEND_S:.0f} s")
        if self.failed is not None:
            failed, self.failed = self.failed, None
            if isinstance(failed, SoilVolumeError):
                raise failed
            raise SoilVolumeError(f"sending the tiles read here to the Dask workers failed ({short_error(failed)})")

    def _prefetch(self) -> None:
        expected, self.expected = self.expected, []
        counts = {t.path: t.count for s in expected for t in s.vpc.tiles}
        todo = [(s, s.tiles()) for s in expected]
        kept = self.futures.keys() | self.sending
        need = sum(counts[p] for _, paths in todo for p in paths if p not in kept) * CACHE_BYTES_PER_POINT
        if need <= self.left:
            for s, paths in todo:
                self.take(s, paths, priority=-1)  # after the scans of the tiles taken now

    def arrived(self) -> None:
        """Every held tile sent and its future here (:meth:`send_held`, then :meth:`sent`)."""
        self.send_held()
        self.sent()

    def meeting(self, src: Source) -> dict:
        """{path: future} of the cached tiles a read of ``src`` (its region) opens."""
        self.arrived()
        if src.vpc is None:
            return {}
        return {p: self.futures[p] for p in src.tiles() if p in self.futures}

    def release(self) -> None:
        """Free the workers' memory (the futures dropped)."""
        self.sent()
        self.futures.clear()


def chunks(src: Source, cached: dict | None, stats: dict):
    """``src.chunks(signals=True)``, the tiles in ``cached`` ({path: chunks}) taken from memory
    (their points counted in ``stats["cached"]``): the same chunks in the same order, so the grid
    sums come out byte-identical."""
    if not cached or src.vpc is None:
        yield from src.chunks(signals=True)
        return
    for path in src.tiles():
        if path in cached:
            stats["cached"] = stats.get("cached", 0) + sum(len(c[0]) for c in cached[path])
            yield from cached[path]
        else:
            yield from file_chunks(path, src.region, CHUNK, signals=True)


def near_after(before: Source, after: Source, radius: float) -> Source:
    """The before VPC where the after cloud's header box plus the crop radius can reach (the
    tiles its first pass will read: the crop polygon lies in that box), when both are in the
    same CRS; else the before as it is (without a VPC: nothing expected)."""
    import pyproj

    same = before.crs_wkt is not None and before.crs_wkt == after.crs_wkt
    if before.vpc is None or not same or pyproj.CRS.from_wkt(before.crs_wkt).is_geographic:
        return replace(before, vpc=None)
    reach = 1.02 * radius + 1.0
    return before.within(after.lo[:2] - reach, after.hi[:2] + reach)
