"""Stacked rigs of cameras (:class:`CameraRig`, :class:`RigTensors`) and their table form.

A rig is the ``V`` cameras of a capture as stacked arrays (row ``v`` is view ``v``), and a sequence of its
:class:`~humancal.camera.model.Camera` objects; the canonical ``cameras`` table has one row per view.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import overload

import numpy as np
import pandas as pd
import torch

from humancal.camera.model import Camera, intrinsic_matrices
from humancal.camera.projection import project_points_np, project_points_torch
from humancal.tables.schemas import validate_table

__all__ = [
    "CameraRig",
    "RigTensors",
    "cameras_by_view",
    "cameras_from_table",
    "cameras_to_table",
    "sorted_views",
    "with_known_distortion",
]


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
        """:func:`~humancal.camera.projection.project_points_torch` through every view.

        Args:
            points_world_m: (N, 3) points seen by all views, or (..., V, N, 3) per view, metres.

        Returns:
            pixels_px (..., V, N, 2), depth_m (..., V, N), in_front (..., V, N).
        """
        return project_points_torch(points_world_m, self.K, self.R_cam_from_world, self.t_cam_from_world_m,
                                    self.distortion)


@dataclass(frozen=True)
class CameraRig(Sequence[Camera]):
    """V static cameras as stacked arrays (views in order: row v is view v), and the sequence of their
    :class:`Camera` objects (``rig[v]``, ``for camera in rig``, ``rig[a:b]`` a sub-rig).

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
        """:func:`~humancal.camera.projection.project_points_np` through every view.

        Args:
            points_world_m: (N, 3) points seen by all views, or (..., V, N, 3) per view, metres.

        Returns:
            pixels_px (..., V, N, 2) (NaN where not in front), depth_m (..., V, N).
        """
        return project_points_np(points_world_m, self.K, self.R_cam_from_world, self.t_cam_from_world_m,
                                 self.distortion)


def cameras_to_table(cameras: CameraRig, sequence: str) -> pd.DataFrame:
    """The canonical ``cameras`` table (one row per view, views numbered in rig order; a list of cameras is taken
    as a rig, list index = view)."""
    return CameraRig.of(cameras).to_table(sequence)


def with_known_distortion(rig: CameraRig, known: Mapping[int, Camera]) -> CameraRig:
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


def cameras_from_table(table: pd.DataFrame) -> CameraRig:
    """The rig of a canonical ``cameras`` table, views ordered by ``view`` (views must be 0..V-1): the same as
    :meth:`CameraRig.from_table`.

    Raises:
        ValueError: views are not exactly 0..V-1.
    """
    return CameraRig.from_table(table)


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
