"""Peak resident memory of every process of a run (the command and its descendants: Dask's
nanny and worker processes), sampled with psutil while it runs."""

from __future__ import annotations

import threading


class TreeSampler:
    """Samples the RSS of ``pid`` and all its descendants every ``interval`` seconds; ``peaks``
    maps pid -> (peak MB, process name); ``largest``/``total`` summarise."""

    def __init__(self, pid: int, interval: float = 0.05) -> None:
        import psutil

        self.root = psutil.Process(pid)
        self.interval = interval
        self.peaks: dict[int, tuple[float, str]] = {}
        self.total = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> TreeSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        import psutil

        while not self._stop.is_set():
            try:
                procs = [self.root, *self.root.children(recursive=True)]
            except psutil.Error:
                return
            total = 0.0
            for p in procs:
                try:
                    mb = p.memory_info().rss / 2**20
                    name = self.peaks.get(p.pid, (0.0, ""))[1] or _label(p)
                except psutil.Error:
                    continue
                total += mb
                if mb > self.peaks.get(p.pid, (0.0, ""))[0]:
                    self.peaks[p.pid] = (mb, name)
            self.total = max(self.total, total)
            self._stop.wait(self.interval)

    @property
    def largest(self) -> tuple[float, str]:
        """(MB, name) of the process with the highest peak."""
        return max(self.peaks.values(), default=(0.0, ""))


def _label(p) -> str:
    cmd = " ".join(p.cmdline())
    if "multiprocessing" in cmd or "spawn_main" in cmd:
        return "dask worker"
    if "time" in p.name() and "-v" in cmd:
        return "time"
    return p.name()
