"""Time offsets checked against cameras: a view whose frames are a frame or two off is moved back where its rays
meet the others', the reference view too; a view tens of frames off disagrees; people who stand still leave every
view as it was, and in doubt; the offsets estimated by ``synchronise_views`` come out exact on a walking scene."""

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
    np.testing.assert_allclose(corrected, [0, 0, -1, 0, 2, 0], atol=0.1)  # and no fraction of a frame to speak of
    assert np.abs(check.sub_frame).max() < 0.1


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


def test_people_standing_still_leave_the_offsets_as_they_were_and_in_doubt(walking_scene):
    """No shift moves anyone's rays: every view is flat, none is confirmed, so none is trusted (unsure)."""
    d = walking_scene.detections
    first = d[d["frame"] == d["frame"].min()]
    rng = np.random.default_rng(0)
    still = pd.concat([first.assign(frame=f) for f in range(60)], ignore_index=True)
    still["x_px"] += rng.normal(0, 1.5, len(still))
    still["y_px"] += rng.normal(0, 1.5, len(still))
    check = check_offsets_with_cameras(detections_to_dense(_late(still, {2: 1})), walking_scene.rig)
    np.testing.assert_array_equal(check.shift_frames, np.zeros(6))
    assert set(check.status[1:]) == {"unsure"}, check.status


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
    np.testing.assert_allclose(sync.offset_frames, starts - starts[0], atol=0.1)  # and the fractions ~0
    assert len(sync.camera_check) == 7
    assert all(c.startswith(("agrees", "moved")) for c in sync.camera_check), sync.camera_check
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


def test_the_fraction_of_a_frame_beyond_the_whole_shift_is_measured(body_model):
    """Cameras started at any instant, not on a frame of view 0's: offsets rounded to whole frames leave up to half a
    frame; the fraction the cameras measure takes most of it out."""
    from humancal.sync import apply_time_offsets
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=6, num_people=3, num_frames=150, seed=7,
                                  time_offset_range_s=(-0.5, 0.5)), body_model, sequence="started")
    fps = scene.view_clocks["fps"].to_numpy()
    truth = (scene.view_clocks["time_offset_s"].to_numpy() - scene.view_clocks["time_offset_s"].iloc[0]) * fps[0]
    whole = np.round(truth)
    dense = detections_to_dense(apply_time_offsets(scene.detections, whole / fps[0], fps).detections)
    check = check_offsets_with_cameras(dense, scene.rig)
    assert not check.shift_frames.any(), check.shift_frames
    corrected = check.corrected_offsets_s(whole / fps[0], fps[0]) * fps[0]
    before, after = np.abs(whole - truth)[1:], np.abs(corrected - truth)[1:]
    print(np.round(before, 3), np.round(after, 3), np.round(check.sub_frame, 3), check.status, check.gain)
    assert after.mean() < 0.5 * before.mean() and after.max() < 0.25


def _slipped(detections: pd.DataFrame, views: list[int]) -> pd.DataFrame:
    """The detections with each of ``views`` two frames late in the first half of the capture and on time in the
    second: a clock that slipped (two frames dropped) mid-capture."""
    split = int(np.median(detections["frame"]))
    d = detections[~(detections["view"].isin(views) & detections["frame"].between(split - 2, split - 1))].copy()
    d.loc[d["view"].isin(views) & (d["frame"] < split), "frame"] += 2
    return d


def test_a_view_the_two_halves_place_apart_is_unsure(walking_scene):
    """View 2's clock slipped mid-capture. The whole capture's curve has some minimum, but each half places it
    elsewhere: ``"unsure"``; the other views agree, their halves within a fraction of a frame."""
    check = check_offsets_with_cameras(detections_to_dense(_slipped(walking_scene.detections, [2])),
                                       walking_scene.rig)
    assert check.status[2] == "unsure" and check.spread_frames[2] > 1.5, (check.status, check.spread_frames)
    others = [0, 1, 3, 4, 5]
    assert all(check.status[v] == "agrees" for v in others), check.status
    assert np.nanmax(check.spread_frames[others]) < CameraCheckConfig().max_spread_frames


def test_unsure_views_are_refused_naming_them_and_the_flag():
    from humancal.sync.capture import _refuse_disagreeing
    from humancal.sync.with_cameras import CameraCheck

    check = CameraCheck(shift_frames=np.array([0, 1, 0]), cost_m=np.full((3, 7), 0.02), level_m=np.full(3, 0.02),
                        gain=np.zeros(3), status=("agrees", "moved", "unsure"), sub_frame=np.array([0, 0.2, -0.1]),
                        spread_frames=np.array([0.0, 0.1, 2.4]))
    names = ["front", "left", "right"]
    with pytest.raises(ValueError) as error:
        _refuse_disagreeing(check, np.array([0.0, 0.5, -1.0]), names, {"time_offsets": "--time-offsets"}, 30.0)
    message = str(error.value)
    assert "view 2 (right, -0.997 s?)" in message and "2.4 frames apart" in message, message
    assert "--time-offsets right=SECONDS" in message and "left" not in message


def test_when_half_the_views_are_unsure_none_is_trusted(walking_scene):
    """Three of the five views besides the reference slipped: the motion does not fix this capture's clock, and the
    two that agree are unsure too."""
    check = check_offsets_with_cameras(detections_to_dense(_slipped(walking_scene.detections, [1, 2, 4])),
                                       walking_scene.rig)
    assert check.status == ("agrees",) + ("unsure",) * 5, (check.status, check.spread_frames)
    assert (check.spread_frames[[3, 5]] < CameraCheckConfig().max_spread_frames).all(), check.spread_frames


@pytest.mark.slow
def test_seated_people_leave_add_refusing_with_the_offsets_in_doubt(body_model):
    """Seated people (scene 1 of ``scripts/sync_sweep.py --seed 0``): the motion leaves every view ambiguous, the
    tentative offsets go to the cameras, and the two halves of the capture place the views apart: refused, naming
    them and the flag, never stored silently."""
    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=7, num_people=3, num_frames=301, seed=1001, behaviour="seated"),
                           body_model, sequence="sync_1")
    detections = started_by_hand(scene.detections, np.array([2, 8, 50, 57, 15, 19, 53]), 241)
    lifter = load_lifter(shipped_checkpoint())
    with pytest.raises(ValueError, match="cannot fix the time offset to the frame") as error:
        synchronise_views(detections, [f"cam{v}" for v in range(7)], fps=30.0, view_fps=(), unsynced=True,
                          time_offsets_s=(), option_names={"view_fps": "--fps", "time_offsets": "--time-offsets"},
                          lifter_factory=lambda: lifter,
                          image_sizes_px=[(c.width_px, c.height_px) for c in scene.rig])
    assert "--time-offsets" in str(error.value) and "cam1=SECONDS" in str(error.value)


def test_views_at_other_frame_rates_interpolated_agree_where_their_nearest_frames_are_unsure(body_model):
    """View 0 films at 60 fps, others at 25 or 30: on view 0's clock by their nearest frames, a slower view repeats
    a detection over two or three reference frames, each shift the check tries moves it by a whole frame of its own
    or not at all, and the two halves of the capture place the views about a reference frame apart (unsure, though
    the offsets are the true ones). Interpolated at view 0's frame times, they move smoothly and the check agrees
    with every view within a fraction of a frame."""
    from humancal.sync import apply_time_offsets
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=6, num_people=3, num_frames=240, seed=1, fps=60.0,
                                  time_offset_range_s=(-0.5, 0.5), view_fps_choices=(25.0, 30.0, 60.0),
                                  behaviour="mixed"), body_model, sequence="rates")
    fps = scene.view_clocks["fps"].to_numpy()
    assert fps[0] == 60.0 and (fps[1:] < 60.0).sum() >= 2, fps
    offsets_s = scene.view_clocks["time_offset_s"].to_numpy() - scene.view_clocks["time_offset_s"].iloc[0]
    checks = {interpolate: check_offsets_with_cameras(detections_to_dense(apply_time_offsets(
        scene.detections, offsets_s, fps, interpolate=interpolate).detections), scene.rig)
        for interpolate in (False, True)}
    nearest, blended = checks[False], checks[True]
    assert list(blended.status) == ["agrees"] * 6, (blended.status, blended.spread_frames)
    assert np.abs(blended.shift).max() < 0.25, blended.shift
    assert "unsure" in nearest.status and np.abs(nearest.shift).max() > 0.5, (nearest.status, nearest.shift)
