"""The 2D-to-3D lifter: one root-relative 3D pose for every 2D detection (``docs/lifter.md``).

Trained here on 3D motion clips seen through random virtual cameras and the synthetic detector model; it
stands in for the image-based SPIN of the paper (the method sees keypoints only).

Example:
    >>> from humancal.lifter import LifterConfig, load_lifter, lift_detections, train_lifter
    >>> checkpoint, history = train_lifter(train_clips, val_clips, LifterConfig.default())  # doctest: +SKIP
    >>> lifted = lift_detections(load_lifter(checkpoint), keypoints_px, scores)  # doctest: +SKIP
    >>> lifted.joints_cam_m.shape, lifted.height_m.shape, lifted.upright_score.shape  # doctest: +SKIP
    ((D, 23, 3), (D,), (D,))
"""

from humancal.lifter.cameras import sample_virtual_cameras
from humancal.lifter.config import LifterConfig, SampleConfig, VirtualCameraRanges, training_noise
from humancal.lifter.data import LifterSamples, check_clips, clip_heights_m, synthesize_samples
from humancal.lifter.evaluate import (
    HELD_OUT_CMU_SUBJECTS,
    evaluate_lifter,
    evaluate_predictions,
    held_out_report,
    split_held_out,
)
from humancal.lifter.features import (
    ROOT_JOINTS,
    NormalizedDetections,
    R_crop_from_cam,
    normalize_detections,
    root_relative,
    rotate_crop_to_camera,
)
from humancal.lifter.infer import CHECKPOINT_FORMAT, LiftedPoses, Lifter, lift_detections, lift_features, load_lifter
from humancal.lifter.model import LifterNet
from humancal.lifter.pose_cues import height_chain_m, height_from_pose_m, standing_score, upright_score
from humancal.lifter.plot import plot_training_history
from humancal.lifter.table import lift_detections_table, lifted_from_table, lifted_to_table
from humancal.lifter.train import checkpoint_digest, checkpoint_num_bytes, mpjpe_loss_m, train_lifter
from humancal.lifter.weights import (
    SHIPPED_LIFTER_STEM,
    LifterWeightsError,
    read_lifter_info,
    read_lifter_weights,
    shipped_checkpoint,
    shipped_info,
    write_lifter_weights,
)

__all__ = [
    "CHECKPOINT_FORMAT",
    "SHIPPED_LIFTER_STEM",
    "LifterWeightsError",
    "read_lifter_info",
    "read_lifter_weights",
    "shipped_checkpoint",
    "shipped_info",
    "write_lifter_weights",
    "LiftedPoses",
    "Lifter",
    "LifterConfig",
    "LifterNet",
    "LifterSamples",
    "NormalizedDetections",
    "ROOT_JOINTS",
    "R_crop_from_cam",
    "SampleConfig",
    "VirtualCameraRanges",
    "HELD_OUT_CMU_SUBJECTS",
    "check_clips",
    "checkpoint_digest",
    "held_out_report",
    "split_held_out",
    "checkpoint_num_bytes",
    "clip_heights_m",
    "evaluate_lifter",
    "evaluate_predictions",
    "height_chain_m",
    "height_from_pose_m",
    "lift_detections",
    "lift_detections_table",
    "lifted_from_table",
    "lifted_to_table",
    "lift_features",
    "load_lifter",
    "mpjpe_loss_m",
    "normalize_detections",
    "plot_training_history",
    "root_relative",
    "rotate_crop_to_camera",
    "sample_virtual_cameras",
    "synthesize_samples",
    "train_lifter",
    "training_noise",
    "standing_score",
    "upright_score",
]
