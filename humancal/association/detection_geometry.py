"""What the affinity needs of each detection, in the world frame: the back-projected rays of its joints (as
Plücker lines: unit direction and moment about the origin), and its lifted 3D pose turned into the world by its
camera's rotation and placed by the translation that best fits the pose to its 2D keypoints
(``docs/association.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from humancal.camera import CameraRig
from humancal.keypoints import NUM_JOINTS
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["DetectionGeometry", "detection_geometry", "ray_distances_m"]

_MIN_SINE = 1e-2
"""Rays closer than ~0.6 degrees to parallel: their line distance is ``|reciprocal| / 0.01`` (the reciprocal
product itself is small there when the rays come from cameras in line with the point)."""


@dataclass(frozen=True)
class DetectionGeometry:
    """What the affinity needs of each detection, in the world frame (row ``d`` = detection row ``d``).

    Attributes:
        frame, view: (D,) int.
        scores: (D, 23) joint confidences, 0 where absent.
        centres_world_m: (D, 3) centre of the camera of each detection's view, metres.
        rays_world: (D, 23, 3) unit directions of the joints' back-projected rays (float32; NaN where absent).
        moments_world_m: (D, 23, 3) Plücker moments ``centre x direction`` of those rays (float32), metres.
        pose_world_m: (D, 23, 3) lifted pose, root-relative, turned into the world (NaN where not lifted).
        root_world_m: (D, 3) the lifted pose's hip midpoint placed by fitting it to the 2D keypoints (NaN where
            not lifted or not placeable), metres.
    """

    frame: np.ndarray
    view: np.ndarray
    scores: np.ndarray
    centres_world_m: np.ndarray
    rays_world: np.ndarray
    moments_world_m: np.ndarray
    pose_world_m: np.ndarray
    root_world_m: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    @property
    def pose_valid(self) -> np.ndarray:
        """(D,) whether the detection has a lifted pose and a placed root."""
        return np.isfinite(self.pose_world_m).all((1, 2)) & np.isfinite(self.root_world_m).all(1)


def _normalized_image_points(keypoints_px: np.ndarray, view: np.ndarray, rig: CameraRig) -> np.ndarray:
    """(D, 23, 2) ``K^-1`` image coordinates, lens distortion undone with OpenCV where the camera has one."""
    K = rig.K[view]
    xy = np.empty_like(keypoints_px)
    xy[..., 0] = (keypoints_px[..., 0] - K[:, None, 0, 2]) / K[:, None, 0, 0]
    xy[..., 1] = (keypoints_px[..., 1] - K[:, None, 1, 2]) / K[:, None, 1, 1]
    for v in np.flatnonzero(np.abs(rig.distortion).sum(1) > 0):
        rows = np.flatnonzero(view == v)
        pts = keypoints_px[rows].reshape(-1, 1, 2)
        finite = np.isfinite(pts).all(-1)[:, 0]
        out = np.full(pts.shape, np.nan)
        if finite.any():
            out[finite] = cv2.undistortPoints(pts[finite], rig.K[v], rig.distortion[v])
        xy[rows] = out.reshape(len(rows), NUM_JOINTS, 2)
    return xy


def _place_roots(joints_cam_m: np.ndarray, xy: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(D, 3) translation ``t`` (camera frame, metres) with ``joints + t`` projecting onto ``xy`` (weighted linear
    least squares of ``(X + t)_x - x (X + t)_z = 0`` and the same in y); NaN where it is not determined or lies
    behind the camera."""
    x, y = xy[..., 0], xy[..., 1]
    w = np.where(np.isfinite(x) & np.isfinite(y) & np.isfinite(joints_cam_m).all(-1), weights, 0.0)
    x, y = np.where(w > 0, x, 0.0), np.where(w > 0, y, 0.0)
    X = np.where(w[..., None] > 0, joints_cam_m, 0.0)
    # rows of the system per joint: [1, 0, -x] t = x Z - X and [0, 1, -y] t = y Z - Y; normal equations summed
    bx, by = x * X[..., 2] - X[..., 0], y * X[..., 2] - X[..., 1]
    sw, swx, swy = w.sum(1), (w * x).sum(1), (w * y).sum(1)
    AtA = np.zeros((len(w), 3, 3))
    AtA[:, 0, 0] = AtA[:, 1, 1] = sw
    AtA[:, 0, 2] = AtA[:, 2, 0] = -swx
    AtA[:, 1, 2] = AtA[:, 2, 1] = -swy
    AtA[:, 2, 2] = (w * (x * x + y * y)).sum(1)
    Atb = np.stack([(w * bx).sum(1), (w * by).sum(1), -(w * (x * bx + y * by)).sum(1)], -1)
    ok = (w > 0).sum(1) >= 2
    t = np.full(Atb.shape, np.nan)
    if ok.any():
        t[ok] = np.linalg.solve(AtA[ok] + 1e-12 * np.eye(3), Atb[ok][..., None])[..., 0]
    t[~(t[:, 2] > 0)] = np.nan
    return t


def detection_geometry(detections: DenseDetections, lifted: LiftedPoses | None, rig: CameraRig) -> DetectionGeometry:
    """Rays, world poses and placed roots of every detection.

    Args:
        detections: D detections (any order; rows are kept).
        lifted: their lifted poses (row-aligned; crop-frame poses are turned into camera frames with the rig's
            intrinsics), or None for the geometric term only.
        rig: the current cameras (view index = row of the rig).

    Returns:
        The :class:`DetectionGeometry`.

    Raises:
        ValueError: lifted poses not row-aligned, or a detection of a view the rig does not have.
    """
    D = len(detections)
    view = np.asarray(detections.view, dtype=np.int64)
    if D and (view.min() < 0 or view.max() >= len(rig)):
        raise ValueError(f"detections use views {int(view.min())}..{int(view.max())} but the rig has "
                         f"{len(rig)} cameras")
    if lifted is not None and len(lifted) != D:
        raise ValueError(f"lifted poses must be row-aligned with the detections: {len(lifted)} vs {D} rows")
    scores = np.where(np.isfinite(detections.keypoints_px).all(-1), np.asarray(detections.scores, float), 0.0)
    xy = _normalized_image_points(np.asarray(detections.keypoints_px, dtype=np.float64), view, rig)
    R = rig.R_cam_from_world[view]
    centres = rig.centers_world_m[view]
    ray_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    rays = np.einsum("dji,dkj->dki", R, ray_cam)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rays[scores <= 0] = np.nan
    moments = np.cross(centres[:, None, :], rays)
    pose = np.full((D, NUM_JOINTS, 3), np.nan)
    root = np.full((D, 3), np.nan)
    if lifted is not None and D:
        cam = lifted.in_camera_frame(rig.K[view])
        t_cam = _place_roots(cam.joints_cam_m, xy, scores)
        pose = np.einsum("dji,dkj->dki", R, cam.joints_cam_m)
        root = np.einsum("dji,dj->di", R, t_cam - rig.t_cam_from_world_m[view])
    return DetectionGeometry(np.asarray(detections.frame, dtype=np.int64), view, scores, centres,
                             rays.astype(np.float32), moments.astype(np.float32), pose, root)


def ray_distances_m(geo: DetectionGeometry, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P, 23) distance between the rays of each joint of detections ``a`` and ``b`` (pairs of rows), metres.

    In Plücker coordinates (unit direction ``d``, moment ``m = c x d``) two lines meet iff their reciprocal product
    ``d_a . m_b + d_b . m_a`` is 0; divided by ``|d_a x d_b|`` (at least ``_MIN_SINE``) it is the distance between
    the lines. NaN where either joint is absent.
    """
    da, db = geo.rays_world[a], geo.rays_world[b]
    reciprocal = np.abs(np.einsum("pjk,pjk->pj", da, geo.moments_world_m[b])
                        + np.einsum("pjk,pjk->pj", db, geo.moments_world_m[a]))
    cos = np.einsum("pjk,pjk->pj", da, db)
    sine = np.sqrt(np.maximum(1.0 - cos * cos, _MIN_SINE**2))
    return reciprocal / sine
