"""Time offsets checked against cameras: a view whose frames are a frame or two off is moved back where its rays
meet the others', the reference view too; a view tens of frames off disagrees; people who stand still leave every
view as it was (flat); the offsets estimated by ``synchronise_views`` come out exact on a walking scene."""

import numpy as np
import pandas as pd
import pytest

from humancal.sync import CameraCheckConfig, check_offsets_with_cameras
from humancal.sync.capture import synchronise_views
from humancal.synthetic.clocks import started_by_hand
from humancal.tables.detections import detections_to_dense


@pytest.fixture(scope="module")
def walking_scene(body_model):
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_views=6, num_people=3, num_frames=120, seed=7), body_model,
                          sequence="walk")


def _late(detections: pd.DataFrame, late_frames: dict[int, int]) -> pd.DataFrame:
    """The detections with view ``v``'s frame ``n`` renumbered ``n + late_frames[v]`` (its frame ``n + k`` then
    shows the instant the others show at ``n``)."""
    out = detections.copy()
    for view, k in late_frames.items():
        out.loc[out["view"] == view, "frame"] += k
    return out


def test_views_a_frame_or_two_off_are_moved_back(walking_scene):
    dense = detections_to_dense(_late(walking_scene.detections, {2: 1, 4: -2}))
    check = check_offsets_with_cameras(dense, walking_scene.rig)
    np.testing.assert_array_equal(check.shift_frames, [0, 0, 1, 0, -2, 0])
    assert check.status == ("agrees", "agrees", "moved", "agrees", "moved", "agrees")
    assert (check.gain[[2, 4]] > CameraCheckConfig().min_gain).all()
    # the offsets the detections were synchronised with, corrected: view v's frame n is at reference n + offset
    corrected = check.corrected_offsets_s(np.zeros(6), 30.0) * 30.0
    np.testing.assert_allclose(corrected, [0, 0, -1, 0, 2, 0])


def test_the_reference_view_off_moves_the_others_relative_to_it(walking_scene):
    dense = detections_to_dense(_late(walking_scene.detections, {0: 1}))
    check = check_offsets_with_cameras(dense, walking_scene.rig)
    np.testing.assert_array_equal(check.shift_frames, [0, -1, -1, -1, -1, -1])


def test_a_view_far_off_disagrees(walking_scene):
    dense = detections_to_dense(_late(walking_scene.detections, {3: 30}))
    check = check_offsets_with_cameras(dense, walking_scene.rig)
    assert check.status[3] == "disagrees", (check.status, check.level_m)
    assert [s for v, s in enumerate(check.status) if v != 3] == ["agrees"] * 5
    assert check.level_m[3] > CameraCheckConfig().max_level_ratio * np.median(check.level_m)


def test_people_standing_still_leave_the_offsets_as_they_were(walking_scene):
    d = walking_scene.detections
    first = d[d["frame"] == d["frame"].min()]
    rng = np.random.default_rng(0)
    still = pd.concat([first.assign(frame=f) for f in range(60)], ignore_index=True)
    still["x_px"] += rng.normal(0, 1.5, len(still))
    still["y_px"] += rng.normal(0, 1.5, len(still))
    check = check_offsets_with_cameras(detections_to_dense(_late(still, {2: 1})), walking_scene.rig)
    np.testing.assert_array_equal(check.shift_frames, np.zeros(6))
    assert set(check.status[1:]) <= {"flat", "agrees"} and check.status[2] == "flat", check.status


def test_bad_rig_is_refused(walking_scene):
    with pytest.raises(ValueError, match="view 5 but the rig has 3 cameras"):
        check_offsets_with_cameras(detections_to_dense(walking_scene.detections), walking_scene.rig[:3])


@pytest.mark.slow
def test_synchronise_views_checks_its_estimate_with_cameras(body_model):
    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset

    # scene 100017 of `scripts/sync_sweep.py --seed 1`: every view's offset cross-checked by the correlation
    scene = generate_scene(preset("demo", num_views=7, num_people=3, num_frames=192, seed=101017, behaviour="mixed"),
                           body_model, sequence="walk")
    starts = np.array([22, 54, 19, 27, 57, 37, 40])
    detections = started_by_hand(scene.detections, starts, 132)
    names = [f"cam{v}" for v in range(7)]
    lifter = load_lifter(shipped_checkpoint())
    _, sync = synchronise_views(detections, names, fps=30.0, view_fps=(), unsynced=True, time_offsets_s=(),
                                option_names={"view_fps": "--fps", "time_offsets": "--time-offsets"},
                                lifter_factory=lambda: lifter,
                                image_sizes_px=[(c.width_px, c.height_px) for c in scene.rig])
    np.testing.assert_allclose(sync.offset_frames, starts - starts[0], atol=1e-6)
    assert len(sync.camera_check) == 7
    assert all(c == "agrees" or c.startswith("moved") for c in sync.camera_check), sync.camera_check
    assert "cameras: " in sync.view_text(1)


def test_offsets_one_pair_of_views_alone_gives_are_refused_without_cameras_to_check_them(body_model):
    """The 7-view scene of ``tests/pipelines/test_capture_cli.py``'s unsynchronised capture: four offsets rest on one
    pair of views each; with no image sizes (no calibration to confirm them) they are refused, the message showing
    each one's estimate and the flag that gives it."""
    import re

    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=7, num_people=4, num_frames=351, seed=109), body_model,
                           sequence="capture")
    starts = np.array([20, 0, 45, 33, 7, 60, 12])
    detections = started_by_hand(scene.detections, starts, 291)
    names = [f"view_{v:02d}" for v in range(7)]
    lifter = load_lifter(shipped_checkpoint())
    with pytest.raises(ValueError, match="one pair of views only, no other pair confirms it") as error:
        synchronise_views(detections, names, fps=30.0, view_fps=(), unsynced=True, time_offsets_s=(),
                          option_names={"view_fps": "--fps", "time_offsets": "--time-offsets"},
                          lifter_factory=lambda: lifter)
    assert "--time-offsets" in str(error.value)
    shown = {int(v): float(t) for v, t in re.findall(r"view (\d) \(view_\d\d, ([-+.\d]+) s\?\)", str(error.value))}
    assert len(shown) >= 1
    for view, seconds in shown.items():
        assert round(seconds * 30) == starts[view] - starts[0], (view, seconds)


def test_a_camera_the_calibration_disagrees_with_cannot_vouch_for_its_offset(walking_scene):
    dense = detections_to_dense(walking_scene.detections)
    verdicts = ["ok", "ok", "disagrees", "ok", "ok", "unchecked"]
    check = check_offsets_with_cameras(dense, walking_scene.rig, camera_verdicts=verdicts)
    assert check.status == ("agrees", "agrees", "disagrees", "agrees", "agrees", "agrees"), check.status


def test_a_view_without_detections_is_unchecked_and_the_others_still_checked(walking_scene):
    d = _late(walking_scene.detections, {2: 1})
    dense = detections_to_dense(d[d["view"] != 4])
    check = check_offsets_with_cameras(dense, walking_scene.rig)
    assert check.status[4] == "unchecked" and np.isnan(check.level_m[4]), check.status
    np.testing.assert_array_equal(check.shift_frames[[0, 1, 2, 3, 5]], [0, 0, 1, 0, 0])
    empty = check_offsets_with_cameras(detections_to_dense(d.iloc[:0]), walking_scene.rig)
    assert empty.status == ("agrees",) + ("unchecked",) * 5 and not empty.shift_frames.any()
