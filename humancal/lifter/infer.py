"""Lift detections with a trained lifter: checkpoint in, one 3D pose per 2D detection out.

Without intrinsics (the situation of the calibration stage) poses come in each detection's crop frame
(``humancal.lifter.features``): the camera frame turned to look straight at the detection's box centre. Give
``K`` (or call :meth:`LiftedPoses.in_camera_frame` later) to get them in the camera frame exactly.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from humancal.keypoints import FLIP_INDEX, NUM_JOINTS
from humancal.lifter.config import LifterConfig
from humancal.lifter.features import normalize_detections
from humancal.lifter.lifted import LiftedPoses
from humancal.lifter.model import LifterNet
from humancal.lifter.pose_cues import height_from_pose_m, upright_score

__all__ = ["CHECKPOINT_FORMAT", "Lifter", "LiftedPoses", "load_lifter", "lift_detections", "lift_features"]

logger = logging.getLogger(__name__)

_FLIP = list(FLIP_INDEX)

CHECKPOINT_FORMAT = "humancal.lifter/1"
"""Value of ``checkpoint["format"]`` this module reads and :func:`humancal.lifter.train.train_lifter` writes."""


@dataclass(frozen=True)
class Lifter:
    """A trained lifting network with the configuration it was trained with.

    Attributes:
        net: the network, in eval mode, float32.
        config: the training configuration (its ``samples.min_joints`` applies at inference too).
    """

    net: LifterNet
    config: LifterConfig

    @property
    def min_joints(self) -> int:
        """Detections with fewer confident joints are not lifted."""
        return self.config.samples.min_joints


def load_lifter(checkpoint: Mapping[str, Any] | str | Path, device: torch.device | str = "cpu") -> Lifter:
    """Build the lifter stored in a checkpoint.

    Args:
        checkpoint: the dict written by ``train_lifter`` or a path to it saved with ``torch.save`` (read with
            ``torch.load(weights_only=True)``).
        device: where the network runs.

    Returns:
        The :class:`Lifter`, in eval mode.

    Raises:
        ValueError: not a lifter checkpoint of this format, or weights that do not fit the stored config.
    """
    if isinstance(checkpoint, (str, Path)):
        checkpoint = torch.load(Path(checkpoint), map_location="cpu", weights_only=True)
    if not isinstance(checkpoint, Mapping) or checkpoint.get("format") != CHECKPOINT_FORMAT:
        found = checkpoint.get("format") if isinstance(checkpoint, Mapping) else type(checkpoint).__name__
        raise ValueError(f"not a lifter checkpoint: expected format {CHECKPOINT_FORMAT!r}, got {found!r}")
    config = LifterConfig.from_dict(checkpoint["config"])
    net = LifterNet(config.width, config.num_blocks, config.dropout)
    try:
        net.load_state_dict(checkpoint["state_dict"])
    except RuntimeError as error:
        raise ValueError(f"lifter checkpoint weights do not fit its config: {error}") from error
    return Lifter(net.to(device=device, dtype=torch.float32).eval(), config)


def _mirror(batch: torch.Tensor) -> torch.Tensor:
    """Left-right mirror of inputs or poses: x negated (image or crop frame), left and right labels swapped."""
    mirrored = batch[:, _FLIP].clone()
    mirrored[..., 0] = -mirrored[..., 0]
    return mirrored


def lift_features(
    net: LifterNet, features: np.ndarray, batch_size: int = 8192, mirror_average: bool = True
) -> np.ndarray:
    """Run the network on normalised inputs, in batches, without gradients.

    Args:
        net: the network (its train/eval mode is restored afterwards; eval is used here).
        features: (N, 23, 3) box-normalised inputs.
        batch_size: rows per forward pass.
        mirror_average: also lift the left-right mirrored input (x negated, labels swapped), mirror that
            answer back and average the two (test-time augmentation: about 2 mm lower PA-MPJPE on held-out
            CMU subjects, for twice the compute).

    Returns:
        (N, 23, 3) float64 root-relative crop-frame joints, metres.
    """
    device = next(net.parameters()).device
    was_training = net.training
    net.eval()
    out = np.empty(features.shape[:1] + (NUM_JOINTS, 3), dtype=np.float64)
    with torch.no_grad():
        for start in range(0, len(features), batch_size):
            batch = torch.as_tensor(features[start : start + batch_size], dtype=torch.float32, device=device)
            joints = net(batch)
            if mirror_average:
                joints = 0.5 * (joints + _mirror(net(_mirror(batch))))
            out[start : start + batch_size] = joints.double().cpu().numpy()
    net.train(was_training)
    return out


def lift_detections(
    lifter: Lifter,
    keypoints_px: np.ndarray,
    scores: np.ndarray,
    K: np.ndarray | None = None,
    batch_size: int = 8192,
) -> LiftedPoses:
    """Lift every detection to a root-relative 3D pose (batched, no gradients).

    Args:
        lifter: from :func:`load_lifter`.
        keypoints_px: (D, 23, 2) canonical keypoints, pixels (NaN or anything where the score is 0).
        scores: (D, 23) confidences in [0, 1], 0 for missing joints.
        K: optional (3, 3) or (D, 3, 3) intrinsics, pixels; with it the poses come in the camera frame,
            without it in each detection's crop frame (never shown to the network either way).
        batch_size: detections per forward pass (results do not depend on it).

    Returns:
        The :class:`LiftedPoses`; detections with fewer than ``lifter.min_joints`` joints get NaN poses and
        ``valid`` False.

    Raises:
        ValueError: wrong shapes, non-finite or out-of-range scores, a non-finite position of a joint with a
            positive score, a bad K, or ``batch_size`` < 1.
    """
    if batch_size < 1:
        raise ValueError(f"batch_size={batch_size} must be >= 1")
    normalized = normalize_detections(keypoints_px, scores, lifter.min_joints)
    valid = normalized.valid
    joints = np.full(valid.shape + (NUM_JOINTS, 3), np.nan)
    if valid.any():
        joints[valid] = lift_features(lifter.net, normalized.features[valid], batch_size)
    if (~valid).any():
        logger.debug(
            "%d of %d detections have fewer than %d joints: not lifted", (~valid).sum(), len(valid), lifter.min_joints
        )
    centre = normalized.box_centre_px
    lifted = LiftedPoses(joints, height_from_pose_m(joints), upright_score(joints), valid, centre, "crop")
    if K is None:
        return lifted
    camera = lifted.in_camera_frame(K)
    return replace(camera, upright_score=upright_score(camera.joints_cam_m))
