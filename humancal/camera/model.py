"""One pinhole camera in the house convention: the :class:`Camera`, projection through it, and the matrices that
place it (:func:`intrinsic_matrix`, :func:`look_at`).

Convention (``docs/conventions.md``): OpenCV pinhole, x right, y down, z forward;
``x_cam = R_cam_from_world @ x_world + t_cam_from_world_m``; ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``
in pixels; distortion as OpenCV's (k1, k2, p1, p2, k3). World: metres, right-handed, Z up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from humancal.camera.projection import project_points_np

__all__ = ["Camera", "intrinsic_matrices", "intrinsic_matrix", "look_at", "pinhole", "project_points"]


@dataclass(frozen=True)
class Camera:
    """One static camera.

    Attributes:
        K: (3, 3) intrinsic matrix, pixels.
        R_cam_from_world: (3, 3) rotation, world to camera.
        t_cam_from_world_m: (3,) translation, metres.
        width_px, height_px: image size in pixels.
        distortion: (5,) OpenCV coefficients (k1, k2, p1, p2, k3); zeros for an ideal pinhole.
    """

    K: np.ndarray
    R_cam_from_world: np.ndarray
    t_cam_from_world_m: np.ndarray
    width_px: int
    height_px: int
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64)
        R = np.asarray(self.R_cam_from_world, dtype=np.float64)
        t = np.asarray(self.t_cam_from_world_m, dtype=np.float64).reshape(-1)
        d = np.asarray(self.distortion, dtype=np.float64).reshape(-1)
        if K.shape != (3, 3) or R.shape != (3, 3) or t.shape != (3,) or d.shape != (5,):
            raise ValueError(
                f"Camera expects K (3,3), R_cam_from_world (3,3), t_cam_from_world_m (3,), distortion (5,); "
                f"got {K.shape}, {R.shape}, {t.shape}, {d.shape}"
            )
        if int(self.width_px) <= 0 or int(self.height_px) <= 0:
            raise ValueError(f"Camera image size must be positive, got {self.width_px}x{self.height_px} px")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "R_cam_from_world", R)
        object.__setattr__(self, "t_cam_from_world_m", t)
        object.__setattr__(self, "distortion", d)
        object.__setattr__(self, "width_px", int(self.width_px))
        object.__setattr__(self, "height_px", int(self.height_px))

    @property
    def center_world_m(self) -> np.ndarray:
        """(3,) camera centre in the world frame, metres."""
        return -self.R_cam_from_world.T @ self.t_cam_from_world_m

    @property
    def P(self) -> np.ndarray:
        """(3, 4) projection matrix ``K [R | t]`` (ignores distortion)."""
        return self.K @ np.hstack([self.R_cam_from_world, self.t_cam_from_world_m[:, None]])

    @classmethod
    def from_center(
        cls, K: np.ndarray, R_cam_from_world: np.ndarray, center_world_m: np.ndarray, width_px: int, height_px: int
    ) -> Camera:
        """A camera placed at ``center_world_m`` with the given orientation."""
        R = np.asarray(R_cam_from_world, dtype=np.float64)
        return cls(K, R, -R @ np.asarray(center_world_m, dtype=np.float64), width_px, height_px)


def project_points(camera: Camera, points_world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points to pixels through one camera, with its lens distortion.

    Args:
        camera: the camera.
        points_world_m: (..., N, 3) or (3,) points in the world frame, metres.

    Returns:
        pixels_px: (..., 2) image coordinates, pixels (NaN where the point is not in front of the camera).
        depth_m: (...,) depth along the optical axis, metres.
    """
    X = np.asarray(points_world_m, dtype=np.float64)
    flat = X.reshape(-1, 3) if X.ndim < 2 else X
    px, depth = project_points_np(flat, camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m,
                                  camera.distortion)
    return px.reshape(X.shape[:-1] + (2,)), depth.reshape(X.shape[:-1])


def intrinsic_matrix(fx_px: float, fy_px: float, cx_px: float, cy_px: float) -> np.ndarray:
    """(3, 3) pinhole matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``, pixels."""
    return np.array([[fx_px, 0.0, cx_px], [0.0, fy_px, cy_px], [0.0, 0.0, 1.0]], dtype=np.float64)


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


def intrinsic_matrices(fx_px, fy_px, cx_px, cy_px) -> np.ndarray:
    """(V, 3, 3) pinhole matrices ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` from (V,) focal lengths and centres."""
    fx = np.asarray(fx_px, dtype=np.float64).reshape(-1)
    K = np.zeros((len(fx), 3, 3))
    K[:, 0, 0], K[:, 1, 1] = fx, np.asarray(fy_px, dtype=np.float64).reshape(-1)
    K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = np.asarray(cx_px).reshape(-1), np.asarray(cy_px).reshape(-1), 1.0
    return K



def pinhole(camera: Camera) -> Camera:
    """The camera without its lens distortion (same intrinsics and pose)."""
    return Camera(camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m, camera.width_px, camera.height_px)

