"""Static camera rigs around the capture area: random rings and arcs, and the Human3.6M cameras.

Every camera is an ideal pinhole (no distortion) with square pixels and the principal point at the image
centre, placed so that the capture area fills about ``area_fill`` of its horizontal field of view, aimed at a
point near the area centre at mid-body height with a little random error in aim and roll.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from humancal.camera import Camera
from humancal.settings import dataset_dir
from humancal.synthetic.config import SceneConfig

__all__ = ["look_at", "intrinsics", "make_rig", "ring_rig", "h36m_rig", "load_h36m_cameras"]

logger = logging.getLogger(__name__)

_AIM_HEIGHT_M = 1.0
"""Height of the aim point above the floor (mid-body), metres."""
_AIM_JITTER_M = 0.25
_ROLL_JITTER_DEG = 2.0
_BODY_RADIUS_M = 0.5
"""Added to the area's half-diagonal when fitting it into a field of view (arms and bodies at the edge)."""


def look_at(center_world_m: np.ndarray, target_world_m: np.ndarray, roll_deg: float = 0.0) -> np.ndarray:
    """World-to-camera rotation of an OpenCV camera at ``center_world_m`` looking at ``target_world_m``.

    The image x axis stays horizontal (up to ``roll_deg``, a rotation about the optical axis) and image y
    points down (world -z) in the image.

    Args:
        center_world_m: (3,) camera centre, metres.
        target_world_m: (3,) point on the optical axis, metres.
        roll_deg: rotation of the image about the optical axis, degrees (clockwise in the image).

    Returns:
        (3, 3) ``R_cam_from_world`` (rows: camera x, y, z axes in world coordinates), det = +1.

    Raises:
        ValueError: the camera looks straight up or down (the horizon is undefined).
    """
    forward = np.asarray(target_world_m, dtype=np.float64) - np.asarray(center_world_m, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:
        raise ValueError("look_at: the optical axis is vertical; the image x axis is undefined")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    roll = np.radians(roll_deg)
    c, s = np.cos(roll), np.sin(roll)
    roll_about_z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return roll_about_z @ R


def intrinsics(focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """(3, 3) pinhole K with square pixels and the principal point at the image centre, pixels."""
    return np.array([[focal_px, 0.0, width_px / 2.0], [0.0, focal_px, height_px / 2.0], [0.0, 0.0, 1.0]])


def ring_rig(config: SceneConfig, rng: np.random.Generator) -> list[Camera]:
    """Cameras on a full circle (``"ring"``) or on an arc of ``arc_span_deg`` (``"arc"``) around the area.

    Azimuths are evenly spaced with a random jitter of a quarter spacing; each camera draws its focal length
    from ``focal_range_px`` and its height from ``camera_height_range_m``, then stands at the distance where
    the area (plus a body radius) spans ``area_fill`` of its horizontal field of view.

    Args:
        config: the scene config (``rig`` must be ``"ring"`` or ``"arc"``).
        rng: source of randomness.

    Returns:
        ``config.num_views`` cameras.
    """
    num = config.num_views
    width, height = config.image_size_px
    if config.rig == "ring":
        spacing = 2 * np.pi / num
        azimuth = rng.uniform(0, 2 * np.pi) + spacing * np.arange(num)
    elif config.rig == "arc":
        span = np.radians(config.arc_span_deg)
        spacing = span / (num - 1)
        azimuth = rng.uniform(0, 2 * np.pi) - span / 2 + spacing * np.arange(num)
    else:
        raise ValueError(f"ring_rig: config.rig={config.rig!r} is not 'ring' or 'arc'")
    azimuth = azimuth + rng.uniform(-0.25, 0.25, num) * spacing
    focal = rng.uniform(*config.focal_range_px, num)
    cam_height = rng.uniform(*config.camera_height_range_m, num)
    radius = 0.5 * float(np.hypot(*config.area_size_m)) + _BODY_RADIUS_M
    half_fov = np.arctan(width / (2.0 * focal))
    distance = radius / np.sin(config.area_fill * half_fov)
    cameras = []
    for v in range(num):
        center = np.array([distance[v] * np.cos(azimuth[v]), distance[v] * np.sin(azimuth[v]), cam_height[v]])
        target = np.array([*rng.normal(0.0, _AIM_JITTER_M, 2), _AIM_HEIGHT_M + rng.normal(0.0, 0.1)])
        R = look_at(center, target, roll_deg=float(rng.normal(0.0, _ROLL_JITTER_DEG)))
        cameras.append(Camera.from_center(intrinsics(focal[v], width, height), R, center, width, height))
    return cameras


def load_h36m_cameras(path: Path, subject: str) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Read the Human3.6M calibration of one subject.

    Args:
        path: ``camera-parameters.json`` (format in the dataset's ``SOURCE.md``: world in millimetres,
            ``P = K [R | t]``).
        subject: ``"S1"`` .. ``"S11"``.

    Returns:
        Per camera, in file order: (camera id, K (3, 3) pixels, R_cam_from_world (3, 3),
        t_cam_from_world_m (3,) metres).

    Raises:
        ValueError: the file does not have the documented structure (naming the missing part).
    """
    try:
        data = json.loads(path.read_text())
        intrinsics_by_id = data["intrinsics"]
        extrinsics = data["extrinsics"][subject]
    except (KeyError, json.JSONDecodeError) as err:
        raise ValueError(
            f"{path}: expected {{'intrinsics': {{id: ...}}, 'extrinsics': {{'{subject}': {{id: {{R, t}}}}}}}}; "
            f"missing or invalid: {err}"
        ) from None
    out = []
    for camera_id, K_list in ((cid, intrinsics_by_id[cid]["calibration_matrix"]) for cid in intrinsics_by_id):
        if camera_id not in extrinsics:
            raise ValueError(f"{path}: camera {camera_id} has no extrinsics for subject {subject}")
        K = np.asarray(K_list, dtype=np.float64)
        R = np.asarray(extrinsics[camera_id]["R"], dtype=np.float64)
        t_mm = np.asarray(extrinsics[camera_id]["t"], dtype=np.float64).reshape(-1)
        if K.shape != (3, 3) or R.shape != (3, 3) or t_mm.shape != (3,):
            raise ValueError(
                f"{path}: camera {camera_id} of {subject}: expected K 3x3, R 3x3, t 3x1; got {K.shape}, {R.shape}, "
                f"{t_mm.shape}"
            )
        out.append((camera_id, K, R, t_mm / 1000.0))
    return out


def _axes_meeting_point(centers: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Least-squares point closest to all lines ``center + s * direction`` (unit directions)."""
    projector = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]
    return np.linalg.solve(projector.sum(axis=0), (projector @ centers[:, :, None]).sum(axis=0)[:, 0])


def h36m_rig(config: SceneConfig) -> list[Camera]:
    """The Human3.6M cameras of ``config.h36m_subject`` (the first ``num_views`` in file order).

    Human3.6M's world is already Z up with the floor at z = 0; it is converted from millimetres to metres
    and shifted horizontally so that the point the cameras look at lies above the origin (the centre of
    our capture area). The measured focal lengths are kept (about 1145 px), the principal point is put at
    the centre of ``config.image_size_px`` and the lens distortion is dropped (the generator projects with
    an ideal pinhole).

    Raises:
        humancal.settings.DataRootError: the data root or its ``h36m_cameras`` folder is missing.
        ValueError: the calibration file is malformed.
    """
    folder = dataset_dir("h36m_cameras", required_for="the synthetic rig 'h36m'")
    cameras_raw = load_h36m_cameras(folder / "camera-parameters.json", config.h36m_subject)
    R = np.stack([c[2] for c in cameras_raw])
    t = np.stack([c[3] for c in cameras_raw])
    centers = -np.einsum("vji,vj->vi", R, t)
    shift = _axes_meeting_point(centers, R[:, 2, :])
    shift[2] = 0.0
    width, height = config.image_size_px
    cameras = []
    for (camera_id, K_raw, R_v, _), center in zip(cameras_raw[: config.num_views], centers):
        focal = 0.5 * (K_raw[0, 0] + K_raw[1, 1])
        cameras.append(Camera.from_center(intrinsics(focal, width, height), R_v, center - shift, width, height))
        logger.debug("h36m camera %s: focal %.1f px, centre %s m", camera_id, focal, np.round(center - shift, 3))
    return cameras


def make_rig(config: SceneConfig, rng: np.random.Generator) -> list[Camera]:
    """The cameras of ``config.rig`` (see :func:`ring_rig`, :func:`h36m_rig`).

    Raises:
        ValueError: unknown rig kind.
        humancal.settings.DataRootError: rig ``"h36m"`` without the data root.
    """
    if config.rig in ("ring", "arc"):
        return ring_rig(config, rng)
    if config.rig == "h36m":
        return h36m_rig(config)
    raise ValueError(f"SceneConfig.rig={config.rig!r} is unknown; allowed: 'ring', 'arc', 'h36m'")
