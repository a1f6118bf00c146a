"""Shared by all sequences: the 2D-to-3D lifter (shipped, or trained here on the retargeted CMU mocap) and its
held-out figures."""

import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd

from assets.common import ON_REQUEST_KEY, UPDATE_CONDITION, png_metadata, table_metadata, table_output, versioned_output
from evaluation.protocols import MetricRow, metrics_table
from humancal.lifter import (
    HELD_OUT_CMU_SUBJECTS,
    LifterConfig,
    LifterWeightsError,
    checkpoint_digest,
    checkpoint_num_bytes,
    held_out_report,
    load_lifter,
    plot_training_history,
    split_held_out,
    train_lifter,
)
from humancal.retarget import motions_table_to_clips
from resources.io_managers import checkpoint_content_version
from resources.lifter_source import ActiveLifter, active_lifter
from resources.torch import TorchResource

HELD_OUT_SEQUENCE = "held_out_" + "_".join(HELD_OUT_CMU_SUBJECTS)
"""Sequence name of the held-out figures in the metrics table (dataset ``cmu_mocap``)."""

_GROUP_SUFFIX = {
    "all": "",
    ">= 20 of 23 joints": "/joints_20_plus",
    "12-19 joints": "/joints_12_19",
    "< 12 joints": "/joints_under_12",
    "left-right flipped": "/left_right_flipped",
}

_HELD_OUT_METRICS = (
    ("mpjpe_mm", "mpjpe_mm"),
    ("pa_mpjpe_mm", "pa_mpjpe_mm"),
    ("height_error_mm", "height_mae_mm"),
    ("height_bias_mm", "height_bias_mm"),
    ("mpjpe_no_intrinsics_mm", "mpjpe_no_intrinsics_mm"),
)
"""(metric name in the table, column of ``held_out_report``)."""


def _subject_clips(motions: pd.DataFrame) -> list[tuple[str, object]]:
    return [(clip.subject, clip.keypoints_world_m) for clip in motions_table_to_clips(motions)]


def build_lifter_assets(config: LifterConfig, storage_root: str) -> list[dg.AssetsDefinition]:
    """The lifter assets: ``lifter_trained`` (trained here), ``lifter_checkpoint`` (the one the graph uses) and
    ``lifter_heldout_metrics``.

    ``lifter_checkpoint`` serves the weights shipped with the package until ``lifter_trained`` has been
    materialized under ``storage_root`` (``humancal train lifter``, or the retraining schedule); from then on it
    serves the trained ones. Which one is active is decided when the definitions load, and is part of the code
    version, so training (or deleting the trained checkpoint) makes the checkpoint stale, and the lifted
    detections follow it through the normal data-version lineage.

    Args:
        config: training configuration of ``lifter_trained`` (its digest is part of that asset's code version).
        storage_root: the artifacts root where ``lifter_trained`` is stored.
    """
    return [_lifter_trained(config), _lifter_checkpoint(active_lifter(storage_root)), lifter_heldout_metrics]


def _lifter_trained(config: LifterConfig) -> dg.AssetsDefinition:
    """``lifter_trained``: the lifter trained here with ``config`` (on request)."""

    @dg.asset(
        group_name="lifter",
        io_manager_key="checkpoint_io_manager",
        code_version=f"1-{config.digest()}",
        metadata={ON_REQUEST_KEY: "humancal train lifter"},
        automation_condition=UPDATE_CONDITION,
    )
    def lifter_trained(
        context: dg.AssetExecutionContext, torch_runtime: TorchResource, mocap_clips: pd.DataFrame
    ) -> dg.Output:
        """The 2D-to-3D lifter trained here on the retargeted CMU clips, subjects 02 and 14 held out
        (docs/lifter.md). Trained on request (``humancal train lifter`` or the weekly schedule), never by a
        plain update: the shipped weights serve until then."""
        train, val = split_held_out(_subject_clips(mocap_clips))
        context.log.info(
            f"training the lifter on {len(train)} clips ({sum(len(k) for _, k in train)} frames), "
            f"{len(val)} held-out clips; {config.epochs} epochs of {config.samples_per_epoch} samples"
        )

        def progress(record: dict) -> None:
            if record["kind"] == "epoch":
                context.log.info(
                    f"epoch {record['epoch']}/{config.epochs}: train loss {1000 * record['train_loss_m']:.1f} mm, "
                    f"held-out MPJPE {record['val_mpjpe_mm']:.1f} mm, PA-MPJPE {record['val_pa_mpjpe_mm']:.1f} mm "
                    f"({record['elapsed_s']:.0f} s)"
                )

        # Training runs on the CPU with the resource's threads (by default torch's own setting, one per physical
        # core; on a 2-core machine shared with other work one thread can be the faster: set them); the training's
        # own randomness comes from config.seed.
        with torch_runtime.applied():
            checkpoint, history = train_lifter(train, val, config, progress=progress)
        final = checkpoint["val_metrics"]
        with tempfile.TemporaryDirectory() as tmp:
            png = plot_training_history(history, Path(tmp) / "history.png", title="lifter training")
            picture = png_metadata(png, "training history")
        return versioned_output(
            checkpoint,
            checkpoint_content_version(checkpoint),
            training_time_s=round(float(checkpoint["training_time_s"]), 1),
            checkpoint_mb=round(checkpoint_num_bytes(checkpoint) / 1e6, 2),
            val_mpjpe_mm=round(final["mpjpe_mm"], 2),
            val_pa_mpjpe_mm=round(final["pa_mpjpe_mm"], 2),
            val_height_mae_mm=round(final["height_mae_mm"], 2),
            train_subjects=", ".join(checkpoint["train_subjects"]),
            held_out_subjects=", ".join(checkpoint["val_subjects"]),
            config_digest=config.digest(),
            history=picture,
        )

    return lifter_trained


def _lifter_checkpoint(active: ActiveLifter) -> dg.AssetsDefinition:
    """``lifter_checkpoint``: the lifter in force (``active``)."""

    @dg.asset(
        group_name="lifter",
        io_manager_key="checkpoint_io_manager",
        code_version=f"2-{active.source}-{active.digest[:16]}",
        automation_condition=UPDATE_CONDITION,
    )
    def lifter_checkpoint(context: dg.AssetExecutionContext) -> dg.Output:
        """The lifter every sequence is lifted with: the weights shipped with humancal, or, once
        ``humancal train lifter`` has run, the ones trained here (``lifter_trained``)."""
        checkpoint = active.load()
        digest = checkpoint_digest(checkpoint)
        if digest != active.digest:
            raise LifterWeightsError(
                f"{active.path}: its digest changed since the definitions loaded ({active.digest[:16]} -> "
                f"{digest[:16]}); reload the definitions (restart `humancal` or reload the code location)"
            )
        context.log.info(active.describe())
        metrics = checkpoint.get("val_metrics", {})
        return versioned_output(
            checkpoint,
            checkpoint_content_version(checkpoint),
            source=active.source,
            path=str(active.path),
            description=active.describe(),
            val_pa_mpjpe_mm=round(float(metrics.get("pa_mpjpe_mm", float("nan"))), 2),
            train_subjects=", ".join(checkpoint["train_subjects"]),
            held_out_subjects=", ".join(checkpoint["val_subjects"]),
        )

    return lifter_checkpoint


@dg.asset(
    group_name="lifter",
    metadata=table_metadata("metrics"),
    code_version="1",
    automation_condition=UPDATE_CONDITION,
)
def lifter_heldout_metrics(
    context: dg.AssetExecutionContext, mocap_clips: pd.DataFrame, lifter_checkpoint: dict
) -> dg.Output:
    """The lifter on fresh samples of the held-out CMU subjects: MPJPE, PA-MPJPE, height error (mm), by visibility."""
    _, val = split_held_out(_subject_clips(mocap_clips))
    report = held_out_report(load_lifter(lifter_checkpoint), val)
    rows = []
    for group, suffix in _GROUP_SUFFIX.items():
        if group not in report.index:
            continue
        r = report.loc[group]
        rows += [MetricRow(metric + suffix, float(r[column]), "mm") for metric, column in _HELD_OUT_METRICS]
        rows.append(MetricRow("share_pct" + suffix, float(r["share_pct"]), "%"))
    table = metrics_table("cmu_mocap", HELD_OUT_SEQUENCE, "lifter", rows)
    context.log.info(report.to_string(float_format=lambda v: f"{v:.1f}"))
    return table_output(table, "metrics", rows=len(table),
                        summary=dg.MetadataValue.md(report.to_markdown(floatfmt=".1f")))

