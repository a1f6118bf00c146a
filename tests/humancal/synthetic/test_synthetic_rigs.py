"""Camera rigs: ring, arc and Human3.6M."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.camera import look_at, project_points
from humancal.settings import DataRootError, data_root
from humancal.synthetic import SceneConfig, make_rig


def _check_rig(cameras, config):
    area_centre = np.array([0.0, 0.0, 1.0])
    corners = np.array([[sx, sy, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, 1.8)], dtype=np.float64)
    corners[:, :2] *= np.array(config.area_size_m) / 2
    for cam in cameras:
        R = cam.R_cam_from_world
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)  # right-handed
        assert (cam.width_px, cam.height_px) == config.image_size_px
        assert cam.K[0, 2] == cam.width_px / 2 and cam.K[1, 2] == cam.height_px / 2
        assert cam.K[0, 0] == cam.K[1, 1]
        # The area centre projects inside the image, in front of the camera.
        pixel, depth = project_points(cam, area_centre)
        assert depth > 0
        assert 0 <= pixel[0] < cam.width_px and 0 <= pixel[1] < cam.height_px
        # Image y points down in the world: a point above the centre is higher in the image.
        above, _ = project_points(cam, area_centre + [0.0, 0.0, 0.5])
        assert above[1] < pixel[1]
    return np.array([cam.center_world_m for cam in cameras]), corners


@pytest.mark.parametrize("num_views", [2, 5, 31])
def test_ring_rig_surrounds_and_sees_the_area(num_views):
    config = SceneConfig(num_views=num_views, seed=4)
    cameras = make_rig(config, np.random.default_rng(0))
    assert len(cameras) == num_views
    centers, corners = _check_rig(cameras, config)
    assert np.all((centers[:, 2] >= 1.5) & (centers[:, 2] <= 4.0))
    focal = np.array([c.K[0, 0] for c in cameras])
    assert np.all((focal >= 900.0) & (focal <= 1600.0))
    # Outside the area, all around it.
    assert np.all(np.abs(centers[:, :2]).max(axis=1) > np.array(config.area_size_m).max() / 2)
    azimuth = np.sort(np.arctan2(centers[:, 1], centers[:, 0]))
    gaps = np.diff(np.concatenate([azimuth, azimuth[:1] + 2 * np.pi]))
    assert gaps.max() < 1.6 * 2 * np.pi / num_views + 1e-9
    # The whole floor area (and standing heads) is in view of every camera at the default area_fill.
    for cam in cameras:
        pixel, depth = project_points(cam, corners)
        assert np.all(depth > 0)
        assert np.all((pixel[:, 0] >= 0) & (pixel[:, 0] < cam.width_px))


def test_arc_rig_spans_the_configured_angle():
    config = SceneConfig(rig="arc", num_views=4, arc_span_deg=90.0, seed=1)
    cameras = make_rig(config, np.random.default_rng(3))
    centers, _ = _check_rig(cameras, config)
    azimuth = np.unwrap(np.arctan2(centers[:, 1], centers[:, 0]))
    span = np.degrees(azimuth.max() - azimuth.min())
    assert 45.0 < span < 135.0  # 90 degrees +- a quarter spacing at each end


def test_rig_is_reproducible_and_seed_dependent():
    config = SceneConfig(num_views=3)
    a = make_rig(config, np.random.default_rng(1))
    b = make_rig(config, np.random.default_rng(1))
    c = make_rig(config, np.random.default_rng(2))
    assert all(np.array_equal(x.P, y.P) for x, y in zip(a, b))
    assert not np.allclose(a[0].P, c[0].P)


def test_look_at_conventions():
    R = look_at(np.array([0.0, -5.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(R[2], [0.0, 1.0, 0.0], atol=1e-12)  # optical axis towards +y
    np.testing.assert_allclose(R[0], [1.0, 0.0, 0.0], atol=1e-12)  # image x = world +x
    np.testing.assert_allclose(R[1], [0.0, 0.0, -1.0], atol=1e-12)  # image y = world down
    rolled = look_at(np.array([0.0, -5.0, 1.0]), np.array([0.0, 0.0, 1.0]), roll_deg=10.0)
    np.testing.assert_allclose(rolled[2], R[2], atol=1e-12)
    assert np.degrees(np.arccos(rolled[0] @ R[0])) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="vertical"):
        look_at(np.zeros(3), np.array([0.0, 0.0, -1.0]))


def test_h36m_rig_needs_the_data_root(monkeypatch, tmp_path):
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path / "missing"))
    with pytest.raises(DataRootError, match="HUMANCAL_DATA_DIR"):
        make_rig(SceneConfig(rig="h36m", num_views=4), np.random.default_rng(0))
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path))
    with pytest.raises(DataRootError, match="h36m_cameras"):
        make_rig(SceneConfig(rig="h36m", num_views=4), np.random.default_rng(0))


def test_h36m_rig_from_the_real_calibration():
    root = data_root()
    if root is None or not (root / "h36m_cameras" / "camera-parameters.json").is_file():
        pytest.skip("Human3.6M camera parameters not available under the data root")
    config = SceneConfig(rig="h36m", num_views=4, image_size_px=(1000, 1000))
    cameras = make_rig(config, np.random.default_rng(0))
    assert len(cameras) == 4
    centers, _ = _check_rig(cameras, config)
    # Metres, not millimetres: the cameras stand about 4-6 m from the re-centred area, 1.4-1.7 m high.
    distance = np.linalg.norm(centers[:, :2], axis=1)
    assert np.all((distance > 3.0) & (distance < 7.0))
    assert np.all((centers[:, 2] > 1.3) & (centers[:, 2] < 1.8))
    focal = np.array([c.K[0, 0] for c in cameras])
    np.testing.assert_allclose(focal, 1146.0, atol=5.0)
    assert len(make_rig(config.replace(num_views=2), np.random.default_rng(0))) == 2


def _pitch_deg(camera) -> float:
    """Angle of the optical axis below the horizon, degrees."""
    return float(np.degrees(np.arcsin(-camera.R_cam_from_world[2, 2])))


def _area_box(config, top_m: float = 1.8) -> np.ndarray:
    half = np.array(config.area_size_m) / 2
    return np.array([[sx * half[0], sy * half[1], z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, top_m)])


def _inside_image(camera, points) -> np.ndarray:
    pixel, depth = project_points(camera, points)
    return (depth > 0) & (pixel[:, 0] >= 0) & (pixel[:, 0] < camera.width_px) & (pixel[:, 1] >= 0) & (
        pixel[:, 1] < camera.height_px
    )


@pytest.mark.parametrize("size", [(1080, 1920), (720, 1280)])
def test_portrait_rigs_fit_the_area_into_the_narrow_width(size):
    config = SceneConfig(num_views=8, image_size_px=size, seed=2)
    cameras = make_rig(config, np.random.default_rng(5))
    _check_rig(cameras, config)
    for cam in cameras:
        assert (cam.width_px, cam.height_px) == size
        assert np.all(_inside_image(cam, _area_box(config)))


@pytest.mark.parametrize(("pitch_range", "height_range"), [((50.0, 70.0), (7.0, 14.0)), ((0.0, 3.0), (0.7, 1.7))])
def test_drawn_camera_tilts_are_exact_and_the_area_fits(pitch_range, height_range):
    for size in ((1920, 1080), (1080, 1920)):
        config = SceneConfig(num_views=6, camera_pitch_range_deg=pitch_range, image_size_px=size)
        cameras = make_rig(config, np.random.default_rng(7))
        _check_rig(cameras, config)
        for cam in cameras:
            assert pitch_range[0] - 1e-9 <= _pitch_deg(cam) <= pitch_range[1] + 1e-9
            assert height_range[0] <= cam.center_world_m[2] <= height_range[1]
            assert np.all(_inside_image(cam, _area_box(config, top_m=2.0)))


def test_height_drawn_rigs_look_down_from_high_and_level_from_low():
    high = make_rig(SceneConfig(num_views=8, camera_height_range_m=(7.0, 9.0)), np.random.default_rng(1))
    low = make_rig(SceneConfig(num_views=8, camera_height_range_m=(1.0, 1.3)), np.random.default_rng(1))
    assert min(_pitch_deg(c) for c in high) > 30.0
    assert max(abs(_pitch_deg(c)) for c in low) < 6.0
    # The distance rule fits the area's width only: from 7-9 m a landscape view may lose the near edge of the
    # floor (``camera_pitch_range_deg`` fits the whole box), but the middle of the area stays in every view.
    middle = _area_box(SceneConfig(num_people=1, area_size_m=(2.5, 2.0)), top_m=1.8)
    for cam in [*high, *low]:
        assert np.all(_inside_image(cam, middle))
    assert np.mean([_inside_image(cam, _area_box(SceneConfig(), top_m=0.0)).mean() for cam in high]) > 0.8


def test_k1_is_drawn_only_when_asked_and_keeps_the_area_in_view():
    plain = make_rig(SceneConfig(num_views=4), np.random.default_rng(3))
    config = SceneConfig(num_views=4, distortion_k1_range=(-0.3, 0.2))
    lensed = make_rig(config, np.random.default_rng(3))
    k1 = np.array([c.distortion[0] for c in lensed])
    assert np.all((k1 >= -0.3) & (k1 <= 0.2)) and np.all(k1 != 0.0)
    assert all(not c.distortion[1:].any() for c in lensed)
    assert all(not c.distortion.any() for c in plain)
    # The draws before the lenses are the same: same azimuths and focal lengths.
    np.testing.assert_allclose([c.K for c in lensed], [c.K for c in plain])
    for cam in lensed:
        assert np.all(_inside_image(cam, _area_box(config, top_m=0.0)))


def test_principal_points_move_only_when_asked():
    config = SceneConfig(num_views=6, seed=4)
    centred = make_rig(config, np.random.default_rng(4))
    moved = make_rig(config.replace(principal_point_offset_px=30.0), np.random.default_rng(4))
    offsets = np.array([m.K[:2, 2] - c.K[:2, 2] for m, c in zip(moved, centred)])
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=1), 30.0)
    assert len({round(float(np.arctan2(y, x)), 6) for x, y in offsets}) == 6  # a direction per camera
    for m, c in zip(moved, centred):  # everything else is the rig of the same seed without the offset
        np.testing.assert_array_equal(m.R_cam_from_world, c.R_cam_from_world)
        np.testing.assert_array_equal(m.t_cam_from_world_m, c.t_cam_from_world_m)
        assert m.K[0, 0] == c.K[0, 0]
    with pytest.raises(ValueError, match="principal_point_offset_px"):
        SceneConfig(principal_point_offset_px=-1.0)
