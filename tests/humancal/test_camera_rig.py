"""CameraRig: round trips between cameras, the cameras table and tensors; projection through the rig."""

from collections.abc import Sequence

import numpy as np
import pandas as pd
import pytest
import torch

from humancal.camera import Camera, CameraRig, cameras_from_table, cameras_to_table, project_points
from humancal.geometry.rotations import rotvec_to_rotmat


def _cameras(V=3, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for v in range(V):
        K = np.array([[1000.0 + 50 * v, 0, 640 + v], [0, 1010.0 + 50 * v, 360 - v], [0, 0, 1]])
        R = rotvec_to_rotmat(rng.normal(scale=0.4, size=3))
        t = rng.normal(size=3) + [0, 0, 5]
        out.append(Camera(K, R, t, 1280 + v, 720, rng.normal(scale=0.01, size=5)))
    return out


def _same(a: Camera, b: Camera):
    for name in ("K", "R_cam_from_world", "t_cam_from_world_m", "distortion"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert (a.width_px, a.height_px) == (b.width_px, b.height_px)


def test_a_rig_is_a_sequence_of_its_cameras():
    cams = _cameras(4)
    rig = CameraRig.from_cameras(cams)
    for a, b in zip(rig, cams, strict=True):
        _same(a, b)
    _same(rig[2], cams[2])
    _same(rig[-1], cams[3])
    assert rig[2] is rig[2]  # built once
    tail = rig[1:3]
    assert isinstance(tail, CameraRig) and len(tail) == 2
    _same(tail[0], cams[1])
    assert CameraRig.of(rig) is rig
    np.testing.assert_array_equal(CameraRig.of(cams).K, rig.K)
    with pytest.raises(IndexError):
        rig[4]
    assert not CameraRig.from_cameras([]) and list(CameraRig.from_cameras([])) == []
    assert isinstance(rig, Sequence) and next(reversed(rig)) is rig[3]


def test_the_cameras_table_reads_back_as_a_rig():
    cams = _cameras()
    back = cameras_from_table(cameras_to_table(cams, "s__x"))
    assert isinstance(back, CameraRig) and len(back) == 3
    np.testing.assert_array_equal(back.K, CameraRig.from_cameras(cams).K)
    np.testing.assert_array_equal(cameras_to_table(CameraRig.from_cameras(cams), "s__x")["fx_px"],
                                  cameras_to_table(cams, "s__x")["fx_px"])


def test_round_trips_cameras_table_and_tensors():
    cams = _cameras()
    rig = CameraRig.from_cameras(cams)
    assert len(rig) == 3 and rig.K.shape == (3, 3, 3) and rig.image_size_px.tolist()[1] == [1281, 720]
    for a, b in zip(rig.to_cameras(), cams):
        _same(a, b)
    table = rig.to_table("s__x")
    back = CameraRig.from_table(table.sample(frac=1.0, random_state=0))  # row order does not matter
    for a, b in zip(back.to_cameras(), cams):
        _same(a, b)
    for a, b in zip(cameras_from_table(cameras_to_table(cams, "s__x")), cams):
        _same(a, b)
    np.testing.assert_allclose(rig.centers_world_m, np.stack([c.center_world_m for c in cams]), atol=1e-12)
    tensors = rig.to_torch(torch.float32)
    assert tensors.K.dtype == torch.float32 and tensors.distortion.shape == (3, 5)
    np.testing.assert_allclose(tensors.R_cam_from_world.double().numpy(), rig.R_cam_from_world, atol=1e-6)


def test_rig_projection_matches_the_single_camera_one():
    cams = _cameras()
    rig = CameraRig.from_cameras(cams)
    X = np.random.default_rng(1).uniform(-1, 1, size=(40, 3))
    px, depth = rig.project(X)
    px_t, depth_t, in_front = rig.to_torch().project(torch.from_numpy(X))
    for v, cam in enumerate(cams):
        one, d = project_points(cam, X)
        np.testing.assert_allclose(px[v], one, atol=1e-9)
        np.testing.assert_allclose(px_t[v].numpy(), one, atol=1e-9)
        np.testing.assert_allclose(depth[v], d, atol=1e-12)
    assert bool(in_front.all())
    assert project_points(cams[0], X[0])[0].shape == (2,)


def test_bad_tables_and_shapes_are_named():
    table = cameras_to_table(_cameras(), "s__x")
    with pytest.raises(ValueError, match=r"'view' must hold 0\.\.V-1 \(here 0\.\.2\)"):
        CameraRig.from_table(table.assign(view=[0, 1, 3]))
    with pytest.raises(ValueError, match=r"CameraRig.distortion must have shape \(V, 5\)"):
        rig = CameraRig.from_cameras(_cameras())
        CameraRig(rig.K, rig.R_cam_from_world, rig.t_cam_from_world_m, rig.distortion[:, :4], rig.image_size_px)
    empty = CameraRig.from_table(pd.DataFrame(columns=table.columns))
    assert len(empty) == 0 and empty.to_cameras() == []
