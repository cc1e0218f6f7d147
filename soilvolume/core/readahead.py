"""Read-ahead: the items of an iterator produced by a thread while the caller works on the last."""

from __future__ import annotations

from collections.abc import Iterator


def prefetch(chunks: Iterator, depth: int = 1) -> Iterator:
    """``chunks`` read ahead by a thread (decoding overlaps the caller: numpy releases the GIL); errors re-raised."""
    import queue
    import threading

    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    end = object()

    def run() -> None:
        try:
            for item in chunks:
                if stop.is_set():
                    return
                q.put(item)
            q.put(end)
        except BaseException as exc:  # handed to the consumer
            q.put(exc)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    try:
        while True:
            item = q.get()
            if item is end:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while worker.is_alive():  # unblock a producer waiting on a full queue
            try:
                q.get_nowait()
            except queue.Empty:
                worker.join(0.05)
