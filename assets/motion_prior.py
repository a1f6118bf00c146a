"""Shared by all sequences: the motion prior, one checkpoint per variant trained on the retargeted CMU mocap, its
held-out figures (docs/motion_prior.md), and the checkpoint the body fit uses.

``motion_prior_trained`` and ``prior_metrics`` are partitioned by variant (``PRIOR_VARIANT_PARTITIONS``: the default
``motion_prior`` and the ablations) and computed on request only: ``humancal train prior [--variant V]``, the
``prior_training`` job, its weekly schedule or the mocap-change sensor (``pipelines/sensors.py``); never by a plain
``humancal update``. ``motion_prior_checkpoint`` serves the prior in force (:mod:`resources.prior_source`): the
weights shipped with humancal until the default variant has been trained here, then those. It is an input of the
body fit, so a retrained prior makes every fitted motion stale and the next ``humancal update`` refits them.
"""

import hashlib
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd
import torch

from assets.common import ON_REQUEST_KEY, UPDATE_CONDITION, png_metadata, table_metadata, table_output, versioned_output
from assets.lifter import HELD_OUT_SEQUENCE
from evaluation.protocols import MetricRow, metrics_table
from humancal.prior import PRIOR_VARIANTS, MotionVAE, PriorConfig, rotmats_to_pose6d
from humancal.prior.evaluate import (
    DENOISE_FIT_CONFIGS,
    denoising_benchmark,
    motion_segments,
    reconstruction_method,
    reconstruction_report,
)
from humancal.prior.plot import plot_latent_interpolation, plot_prior_samples, plot_training_history
from humancal.prior.train import train_motion_prior
from humancal.prior.weights import PriorWeightsError
from humancal.retarget import motions_table_to_clips
from resources.body_model import BodyModelResource
from resources.io_managers import checkpoint_content_version
from resources.prior_source import ActivePrior, active_prior, shipped_active_prior
from resources.torch import TorchResource

PRIOR_VARIANT_PARTITIONS = dg.StaticPartitionsDefinition(list(PRIOR_VARIANTS))
"""One partition per variant of the motion prior."""

TRAIN_COMMAND = "humancal train prior"


@dataclass(frozen=True)
class PriorEvaluationSettings:
    """Size of the held-out denoising benchmark of ``prior_metrics``.

    Attributes:
        segments: held-out segments fitted (one batch).
        frames: frames per segment.
        seed: seeds the choice of segments and the corruption.
        iterations: Adam steps of every fit (None: those of ``DENOISE_FIT_CONFIGS``).
    """

    segments: int = 16
    frames: int = 120
    seed: int = 0
    iterations: int | None = None


def prior_checkpoint(trained) -> dict:
    """A ``humancal.prior.train.TrainedPrior`` as a checkpoint dict (tensors and plain values, ``weights_only``-safe).

    The keys hashed into the content version (:func:`resources.io_managers.checkpoint_content_version`) are
    ``state_dict``, ``config``, ``train_subjects`` and ``val_subjects``: new weights give a new data version.
    """
    return {
        "state_dict": {k: v.detach().cpu().clone() for k, v in trained.model.state_dict().items()},
        "config": trained.config.to_dict(),
        "train_subjects": list(trained.train_subjects),
        "val_subjects": list(trained.held_out_subjects),
        "history": [{k: float(v) for k, v in record.items()} for record in trained.history],
        "train_seconds": float(trained.train_seconds),
        "held_out": {k: float(v) for k, v in trained.held_out.items()},
    }


def prior_from_checkpoint(checkpoint: dict) -> MotionVAE:
    """The motion VAE of a checkpoint written by :func:`prior_checkpoint` (eval mode, parameters frozen)."""
    model = MotionVAE(PriorConfig.from_dict(checkpoint["config"]))
    model.load_state_dict(checkpoint["state_dict"])
    model.requires_grad_(False)
    return model.eval()


def _configs_digest(configs: Mapping[str, PriorConfig]) -> str:
    text = ",".join(f"{v}:{configs[v].digest()}" for v in sorted(configs))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def build_motion_prior_assets(
    configs: Mapping[str, PriorConfig] | None = None,
    evaluation: PriorEvaluationSettings | None = None,
    train_workers: int = 2,
    storage_root: str | None = None,
) -> list[dg.AssetsDefinition]:
    """``motion_prior_trained`` and ``prior_metrics``, partitioned by variant, and ``motion_prior_checkpoint``.

    Args:
        configs: training configuration by variant (default :meth:`PriorConfig.default` of each; tests use tiny
            ones). Their digest is part of the checkpoint's code version.
        evaluation: size of the denoising benchmark (default :class:`PriorEvaluationSettings`).
        train_workers: processes sharing each training step (``humancal.prior.train_motion_prior``'s ``workers``,
            one intra-op thread each; 2 suits a 2-core machine). Part of the checkpoint's code version: the
            worker count changes the windows drawn.
        storage_root: the artifacts root where ``motion_prior_trained`` is stored (None: the shipped prior is
            the one in force).
    """
    configs = dict(configs or {v: PriorConfig.default(v) for v in PRIOR_VARIANTS})
    missing = [v for v in PRIOR_VARIANTS if v not in configs or configs[v].variant != v]
    if missing:
        raise ValueError(f"build_motion_prior_assets: configs needs one PriorConfig per variant; wrong or missing: {missing}")
    evaluation = evaluation or PriorEvaluationSettings()
    undivided = [v for v in PRIOR_VARIANTS if isinstance(train_workers, int) and train_workers >= 1
                 and configs[v].batch_size % train_workers]
    if isinstance(train_workers, bool) or not isinstance(train_workers, int) or train_workers < 1 or undivided:
        raise ValueError(f"build_motion_prior_assets: train_workers={train_workers!r} must be a positive integer "
                         f"dividing every variant's batch_size (not: {undivided})")

    active = active_prior(storage_root) if storage_root is not None else shipped_active_prior()
    return [_motion_prior_trained(configs, train_workers), _prior_metrics(evaluation), _motion_prior_checkpoint(active)]


def _motion_prior_trained(configs: Mapping[str, PriorConfig], train_workers: int) -> dg.AssetsDefinition:
    """``motion_prior_trained``: one variant's prior trained here with its configuration (on request)."""

    @dg.asset(
        group_name="motion_prior",
        partitions_def=PRIOR_VARIANT_PARTITIONS,
        io_manager_key="checkpoint_io_manager",
        code_version=f"2-{_configs_digest(configs)}-{train_workers}w",
        metadata={ON_REQUEST_KEY: TRAIN_COMMAND},
    )
    def motion_prior_trained(
        context: dg.AssetExecutionContext, torch_runtime: TorchResource, body_model: BodyModelResource,
        mocap_clips: pd.DataFrame,
    ) -> dg.Output:
        """The motion prior of one variant trained here on the retargeted CMU clips, subjects 02 and 14 held out.
        Trained on request (``humancal train prior``, the weekly schedule or the mocap-change sensor)."""
        config = configs[context.partition_key]
        clips = motions_table_to_clips(mocap_clips)
        context.log.info(f"training the motion prior '{config.variant}' on {len(clips)} clips "
                         f"({config.epochs} epochs of {config.steps_per_epoch} steps, seed {config.seed})")

        def progress(record: dict) -> None:
            context.log.info(f"epoch {record['epoch']}/{config.epochs}: loss {record['train_loss']:.4f}, held-out "
                             f"reconstruction {record['val_mpjpe_mm']:.1f} mm ({record['elapsed_s']:.0f} s)")

        body = body_model.get()
        with torch_runtime.applied():
            trained = train_motion_prior(clips, config, body, progress=progress, workers=train_workers)
        checkpoint = prior_checkpoint(trained)
        with tempfile.TemporaryDirectory() as tmp:
            pictures = _pictures(trained.model, body, clips, checkpoint, Path(tmp), config.variant)
        return versioned_output(
            checkpoint,
            checkpoint_content_version(checkpoint),
            variant=config.variant,
            train_seconds=round(trained.train_seconds, 1),
            held_out_mpjpe_mm=round(float(trained.held_out.get("mpjpe_mm", float("nan"))), 2),
            train_subjects=", ".join(trained.train_subjects),
            held_out_subjects=", ".join(trained.held_out_subjects),
            config_digest=config.digest(),
            **pictures,
        )

    return motion_prior_trained


def _prior_metrics(evaluation: PriorEvaluationSettings) -> dg.AssetsDefinition:
    """``prior_metrics``: one variant's held-out figures, with the denoising benchmark of size ``evaluation``."""

    @dg.asset(
        group_name="motion_prior",
        partitions_def=PRIOR_VARIANT_PARTITIONS,
        metadata={**table_metadata("metrics"), ON_REQUEST_KEY: TRAIN_COMMAND},
        code_version="2",  # 2: the fit weights of DENOISE_FIT_CONFIGS chosen again for the 40-epoch priors
    )
    def prior_metrics(
        context: dg.AssetExecutionContext, torch_runtime: TorchResource, body_model: BodyModelResource,
        mocap_clips: pd.DataFrame, motion_prior_trained: dict,
    ) -> dg.Output:
        """Held-out figures of one variant: reconstruction (method ``motion_prior[/<variant>]``) and the denoising
        benchmark in 3D and through four virtual cameras (metrics suffixed ``/views_2d``); the default variant's
        partition also holds the no-prior fit (docs/motion_prior.md, "Evaluation")."""
        variant = context.partition_key
        prior = prior_from_checkpoint(motion_prior_trained)
        held = set(motion_prior_trained["val_subjects"])
        clips = [c for c in motions_table_to_clips(mocap_clips) if c.subject in held]
        body = body_model.get()
        with torch_runtime.applied():
            table, summary = prior_metric_rows(prior, variant, clips, body, evaluation,
                                               float(motion_prior_trained["train_seconds"]))
        context.log.info("\n" + summary.to_string(float_format=lambda v: f"{v:.1f}"))
        return table_output(table, "metrics", rows=len(table),
                            summary=dg.MetadataValue.md(summary.to_markdown(floatfmt=".1f")))

    return prior_metrics


def _motion_prior_checkpoint(active: ActivePrior) -> dg.AssetsDefinition:
    """``motion_prior_checkpoint``: the prior in force (``active``)."""

    @dg.asset(
        group_name="motion_prior",
        io_manager_key="checkpoint_io_manager",
        code_version=f"1-{active.source}-{active.digest[:16]}",
        automation_condition=UPDATE_CONDITION,
    )
    def motion_prior_checkpoint(context: dg.AssetExecutionContext) -> dg.Output:
        """The motion prior every body fit uses: the weights shipped with humancal, or, once ``humancal train
        prior`` has trained the default variant here, those (``motion_prior_trained``)."""
        checkpoint = active.load()
        if active.source == "trained" and checkpoint_content_version(checkpoint) != active.digest:
            raise PriorWeightsError(f"{active.path}: its weights changed since the definitions loaded; reload the "
                                    "definitions (restart `humancal`, or reload the code location in the UI)")
        context.log.info(active.describe())
        return versioned_output(checkpoint, checkpoint_content_version(checkpoint), source=active.source,
                                path=str(active.path), description=active.describe(),
                                train_subjects=", ".join(checkpoint["train_subjects"]),
                                held_out_subjects=", ".join(checkpoint["val_subjects"]))

    return motion_prior_checkpoint


def prior_metric_rows(prior: MotionVAE, variant: str, held_out_clips: list, body, evaluation: PriorEvaluationSettings,
                      train_seconds: float) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The metrics table of one variant on the held-out clips, and a summary (one row per method and setting)."""
    recon = reconstruction_report(prior, held_out_clips, body)  # in the body fit's windows
    whole = reconstruction_report(prior, held_out_clips, body, window=None)
    tables = [metrics_table("cmu_mocap", HELD_OUT_SEQUENCE, reconstruction_method(variant), [
        MetricRow("mpjpe_mm", recon["mpjpe_mm"], "mm"),
        MetricRow("accel_error_mm_s2", recon["accel_error_mm_s2"], "mm/s^2"),
        MetricRow("mpjpe_whole_clip_mm", whole["mpjpe_mm"], "mm"),
        MetricRow("train_seconds", train_seconds, "s"),
    ])]
    summary = [{"method": reconstruction_method(variant), "setting": "reconstruction",
                "mpjpe_mm": recon["mpjpe_mm"], "accel_error_mm_s2": recon["accel_error_mm_s2"]}]
    segments = motion_segments(held_out_clips, evaluation.frames, evaluation.segments, evaluation.seed)
    fit_configs = {m: c if evaluation.iterations is None else c.replace(iterations=evaluation.iterations)
                   for m, c in DENOISE_FIT_CONFIGS.items()}
    for setting, suffix in (("3d", ""), ("2d", "/views_2d")):
        bench = denoising_benchmark(body, segments, {variant: prior}, fit_configs, setting, evaluation.seed,
                                    include_no_prior=variant == "motion_prior")
        for row in bench.itertuples():
            tables.append(metrics_table("cmu_mocap", HELD_OUT_SEQUENCE, row.method, [
                MetricRow("mpjpe_mm" + suffix, row.mpjpe_mm, "mm"),
                MetricRow("accel_error_mm_s2" + suffix, row.accel_error_mm_s2, "mm/s^2"),
                MetricRow("fit_seconds" + suffix, row.fit_seconds, "s"),
            ]))
            summary.append({"method": row.method, "setting": setting, "mpjpe_mm": row.mpjpe_mm,
                            "accel_error_mm_s2": row.accel_error_mm_s2})
    return pd.concat(tables, ignore_index=True), pd.DataFrame(summary).set_index(["method", "setting"])


def _pictures(model: MotionVAE, body, clips: list, checkpoint: dict, folder: Path, variant: str) -> dict:
    """Training curves, an interpolation between two held-out frames' codes and samples, as metadata."""
    held = set(checkpoint["val_subjects"])
    shown = [c for c in clips if c.subject in held][:2] or clips[:2]
    with torch.no_grad():
        codes = []
        for clip in shown:
            rotmats = torch.as_tensor(np.array(clip.bone_rotmats_local[:, 1:]), dtype=torch.float32)[None]
            codes.append(model.encode(rotmats_to_pose6d(rotmats))[0][0, len(clip.bone_rotmats_local) // 2])
    history = plot_training_history(checkpoint["history"], folder / "history.png", title=f"motion prior: {variant}")
    interpolation = plot_latent_interpolation(model, body, codes[0], codes[-1], folder / "interpolation.png",
                                              title=f"{variant}: from {shown[0].name} to {shown[-1].name}")
    samples = plot_prior_samples(model, body, folder / "samples.png", title=f"{variant}: samples from N(0, I)")
    return {
        "history": png_metadata(history, "training history"),
        "interpolation": png_metadata(interpolation, "latent interpolation"),
        "samples": png_metadata(samples, "samples"),
    }
