"""Pinhole cameras in the house convention, and their table form.

Convention (``docs/conventions.md``): OpenCV pinhole, x right, y down, z forward;
``x_cam = R_cam_from_world @ x_world + t_cam_from_world_m``; ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``
in pixels; distortion as OpenCV's (k1, k2, p1, p2, k3). World: metres, right-handed, Z up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.tables import validate_table

__all__ = ["Camera", "cameras_to_table", "cameras_from_table", "project_points"]


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
    """Project world points to pixels (no distortion; see ``humancal.geometry`` for the distorted model).

    Args:
        camera: the camera.
        points_world_m: (..., 3) points in the world frame, metres.

    Returns:
        pixels_px: (..., 2) image coordinates, pixels (NaN where the point is not in front of the camera).
        depth_m: (...,) depth along the optical axis, metres.
    """
    X = np.asarray(points_world_m, dtype=np.float64)
    x_cam = X @ camera.R_cam_from_world.T + camera.t_cam_from_world_m
    depth = x_cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = x_cam[..., :2] / depth[..., None]
    px = uv @ camera.K[:2, :2].T + camera.K[:2, 2]
    px[depth <= 0] = np.nan
    return px, depth


def cameras_to_table(cameras: list[Camera], sequence: str) -> pd.DataFrame:
    """The canonical ``cameras`` table (one row per view, views numbered in list order)."""
    rows = [
        {
            "sequence": sequence,
            "view": v,
            "fx_px": c.K[0, 0],
            "fy_px": c.K[1, 1],
            "cx_px": c.K[0, 2],
            "cy_px": c.K[1, 2],
            "R_cam_from_world": c.R_cam_from_world.reshape(-1),
            "t_cam_from_world_m": c.t_cam_from_world_m,
            "distortion": c.distortion,
            "width_px": c.width_px,
            "height_px": c.height_px,
        }
        for v, c in enumerate(cameras)
    ]
    return validate_table(pd.DataFrame(rows, columns=_CAMERA_COLUMNS), "cameras")


def cameras_from_table(table: pd.DataFrame) -> list[Camera]:
    """Cameras from a canonical ``cameras`` table, ordered by ``view`` (views must be 0..V-1).

    Raises:
        ValueError: views are not exactly 0..V-1.
    """
    table = table.sort_values("view")
    views = table["view"].to_numpy()
    if not np.array_equal(views, np.arange(len(views))):
        raise ValueError(f"cameras table: views must be 0..{len(views) - 1} once each, got {views.tolist()}")
    out = []
    for row in table.itertuples(index=False):
        K = np.array([[row.fx_px, 0.0, row.cx_px], [0.0, row.fy_px, row.cy_px], [0.0, 0.0, 1.0]])
        out.append(
            Camera(
                K,
                np.asarray(row.R_cam_from_world, dtype=np.float64).reshape(3, 3),
                np.asarray(row.t_cam_from_world_m, dtype=np.float64),
                int(row.width_px),
                int(row.height_px),
                np.asarray(row.distortion, dtype=np.float64),
            )
        )
    return out


_CAMERA_COLUMNS = [
    "sequence",
    "view",
    "fx_px",
    "fy_px",
    "cx_px",
    "cy_px",
    "R_cam_from_world",
    "t_cam_from_world_m",
    "distortion",
    "width_px",
    "height_px",
]
