"""Training samples for the lifter: 3D motion seen by random virtual cameras through a simulated detector.

Motion comes as plain arrays, one ``(subject, keypoints_world_m (F, 23, 3))`` pair per clip (world metres,
Z up, floor z = 0; e.g. from ``humancal.retarget.RetargetedClip`` or ``humancal.synthetic.Motions``), so any
source works. Samples are made in groups:

1. draw ``frames_per_group`` frames uniformly from all frames of all clips (so every group mixes clips and a
   few thousand samples already cover many motions);
2. per frame: mirror left-right with probability ``mirror_prob`` (negate x, swap left/right labels), turn
   about the vertical by a uniform random angle, and move the hip midpoint horizontally to a random point
   near the origin (std ``root_offset_std_m``); heights are kept, so the feet stay on the floor;
3. draw ``cameras_per_group`` virtual cameras around the origin (:mod:`humancal.lifter.cameras`), sized for the
   median standing height of the group's clips (:func:`clip_heights_m`);
4. run the synthetic detector on every frame and camera (the group's median height sets the detector's pixel
   spreads; clips differ by a few percent, so the spreads do too) (``humancal.synthetic.simulate_detections``: self-
   occlusion, jitter, outliers, confidences, missing joints, left-right flips), and scale each detection's
   confidences by a random factor in ``score_scale_range``;
5. input = the box-normalised detection (:func:`humancal.lifter.features.normalize_detections`); target =
   the true keypoints in the camera frame, relative to the hip midpoint, turned into the detection's crop
   frame, in the detection's label order (a left-right flipped detection gets the flipped 3D pose, so
   every lifted 3D joint corresponds to the 2D joint of the same label).

Detections with fewer than ``min_joints`` joints are dropped.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

from humancal.keypoints import FLIP_INDEX, NUM_JOINTS
from humancal.lifter.cameras import sample_virtual_cameras
from humancal.lifter.config import SampleConfig
from humancal.lifter.features import ROOT_JOINTS, R_crop_from_cam, normalize_detections, root_relative
from humancal.lifter.pose_cues import height_from_pose_m
from humancal.synthetic.noise import simulate_detections

__all__ = ["LifterSamples", "check_clips", "clip_heights_m", "synthesize_samples"]

logger = logging.getLogger(__name__)

_FLIP = np.array(FLIP_INDEX)
_ROOT = list(ROOT_JOINTS)


@dataclass(frozen=True)
class LifterSamples:
    """N training (or validation) samples.

    Attributes:
        features: (N, 23, 3) float32 network inputs (box-normalised x, y, confidence).
        targets_m: (N, 23, 3) float32 true root-relative keypoints in the crop frame, metres, in the
            detection's label order.
        keypoints_px: (N, 23, 2) float32 the detections, pixels (NaN for missing joints).
        scores: (N, 23) float32 their confidences (0 for missing joints).
        box_centre_px: (N, 2) box centre of each detection, pixels.
        K: (N, 3, 3) intrinsics of the virtual camera, pixels.
        R_crop_from_cam: (N, 3, 3) rotation from the camera frame to the crop frame.
        root_cam_m: (N, 3) true hip midpoint in the camera frame, metres.
        clip_index: (N,) index of the source clip.
        height_m: (N,) standing height of the source clip (:func:`clip_heights_m`), metres.
        flipped: (N,) whether the detector swapped the detection's left/right labels.
    """

    features: np.ndarray
    targets_m: np.ndarray
    keypoints_px: np.ndarray
    scores: np.ndarray
    box_centre_px: np.ndarray
    K: np.ndarray
    R_crop_from_cam: np.ndarray
    root_cam_m: np.ndarray
    clip_index: np.ndarray
    height_m: np.ndarray
    flipped: np.ndarray

    def __len__(self) -> int:
        return int(self.features.shape[0])

    def subset(self, rows: np.ndarray) -> LifterSamples:
        """The samples of the given rows (indices or boolean mask)."""
        return LifterSamples(**{f.name: getattr(self, f.name)[rows] for f in fields(self)})

    @property
    def targets_cam_m(self) -> np.ndarray:
        """(N, 23, 3) the targets in the camera frame (root-relative, metres)."""
        return self.targets_m.astype(np.float64) @ self.R_crop_from_cam


def check_clips(clips: Sequence[tuple[str, np.ndarray]], name: str = "clips") -> list[tuple[str, np.ndarray]]:
    """Validate motion clips and return them as (subject, float64 array) pairs.

    Args:
        clips: non-empty sequence of ``(subject, keypoints_world_m (F, 23, 3))``, F >= 1, metres.
        name: the argument name used in error messages.

    Raises:
        ValueError: empty, malformed, or non-finite clips.
    """
    if isinstance(clips, (str, bytes)) or not isinstance(clips, Sequence) or len(clips) == 0:
        raise ValueError(f"{name} must be a non-empty sequence of (subject, keypoints_world_m (F, 23, 3)) pairs")
    checked = []
    for i, clip in enumerate(clips):
        if not (isinstance(clip, (tuple, list)) and len(clip) == 2 and isinstance(clip[0], str)):
            raise ValueError(f"{name}[{i}] must be a (subject: str, keypoints_world_m) pair, got {type(clip).__name__}")
        keypoints = np.asarray(clip[1], dtype=np.float64)
        if keypoints.ndim != 3 or keypoints.shape[1:] != (NUM_JOINTS, 3) or keypoints.shape[0] < 1:
            raise ValueError(
                f"{name}[{i}] keypoints_world_m must have shape (F >= 1, {NUM_JOINTS}, 3), got {keypoints.shape}"
            )
        if not np.isfinite(keypoints).all():
            raise ValueError(f"{name}[{i}] (subject {clip[0]!r}) has non-finite keypoints")
        checked.append((clip[0], keypoints))
    return checked


def clip_heights_m(clips: Sequence[tuple[str, np.ndarray]]) -> np.ndarray:
    """Standing height of each clip's person: the median of :func:`height_from_pose_m` over its frames.

    Returns:
        (C,) metres.
    """
    return np.array([float(np.median(height_from_pose_m(keypoints))) for _, keypoints in check_clips(clips)])


def _augment(world: np.ndarray, config: SampleConfig, rng: np.random.Generator) -> np.ndarray:
    """Mirror, turn and place the frames of one group (module docstring, step 2)."""
    n = world.shape[0]
    mirror = rng.random(n) < config.mirror_prob
    world = world.copy()
    world[mirror, :, 0] *= -1.0
    world[mirror] = world[mirror][:, _FLIP]
    world[..., :2] -= world[:, _ROOT, :2].mean(axis=1, keepdims=True)
    yaw = rng.uniform(0.0, 2.0 * np.pi, n)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, y = world[..., 0].copy(), world[..., 1].copy()
    world[..., 0], world[..., 1] = c * x - s * y, s * x + c * y
    world[..., :2] += rng.normal(0.0, config.root_offset_std_m, (n, 1, 2))
    return world


def _group_samples(
    world: np.ndarray, height_m: float, config: SampleConfig, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Detections and targets of one group of frames (module docstring, steps 3-5)."""
    pelvis_height = float(np.median(world[:, _ROOT, 2].mean(axis=1)))
    cameras = sample_virtual_cameras(config.cameras_per_group, height_m, pelvis_height, config.cameras, rng)
    out = simulate_detections(world[None], np.array([height_m]), cameras, config.noise, rng)
    real = out.person_id >= 0
    frame, view, flipped = out.frame[real], out.view[real], out.flipped[real]
    present = out.present[real]
    keypoints = np.where(present[..., None], out.keypoints_px[real], np.nan)
    factor = rng.uniform(*config.score_scale_range, len(frame))
    scores = np.where(present, np.clip(out.scores[real] * factor[:, None], 0.0, 1.0), 0.0)
    normalized = normalize_detections(keypoints, scores, config.min_joints)
    keep = normalized.valid
    frame, view, flipped = frame[keep], view[keep], flipped[keep]

    R = np.stack([c.R_cam_from_world for c in cameras])[view]
    t = np.stack([c.t_cam_from_world_m for c in cameras])[view]
    K = np.stack([c.K for c in cameras])[view]
    absolute_cam = world[frame] @ R.transpose(0, 2, 1) + t[:, None, :]
    joints_cam = root_relative(absolute_cam)
    joints_cam[flipped] = joints_cam[flipped][:, _FLIP]
    centre = normalized.box_centre_px[keep]
    R_crop = R_crop_from_cam(centre, K)
    return {
        "features": normalized.features[keep],
        "targets_m": (joints_cam @ R_crop.transpose(0, 2, 1)).astype(np.float32),
        "keypoints_px": keypoints[keep].astype(np.float32),
        "scores": scores[keep].astype(np.float32),
        "box_centre_px": centre,
        "K": K,
        "R_crop_from_cam": R_crop,
        "root_cam_m": absolute_cam[:, _ROOT].mean(axis=1),
        "flipped": flipped,
        "frame": frame,
    }


def synthesize_samples(
    clips: Sequence[tuple[str, np.ndarray]],
    num_samples: int,
    config: SampleConfig,
    rng: np.random.Generator,
) -> LifterSamples:
    """Exactly ``num_samples`` samples from the clips (see the module docstring).

    Args:
        clips: ``(subject, keypoints_world_m (F, 23, 3))`` pairs, world metres, Z up, floor z = 0.
        num_samples: N >= 1.
        config: the synthesis settings.
        rng: source of randomness (the same generator state gives the same samples).

    Returns:
        The :class:`LifterSamples`.

    Raises:
        ValueError: malformed clips, ``num_samples`` < 1, or no detection survives many groups in a row (the
            clips do not look like people standing on the floor near the origin's height).
    """
    clips = check_clips(clips)
    if num_samples < 1:
        raise ValueError(f"num_samples={num_samples} must be >= 1")
    # False positives and missed people have no target; skip simulating them.
    noise = replace(config.noise, false_positives_per_image=0.0, person_miss_rate=0.0)
    heights = clip_heights_m(clips)
    all_frames = np.concatenate([keypoints for _, keypoints in clips])
    clip_of_frame = np.repeat(np.arange(len(clips)), [len(keypoints) for _, keypoints in clips])
    group_config = replace(config, noise=noise)
    parts: list[dict[str, np.ndarray]] = []
    total, empty_groups = 0, 0
    while total < num_samples:
        picked = rng.integers(0, len(all_frames), config.frames_per_group)
        world = _augment(all_frames[picked], config, rng)
        group = _group_samples(world, float(np.median(heights[clip_of_frame[picked]])), group_config, rng)
        n = len(group["features"])
        empty_groups = empty_groups + 1 if n == 0 else 0
        if empty_groups >= 20:
            raise ValueError(
                "synthesize_samples: 20 groups in a row gave no detection; check the clips' units and axes"
            )
        group["clip_index"] = clip_of_frame[picked][group.pop("frame")]
        group["height_m"] = heights[group["clip_index"]]
        parts.append(group)
        total += n
    merged = {key: np.concatenate([p[key] for p in parts])[:num_samples] for key in parts[0]}
    logger.debug("synthesised %d samples from %d groups", num_samples, len(parts))
    return LifterSamples(**merged)
