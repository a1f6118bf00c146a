"""What one ``humancal update`` did (:class:`UpdateResult`), in terms the CLI prints."""

from __future__ import annotations

from dataclasses import dataclass

from assets.checks import CheckOutcome
from pipelines.failure_record import Failure

__all__ = ["UpdateResult", "asset_name"]


def asset_name(key: str, pk: str | None) -> str:
    return f"{key}[{pk}]" if pk else key


@dataclass(frozen=True)
class UpdateResult:
    """What an update did."""

    materialized: tuple[tuple[str, str | None], ...]
    """(asset key, partition key) pairs materialized, in order."""
    rounds: int
    failed: tuple[tuple[str, str | None, str], ...] = ()
    """(asset key, partition key, error message) of the asset partitions whose computation failed in this update;
    what depends on them was left out (other partitions went on)."""
    waiting: tuple[tuple[str, str | None, str], ...] = ()
    """(asset key, partition key, reason) of the asset partitions left missing or stale because an input could
    not be brought up to date here (e.g. a fan-in asset whose other partitions are outside ``--partition``), or
    held back by a failed blocking check upstream."""
    checks: tuple[CheckOutcome, ...] = ()
    """Every check that failed in this update's runs (warnings too), and the failing blocking checks recorded by
    earlier runs on asset partitions in scope (what depends on those was held back)."""
    earlier_checks: tuple[CheckOutcome, ...] = ()
    """Those of :attr:`checks` that were evaluated before this update (their asset partition was up to date)."""
    earlier_failed: tuple[Failure, ...] = ()
    """Asset partitions that failed in an earlier update and were not retried: nothing they are computed from
    changed since (``pipelines.failure_record``); what depends on them was left out."""
    left_out: tuple[tuple[str, str, str], ...] = ()
    """(fan-in asset, partition, reason): partitions a fan-in asset (``benchmark_table``) was computed without,
    because they failed or are held back by a failed blocking check."""
    requested: tuple[str, ...] = ()
    """The partitions the update was asked for by name (``--partition``); empty: every registered one."""

    @property
    def count(self) -> int:
        return len(self.materialized)

    @property
    def blocking_failed(self) -> bool:
        """A blocking check failed: something downstream of it was not computed."""
        return any(outcome.blocks for outcome in self.checks)

    @property
    def failed_now(self) -> bool:
        """Something failed in this update: an asset partition, or a blocking check evaluated by its runs."""
        return bool(self.failed) or any(o.blocks for o in self.checks if o not in self.earlier_checks)

    @property
    def exit_status(self) -> int:
        """1 when something failed in this update, or when a partition asked for by name (``--partition``) is
        failed or held back; 0 otherwise. A failure of an earlier update that nothing changed since (reported as a
        reminder) does not fail a plain update again: exit 1 then means something new went wrong."""
        if self.failed_now:
            return 1
        earlier = bool(self.earlier_failed) or any(o.blocks for o in self.earlier_checks)
        return 1 if self.requested and earlier else 0

    def waiting_lines(self) -> list[str]:
        """One line per waiting asset partition, for the user."""
        return [f"left {asset_name(key, pk)}: {reason}" for key, pk, reason in self.waiting]

    def left_out_lines(self) -> list[str]:
        """One line per fan-in asset computed without some partitions."""
        by_asset: dict[str, list[str]] = {}
        for asset, partition, reason in self.left_out:
            by_asset.setdefault(asset, []).append(f"{partition} ({reason})")
        return [f"{asset} computed without {'; '.join(parts)}" for asset, parts in by_asset.items()]
