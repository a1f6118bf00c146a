"""Asset check results from the library's plausibility reports (:mod:`humancal.tables.plausibility`), and the recorded
outcomes of the checks of an asset partition (read back by ``humancal update`` and the metric tables)."""

from dataclasses import dataclass

import dagster as dg

from humancal.tables.plausibility import CheckReport


def check_result(
    context: dg.AssetExecutionContext,
    check_name: str,
    report: CheckReport,
    *,
    asset_key: str | None = None,
    severity: dg.AssetCheckSeverity = dg.AssetCheckSeverity.ERROR,
    note: str = "",
) -> dg.AssetCheckResult:
    """The ``AssetCheckResult`` of a report; a check that had nothing to examine is a warning, never a pass.

    Args:
        context: the asset's context (a "not checked" outcome is also logged as a warning).
        check_name: name of the check spec.
        report: the library's report.
        asset_key: the checked asset, for multi-assets.
        severity: severity of a failure (a "not checked" outcome is always ``WARN``: it says nothing about the
            data, and must not block what comes after).
        note: appended to the description.
    """
    metadata = dict(report.figures)
    if report.checked is not None:
        metadata["checked"] = int(report.checked)
    if report.not_checked:
        context.log.warning(f"check {check_name}: {report.description}{note}")
        severity = dg.AssetCheckSeverity.WARN
    return dg.AssetCheckResult(
        check_name=check_name,
        asset_key=asset_key,
        passed=report.passed,
        severity=severity,
        description=report.description + note,
        metadata=metadata,
    )


@dataclass(frozen=True)
class CheckOutcome:
    """One evaluation of an asset check, as ``humancal`` reports it.

    Attributes:
        asset: the checked asset's key (user string).
        partition: the checked partition (``None`` for an unpartitioned asset).
        check: the check's name.
        passed: whether it passed.
        severity: ``"ERROR"`` or ``"WARN"``.
        blocking: whether the check's spec is blocking.
        description: what the check found.
    """

    asset: str
    partition: str | None
    check: str
    passed: bool
    severity: str
    blocking: bool
    description: str

    @property
    def blocks(self) -> bool:
        """A failed blocking check of severity ERROR: nothing may be computed from the checked asset partition
        (Dagster's rule: a failed blocking check of severity WARN does not block)."""
        return not self.passed and self.blocking and self.severity == dg.AssetCheckSeverity.ERROR.value

    @property
    def where(self) -> str:
        return f"{self.asset}[{self.partition}]" if self.partition else self.asset

    @classmethod
    def of(cls, evaluation: dg.AssetCheckEvaluation, partition: str | None) -> "CheckOutcome":
        """From Dagster's evaluation event of a check run on ``partition`` (embedded checks do not record it)."""
        return cls(
            asset=evaluation.asset_key.to_user_string(),
            partition=evaluation.partition or partition,
            check=evaluation.check_name,
            passed=bool(evaluation.passed),
            severity=evaluation.severity.value,
            blocking=bool(evaluation.blocking),
            description=evaluation.description or "",
        )


def latest_check_outcomes(
    instance: dg.DagsterInstance, asset_key: dg.AssetKey, partition: str | None = None
) -> tuple[CheckOutcome, ...] | None:
    """The check evaluations of the latest materialization of an asset partition (``None``: never materialized).

    Checks yielded by a partitioned asset are recorded without their partition, so they are found through the
    materialization they evaluated: the evaluations of its run that target its storage id. Public API only.
    """
    records = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=asset_key, asset_partitions=[partition] if partition else None), limit=1
    ).records
    if not records:
        return None
    record = records[0]
    outcomes = {}
    for entry in instance.all_logs(record.run_id, of_type=dg.DagsterEventType.ASSET_CHECK_EVALUATION):
        evaluation = entry.dagster_event.event_specific_data
        target = evaluation.target_materialization_data
        if evaluation.asset_key == asset_key and target is not None and target.storage_id == record.storage_id:
            outcomes[evaluation.check_name] = CheckOutcome.of(evaluation, partition)  # a later one wins
    return tuple(outcomes.values())
