"""The asset partitions whose computation failed, remembered between updates (``<state dir>/update_failures.json``,
on the shared state dir: an update run from another machine knows them too).

A plain ``humancal update`` does not retry an asset partition that failed in an earlier update while nothing it is
computed from changed since: not its code version, not the data versions of its inputs, not its sequence's entry
in the datasets config (the *attempt fingerprint*). It reminds the user of it in one line instead. An update that
names the partition (``--partition``) retries it; so does any update once the fingerprint changed. A success, or
the asset partition found up to date, forgets it; ``humancal remove`` forgets a removed dataset's partitions.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from upath import UPath

from humancal.storage import write_atomic

__all__ = ["Failure", "FailureRecord", "attempt_fingerprint"]

FILE_NAME = "update_failures.json"


@dataclass(frozen=True)
class Failure:
    """One failed asset partition.

    Attributes:
        asset: the asset key (user string).
        partition: the partition key (``None`` for an unpartitioned asset).
        message: the error (one line).
        fingerprint: :func:`attempt_fingerprint` of the failed attempt.
        when: seconds since the epoch.
    """

    asset: str
    partition: str | None
    message: str
    fingerprint: str
    when: float

    @property
    def name(self) -> str:
        return f"{self.asset}[{self.partition}]" if self.partition else self.asset

    @property
    def when_text(self) -> str:
        return time.strftime("%Y-%m-%d %H:%M", time.localtime(self.when))


def attempt_fingerprint(code_version: str | None, inputs: dict[str, str | None], config: str = "") -> str:
    """What an attempt to compute an asset partition depended on: its code version, the recorded data version of
    each input (``"asset[partition]" -> version``, ``None`` for one never materialized) and its configuration."""
    payload = json.dumps([code_version, sorted(inputs.items()), config], default=str)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


class FailureRecord:
    """The failed asset partitions stored in a JSON file, local or on a store (or only in memory when ``path`` is
    ``None``)."""

    def __init__(self, path: str | Path | UPath | None = None):
        self.path = UPath(path) if path is not None else None
        self._entries: dict[str, Failure] = {}
        self._changed = False
        if self.path is not None:
            try:
                raw = json.loads(self.path.read_text())
                self._entries = {key: Failure(**value) for key, value in raw.items()}
            except FileNotFoundError:
                pass
            except (ValueError, TypeError, OSError):
                self._entries, self._changed = {}, True  # unreadable: start afresh (failures are retried)

    @classmethod
    def in_state_dir(cls, state_dir: str | Path | UPath) -> "FailureRecord":
        return cls(UPath(state_dir) / FILE_NAME)

    def get(self, asset: str, partition: str | None) -> Failure | None:
        return self._entries.get(_key(asset, partition))

    def all(self) -> list[Failure]:
        return list(self._entries.values())

    def record(self, asset: str, partition: str | None, message: str, fingerprint: str) -> None:
        self._entries[_key(asset, partition)] = Failure(asset, partition, message, fingerprint, time.time())
        self._changed = True

    def forget(self, asset: str, partition: str | None) -> None:
        if self._entries.pop(_key(asset, partition), None) is not None:
            self._changed = True

    def forget_partitions(self, partitions: set[str]) -> int:
        """Forget every failure in ``partitions``; returns how many."""
        keys = [key for key, failure in self._entries.items() if failure.partition in partitions]
        for key in keys:
            del self._entries[key]
        self._changed |= bool(keys)
        return len(keys)

    def save(self) -> None:
        """Write the file atomically if anything changed (remove it when nothing is left)."""
        if self.path is None or not self._changed:
            return
        if not self._entries:
            self.path.unlink(missing_ok=True)
        else:
            text = json.dumps({key: asdict(value) for key, value in sorted(self._entries.items())}, indent=1)
            write_atomic(self.path, text.encode())
        self._changed = False


def _key(asset: str, partition: str | None) -> str:
    return f"{asset}[{partition}]" if partition else asset
