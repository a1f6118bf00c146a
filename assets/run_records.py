"""Per sequence: what the runs that computed the method's stages recorded about them, as a table.

The metric tables report how long the association and the body fit took, and mark the camera figures computed
from cameras that failed a check of ``extrinsics``. Neither fact is in the stages' data: the seconds are in each
materialization's metadata (``seconds_total``), the check outcomes in the run's check evaluations. ``run_records``
reads them from the Dagster instance through its public API, once, and hands them on as an ordinary input: the
metric assets read no instance, and the graph shows where these facts come from.

``run_records`` depends on the assets it describes (``extrinsics``, ``associations``, ``gt_camera_associations``,
``fitted_motions``), so it is recomputed after them, and only when one of them produced different data.
"""

import dagster as dg
import pandas as pd

from assets.checks import latest_check_outcomes
from assets.common import sequence_asset, table_output
from humancal.tables.schemas import empty_table

__all__ = ["CHECKED_ASSET", "TIMED_ASSETS", "UNCHECKED", "failed_checks", "recorded_failed_checks",
           "recorded_seconds", "run_records", "stage_seconds"]

CHECKED_ASSET = "extrinsics"
"""The asset whose check outcomes mark the camera figures."""

TIMED_ASSETS = ("associations", "gt_camera_associations", "fitted_motions")
"""The assets whose ``seconds_total`` metadata the metric tables report."""

UNCHECKED = "unchecked"
"""``failed_checks`` of cameras whose checks were never recorded (materialized without them): not a pass."""


def recorded_seconds(instance: dg.DagsterInstance, asset: str, partition: str) -> tuple[float, str | None]:
    """The ``seconds_total`` metadata of an asset partition's latest materialization and its run id
    ((NaN, None) if never materialized; NaN if the figure was not recorded)."""
    records = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey(asset), asset_partitions=[partition]), limit=1).records
    if not records:
        return float("nan"), None
    value = records[0].asset_materialization.metadata.get("seconds_total")
    return (float(value.value) if value is not None else float("nan")), records[0].run_id


def recorded_failed_checks(instance: dg.DagsterInstance, partition: str) -> str:
    """The checks that the latest ``extrinsics`` of a partition failed, comma-separated and sorted ("" if none;
    :data:`UNCHECKED` if its checks were never recorded)."""
    outcomes = latest_check_outcomes(instance, dg.AssetKey(CHECKED_ASSET), partition)
    if not outcomes:
        return UNCHECKED
    return ",".join(sorted(o.check for o in outcomes if not o.passed))


def _records_table(instance: dg.DagsterInstance, partition: str) -> pd.DataFrame:
    rows = [{"sequence": partition, "asset": CHECKED_ASSET, "seconds": float("nan"), "run_id": None,
             "failed_checks": recorded_failed_checks(instance, partition)}]
    for asset in TIMED_ASSETS:
        seconds, run_id = recorded_seconds(instance, asset, partition)
        rows.append({"sequence": partition, "asset": asset, "seconds": seconds, "run_id": run_id,
                     "failed_checks": None})
    return pd.DataFrame(rows, columns=empty_table("run_records").columns)


def stage_seconds(records: pd.DataFrame, asset: str) -> float:
    """The seconds ``records`` (a ``run_records`` table) holds for ``asset`` (NaN if unrecorded)."""
    row = records.loc[records["asset"] == asset, "seconds"]
    return float(row.iloc[0]) if len(row) and pd.notna(row.iloc[0]) else float("nan")


def failed_checks(records: pd.DataFrame) -> str:
    """The checks of ``extrinsics`` that ``records`` (a ``run_records`` table) names as failed ("" if none)."""
    row = records.loc[records["asset"] == CHECKED_ASSET, "failed_checks"]
    return str(row.iloc[0]) if len(row) and pd.notna(row.iloc[0]) else UNCHECKED


@sequence_asset("run_records", code_version="1",
                deps=[CHECKED_ASSET, *TIMED_ASSETS])
def run_records(context: dg.AssetExecutionContext) -> dg.Output:
    """What the latest runs recorded of this sequence's stages: the checks the cameras of ``extrinsics`` failed,
    and the seconds of the association (with the estimated and with the reference cameras) and of the body fit."""
    table = _records_table(context.instance, context.partition_key)
    failed = failed_checks(table)
    if failed == UNCHECKED:
        context.log.warning("the checks of the extrinsics were not recorded: camera figures will be marked unchecked")
    elif failed:
        context.log.warning(f"the cameras of extrinsics failed {failed}: their figures will name these checks")
    return table_output(table, "run_records", rows=len(table), failed_checks=failed or "none",
                        **{f"seconds_{a}": round(stage_seconds(table, a), 3) for a in TIMED_ASSETS
                           if pd.notna(stage_seconds(table, a))})
