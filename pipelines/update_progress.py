"""Progress within a round of ``humancal update``: each asset partition as its materialization is stored.

A new capture goes through the whole graph in one run (:mod:`pipelines.update`), minutes for a real capture; the
round's line alone would say nothing until it ends. :class:`StoredWatcher` polls the instance for the round's asset
partitions from a thread and reports each once, as it is stored, whichever process stored it.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterable

import dagster as dg

__all__ = ["StoredWatcher"]


class StoredWatcher:
    """Calls ``on_stored(key, partition, seconds)`` once for each of ``items`` materialized after the watcher
    started (``seconds``: since then), polling every ``interval_s`` while used as a context manager, and once more
    as it exits.

    Args:
        instance: the Dagster instance the runs record their events in.
        items: the (asset key, partition or None) pairs to watch.
        on_stored: the callback (called from the watcher's thread while it runs, then from the caller's).
        interval_s: seconds between polls.
    """

    def __init__(self, instance: dg.DagsterInstance, items: Iterable[tuple[dg.AssetKey, str | None]],
                 on_stored: Callable[[dg.AssetKey, str | None, float], None], interval_s: float = 1.0) -> None:
        self.instance, self.on_stored, self.interval_s = instance, on_stored, interval_s
        self.pending: dict[dg.AssetKey, set[str | None]] = defaultdict(set)
        for key, partition in items:
            self.pending[key].add(partition)
        self.start = time.time()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="humancal-progress", daemon=True)

    def __enter__(self) -> StoredWatcher:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.poll()

    def _watch(self) -> None:
        while not self._stop.wait(self.interval_s):
            self.poll()

    def poll(self) -> None:
        """Report what of the pending items has been stored since the start."""
        for key in list(self.pending):
            partitions = self.pending[key]
            named = sorted(p for p in partitions if p is not None)
            records = self.instance.fetch_materializations(
                dg.AssetRecordsFilter(asset_key=key, asset_partitions=named or None, after_timestamp=self.start),
                limit=max(len(partitions), 1) * 4, ascending=True).records
            for record in records:
                partition = record.partition_key if named else None
                if partition in partitions:
                    partitions.discard(partition)
                    self.on_stored(key, partition, record.timestamp - self.start)
            if not partitions:
                del self.pending[key]
