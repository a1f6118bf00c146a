"""Retraining the motion prior: the ``prior_training`` job, its weekly schedule and the mocap-change sensor.

Both the schedule (``weekly_prior_retraining``, Sundays 04:00) and the sensor (``mocap_change_prior_retraining``)
request one run of ``prior_training`` for the default variant (partition ``motion_prior``): retarget the CMU mocap
of the data root (``mocap_clips``), train the prior and compute its held-out figures. The ablation variants
are retrained on request (``humancal train prior --variant V``, or the job's other partitions in the UI); a new
``mocap_clips`` makes them stale in the UI. Both start STOPPED: turn them on in the UI.

The sensor's cursor is a fingerprint of the mocap files (``<data root>/cmu_mocap/bvh_daz/**/*.bvh.gz``: relative
path, size, modification time). Its first tick records the fingerprint and requests nothing (the prior in force
stays); a later tick whose fingerprint differs requests a run, keyed by the fingerprint (so one change is trained
once); a folder that disappears is recorded and requests nothing.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import dagster as dg

from resources.datasets import DatasetsResource

DEFAULT_VARIANT = "motion_prior"
MOCAP_FOLDER = ("cmu_mocap", "bvh_daz")
"""Where ``mocap_clips`` reads the BVH clips under the data root."""
MOCAP_PATTERN = "*.bvh.gz"
RETRAIN_SELECTION = ("mocap_clips", "motion_prior_trained", "prior_metrics")
"""What a scheduled or sensed retraining materializes."""


def mocap_fingerprint(root: Path | None) -> str:
    """SHA-256 (16 hex) of the mocap files' relative paths, sizes and modification times; ``""`` when the data root
    has no mocap folder."""
    folder = None if root is None else Path(root).joinpath(*MOCAP_FOLDER)
    if folder is None or not folder.is_dir():
        return ""
    digest = hashlib.sha256()
    for path in sorted(folder.rglob(MOCAP_PATTERN)):
        stat = path.stat()
        digest.update(f"{path.relative_to(folder).as_posix()}:{stat.st_size}:{stat.st_mtime_ns}\n".encode())
    return digest.hexdigest()[:16]


def _retrain_request(run_key: str | None) -> dg.RunRequest:
    return dg.RunRequest(run_key=run_key, partition_key=DEFAULT_VARIANT,
                         asset_selection=[dg.AssetKey(name) for name in RETRAIN_SELECTION])


def prior_training_job() -> dg.UnresolvedAssetJobDefinition:
    """The job: the mocap, the prior checkpoint and its metrics, partitioned by variant."""
    return dg.define_asset_job(
        "prior_training",
        selection=dg.AssetSelection.assets(*RETRAIN_SELECTION),
        description="Retarget the CMU mocap of the data root, train the motion prior of one variant (the partition) "
                    "on it and compute its held-out figures.",
    )


def build_weekly_prior_schedule(job) -> dg.ScheduleDefinition:
    """``weekly_prior_retraining``: Sundays 04:00, one run for the default variant (STOPPED by default)."""

    @dg.schedule(
        name="weekly_prior_retraining", job=job, cron_schedule="0 4 * * 0",
        default_status=dg.DefaultScheduleStatus.STOPPED,
        description="Sundays 04:00: retarget the mocap under the data root and retrain the default motion prior "
                    "(turn on in the UI).",
    )
    def weekly_prior_retraining(context: dg.ScheduleEvaluationContext) -> dg.RunRequest:
        return _retrain_request(None)

    return weekly_prior_retraining


def build_mocap_change_sensor(job, minimum_interval_seconds: int = 3600) -> dg.SensorDefinition:
    """``mocap_change_prior_retraining`` (module docstring); STOPPED by default.

    Args:
        job: the ``prior_training`` job.
        minimum_interval_seconds: seconds between ticks (the fingerprint reads every file's metadata).
    """

    @dg.sensor(
        name="mocap_change_prior_retraining", job=job, minimum_interval_seconds=minimum_interval_seconds,
        default_status=dg.DefaultSensorStatus.STOPPED,
        description="Retrains the default motion prior when the mocap files under the data root change.",
    )
    def mocap_change_prior_retraining(context: dg.SensorEvaluationContext, datasets: DatasetsResource) -> dg.SensorResult:
        stamp = mocap_fingerprint(datasets.root())
        previous = context.cursor
        if previous is None:
            return dg.SensorResult(skip_reason=f"recorded the mocap fingerprint {stamp or '(no mocap)'}", cursor=stamp)
        if stamp == previous:
            return dg.SensorResult(skip_reason="the mocap has not changed", cursor=stamp)
        if not stamp:
            return dg.SensorResult(skip_reason="no mocap under the data root any more; the prior in force stays",
                                   cursor=stamp)
        context.log.info(f"mocap changed ({previous or 'none'} -> {stamp}): retraining the motion prior")
        return dg.SensorResult(run_requests=[_retrain_request(f"mocap-{stamp}")], cursor=stamp)

    return mocap_change_prior_retraining
