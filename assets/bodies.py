"""Per sequence: every person's body shape and motion fitted to the associated detections through the motion
prior, and the cameras refined together with them (the paper's III-E; ``docs/bodies.md``, ``docs/refinement.md``)."""

import tempfile
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd

from assets.common import UPDATE_CONDITION, png_metadata, table_metadata, table_output
from assets.motion_prior import prior_from_checkpoint
from assets.partitions import SEQUENCES
from assets.settings import BodyFitSettings
from humancal.camera import CameraRig
from humancal.datasets.inputs import body_fit_regime, sequence_fps
from humancal.fitting import body_observations, fit_bodies
from humancal.fitting.plot import plot_fit_reprojection, plot_fit_scene
from humancal.geometry.rotations import rotation_distance_deg
from humancal.lifter import lifted_from_table
from humancal.viewing.pictures import plot_reprojection_errors
from humancal.viewing.reprojection import fitted_keypoints
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource
from resources.io_managers import checkpoint_content_version
from resources.torch import TorchResource

CODE_VERSION = "13"
"""13: the prior is an input (``motion_prior_checkpoint``): new weights make every fit stale through its data
version."""


_OUTPUTS = {
    "fitted_motions": ("motions", "Every person's anny body (phenotypes) and motion (bone rotations, root "
                                  "translation, keypoints) per frame, fitted to the associated detections through "
                                  "the motion prior, the cameras refined with them."),
    "refined_cameras": ("cameras", "The cameras refined together with the people's bodies and motions (focal "
                                   "length and extrinsics unless the settings hold some), in the same world as "
                                   "fitted_motions (floor at z = 0)."),
}


@dg.multi_asset(
    outs={name: dg.AssetOut(description=desc, metadata=table_metadata(table), code_version=CODE_VERSION,
                            automation_condition=UPDATE_CONDITION)
          for name, (table, desc) in _OUTPUTS.items()},
    partitions_def=SEQUENCES,
    group_name="sequence",
)
def body_fit(context: dg.AssetExecutionContext, config: BodyFitSettings, body_model: BodyModelResource,
             torch_runtime: TorchResource, datasets: DatasetsResource, detections: pd.DataFrame,
             associations: pd.DataFrame, skeletons3d: pd.DataFrame, extrinsics: pd.DataFrame,
             motion_prior_checkpoint: dict):
    """Fit shape and motion of every tracked person and refine the cameras with them
    (``humancal.fitting.fit_bodies``): from the detections, the association and the calibrated cameras only
    (never ground truth), through the motion prior in force (``motion_prior_checkpoint``). A capture whose cameras
    are all known holds them (regime ``fixed``) unless its
    ``cameras`` option says ``refine``."""
    sequence = context.partition_key
    spec = datasets.spec(sequence)
    fit_config = config.to_library().replace(cameras=body_fit_regime(spec, config.cameras))
    if fit_config.cameras != config.cameras:
        context.log.info(f"{sequence}: every camera is known: held by the fit (cameras: fixed)")
    fps, fps_source = sequence_fps(spec)
    dense, _ = lifted_from_table(detections)
    rig = CameraRig.from_table(extrinsics)
    body = body_model.get()
    observations, warnings = body_observations(dense, associations, skeletons3d, len(rig))
    for warning in warnings:
        context.log.warning(warning)
    context.log.info(f"{sequence}: fitting {observations.num_people} people over {observations.num_frames} frames "
                     f"in {observations.num_views} views at {fps:g} fps ({fps_source})")
    with torch_runtime.applied():
        prior = prior_from_checkpoint(motion_prior_checkpoint)
        result = fit_bodies(body, observations, rig, prior, fit_config, fps=fps,
                            warnings=tuple(warnings))
    table = result.motions.to_table(sequence)
    refined = result.cameras
    with tempfile.TemporaryDirectory() as tmp:
        pictures = {
            "reprojection": png_metadata(plot_fit_reprojection(body, result.motions, observations, refined,
                                                               Path(tmp) / "reprojection.png"),
                                         "fitted meshes reprojected over the detections"),
            "scene": png_metadata(plot_fit_scene(body, result.motions, refined, Path(tmp) / "scene.png"),
                                  "the fitted people and the cameras in 3D"),
            "errors_per_view": png_metadata(plot_reprojection_errors(
                fitted_keypoints(result.motions), refined, detections, associations,
                [f"view {v}" for v in range(len(refined))], Path(tmp) / "errors.png"),
                "per-view reprojection error over time"),
        }
    context.log.info(f"{sequence}: {result.motions.num_people} bodies fitted in {result.stage_seconds['total']:.1f} s, "
                     f"reprojection {result.reprojection_error_px:.2f} px")
    for warning in result.warnings[len(warnings):]:
        context.log.warning(warning)
    yield table_output(
        table, "motions", output_name="fitted_motions", rows=len(table), num_people=result.motions.num_people,
        fps=fps, reprojection_error_px=round(result.reprojection_error_px, 3), cameras=fit_config.cameras,
        **{f"seconds_{stage}": round(s, 3) for stage, s in result.stage_seconds.items()},
        **{f"loss_{term}": float(v) for term, v in result.loss_terms.items()},
        camera_rounds=len(result.round_shifts_px),
        camera_round_shifts_px=", ".join(f"{shift:.3f}" for shift in result.round_shifts_px) or "none",
        prior_weights=checkpoint_content_version(motion_prior_checkpoint)[:12],
        warnings="; ".join(result.warnings) or "none", **pictures)
    changes = _camera_changes(rig, refined)
    context.log.info(f"{sequence}: cameras ({fit_config.cameras}) moved by " + ", ".join(
        f"{k} {v:.3g}" for k, v in changes.items()))
    yield table_output(refined.to_table(sequence), "cameras", output_name="refined_cameras", rows=len(refined),
                       regime=fit_config.cameras, **changes)


def _camera_changes(before: CameraRig, after: CameraRig) -> dict[str, float]:
    """How far the refinement moved the cameras (means over views): focal %, centre mm, orientation deg."""
    focal = np.sqrt(after.K[:, 0, 0] * after.K[:, 1, 1]) / np.sqrt(before.K[:, 0, 0] * before.K[:, 1, 1])
    return {
        "focal_change_pct": float(np.mean(np.abs(focal - 1.0)) * 100.0),
        "centre_change_mm": float(np.linalg.norm(after.centers_world_m - before.centers_world_m, axis=1).mean()
                                  * 1000.0),
        "angle_change_deg": float(rotation_distance_deg(after.R_cam_from_world, before.R_cam_from_world).mean()),
    }
