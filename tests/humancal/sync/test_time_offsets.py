"""Time offsets of unsynchronised views from the people's motion: exact to the frame on synthetic scenes shifted by
known frames, refused (ambiguous) when nobody moves, and the detections moved to view 0's clock."""

import numpy as np
import pandas as pd
import pytest

from humancal.sync import SyncConfig, apply_time_offsets, estimate_time_offsets, link_view_tracks
from humancal.sync.capture import synchronise_views
from humancal.synthetic.clocks import started_by_hand


@pytest.fixture(scope="module")
def lifter():
    from humancal.lifter import load_lifter, shipped_checkpoint

    return load_lifter(shipped_checkpoint())


@pytest.fixture(scope="module")
def walking_scene(body_model):
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_views=7, num_people=4, num_frames=351, seed=109), body_model,
                          sequence="walk")


def test_integer_frame_offsets_are_found_exactly(walking_scene, lifter):
    starts = np.array([20, 0, 45, 33, 7, 60, 12])
    detections = started_by_hand(walking_scene.detections, starts, 291)
    offsets = estimate_time_offsets(detections, 30.0, lifter=lifter)
    truth = starts - starts[0]
    assert offsets.status[0] == "ok" and offsets.offset_s[0] == 0.0
    assert all(s in ("ok", "unchecked") for s in offsets.status), offsets.status
    np.testing.assert_array_equal(np.round(offsets.offset_frames), truth)
    assert np.abs(offsets.offset_frames - truth).max() < 0.5
    np.testing.assert_allclose(offsets.offset_s, offsets.offset_frames / 30.0)
    assert (offsets.confidence[offsets.confidence > 0] >= SyncConfig().min_margin).all()


def test_applied_offsets_give_back_the_synchronised_detections(walking_scene, lifter):
    starts = np.array([10, 0, 25, 3, 17, 40, 31])
    shifted = started_by_hand(walking_scene.detections, starts, 291)
    offsets = estimate_time_offsets(shifted, 30.0, lifter=lifter)
    applied = apply_time_offsets(shifted, np.round(offsets.offset_frames) / 30.0, 30.0)
    # on view 0's clock, view v's frame n is the scene's frame n + starts[0]: the rows of the original scene
    expected = started_by_hand(walking_scene.detections, np.full(7, starts[0]), 291)
    expected = expected[expected["frame"] <= shifted.loc[shifted["view"] == 0, "frame"].max()]
    got = applied.detections.merge(expected, on=["sequence", "frame", "view", "det_id", "joint"], how="outer",
                                   indicator=True)
    both = got["_merge"] == "both"
    assert (got["_merge"] != "left_only").all()  # every row moved lands on the scene's own frame
    assert both.sum() > 0.85 * len(expected)  # the rest: frames a view did not film
    np.testing.assert_array_equal(got.loc[both, "x_px_x"], got.loc[both, "x_px_y"])
    assert applied.residual_frames.max() < 1e-6


def test_people_standing_still_are_ambiguous_never_ok(body_model, lifter):
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=4, num_people=3, num_frames=150, seed=4), body_model,
                           sequence="still")
    # every person frozen in their first detected pose in each view (nobody moves; the detector's jitter stays)
    d = scene.detections.copy()
    rng = np.random.default_rng(0)
    first = d[d["frame"] == d["frame"].min()]
    frozen = [first.assign(frame=f) for f in range(150)]
    still = pd.concat(frozen, ignore_index=True)
    still["x_px"] += rng.normal(0, 1.5, len(still))
    still["y_px"] += rng.normal(0, 1.5, len(still))
    offsets = estimate_time_offsets(still, 30.0, lifter=lifter)
    assert offsets.status[1:] == ("ambiguous",) * 3, offsets.status
    assert np.isnan(offsets.offset_s[1:]).all()
    with pytest.raises(ValueError, match=r"view 1 \(b\).*ambiguous.*--time-offsets b=SECONDS"):
        synchronise_views(still, ["a", "b", "c", "d"], fps=30.0, view_fps=(), unsynced=True, time_offsets_s=(),
                          option_names={"view_fps": "--fps", "time_offsets": "--time-offsets"},
                          lifter_factory=lambda: lifter)


def test_offsets_on_the_generators_unsynchronised_clocks(body_model, lifter):
    from humancal.synthetic import SceneConfig, generate_scene, preset

    if "time_offset_range_s" not in SceneConfig.__dataclass_fields__:
        pytest.skip("the synthetic generator has no time offsets yet")
    scene = generate_scene(preset("demo", num_views=6, num_people=4, num_frames=300, seed=113,
                                  time_offset_range_s=(-1.5, 1.5)), body_model, sequence="clocks")
    truth = scene.clocks.time_offset_s * 30.0
    offsets = estimate_time_offsets(scene.detections, scene.clocks.fps, lifter=lifter)
    used = np.array([s == "ok" for s in offsets.status])  # what synchronise_views accepts
    assert used.sum() >= 4  # view 0 and most others cross-checked
    np.testing.assert_array_equal(np.round(offsets.offset_frames[used]), np.round(truth[used]))


# --- applying offsets -----------------------------------------------------------------------------------------------


def _table(rows):
    return pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"]
                        ).astype({"frame": "int32", "view": "int32", "det_id": "int32"})


def test_apply_renumbers_integer_offsets_and_drops_frames_outside_view_0():
    rows = [("s", f, v, 0, "nose", float(f), float(v), 0.9) for v in range(2) for f in range(10)]
    out = apply_time_offsets(_table(rows), [0.0, 3 / 30], 30.0)
    v1 = out.detections[out.detections["view"] == 1]
    assert v1["frame"].tolist() == list(range(3, 10))  # view 1's frame n is view 0's n + 3; 7..9 fall past frame 9
    assert v1["x_px"].tolist() == [float(f) for f in range(7)]
    assert out.dropped_frames.tolist() == [0, 3]
    assert out.detections["frame"].dtype == np.int32
    pd.testing.assert_frame_equal(out.detections[out.detections["view"] == 0].reset_index(drop=True),
                                  _table(rows[:10]))


def test_apply_rounds_sub_frame_offsets_and_reports_the_remainder():
    rows = [("s", f, v, 0, "nose", float(f), 0.0, 0.9) for v in range(2) for f in range(10)]
    out = apply_time_offsets(_table(rows), [0.0, -2.3 / 30], 30.0)
    assert out.detections.loc[out.detections["view"] == 1, "frame"].tolist() == list(range(8))
    np.testing.assert_allclose(out.residual_frames, [0.0, 0.3], atol=1e-9)


def test_apply_a_faster_view_keeps_the_nearest_frame_per_reference_frame():
    rows = [("s", f, 0, 0, "nose", float(f), 0.0, 0.9) for f in range(10)]
    rows += [("s", f, 1, 0, "nose", float(f), 0.0, 0.9) for f in range(20)]
    out = apply_time_offsets(_table(rows), [0.0, 0.0], [30.0, 60.0])
    v1 = out.detections[out.detections["view"] == 1]
    assert v1["frame"].tolist() == list(range(10))
    assert v1["x_px"].tolist() == [2.0 * f for f in range(10)]  # 60 fps frame 2n is at 30 fps frame n exactly
    assert out.dropped_frames[1] == 10


def test_bad_offsets_are_refused():
    rows = [("s", 0, v, 0, "nose", 1.0, 1.0, 0.9) for v in range(3)]
    with pytest.raises(ValueError, match="one offset per view"):
        apply_time_offsets(_table(rows), [0.0, 1.0], 30.0)
    with pytest.raises(ValueError, match="finite"):
        apply_time_offsets(_table(rows), [0.0, np.nan, 0.0], 30.0)
    with pytest.raises(ValueError, match="positive frame rates"):
        apply_time_offsets(_table(rows), [0.0, 0.0, 0.0], [30.0, 0.0, 30.0])
    with pytest.raises(ValueError, match="max_offset_s"):
        SyncConfig(max_offset_s=0)


def test_tracks_follow_each_person_in_a_view(walking_scene):
    from humancal.tables.detections import detections_to_dense

    dense = detections_to_dense(walking_scene.detections)
    track = link_view_tracks(dense, 0)
    truth = walking_scene.associations.set_index(["frame", "view", "det_id"])["person_id"].reindex(
        pd.MultiIndex.from_arrays([dense.frame, dense.view, dense.det_id])).to_numpy()
    mine = (dense.view == 0) & (track >= 0) & (truth >= 0)
    # a track is one person: its detections are that person's (false positives and rare switches aside)
    purity = [np.bincount(truth[mine & (track == t)]).max() / (mine & (track == t)).sum()
              for t in np.unique(track[mine])]
    assert np.median(purity) == 1.0
    assert np.mean(purity) > 0.95


def test_image_signal_without_a_lifter_finds_walking_offsets(walking_scene):
    """``signal="2d"`` (no lifter) runs: joint angles of 2D keypoints are angles in the image plane. It places fewer
    views than the lifted signal (``SyncConfig.signal``), and no closer (a view 2.2 frames off here, with offsets up to
    60 frames); the cameras' check is what makes them exact (:mod:`humancal.sync.with_cameras`)."""
    starts = np.array([20, 0, 45, 33, 7, 60, 12])
    detections = started_by_hand(walking_scene.detections, starts, 291)
    offsets = estimate_time_offsets(detections, 30.0, config=SyncConfig(signal="2d", fine_samples=0))
    truth = starts - starts[0]
    placed = np.array([s != "ambiguous" for s in offsets.status])
    assert placed.sum() >= 3, offsets.status
    assert np.abs(offsets.offset_frames[placed] - truth[placed]).max() < 3


def test_tentative_offsets_for_views_the_motion_leaves_ambiguous(body_model, lifter):
    """Seated people (scene 1 of ``scripts/sync_sweep.py --seed 0``): every pair's correlation peaks near the truth
    but none clearly, so every view but the reference is ambiguous; the tentative offsets from all the peaks
    together are within a few frames (for the cameras to check, never to be used as they are)."""
    from humancal.sync import tentative_offsets_s
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_views=7, num_people=3, num_frames=301, seed=1001, behaviour="seated"),
                           body_model, sequence="sync_1")
    starts = np.array([2, 8, 50, 57, 15, 19, 53])
    estimate = estimate_time_offsets(started_by_hand(scene.detections, starts, 241), 30.0, lifter=lifter)
    assert estimate.ambiguous_views() == [1, 2, 3, 4, 5, 6], estimate.status
    tentative = tentative_offsets_s(estimate) * 30.0
    assert tentative[0] == 0 and np.isfinite(tentative).all()
    assert np.abs(tentative - (starts - starts[0])).max() < 3, tentative
