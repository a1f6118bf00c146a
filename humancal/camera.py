"""Pinhole cameras in the house convention, stacked rigs, and their table form.

Convention (``docs/conventions.md``): OpenCV pinhole, x right, y down, z forward;
``x_cam = R_cam_from_world @ x_world + t_cam_from_world_m``; ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``
in pixels; distortion as OpenCV's (k1, k2, p1, p2, k3). World: metres, right-handed, Z up.

Example: a camera 5 m back along -y, looking along +y (world z up is its -y), sees the origin at its principal point
and a point 1 m up 200 px higher in the image:

    >>> import numpy as np
    >>> from humancal.camera import Camera, project_points
    >>> K = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]])
    >>> R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # rows: camera x, y, z in the world
    >>> camera = Camera.from_center(K, R, [0.0, -5.0, 0.0], 1280, 720)
    >>> pixels, depth = project_points(camera, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    >>> pixels.round(6).tolist(), depth.tolist()
    ([[640.0, 360.0], [640.0, 160.0]], [5.0, 5.0])
"""

from __future__ import annotations


from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import overload

import numpy as np
import pandas as pd
import torch

from humancal.geometry.projection import project_points_np, project_points_torch
from humancal.tables import validate_table

__all__ = [
    "Camera",
    "CameraRig",
    "RigTensors",
    "cameras_to_table",
    "cameras_from_table",
    "intrinsic_matrix",
    "intrinsic_matrices",
    "look_at",
    "project_points",
    "sorted_views",
]


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


def sorted_views(table: pd.DataFrame, name: str) -> pd.DataFrame:
    """The rows of a one-row-per-view table ordered by ``view``, which must hold 0..V-1 once each.

    Raises:
        ValueError: the views are not exactly 0..V-1.
    """
    rows = table.sort_values("view")
    views = rows["view"].to_numpy()
    if not np.array_equal(views, np.arange(len(views))):
        raise ValueError(f"{name}: column 'view' must hold 0..V-1 (here 0..{len(views) - 1}) once each, got "
                         f"{views.tolist()}")
    return rows


@dataclass(frozen=True)
class RigTensors:
    """A rig's parameters as tensors, for differentiable projection (:meth:`CameraRig.to_torch`).

    Attributes:
        K: (V, 3, 3) intrinsics, pixels.
        R_cam_from_world: (V, 3, 3).
        t_cam_from_world_m: (V, 3), metres.
        distortion: (V, 5) ``(k1, k2, p1, p2, k3)``.
    """

    K: torch.Tensor
    R_cam_from_world: torch.Tensor
    t_cam_from_world_m: torch.Tensor
    distortion: torch.Tensor

    def project(self, points_world_m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """:func:`~humancal.geometry.projection.project_points_torch` through every view.

        Args:
            points_world_m: (N, 3) points seen by all views, or (..., V, N, 3) per view, metres.

        Returns:
            pixels_px (..., V, N, 2), depth_m (..., V, N), in_front (..., V, N).
        """
        return project_points_torch(points_world_m, self.K, self.R_cam_from_world, self.t_cam_from_world_m,
                                    self.distortion)


@dataclass(frozen=True)
class CameraRig:
    """V static cameras as stacked arrays (views in order: row v is view v).

    Attributes:
        K: (V, 3, 3) intrinsics, pixels.
        R_cam_from_world: (V, 3, 3) rotations, world to camera.
        t_cam_from_world_m: (V, 3) translations, metres.
        distortion: (V, 5) OpenCV ``(k1, k2, p1, p2, k3)``.
        image_size_px: (V, 2) int ``(width, height)``, pixels.
    """

    K: np.ndarray
    R_cam_from_world: np.ndarray
    t_cam_from_world_m: np.ndarray
    distortion: np.ndarray
    image_size_px: np.ndarray

    def __post_init__(self) -> None:
        arrays = {
            "K": np.asarray(self.K, dtype=np.float64),
            "R_cam_from_world": np.asarray(self.R_cam_from_world, dtype=np.float64),
            "t_cam_from_world_m": np.asarray(self.t_cam_from_world_m, dtype=np.float64),
            "distortion": np.asarray(self.distortion, dtype=np.float64),
            "image_size_px": np.asarray(self.image_size_px, dtype=np.int64),
        }
        V = arrays["K"].shape[0] if arrays["K"].ndim == 3 else -1
        tails = {"K": (3, 3), "R_cam_from_world": (3, 3), "t_cam_from_world_m": (3,), "distortion": (5,),
                 "image_size_px": (2,)}
        for name, tail in tails.items():
            if V < 0 or arrays[name].shape != (V,) + tail:
                raise ValueError(f"CameraRig.{name} must have shape (V,{' ' if tail else ''}"
                                 f"{', '.join(map(str, tail))}) with V from K, got {arrays[name].shape}")
        if (arrays["image_size_px"] <= 0).any():
            raise ValueError("CameraRig.image_size_px must be positive (width, height) pixels")
        for name, value in arrays.items():
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return int(self.K.shape[0])

    @overload
    def __getitem__(self, view: int) -> Camera: ...

    @overload
    def __getitem__(self, views: slice) -> CameraRig: ...

    def __getitem__(self, index):
        """View ``v``'s :class:`Camera`, or a sub-rig for a slice (its views numbered from 0)."""
        if isinstance(index, slice):
            return CameraRig.from_cameras(self.cameras[index])
        return self.cameras[index]

    def __iter__(self) -> Iterator[Camera]:
        return iter(self.cameras)

    @property
    def cameras(self) -> tuple[Camera, ...]:
        """One :class:`Camera` per view, in view order (built once; a rig is a sequence of these)."""
        cached = self.__dict__.get("_cameras")
        if cached is None:
            cached = tuple(
                Camera(self.K[v], self.R_cam_from_world[v], self.t_cam_from_world_m[v], int(self.image_size_px[v, 0]),
                       int(self.image_size_px[v, 1]), self.distortion[v])
                for v in range(len(self)))
            object.__setattr__(self, "_cameras", cached)
        return cached

    @classmethod
    def of(cls, cameras: CameraRig | Sequence[Camera]) -> CameraRig:
        """``cameras`` as a rig (a rig is returned as it is; a sequence of cameras is stacked, index = view)."""
        return cameras if isinstance(cameras, CameraRig) else cls.from_cameras(cameras)

    @property
    def centers_world_m(self) -> np.ndarray:
        """(V, 3) camera centres in the world frame, metres: ``-R^T t``."""
        return -np.einsum("vji,vj->vi", self.R_cam_from_world, self.t_cam_from_world_m)

    @classmethod
    def from_cameras(cls, cameras: Sequence[Camera]) -> CameraRig:
        """Stack a list of cameras (list index = view)."""
        if len(cameras) == 0:
            return cls(np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 5)),
                       np.zeros((0, 2), np.int64))
        return cls(
            np.stack([c.K for c in cameras]),
            np.stack([c.R_cam_from_world for c in cameras]),
            np.stack([c.t_cam_from_world_m for c in cameras]),
            np.stack([c.distortion for c in cameras]),
            np.array([(c.width_px, c.height_px) for c in cameras], dtype=np.int64),
        )

    def to_cameras(self) -> list[Camera]:
        """One :class:`Camera` per view, in view order, as a list."""
        return list(self.cameras)

    @classmethod
    def from_table(cls, table: pd.DataFrame) -> CameraRig:
        """The rig of a canonical ``cameras`` table (views must be 0..V-1).

        Raises:
            ValueError: views are not exactly 0..V-1.
        """
        rows = sorted_views(table, "cameras")
        V = len(rows)
        stack = lambda column, shape: (  # noqa: E731
            np.stack([np.asarray(x, dtype=np.float64) for x in rows[column]]).reshape((V,) + shape)
            if V else np.zeros((0,) + shape)
        )
        return cls(
            intrinsic_matrices(rows["fx_px"], rows["fy_px"], rows["cx_px"], rows["cy_px"]),
            stack("R_cam_from_world", (3, 3)),
            stack("t_cam_from_world_m", (3,)),
            stack("distortion", (5,)),
            rows[["width_px", "height_px"]].to_numpy(np.int64).reshape(V, 2),
        )

    def to_table(self, sequence: str) -> pd.DataFrame:
        """The canonical ``cameras`` table, one row per view."""
        table = pd.DataFrame(
            {
                "sequence": sequence,
                "view": np.arange(len(self)),
                "fx_px": self.K[:, 0, 0],
                "fy_px": self.K[:, 1, 1],
                "cx_px": self.K[:, 0, 2],
                "cy_px": self.K[:, 1, 2],
                "R_cam_from_world": list(self.R_cam_from_world.reshape(-1, 9)),
                "t_cam_from_world_m": list(self.t_cam_from_world_m),
                "distortion": list(self.distortion),
                "width_px": self.image_size_px[:, 0],
                "height_px": self.image_size_px[:, 1],
            },
            columns=_CAMERA_COLUMNS,
        )
        return validate_table(table, "cameras")

    def to_torch(self, dtype: torch.dtype = torch.float64, device: torch.device | str = "cpu") -> RigTensors:
        """The parameters as tensors (no gradients; call ``requires_grad_`` on the ones to optimise)."""
        as_t = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
        return RigTensors(as_t(self.K), as_t(self.R_cam_from_world), as_t(self.t_cam_from_world_m),
                          as_t(self.distortion))

    def project(self, points_world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~humancal.geometry.projection.project_points_np` through every view.

        Args:
            points_world_m: (N, 3) points seen by all views, or (..., V, N, 3) per view, metres.

        Returns:
            pixels_px (..., V, N, 2) (NaN where not in front), depth_m (..., V, N).
        """
        return project_points_np(points_world_m, self.K, self.R_cam_from_world, self.t_cam_from_world_m,
                                 self.distortion)


def cameras_to_table(cameras: list[Camera], sequence: str) -> pd.DataFrame:
    """The canonical ``cameras`` table (one row per view, views numbered in list order)."""
    return CameraRig.from_cameras(cameras).to_table(sequence)


def pinhole(camera: Camera) -> Camera:
    """The camera without its lens distortion (same intrinsics and pose)."""
    return Camera(camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m, camera.width_px, camera.height_px)


def with_known_distortion(rig: CameraRig, known: dict[int, Camera]) -> CameraRig:
    """The rig with the lens distortion of the known cameras put back in their views."""
    distortion = rig.distortion.copy()
    for v, camera in known.items():
        distortion[v] = camera.distortion
    return replace(rig, distortion=distortion)


def cameras_by_view(table: pd.DataFrame) -> dict[int, Camera]:
    """The cameras of a canonical ``cameras`` table that holds some views only (e.g. a capture's known cameras), by
    view."""
    views = [int(v) for v in sorted(table["view"])]
    renumbered = table.assign(view=table["view"].map({v: i for i, v in enumerate(views)}))
    return dict(zip(views, cameras_from_table(renumbered)))


def cameras_from_table(table: pd.DataFrame) -> list[Camera]:
    """Cameras from a canonical ``cameras`` table, ordered by ``view`` (views must be 0..V-1).

    Raises:
        ValueError: views are not exactly 0..V-1.
    """
    return CameraRig.from_table(table).to_cameras()


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
