"""Consumer rigs: k1/k2 lenses, fx != fy, principal points off centre, fields of view through the lens, and
unsynchronised views with their own frame rates; the older options' scenes unchanged."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from humancal.camera import Camera, look_at
from humancal.keypoints import NUM_JOINTS
from humancal.synthetic import DetectorNoise, SceneConfig, generate_scene, preset, simulate_detections
from humancal.synthetic.clocks import to_reference_frames
from humancal.synthetic.lenses import distorted_radius, fold_radius, undistorted_radius

GOLDEN = Path(__file__).parent / "golden" / "existing_options.npz"
"""Arrays of scenes with the lens, tilt, dome, far-view, principal point, out-of-view and keypoint-bias options, recorded
with the generator as it was before the k2, aspect, field-of-view and clock options existed
(``existing_options.npz``: ``K, R, t, distortion``, per detection ``frame, view, person, det_id`` and the packed
``present`` mask, the first 50 detections' keypoints, every person's frame-0 keypoints)."""
_GOLDEN_CONFIGS = {
    "k1tilt": dict(num_views=4, num_frames=20, distortion_k1_range=(-0.15, 0.05), image_size_px=(1080, 1920),
                   camera_pitch_range_deg=(45.0, 70.0), seed=7),
    "domefarpp": dict(num_frames=20, rig="dome", far_views=1, num_views=5, distortion_k1_range=(-0.1, 0.0),
                      principal_point_offset_px=30.0, seed=9),
    "spellsbias": dict(num_frames=90, out_of_view_spells=1.0, seed=4, noise=DetectorNoise(keypoint_bias_m=0.02)),
    "barrel": dict(num_frames=20, distortion_k1_range=(-0.5, -0.4), focal_range_px=(500.0, 700.0), seed=3),
}


def _project_cv2(camera: Camera, points_world_m: np.ndarray) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(camera.R_cam_from_world)
    pixels, _ = cv2.projectPoints(points_world_m, rvec, camera.t_cam_from_world_m, camera.K, camera.distortion)
    return pixels[:, 0]


@pytest.mark.parametrize("name", sorted(_GOLDEN_CONFIGS))
def test_scenes_of_the_older_options_are_unchanged(body_model, name):
    golden = np.load(GOLDEN)
    g = {key[len(name) + 1:]: golden[key] for key in golden.files if key.startswith(name + "_")}
    config = preset("tiny", **_GOLDEN_CONFIGS[name])
    assert not config.unsynced
    scene = generate_scene(config, body_model, sequence=name)
    for key, value in (("K", [c.K for c in scene.rig]), ("R", [c.R_cam_from_world for c in scene.rig]),
                       ("t", [c.t_cam_from_world_m for c in scene.rig]), ("distortion", [c.distortion for c in scene.rig])):
        np.testing.assert_allclose(np.stack(value), g[key], atol=1e-12, rtol=1e-12, err_msg=key)
    d = scene.detector
    for key, value in (("det_frame", d.frame), ("det_view", d.view), ("det_person", d.person_id),
                       ("det_id", scene.det_id), ("det_present", np.packbits(d.present, axis=-1))):
        np.testing.assert_array_equal(value, g[key], err_msg=key)
    first = g["det_keypoints_px_first50"]
    np.testing.assert_allclose(d.keypoints_px[: len(first)], first, atol=1e-3, rtol=0)
    np.testing.assert_allclose(scene.keypoints_world_m[:, 0], g["keypoints_world_m_frame0"], atol=2e-5, rtol=0)
    clocks = scene.view_clocks
    assert (clocks["fps"] == config.fps).all() and (clocks["time_offset_s"] == 0).all()
    assert (clocks["first_frame"] == 0).all() and (clocks["num_frames"] == config.num_frames).all()


def test_fold_radius_and_inverse_of_k1_k2_lenses():
    rng = np.random.default_rng(0)
    r = np.linspace(0.0, 4.0, 400_001)
    for k1, k2 in [(-0.3, 0.1), (-0.35, 0.07), (-0.2, -0.05), (0.1, -0.02), (-0.4, 0.0), (-0.3, 0.02), (0.05, 0.0)]:
        slope = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4
        folds = np.nonzero(slope <= 0.0)[0]
        expected = r[folds[0]] if len(folds) else np.inf
        assert fold_radius(k1, k2) == pytest.approx(expected, abs=2e-5), (k1, k2)
        top = min(fold_radius(k1, k2), 3.0)
        radius = rng.uniform(0.0, top * 0.999, 200)
        back = undistorted_radius(distorted_radius(radius, k1, k2), np.full(200, k1), np.full(200, k2))
        np.testing.assert_allclose(back, radius, atol=1e-9)
    # the action camera's lens never folds: k2 turns it outwards again first
    assert fold_radius(-0.3, 0.1) == np.inf
    assert fold_radius(-0.3, 0.0) == pytest.approx(1.0 / np.sqrt(0.9))


def test_action_cam_detections_follow_the_full_lens_like_opencv(body_model):
    config = preset("action_cam", noise=DetectorNoise.none(), num_frames=8, focal_aspect_range=(0.98, 1.02), area_fill=1.2,
                    principal_point_offset_max_frac=0.05)
    scene = generate_scene(config, body_model, sequence="action")
    k = np.stack([c.distortion for c in scene.rig])
    assert np.all((k[:, 0] >= -0.35) & (k[:, 0] <= -0.25) & (k[:, 1] >= 0.07) & (k[:, 1] <= 0.13))
    assert not k[:, 2:].any()
    np.testing.assert_allclose(np.stack(scene.cameras.sort_values("view")["distortion"]), k)
    for c in scene.rig:
        assert 0.98 <= c.K[1, 1] / c.K[0, 0] <= 1.02 and c.K[1, 1] != c.K[0, 0]
        assert abs(c.K[0, 2] - c.width_px / 2.0) <= 0.05 * c.width_px + 1e-9
        assert abs(c.K[1, 2] - c.height_px / 2.0) <= 0.05 * c.height_px + 1e-9
    d = scene.detector
    rows = np.nonzero(d.person_id >= 0)[0]
    assert len(rows) > 30
    largest_shift_px = 0.0
    for n in rows:
        camera = scene.rig[d.view[n]]
        expected = _project_cv2(camera, scene.keypoints_world_m[d.person_id[n], d.frame[n]])
        present = d.present[n]
        np.testing.assert_allclose(d.keypoints_px[n][present], expected[present], atol=1e-6)
        k1_only = camera.distortion * np.array([1.0, 0.0, 0.0, 0.0, 0.0])
        plain = _project_cv2(Camera(camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m, camera.width_px,
                                    camera.height_px, k1_only), scene.keypoints_world_m[d.person_id[n], d.frame[n]])
        largest_shift_px = max(largest_shift_px, float(np.abs(plain - expected)[present].max()))
    assert largest_shift_px > 5.0  # k2 matters: it is not a k1-only projection


def test_action_cam_fields_of_view_before_the_principal_point_moves(body_model):
    scene = generate_scene(preset("action_cam", num_frames=2), body_model, sequence="fov")
    for c in scene.rig:
        half = undistorted_radius(np.array([c.width_px / 2.0 / c.K[0, 0]]), c.distortion[0], c.distortion[1])
        assert 100.0 - 1e-6 <= np.degrees(2.0 * np.arctan(half[0])) <= 120.0 + 1e-6
        assert c.K[0, 2] == c.width_px / 2.0


def test_a_folding_k2_lens_never_folds_far_points_into_the_image(tiny_scene):
    # k1 = -0.2, k2 = -0.05 folds at r = 1.06 (normalised) and maps 1.6 back to 0.26: a person 1.6 depths off the axis
    # would land near the image centre. The detector must not see them there
    lens = np.array([-0.2, -0.05, 0.0, 0.0, 0.0])
    fold = fold_radius(-0.2, -0.05)
    assert 1.0 < fold < 1.1
    person = tiny_scene.keypoints_world_m[:1, :1].copy()
    person[..., 0] += 1.6 * 5.0 - person[..., 0].mean()
    person[..., 1] -= person[..., 1].mean()
    K = np.array([[500.0, 0.0, 960.0], [0.0, 500.0, 540.0], [0.0, 0.0, 1.0]])
    R = look_at(np.array([0.0, -5.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    pinhole = Camera.from_center(K, R, np.array([0.0, -5.0, 1.0]), 1920, 1080)
    folding = Camera(pinhole.K, pinhole.R_cam_from_world, pinhole.t_cam_from_world_m, 1920, 1080, lens)
    folded = _project_cv2(folding, person[0, 0])
    assert np.all((folded[:, 0] > 0) & (folded[:, 0] < 1920))  # where the folding polynomial would put them
    out = simulate_detections(person, tiny_scene.height_m[:1], [folding], DetectorNoise.none(),
                              np.random.default_rng(0))
    assert not out.in_image.any() and not out.detected.any()


@pytest.mark.parametrize(
    ("changes", "field", "allowed"),
    [
        ({"distortion_k2_range": (-0.6, 0.0)}, "distortion_k2_range", "[-0.5, 0.5]"),
        ({"distortion_k2_range": (0.2, 0.1)}, "distortion_k2_range", "min <= max"),
        ({"distortion_k1_range": (-0.4, -0.3), "distortion_k2_range": (-0.1, 0.0), "focal_range_px": (500.0, 600.0)},
         "distortion_k2_range", "folds inside the image"),
        ({"focal_aspect_range": (0.9, 1.0)}, "focal_aspect_range", "[0.98, 1.02]"),
        ({"principal_point_offset_max_frac": 0.2}, "principal_point_offset_max_frac", "[0, 0.1]"),
        ({"principal_point_offset_max_frac": 0.05, "principal_point_offset_px": 20.0},
         "principal_point_offset_max_frac", "one of them"),
        ({"horizontal_fov_range_deg": (20.0, 60.0)}, "horizontal_fov_range_deg", "[30.0, 160.0]"),
        ({"horizontal_fov_range_deg": (100.0, 150.0), "distortion_k1_range": (-0.3, -0.3)}, "horizontal_fov_range_deg",
         "folds at"),
        ({"horizontal_fov_range_deg": (60.0, 90.0), "rig": "h36m", "num_views": 4}, "horizontal_fov_range_deg",
         "must be None for rig 'h36m'"),
        ({"time_offset_range_s": (-3.0, 1.0)}, "time_offset_range_s", "[-2.0, 2.0]"),
        ({"time_offset_range_s": 1.0}, "time_offset_range_s", "(min, max)"),
        ({"view_fps_choices": ()}, "view_fps_choices", "1 to 8 frame rates"),
        ({"view_fps_choices": (30.0, 0.0)}, "view_fps_choices", "[1, 1000]"),
        ({"view_fps_choices": 30.0}, "view_fps_choices", "1 to 8 frame rates"),
    ],
)
def test_consumer_options_reject_bad_values_naming_the_field(changes, field, allowed):
    with pytest.raises(ValueError) as info:
        SceneConfig(**changes)
    message = str(info.value)
    assert f"SceneConfig.{field}" in message and allowed in message and "\n" not in message


def test_consumer_options_default_to_todays_scenes():
    config = SceneConfig()
    assert config.distortion_k2_range == (0.0, 0.0) and config.focal_aspect_range == (1.0, 1.0)
    assert config.principal_point_offset_max_frac == 0.0 and config.horizontal_fov_range_deg is None
    assert config.time_offset_range_s == (0.0, 0.0) and config.view_fps_choices is None and not config.unsynced
    unsynced = SceneConfig(view_fps_choices=[25, 30, 50, 60], time_offset_range_s=[-2, 2])
    assert unsynced.view_fps_choices == (25.0, 30.0, 50.0, 60.0) and unsynced.time_offset_range_s == (-2.0, 2.0)
    assert unsynced.unsynced and hash(unsynced) == hash(unsynced.replace())


@pytest.fixture(scope="module")
def unsynced_scene(body_model):
    config = preset("phone", noise=DetectorNoise.none(), num_frames=24, view_fps_choices=(25.0, 30.0, 50.0, 60.0),
                    seed=12)
    return generate_scene(config, body_model, sequence="unsynced")


def test_unsynced_views_see_the_truth_interpolated_at_their_own_times(unsynced_scene):
    scene = unsynced_scene
    clocks = scene.view_clocks
    assert clocks.loc[0, "time_offset_s"] == 0.0
    offsets = clocks["time_offset_s"].to_numpy()[1:]
    assert np.all(np.abs(offsets) <= 2.0) and np.any(offsets != 0.0)
    assert set(clocks["fps"]) <= {25.0, 30.0, 50.0, 60.0}
    truth = scene.keypoints_world_m  # (P, F_ref, 23, 3) on the reference clock
    reference = np.arange(truth.shape[1]) / scene.config.fps
    d = scene.detector
    rows = np.nonzero(d.person_id >= 0)[0]
    checked_between = 0
    for n in rows[:: max(1, len(rows) // 400)]:
        v, p, frame = d.view[n], d.person_id[n], d.frame[n]
        t = frame / clocks.loc[v, "fps"] + clocks.loc[v, "time_offset_s"]
        assert 0.0 <= t <= reference[-1]
        points = np.stack([[np.interp(t, reference, truth[p, :, j, a]) for a in range(3)] for j in range(NUM_JOINTS)])
        expected = _project_cv2(scene.rig[v], points)
        np.testing.assert_allclose(d.keypoints_px[n][d.present[n]], expected[d.present[n]], atol=1e-6)
        checked_between += not np.isclose(t * scene.config.fps, np.round(t * scene.config.fps))
    assert checked_between > 50  # most times fall between the reference frames


def test_unsynced_views_number_their_own_frames_and_cover_the_scene(unsynced_scene):
    scene = unsynced_scene
    config = scene.config
    clocks = scene.view_clocks
    det = scene.detections
    assert scene.keypoints_world_m.shape[1] == scene.summary()["reference_frames"] >= config.num_frames
    assert scene.poses3d["frame"].max() == scene.keypoints_world_m.shape[1] - 1  # ground truth on the reference clock
    start_s = max(0.0, clocks["time_offset_s"].max())  # every view films from when the last camera started
    assert start_s > 0.0
    for row in clocks.itertuples():
        frames = det.loc[det["view"] == row.view, "frame"]
        first = int(np.ceil((start_s - row.time_offset_s) * row.fps - 1e-9))
        assert row.first_frame == first and frames.min() >= first  # nothing before the common span
        assert start_s <= first / row.fps + row.time_offset_s < start_s + 1.0 / row.fps
        assert row.num_frames == round(config.duration_s * row.fps)
        assert frames.nunique() >= 0.9 * row.num_frames  # the whole duration, at the view's own rate
        assert frames.max() <= row.last_frame
    # the associations hold every detection of the detections table, keyed by the views' own frames
    keys = ["frame", "view", "det_id"]
    detections = det[keys].drop_duplicates()
    merged = detections.merge(scene.associations, on=keys, how="left", indicator=True)
    assert (merged["_merge"] == "both").all()
    truth = pd.DataFrame({"frame": scene.detector.frame, "view": scene.detector.view, "det_id": scene.det_id,
                          "person": scene.detector.person_id})
    joined = scene.associations.merge(truth, on=keys)
    assert len(joined) == len(scene.associations) and (joined["person_id"] == joined["person"]).all()


def test_unsynced_scenes_keep_people_and_cameras_of_the_seed(body_model):
    base = preset("tiny", num_frames=10, seed=3)
    synced = generate_scene(base, body_model, sequence="a")
    unsynced = generate_scene(base.replace(time_offset_range_s=(-0.5, 0.5)), body_model, sequence="b")
    np.testing.assert_array_equal(synced.phenotypes, unsynced.phenotypes)
    for a, b in zip(synced.rig, unsynced.rig):
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.t_cam_from_world_m, b.t_cam_from_world_m)


def test_oracle_synchronisation_moves_frames_to_the_reference_clock():
    detections = pd.DataFrame({"sequence": "s", "frame": [0, 1, 2, 3, 4, 0, 1, 2], "view": [1] * 5 + [2] * 3,
                               "det_id": 0, "joint": "nose", "x_px": 0.0, "y_px": 0.0, "score": 1.0})
    # view 1 at 60 fps started 0.5 s after the reference (30 fps): its frame n is reference frame 15 + n / 2;
    # view 2 at 30 fps started 0.1 s before it: its frame n is reference frame n - 3 (frames 0-2 precede the reference)
    moved = to_reference_frames(detections, np.array([30.0, 60.0, 30.0]), np.array([0.0, 0.5, -0.1]), 30.0)
    assert moved[moved["view"] == 1]["frame"].tolist() == [15, 16, 17]
    assert moved[moved["view"] == 2].empty


def test_presets_of_consumer_rigs_generate_in_seconds(body_model):
    import time

    for name in ("phone", "action_cam"):
        started = time.perf_counter()
        scene = generate_scene(preset(name), body_model, sequence=name)
        assert time.perf_counter() - started < 20.0
        assert len(scene.detections) > 1000
    phone = preset("phone")
    assert phone.image_size_px == (1080, 1920) and phone.unsynced and max(map(abs, phone.distortion_k1_range)) <= 0.1
