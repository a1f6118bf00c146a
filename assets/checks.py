"""Asset check results from the library's plausibility reports (:mod:`humancal.validation`)."""

import dagster as dg

from humancal.validation import CheckReport


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
