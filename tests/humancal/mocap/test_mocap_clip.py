"""MocapClip (validation, resampling) and the shared kinematics helpers."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humancal.mocap import R_ZUP_FROM_YUP, MocapClip, MocapFormatError, euler_rotmat
from humancal.mocap.reading import clip_name_and_subject, floor_height_m, read_text_lines


def make_clip(positions: np.ndarray, fps: float = 120.0) -> MocapClip:
    return MocapClip("01_01", "01", ("root", "child"), (-1, 0), positions, fps, None)


def linear_motion(frames: int) -> np.ndarray:
    t = np.arange(frames)[:, None, None]
    base = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.5]])
    return base[None] + t * np.array([0.01, -0.02, 0.0])  # 1.2 m/s and -2.4 m/s at 120 fps


def test_properties_and_read_only():
    clip = make_clip(linear_motion(240))
    assert clip.frames == 240 and clip.duration_s == pytest.approx(2.0)
    assert clip.joint_index("child") == 1
    np.testing.assert_allclose(clip.bone_lengths_m(), np.tile([0.0, 0.5], (240, 1)))
    with pytest.raises(ValueError):
        clip.positions_world_m[0, 0, 0] = 1.0
    with pytest.raises(KeyError, match="has no joint 'head'"):
        clip.joint_index("head")
    part = clip.trimmed(10, 20)
    assert part.frames == 10 and part.joint_names == clip.joint_names
    np.testing.assert_array_equal(part.positions_world_m, clip.positions_world_m[10:20])
    with pytest.raises(ValueError, match="are empty"):
        clip.trimmed(300)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"positions_world_m": np.zeros((3, 2))}, r"must be \(F, J, 3\)"),
        ({"positions_world_m": np.zeros((3, 3, 3))}, "3 joints in positions_world_m but 2 joint_names"),
        ({"parents": (-1, 1)}, "expected -1 .root. or the index of an earlier joint"),
        ({"fps": 0.0}, "fps must be positive"),
        ({"positions_world_m": np.full((2, 2, 3), np.nan)}, "non-finite"),
        ({"joint_names": ("a", "a")}, "unique"),
    ],
)
def test_validation(kwargs, message):
    args = {"name": "x", "subject": "x", "joint_names": ("root", "child"), "parents": (-1, 0),
            "positions_world_m": np.zeros((2, 2, 3)), "fps": 30.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        MocapClip(**args)


def test_resample_down_is_exact_on_linear_motion():
    clip = make_clip(linear_motion(121))  # 1 s at 120 fps, last frame at t = 1 s
    out = clip.resample(30.0)
    assert out.fps == 30.0 and out.frames == 31  # t = 0, 1/30, ..., 1 s: the last frame is kept
    np.testing.assert_allclose(out.positions_world_m, clip.positions_world_m[::4], atol=1e-12)


def test_resample_up_interpolates_between_frames():
    clip = make_clip(linear_motion(3), fps=10.0)  # t = 0, 0.1, 0.2 s
    out = clip.resample(25.0)  # t = 0, 0.04, ..., 0.2 s
    assert out.frames == 6
    np.testing.assert_allclose(out.positions_world_m[:, 0, 0], np.arange(6) * 0.04 * 0.1, atol=1e-12)
    assert out.name == clip.name and out.joint_names == clip.joint_names


def test_resample_non_multiple_rate_does_not_extrapolate():
    clip = make_clip(linear_motion(10))
    out = clip.resample(50.0)  # last input time 9/120 = 0.075 s -> outputs at 0, 0.02, 0.04, 0.06
    assert out.frames == 4
    assert out.positions_world_m[-1, 0, 0] <= clip.positions_world_m[-1, 0, 0]
    with pytest.raises(ValueError, match="fps_out must be positive"):
        clip.resample(-1.0)


@pytest.mark.parametrize("order", ["zxy", "xyz", "zyx", "yxz", "xzy", "yzx"])
def test_euler_rotmat_is_intrinsic_like_scipy(order):
    angles = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(50, 3))
    expected = Rotation.from_euler(order.upper(), angles).as_matrix()  # upper case: intrinsic in scipy
    np.testing.assert_allclose(euler_rotmat(order, angles), expected, atol=1e-12)


def test_euler_rotmat_degenerate_orders():
    np.testing.assert_allclose(euler_rotmat("", np.zeros((4, 0))), np.tile(np.eye(3), (4, 1, 1)))
    np.testing.assert_allclose(euler_rotmat("z", np.array([np.pi / 2])), [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                               atol=1e-12)
    with pytest.raises(ValueError, match=r"must be \(\.\.\., 2\)"):
        euler_rotmat("xy", np.zeros(3))


def test_y_up_to_z_up_is_a_proper_rotation_keeping_left_left():
    assert np.linalg.det(R_ZUP_FROM_YUP) == pytest.approx(1.0)
    np.testing.assert_allclose(R_ZUP_FROM_YUP @ R_ZUP_FROM_YUP.T, np.eye(3))
    up, forward, left = R_ZUP_FROM_YUP @ [0, 1, 0], R_ZUP_FROM_YUP @ [0, 0, 1], R_ZUP_FROM_YUP @ [1, 0, 0]
    np.testing.assert_allclose(up, [0, 0, 1])
    np.testing.assert_allclose(np.cross(up, forward), left)  # a person's left is up x forward


def test_floor_height_is_a_low_percentile_of_the_per_frame_lowest_point():
    foot_z = np.stack([np.r_[np.zeros(95), np.full(5, -1.0)], np.ones(100)], axis=1)
    assert floor_height_m(foot_z, 50.0) == 0.0
    assert floor_height_m(foot_z, 0.0) == -1.0


def test_read_text_lines_plain_gzip_crlf(tmp_path):
    (tmp_path / "a.txt").write_bytes(b"one\r\ntwo\r\n")
    (tmp_path / "b").write_bytes(gzip.compress(b"one\ntwo"))  # detected by content, not by name
    assert read_text_lines(tmp_path / "a.txt") == ["one", "two"] == read_text_lines(tmp_path / "b")
    (tmp_path / "c.txt").write_bytes(b"ok\n\xff\n")
    with pytest.raises(MocapFormatError, match="line 2: expected UTF-8"):
        read_text_lines(tmp_path / "c.txt")
    with pytest.raises(FileNotFoundError):
        read_text_lines(tmp_path / "missing.bvh")


def test_clip_name_and_subject():
    assert clip_name_and_subject("x/02_01.bvh.gz") == ("02_01", "02")
    assert clip_name_and_subject("x/13_29.amc") == ("13_29", "13")
    assert clip_name_and_subject("walk.bvh") == ("walk", "walk")
