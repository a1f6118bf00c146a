"""An oracle in place of the 2D-to-3D lifter: lifted poses made from the ground truth (evaluation only).

The calibration stage needs one lifted 3D pose per detection (:class:`~humancal.lifter.LiftedPoses`). To
develop, test and bound it without the learned lifter, :func:`stand_in_lifted_poses` makes them from the ground
truth of a synthetic scene, with lifter-like errors:

* the person's true keypoints are moved into the detection's camera frame and made relative to the hip midpoint;
* the whole pose is scaled by the error of the height estimate (``height_noise_m``, std) and turned by a small
  random rotation (``rotation_noise_deg``, std of the angle), then every joint gets independent Gaussian noise
  with an RMS 3D error of ``joint_noise_m``;
* a detection whose 2D labels are left-right flipped gets a lifted pose with the same flip (the lifter sees the
  flipped 2D), and with probability ``depth_flip_rate`` the pose is mirrored in depth (the monocular ambiguity);
* false positives get the pose of a random other person-frame, turned about the camera's vertical axis;
* the upright score (:func:`upright_scores`) comes from the true pose's internal angles only (knees, hips,
  ankle heights along the body axis), like a lifter that does not know the vertical. It is deliberately more
  permissive than the library's :func:`humancal.lifter.standing_score` (Gaussian factors instead of
  smoothstep ramps); the calibration tests' figures were set with it.

Never use it for reporting the method's accuracy on real data: it knows the true identities and poses. The
library never imports it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.calibration.types import ankle_midpoints, hip_midpoints
from humancal.camera import CameraRig
from humancal.geometry.rotations import angle_between_deg, axis_angle_to_rotmat
from humancal.keypoints import FLIP_INDEX, JOINT_INDEX
from humancal.lifter import LiftedPoses
from humancal.tables.associations import Associations
from humancal.tables.detections import DenseDetections, detections_to_dense

__all__ = [
    "StandIn",
    "stand_in_lifted_poses",
    "stand_in_from_matches",
    "lift_ground_truth",
    "upright_scores",
    "canonical_from_shelf15",
]

_J = JOINT_INDEX


@dataclass(frozen=True)
class StandIn:
    """Detections with their stand-in lifted poses.

    Attributes:
        detections: the dense detections (rows sorted by frame, view, det_id).
        lifted: one lifted pose per detection.
        person_id: (D,) ground-truth identity of each detection, -1 for false positives (evaluation only).
    """

    detections: DenseDetections
    lifted: LiftedPoses
    person_id: np.ndarray


def upright_scores(keypoints: np.ndarray) -> np.ndarray:
    """Upright-standing score of poses from body-internal angles only (no knowledge of the true vertical).

    A lifter knows the body's joint angles, not the world's vertical, so the score uses only: the larger knee
    flexion beyond 5 degrees (scale 15 degrees), the larger hip flexion (angle between the thigh and the trunk,
    beyond 10 degrees; scale 15 degrees), and the ankles' height difference along the body axis (ankle midpoint
    to shoulder midpoint; scale 5 cm). The product of the three Gaussian factors is the score.

    Args:
        keypoints: (N, 23, 3) canonical keypoints, metres, any frame.

    Returns:
        (N,) scores in [0, 1].
    """
    X = np.asarray(keypoints, dtype=np.float64)

    shoulders = 0.5 * (X[:, _J["left_shoulder"]] + X[:, _J["right_shoulder"]])
    hips = hip_midpoints(X)
    axis = shoulders - ankle_midpoints(X)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    knee, hip = [], []
    for side in ("left", "right"):
        thigh = X[:, _J[f"{side}_knee"]] - X[:, _J[f"{side}_hip"]]
        shank = X[:, _J[f"{side}_ankle"]] - X[:, _J[f"{side}_knee"]]
        knee.append(angle_between_deg(thigh, shank))
        hip.append(angle_between_deg(thigh, hips - shoulders))
    knee_deg = np.maximum(np.maximum(knee[0], knee[1]) - 5.0, 0.0)
    hip_deg = np.maximum(np.maximum(hip[0], hip[1]) - 10.0, 0.0)
    ankle_dz_m = np.abs(((X[:, _J["left_ankle"]] - X[:, _J["right_ankle"]]) * axis).sum(1))
    return np.exp(-0.5 * ((knee_deg / 15.0) ** 2 + (hip_deg / 15.0) ** 2 + (ankle_dz_m / 0.05) ** 2))


def _random_rotations(n: int, std_deg: float, rng: np.random.Generator) -> np.ndarray:
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis_angle_to_rotmat(axis, np.radians(std_deg) * rng.normal(size=n))


def lift_ground_truth(
    keypoints_world_m: np.ndarray,
    height_m: np.ndarray,
    cameras: CameraRig,
    frame: np.ndarray,
    view: np.ndarray,
    person_id: np.ndarray,
    flipped: np.ndarray,
    rng: np.random.Generator,
    *,
    joint_noise_m: float = 0.05,
    height_noise_m: float = 0.04,
    rotation_noise_deg: float = 3.0,
    depth_flip_rate: float = 0.01,
) -> LiftedPoses:
    """Stand-in lifted poses for arbitrary detections of known people (the array-level form).

    Args:
        keypoints_world_m: (P, F, 23, 3) ground-truth keypoints, world metres, Z up.
        height_m: (P,) true standing heights, metres.
        cameras: the V cameras.
        frame, view, person_id: (D,) of each detection; ``person_id`` -1 marks a false positive.
        flipped: (D,) whether the detection's left/right labels are swapped.
        rng: source of randomness.
        joint_noise_m: RMS 3D error added independently to every joint, metres.
        height_noise_m: std of the height estimate; the pose is scaled by the same relative error, metres.
        rotation_noise_deg: std of a random rotation of the whole pose, degrees.
        depth_flip_rate: probability of mirroring the pose in depth (camera z), the monocular ambiguity.

    Returns:
        The :class:`LiftedPoses` of the D detections.
    """
    X = np.asarray(keypoints_world_m, dtype=np.float64)
    P, F = X.shape[:2]
    frame, view, person_id = (np.asarray(a, dtype=np.int64) for a in (frame, view, person_id))
    D = len(frame)
    source_person = person_id.copy()
    source_frame = frame.copy()
    fp = person_id < 0
    source_person[fp] = rng.integers(0, P, int(fp.sum()))
    source_frame[fp] = rng.integers(0, F, int(fp.sum()))
    world = X[source_person, source_frame]  # (D, 23, 3)
    R = np.stack([c.R_cam_from_world for c in cameras])[view]
    joints = np.einsum("dij,dkj->dki", R, world - hip_midpoints(world)[:, None])
    if fp.any():  # a pose from elsewhere, turned about the camera's vertical (image y) axis
        yaw = rng.uniform(0, 2 * np.pi, int(fp.sum()))
        c, s = np.cos(yaw), np.sin(yaw)
        Ry = np.zeros((len(yaw), 3, 3))
        Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 1, 1], Ry[:, 2, 0], Ry[:, 2, 2] = c, s, 1.0, -s, c
        joints[fp] = np.einsum("dij,dkj->dki", Ry, joints[fp])
    flipped = np.asarray(flipped, dtype=bool)
    joints[flipped] = joints[flipped][:, list(FLIP_INDEX)]
    depth_flip = rng.random(D) < depth_flip_rate
    joints[depth_flip, :, 2] *= -1.0
    true_height = np.asarray(height_m, dtype=np.float64)[source_person]
    height = true_height + height_noise_m * rng.normal(size=D)
    joints *= (height / true_height)[:, None, None]
    if rotation_noise_deg > 0:
        joints = np.einsum("dij,dkj->dki", _random_rotations(D, rotation_noise_deg, rng), joints)
    joints += (joint_noise_m / np.sqrt(3.0)) * rng.normal(size=joints.shape)
    joints -= hip_midpoints(joints)[:, None]
    return LiftedPoses(joints, np.maximum(height, 0.5), upright_scores(world))


def stand_in_lifted_poses(
    scene,
    rng: np.random.Generator,
    joint_noise_m: float = 0.05,
    height_noise_m: float = 0.04,
    *,
    rotation_noise_deg: float = 3.0,
    depth_flip_rate: float = 0.01,
) -> StandIn:
    """Stand-in lifted poses for every detection of a synthetic scene (see the module docstring).

    Args:
        scene: a :class:`humancal.synthetic.SyntheticScene`.
        rng: source of randomness.
        joint_noise_m: RMS 3D error per joint, metres.
        height_noise_m: std of the height estimate, metres.
        rotation_noise_deg: std of a random rotation of each whole pose, degrees.
        depth_flip_rate: probability of a pose mirrored in depth.

    Returns:
        :class:`StandIn` with the dense detections of ``scene.detections``, their lifted poses and true ids.
    """
    dense = detections_to_dense(scene.detections)
    d = scene.detector
    row = Associations(d.frame, d.view, scene.det_id, d.person_id).row_of_detections(dense)
    if (row < 0).any():
        raise ValueError("stand_in_lifted_poses: scene.detections and scene.detector disagree on detection keys")
    person_id = np.asarray(d.person_id, dtype=np.int64)[row]
    lifted = lift_ground_truth(
        scene.keypoints_world_m,
        scene.height_m,
        scene.rig,
        dense.frame,
        dense.view,
        person_id,
        np.asarray(d.flipped, dtype=bool)[row],
        rng,
        joint_noise_m=joint_noise_m,
        height_noise_m=height_noise_m,
        rotation_noise_deg=rotation_noise_deg,
        depth_flip_rate=depth_flip_rate,
    )
    return StandIn(dense, lifted, person_id)


def stand_in_from_matches(
    detections: pd.DataFrame,
    cameras: CameraRig,
    keypoints_world_m: np.ndarray,
    height_m: np.ndarray,
    matches: pd.DataFrame,
    rng: np.random.Generator,
    **noise,
) -> StandIn:
    """Stand-in lifted poses for any dataset with 3D ground truth, given which detection shows which person.

    Detections without a match get the pose of a random person-frame (like false positives), never flipped.

    Args:
        detections: canonical ``detections`` table.
        cameras: the ground-truth cameras (views in order).
        keypoints_world_m: (P, F, 23, 3) canonical ground-truth keypoints, world metres, Z up (finite where used).
        height_m: (P,) standing heights, metres.
        matches: rows ``frame, view, det_id, person_id`` (e.g. ``evaluate_grouping(...).person_views`` with
            ``det_id >= 0``).
        rng: source of randomness.
        **noise: keyword arguments of :func:`lift_ground_truth` (``joint_noise_m``, ...).

    Returns:
        :class:`StandIn` (``person_id`` -1 for unmatched detections).
    """
    dense = detections_to_dense(detections)
    m = matches[matches["det_id"] >= 0].drop_duplicates(["frame", "view", "det_id"])
    person_id = Associations.from_table(m).person_of_detections(dense)
    usable = np.isfinite(keypoints_world_m).all((-1, -2))  # (P, F)
    ok = person_id >= 0
    ok[ok] = usable[person_id[ok], dense.frame[ok]]
    person_id = np.where(ok, person_id, -1)
    # random sources for unmatched detections must be usable person-frames
    X = np.asarray(keypoints_world_m, dtype=np.float64)
    P, F = X.shape[:2]
    pool = np.argwhere(usable)
    fill = pool[rng.integers(0, len(pool), P * F)].T
    X_filled = X.copy()
    bad = ~usable
    X_filled[bad] = X[fill[0][: bad.sum()], fill[1][: bad.sum()]]
    lifted = lift_ground_truth(X_filled, height_m, cameras, dense.frame, dense.view, person_id,
                               np.zeros(len(dense), bool), rng, **noise)
    return StandIn(dense, lifted, person_id)


def canonical_from_shelf15(joints_world_m: np.ndarray) -> np.ndarray:
    """Approximate canonical-23 keypoints from SHELF15 joints (an evaluation aid for a stand-in lifter).

    The 12 limb joints are copied; the face points are placed on the head between ``bottom_head`` (neck) and
    ``top_head`` (ears at 55 % of the way up, 7.5 cm to the sides; eyes 8 cm forward; nose 10 cm forward, a
    little lower) and the foot points around each ankle (soles 6.5 cm lower, heel 6 cm back, toes 14-17 cm
    forward), with "forward" from the shoulder line and the head axis. Errors of a few centimetres, below a
    lifter's.

    Args:
        joints_world_m: (..., 15, 3) in ``humancal.datasets.shelf.SHELF15_JOINTS`` order, world Z up, metres.

    Returns:
        (..., 23, 3) canonical keypoints.
    """
    from humancal.datasets.shelf import SHELF15_JOINTS

    S = {n: i for i, n in enumerate(SHELF15_JOINTS)}
    X = np.asarray(joints_world_m, dtype=np.float64)
    out = np.zeros(X.shape[:-2] + (len(JOINT_INDEX), 3))
    for name in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
        for side in ("left", "right"):
            out[..., _J[f"{side}_{name}"], :] = X[..., S[f"{side}_{name}"], :]
    neck, top = X[..., S["bottom_head"], :], X[..., S["top_head"], :]
    up = top - neck
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    left = X[..., S["left_shoulder"], :] - X[..., S["right_shoulder"], :]
    fwd = np.cross(left, up)
    fwd = fwd / np.linalg.norm(fwd, axis=-1, keepdims=True)
    lat = np.cross(up, fwd)  # unit, to the person's left
    centre = neck + 0.55 * (top - neck)
    out[..., _J["left_ear"], :] = centre + 0.075 * lat
    out[..., _J["right_ear"], :] = centre - 0.075 * lat
    out[..., _J["left_eye"], :] = centre + 0.08 * fwd + 0.032 * lat + 0.01 * up
    out[..., _J["right_eye"], :] = centre + 0.08 * fwd - 0.032 * lat + 0.01 * up
    out[..., _J["nose"], :] = centre + 0.10 * fwd - 0.02 * up
    z = np.array([0.0, 0.0, 1.0])
    fwd_h = fwd - (fwd @ z)[..., None] * z
    fwd_h = fwd_h / np.linalg.norm(fwd_h, axis=-1, keepdims=True)
    lat_h = np.cross(z, fwd_h)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        ankle = out[..., _J[f"{side}_ankle"], :]
        sole = ankle - 0.065 * z
        out[..., _J[f"{side}_heel"], :] = sole - 0.06 * fwd_h
        out[..., _J[f"{side}_big_toe"], :] = sole + 0.17 * fwd_h - sign * 0.02 * lat_h
        out[..., _J[f"{side}_small_toe"], :] = sole + 0.14 * fwd_h + sign * 0.035 * lat_h
    return out
