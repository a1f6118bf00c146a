"""A simulated 2D pose detector: ground-truth keypoints in, realistic detections out.

Per view, for every person and frame (all vectorised with numpy; the only loop is over views):

1. project the 23 keypoints through the lens (its distortion included); joints behind the camera, outside
   the image, or beyond the radius where a barrel lens model folds back on itself are not seen;
2. occlusion degree of each joint from a capsule model of all bodies (:mod:`humancal.synthetic.occlusion`);
3. a person is *eligible* when at least ``min_visible_joints`` joints are in the image and not fully occluded;
   an eligible person is missed with probability ``person_miss_rate``;
4. Gaussian jitter per joint, proportional to the apparent height ``scale_px = fx * height_m / depth_m`` and
   to per-joint weights (COCO keypoint sigmas), inflated for occluded joints; rare gross outliers;
5. confidence = ``score_mean`` + noise, lowered by occlusion and near the image border;
6. joints go missing with a probability rising with occlusion, and jittered joints that leave the image are
   dropped; a detection left with fewer than ``min_visible_joints`` joints is dropped;
7. a detection has its left/right labels swapped with probability ``flip_rate``.

Then false positives are added per view and frame (Poisson): a real pose from elsewhere in the scene,
placed at a random image position and depth (a reflection, a poster, a passer-by), whole or only one body
part. Every random number comes from the one generator passed in, in a fixed order. A person out of the
capture (``hidden``: the scene's ``out_of_view_spells``) is in no image: nobody detects or is occluded by them.
Views on their own clocks (unsynchronised videos) go through :func:`simulate_view_detections`: each view with the
people's keypoints at its own frames' times, numbered by its own frames. The per-joint pieces (lens fold, image
bounds, jitter, confidence) are in :mod:`humancal.synthetic.detector_errors`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.camera import Camera, CameraRig, project_points
from humancal.keypoints import FLIP_INDEX, JOINT_INDEX, NUM_JOINTS, joint_indices
from humancal.synthetic.detector_errors import (
    border_distance_px,
    distort,
    inside_image,
    jitter_px,
    joint_scores,
    lens_fold_radius,
    within_lens,
)
from humancal.synthetic.detector_noise import DetectorNoise
from humancal.synthetic.occlusion import occlusion_degree

__all__ = ["DetectorNoise", "DetectorOutput", "draw_keypoint_bias", "simulate_detections", "simulate_view_detections"]

_FLIP = np.array(FLIP_INDEX)
_HIPS = joint_indices(["left_hip", "right_hip"])
_FRAGMENTS: tuple[tuple[int, ...], ...] = (
    tuple(joint_indices(["nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder"])),
    tuple(joint_indices(["left_shoulder", "left_elbow", "left_wrist"])),
    tuple(joint_indices(["right_shoulder", "right_elbow", "right_wrist"])),
    tuple(range(JOINT_INDEX["left_hip"], NUM_JOINTS)),
    tuple(range(0, JOINT_INDEX["left_hip"])),
    tuple(joint_indices(["left_hip", "left_knee", "left_ankle", "left_big_toe", "left_small_toe", "left_heel"])),
)
"""Body parts a fragmentary false positive may consist of: head and shoulders, an arm, the legs, the upper
body, one leg."""
_FP_DEPTH_RANGE_M = (2.0, 12.0)


@dataclass(frozen=True)
class DetectorOutput:
    """Simulated detections (one entry per detection, N in all) and the per-view truth behind them.

    Attributes:
        frame: (N,) frame index.
        view: (N,) view index.
        person_id: (N,) ground-truth person id (row of the keypoint array), -1 for false positives.
        keypoints_px: (N, 23, 2) detected image positions, pixels (meaningless where not ``present``).
        scores: (N, 23) confidences in [0, 1] (0 where not ``present``).
        present: (N, 23) whether the detector reports the joint.
        flipped: (N,) whether the left/right labels of the detection are swapped.
        in_image: (V, P, F, 23) whether the true joint projects inside the image, in front of the camera.
        occlusion: (V, P, F, 23) occlusion degree in [0, 1] (float32).
        scale_px: (V, P, F) apparent height of each person, ``fx * height_m / pelvis depth``, pixels.
        eligible: (V, P, F) whether the person is visible enough to be detected at all.
        detected: (V, P, F) whether the person gave a detection.
    """

    frame: np.ndarray
    view: np.ndarray
    person_id: np.ndarray
    keypoints_px: np.ndarray
    scores: np.ndarray
    present: np.ndarray
    flipped: np.ndarray
    in_image: np.ndarray
    occlusion: np.ndarray
    scale_px: np.ndarray
    eligible: np.ndarray
    detected: np.ndarray

    @property
    def num_detections(self) -> int:
        """N."""
        return int(self.frame.shape[0])


def draw_keypoint_bias(std_m: float, rng: np.random.Generator) -> np.ndarray:
    """A detector's systematic keypoint offsets (``DetectorNoise.keypoint_bias_m``): (23, 3) metres, in the axes
    of the reference pose (X to the body's left), mirrored between left and right (a right keypoint's offset is
    its left twin's with X negated; a middle keypoint's X is 0), Gaussian with ``std_m`` per axis."""
    offsets = rng.normal(0.0, std_m, size=(NUM_JOINTS, 3))
    mirrored = offsets[list(FLIP_INDEX)] * np.array([-1.0, 1.0, 1.0])
    middle = np.arange(NUM_JOINTS) == np.asarray(FLIP_INDEX)
    offsets[middle, 0] = 0.0
    right = np.array([name.startswith("right_") for name in JOINT_INDEX])
    offsets[right] = mirrored[right]
    return offsets


def _view_detections(
    keypoints_world_m: np.ndarray,
    height_m: np.ndarray,
    camera: Camera,
    noise: DetectorNoise,
    rng: np.random.Generator,
    hidden: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Detections of the real people in one view (see the module docstring, steps 1-7)."""
    num_people, num_frames = keypoints_world_m.shape[:2]
    pixels, depth = project_points(camera, keypoints_world_m)
    in_front = (np.nan_to_num(depth, nan=-1.0) > 0.05) & within_lens(camera, keypoints_world_m)
    if hidden is not None:
        in_front &= ~hidden[..., None]
    pixels = np.where(in_front[..., None], pixels, np.nan)
    in_image = in_front & inside_image(pixels, camera.width_px, camera.height_px)
    pelvis_depth = np.maximum(depth[..., _HIPS].mean(axis=-1), 0.1)
    scale = camera.K[0, 0] * height_m[:, None] / pelvis_depth
    occ = occlusion_degree(pixels, depth, camera.K[0, 0])
    eligible = (in_image & (occ < 1.0)).sum(axis=-1) >= noise.min_visible_joints

    shape = (num_people, num_frames, NUM_JOINTS)
    jitter_draws = rng.standard_normal(shape + (2,))
    outlier = rng.random(shape) < noise.outlier_rate
    outlier_draws = rng.standard_normal(shape + (2,))
    score_draws = rng.standard_normal(shape)
    miss_draws = rng.random(shape)
    person_miss = rng.random((num_people, num_frames)) < noise.person_miss_rate
    flip = rng.random((num_people, num_frames)) < noise.flip_rate

    detected_px = pixels + jitter_px(noise, jitter_draws, outlier, outlier_draws, occ, scale)
    scores = joint_scores(noise, score_draws, occ, detected_px, scale, camera)
    miss_probability = noise.joint_miss_rate + (noise.occluded_joint_miss_rate - noise.joint_miss_rate) * occ
    present = in_image & inside_image(detected_px, camera.width_px, camera.height_px) & (miss_draws >= miss_probability)
    detected = eligible & ~person_miss & (present.sum(axis=-1) >= noise.min_visible_joints)

    p_idx, f_idx = np.nonzero(detected)
    det_flip = flip[p_idx, f_idx]
    order = np.where(det_flip[:, None], _FLIP[None, :], np.arange(NUM_JOINTS)[None, :])
    rows = np.arange(len(p_idx))[:, None]
    return {
        "frame": f_idx,
        "person_id": p_idx,
        "keypoints_px": detected_px[p_idx, f_idx][rows, order],
        "scores": np.where(present, scores, 0.0)[p_idx, f_idx][rows, order],
        "present": present[p_idx, f_idx][rows, order],
        "flipped": det_flip,
        "in_image": in_image,
        "occlusion": occ.astype(np.float32),
        "scale_px": scale,
        "eligible": eligible,
        "detected": detected,
    }


def _false_positives(
    keypoints_world_m: np.ndarray,
    height_m: np.ndarray,
    cameras: CameraRig,
    noise: DetectorNoise,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """False-positive detections for every view and frame (see the module docstring)."""
    num_people, num_frames = keypoints_world_m.shape[:2]
    num_views = len(cameras)
    counts = rng.poisson(noise.false_positives_per_image, (num_frames, num_views))
    frame, view = np.nonzero(counts)
    frame, view = np.repeat(frame, counts[frame, view]), np.repeat(view, counts[frame, view])
    n = len(frame)
    source_person = rng.integers(num_people, size=n)
    source_frame = rng.integers(num_frames, size=n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    anchor_px = rng.uniform(0.0, 1.0, (n, 2))
    depth = rng.uniform(*_FP_DEPTH_RANGE_M, n)
    fragment = rng.random(n) < noise.false_positive_fragment_prob
    part = rng.integers(len(_FRAGMENTS), size=n)
    jitter_draws = rng.standard_normal((n, NUM_JOINTS, 2))
    score_draws = rng.standard_normal((n, NUM_JOINTS))
    score_offset = rng.normal(0.0, 0.1, n)

    K = np.stack([c.K for c in cameras])[view]
    R = np.stack([c.R_cam_from_world for c in cameras])[view]
    size = np.array([[c.width_px, c.height_px] for c in cameras], dtype=np.float64)[view]
    # The pose, centred on its pelvis and turned about the vertical, stands with its pelvis on the ray
    # through a random pixel at a random depth.
    pose = keypoints_world_m[source_person, source_frame]
    pose = pose - pose[:, _HIPS].mean(axis=1, keepdims=True)
    c, s = np.cos(yaw), np.sin(yaw)
    turn = np.zeros((n, 3, 3))
    turn[:, 0, 0], turn[:, 0, 1], turn[:, 1, 0], turn[:, 1, 1], turn[:, 2, 2] = c, -s, s, c, 1.0
    pose = np.einsum("nij,nkj->nki", turn, pose)
    pixel = anchor_px * size
    ray_x = (pixel[:, 0] - K[:, 0, 2]) / K[:, 0, 0]
    ray_y = (pixel[:, 1] - K[:, 1, 2]) / K[:, 1, 1]
    ray_cam = np.stack([ray_x, ray_y, np.ones(n)], axis=1)
    pelvis_cam = ray_cam * depth[:, None]
    x_cam = np.einsum("nij,nkj->nki", R, pose) + pelvis_cam[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = x_cam[..., :2] / x_cam[..., 2:3]
    in_front = x_cam[..., 2] > 0.05
    distortion = np.stack([c.distortion for c in cameras])[view]
    if np.any(distortion):
        fold = np.array([lens_fold_radius(c.distortion) for c in cameras])[view]
        with np.errstate(invalid="ignore"):
            in_front &= np.nan_to_num(np.hypot(uv[..., 0], uv[..., 1]), nan=np.inf) < fold[:, None]
            uv = distort(uv, distortion)
    focal = np.stack([K[:, 0, 0], K[:, 1, 1]], axis=-1)[:, None, :]
    centre = np.stack([K[:, 0, 2], K[:, 1, 2]], axis=-1)[:, None, :]
    pixels = uv * focal + centre
    scale = K[:, 0, 0] * height_m[source_person] / depth
    detected_px = pixels + jitter_px(noise, jitter_draws, np.zeros((n, NUM_JOINTS), bool), jitter_draws, 0.0, scale)
    inside = in_front & (detected_px[..., 0] >= 0) & (detected_px[..., 0] < size[:, None, 0])
    inside &= (detected_px[..., 1] >= 0) & (detected_px[..., 1] < size[:, None, 1])
    keep_part = np.ones((n, NUM_JOINTS), bool)
    for k, joints in enumerate(_FRAGMENTS):
        mask = np.zeros(NUM_JOINTS, bool)
        mask[list(joints)] = True
        keep_part = np.where((fragment & (part == k))[:, None], mask[None, :], keep_part)
    present = inside & keep_part
    needed = np.minimum(noise.min_visible_joints, keep_part.sum(axis=1))
    keep = present.sum(axis=1) >= np.maximum(needed, 2)
    margin = np.maximum(noise.border_margin_frac * scale, 1e-6)
    border = border_distance_px(detected_px, size[:, None, 0], size[:, None, 1])
    near_border = np.clip(1.0 - border / margin[:, None], 0.0, 1.0)
    score = noise.false_positive_score_mean + score_offset[:, None] + noise.score_std * score_draws
    score = np.clip(score - noise.border_score_drop * np.nan_to_num(near_border, nan=1.0), 0.01, 1.0)
    return {
        "frame": frame[keep],
        "view": view[keep],
        "person_id": np.full(int(keep.sum()), -1),
        "keypoints_px": detected_px[keep],
        "scores": np.where(present, score, 0.0)[keep],
        "present": present[keep],
        "flipped": np.zeros(int(keep.sum()), bool),
    }


def simulate_detections(
    keypoints_world_m: np.ndarray,
    height_m: np.ndarray,
    cameras: CameraRig,
    noise: DetectorNoise,
    rng: np.random.Generator,
    hidden: np.ndarray | None = None,
) -> DetectorOutput:
    """Run the simulated detector over every view and frame.

    Args:
        keypoints_world_m: (P, F, 23, 3) ground-truth canonical keypoints, world metres.
        height_m: (P,) standing heights (set the apparent size), metres.
        cameras: the V cameras.
        noise: the detector model.
        rng: source of randomness.
        hidden: optional (P, F) bool, True where a person is out of every view (seen by no camera, occluding
            nobody); the random draws are the same with or without it.

    Returns:
        The :class:`DetectorOutput`; detections ordered by frame, then view, then person (false positives
        last within a frame and view). Identity-free ids are assigned by the caller.

    Raises:
        ValueError: wrong array shapes.
    """
    keypoints = np.asarray(keypoints_world_m, dtype=np.float64)
    height = np.asarray(height_m, dtype=np.float64)
    if keypoints.ndim != 4 or keypoints.shape[2:] != (NUM_JOINTS, 3) or height.shape != keypoints.shape[:1]:
        raise ValueError(
            f"keypoints_world_m must be (P, F, {NUM_JOINTS}, 3) and height_m (P,), "
            f"got {keypoints.shape} and {height.shape}"
        )
    if hidden is not None:
        hidden = np.asarray(hidden)
        if hidden.dtype != bool or hidden.shape != keypoints.shape[:2]:
            raise ValueError(f"hidden must be a (P, F) = {keypoints.shape[:2]} bool array, "
                             f"got {hidden.dtype} {hidden.shape}")
    per_view = []
    for v, camera in enumerate(cameras):
        out = _view_detections(keypoints, height, camera, noise, rng, hidden)
        out["view"] = np.full(len(out["frame"]), v)
        per_view.append(out)
    fp = _false_positives(keypoints, height, cameras, noise, rng)
    return _assemble(per_view, [fp])


def simulate_view_detections(
    view_keypoints_world_m: list[np.ndarray],
    view_frames: list[np.ndarray],
    height_m: np.ndarray,
    cameras: CameraRig,
    noise: DetectorNoise,
    rng: np.random.Generator,
    view_hidden: list[np.ndarray | None] | None = None,
) -> DetectorOutput:
    """Run the simulated detector over views that film on their own clocks (unsynchronised videos): each view sees
    the people at its own frames' times, numbered by its own frame numbers.

    Per view, the real people's detections and then the view's false positives (whose poses are drawn from the
    view's own frames); the random draws differ from :func:`simulate_detections` (a synchronised scene keeps that).

    Args:
        view_keypoints_world_m: per view, (P, N_v, 23, 3) keypoints at the view's frame times, world metres.
        view_frames: per view, (N_v,) the view's own frame numbers of those frames (ascending, >= 0).
        height_m: (P,) standing heights, metres.
        cameras: the V cameras.
        noise: the detector model.
        rng: source of randomness.
        view_hidden: optional per view (P, N_v) bool (or None), True where a person is out of every view.

    Returns:
        The :class:`DetectorOutput` with ``frame`` the view's own frame numbers; its per-view arrays
        (``in_image`` ...) span frames ``0..max_v(last frame)`` of every view's own numbering, False (``scale_px``:
        NaN) at frames a view does not film.

    Raises:
        ValueError: inconsistent numbers of views, frames or people.
    """
    height = np.asarray(height_m, dtype=np.float64)
    if not (len(view_keypoints_world_m) == len(view_frames) == len(cameras)):
        raise ValueError(f"view_keypoints_world_m, view_frames and cameras must have one entry per view, got "
                         f"{len(view_keypoints_world_m)}, {len(view_frames)}, {len(cameras)}")
    hidden = view_hidden if view_hidden is not None else [None] * len(cameras)
    num_frames = max(int(np.max(f)) + 1 if len(f) else 0 for f in view_frames)
    per_view, false_positives = [], []
    for v, camera in enumerate(cameras):
        keypoints = np.asarray(view_keypoints_world_m[v], dtype=np.float64)
        frames = np.asarray(view_frames[v], dtype=np.int64)
        if keypoints.ndim != 4 or keypoints.shape[1:] != (len(frames), NUM_JOINTS, 3) or len(keypoints) != len(height):
            raise ValueError(f"view {v}: keypoints must be (P, N_v, {NUM_JOINTS}, 3) with P = {len(height)} and "
                             f"N_v = {len(frames)} frames, got {keypoints.shape}")
        out = _view_detections(keypoints, height, camera, noise, rng, hidden[v])
        out["frame"] = frames[out["frame"]]
        out["view"] = np.full(len(out["frame"]), v)
        for key, fill in (("in_image", False), ("occlusion", 0.0), ("scale_px", np.nan), ("eligible", False),
                          ("detected", False)):
            padded = np.full(out[key].shape[:1] + (num_frames,) + out[key].shape[2:], fill, dtype=out[key].dtype)
            padded[:, frames] = out[key]
            out[key] = padded
        per_view.append(out)
        fp = _false_positives(keypoints, height, [camera], noise, rng)
        fp["frame"], fp["view"] = frames[fp["frame"]], np.full(len(fp["frame"]), v)
        false_positives.append(fp)
    return _assemble(per_view, false_positives)


def _assemble(per_view: list[dict[str, np.ndarray]], false_positives: list[dict[str, np.ndarray]]) -> DetectorOutput:
    """One :class:`DetectorOutput` from the views' detections and the false positives, ordered by frame, then view,
    then person (false positives last within a frame and view)."""
    parts = per_view + false_positives
    frame = np.concatenate([p["frame"] for p in parts])
    view = np.concatenate([p["view"] for p in parts])
    person = np.concatenate([p["person_id"] for p in parts])
    is_fp = person < 0
    order = np.lexsort((person, is_fp, view, frame))
    return DetectorOutput(
        frame=frame[order].astype(np.int64),
        view=view[order].astype(np.int64),
        person_id=person[order].astype(np.int64),
        keypoints_px=np.concatenate([p["keypoints_px"] for p in parts])[order],
        scores=np.concatenate([p["scores"] for p in parts])[order],
        present=np.concatenate([p["present"] for p in parts])[order],
        flipped=np.concatenate([p["flipped"] for p in parts])[order],
        in_image=np.stack([p["in_image"] for p in per_view]),
        occlusion=np.stack([p["occlusion"] for p in per_view]),
        scale_px=np.stack([p["scale_px"] for p in per_view]),
        eligible=np.stack([p["eligible"] for p in per_view]),
        detected=np.stack([p["detected"] for p in per_view]),
    )
