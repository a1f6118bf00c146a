"""Shared fixtures of the format tests: random cameras and a random canonical detections table.

Helpers are handed out as fixtures (not imported), so they work under any pytest import mode.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from humancal.camera import Camera
from humancal.formats.detections import sort_detections
from humancal.keypoints import CANONICAL_JOINTS
from humancal.tables.schemas import validate_table


def make_cameras(seed: int = 0, count: int = 3, distortion: bool = True) -> list[Camera]:
    """Cameras with random poses, distinct intrinsics and (optionally) distortion, one of them with k3 != 0."""
    rng = np.random.default_rng(seed)
    cameras = []
    for i in range(count):
        K = np.array(
            [[900.0 + 300.0 * rng.random(), 0.0, 950.0 + 20.0 * rng.random()],
             [0.0, 900.0 + 300.0 * rng.random(), 530.0 + 20.0 * rng.random()],
             [0.0, 0.0, 1.0]]
        )  # fmt: skip
        R = Rotation.random(random_state=seed * 100 + i).as_matrix()
        t = rng.normal(size=3) * 3.0
        d = np.r_[rng.normal(size=4) * 0.01, 0.003 * (i == count - 1)] if distortion else np.zeros(5)
        cameras.append(Camera(K, R, t, 1920 - 10 * i, 1080, d))
    return cameras


def make_detections(seed: int = 0, frames=(3, 4, 6), views=(0, 1), sequence: str = "demo") -> pd.DataFrame:
    """A canonical detections table: up to 3 people per image, random missing joints, one empty (frame, view)."""
    rng = np.random.default_rng(seed)
    rows = []
    for frame in frames:
        for view in views:
            if (frame, view) == (frames[-1], views[-1]):
                continue  # an image without detections
            for det in range(int(rng.integers(1, 4))):
                for joint in CANONICAL_JOINTS:
                    if rng.random() < 0.2:
                        continue
                    x, y, score = rng.uniform(0, 1920), rng.uniform(0, 1080), rng.uniform(0.05, 1.0)
                    rows.append((sequence, frame, view, det, joint, x, y, score))
    df = pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"])
    return sort_detections(validate_table(df, "detections"))


def assert_cameras_close(a: list[Camera], b: list[Camera], atol: float = 1e-9) -> None:
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        np.testing.assert_allclose(y.K, x.K, rtol=0, atol=atol, err_msg=f"K of camera {i}")
        R, t = x.R_cam_from_world, x.t_cam_from_world_m
        np.testing.assert_allclose(y.R_cam_from_world, R, rtol=0, atol=atol, err_msg=f"R of camera {i}")
        np.testing.assert_allclose(y.t_cam_from_world_m, t, rtol=0, atol=atol, err_msg=f"t of camera {i}")
        np.testing.assert_allclose(y.distortion, x.distortion, rtol=0, atol=atol, err_msg=f"distortion of camera {i}")
        assert (y.width_px, y.height_px) == (x.width_px, x.height_px), f"size of camera {i}"


@pytest.fixture
def cameras() -> list[Camera]:
    return make_cameras()


@pytest.fixture
def detections() -> pd.DataFrame:
    return make_detections()


@pytest.fixture
def detections_factory():
    return make_detections


@pytest.fixture
def cameras_factory():
    return make_cameras


@pytest.fixture
def cameras_close():
    return assert_cameras_close
