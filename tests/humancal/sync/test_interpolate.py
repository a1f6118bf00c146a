"""Detections interpolated between a view's frames (``humancal.sync.interpolate``, ``apply_time_offsets(...,
interpolate=True)``): exact for people moving at constant speed, left-right flips undone, the nearest frame (and its
remainder) where a track has no frame on the other side."""

import numpy as np
import pandas as pd
import pytest

from humancal.keypoints import CANONICAL_JOINTS, FLIP_INDEX, NUM_JOINTS
from humancal.sync import apply_time_offsets
from humancal.sync.interpolate import view_at_times
from humancal.tables.detections import dense_to_detections, detections_to_dense

_SHAPE = np.random.default_rng(0).uniform(0, 120, size=(NUM_JOINTS, 2))
"""A person's keypoints around their position, pixels (a fixed random figure, every joint distinct)."""

_VELOCITY = np.array([6.0, -2.0])
"""Pixels per second."""


def _person(t_s: float, start_px) -> np.ndarray:
    return np.asarray(start_px) + _SHAPE + _VELOCITY * 30.0 * t_s


def _capture(fps, offsets_s, frames, starts=((100.0, 100.0), (600.0, 300.0)), *, skip=(), flipped=(), drop=()):
    """Detections of people moving at constant speed: view v's frame n at time n / fps_v + offset_v. ``skip``:
    (view, frame) pairs not detected; ``flipped``: (view, frame) pairs detected left-right swapped; ``drop``:
    (view, frame, joint) joints not detected."""
    rows = []
    for v, (rate, offset) in enumerate(zip(fps, offsets_s)):
        for n in range(frames[v]):
            if (v, n) in skip:
                continue
            for d, start in enumerate(starts):
                kp = _person(n / rate + offset, start)
                if (v, n) in flipped:
                    kp = kp[list(FLIP_INDEX)]
                for j, name in enumerate(CANONICAL_JOINTS):
                    if (v, n, j) not in drop:
                        rows.append(("s", n, v, d, name, kp[j, 0], kp[j, 1], 0.9))
    return pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"]
                        ).astype({"frame": "int32", "view": "int32", "det_id": "int32"})


def _keypoints(d: pd.DataFrame, view: int, frame: int, det: int) -> np.ndarray:
    rows = d[(d["view"] == view) & (d["frame"] == frame) & (d["det_id"] == det)]
    kp = np.full((NUM_JOINTS, 2), np.nan)
    index = rows["joint"].map({n: j for j, n in enumerate(CANONICAL_JOINTS)}).to_numpy()
    kp[index] = rows[["x_px", "y_px"]].to_numpy()
    return kp


def test_interpolation_puts_people_moving_at_constant_speed_where_they_were():
    fps, offsets = [30.0, 30.0], [0.0, -2.3 / 30]
    table = _capture(fps, offsets, [20, 20])
    nearest = apply_time_offsets(table, offsets, fps)
    blended = apply_time_offsets(table, offsets, fps, interpolate=True)
    errors = {"nearest": [], "blended": []}
    for m in range(17):  # view 1 films reference frames -2.3 .. 16.7: 0..16 lie between two of its frames
        for d, start in enumerate(((100.0, 100.0), (600.0, 300.0))):
            truth = _person(m / 30.0, start)
            errors["blended"].append(np.abs(_keypoints(blended.detections, 1, m, d) - truth).max())
            errors["nearest"].append(np.abs(_keypoints(nearest.detections, 1, m, d) - truth).max())
    assert max(errors["blended"]) < 1e-9
    np.testing.assert_allclose(errors["nearest"], 0.3 * 6.0, rtol=1e-6)  # 0.3 frame early at 6 px per frame
    assert blended.interpolated[1] == 2 * 17
    assert blended.interpolated[0] == 0
    # reference frame 17 lies past view 1's last frame (19 -> 16.7): the nearest frame, its remainder reported
    np.testing.assert_allclose(blended.residual_frames, [0.0, 0.3], atol=1e-9)


def test_a_faster_view_is_blended_once_per_reference_frame():
    fps, offsets = [30.0, 60.0], [0.0, 0.4 / 30]
    blended = apply_time_offsets(_capture(fps, offsets, [15, 30]), offsets, fps, interpolate=True)
    v1 = blended.detections[blended.detections["view"] == 1]
    assert sorted(v1["frame"].unique()) == list(range(1, 15))
    assert not v1.duplicated(["frame", "det_id", "joint"]).any()
    for m in range(1, 15):
        np.testing.assert_allclose(_keypoints(blended.detections, 1, m, 0), _person(m / 30.0, (100.0, 100.0)),
                                   atol=1e-9)
    assert blended.dropped_frames[1] == 2  # frame 0 lies before reference frame 1's time, 29 after 14's


def test_whole_frame_offsets_are_the_same_renumbering_either_way():
    fps, offsets = [30.0, 30.0], [0.0, 3 / 30]
    table = _capture(fps, offsets, [12, 12])
    nearest = apply_time_offsets(table, offsets, fps).detections
    blended = apply_time_offsets(table, offsets, fps, interpolate=True)
    key = ["frame", "view", "det_id", "joint"]
    pd.testing.assert_frame_equal(blended.detections.sort_values(key).reset_index(drop=True),
                                  nearest.sort_values(key).reset_index(drop=True))
    assert blended.interpolated.tolist() == [0, 0]


def test_a_left_right_flipped_partner_is_flipped_back():
    fps, offsets = [30.0, 30.0], [0.0, -0.4 / 30]
    table = _capture(fps, offsets, [12, 12], flipped={(1, 6)})
    blended = apply_time_offsets(table, offsets, fps, interpolate=True)
    # reference frame 5 is view 1's frame 5.4: frame 5 nearer, its flipped partner 6 flipped back
    np.testing.assert_allclose(_keypoints(blended.detections, 1, 5, 0), _person(5 / 30.0, (100.0, 100.0)), atol=1e-9)
    # reference frame 6 is view 1's 6.4: the nearer frame 6 was flipped, and the blend keeps its left and right
    flipped_truth = _person(6 / 30.0, (100.0, 100.0))[list(FLIP_INDEX)]
    np.testing.assert_allclose(_keypoints(blended.detections, 1, 6, 0), flipped_truth, atol=1e-9)


def test_without_a_frame_on_the_other_side_the_nearest_frame_is_taken():
    fps, offsets = [30.0, 30.0], [0.0, -0.25 / 30]
    table = _capture(fps, offsets, [12, 12], skip={(1, 6)})
    blended = apply_time_offsets(table, offsets, fps, interpolate=True)
    # reference frame 5 is view 1's frame 5.25: frame 6 was missed, so frame 5 as it is, 0.25 frame early
    np.testing.assert_allclose(_keypoints(blended.detections, 1, 5, 0), _person(5 / 30.0 - 0.25 / 30, (100.0, 100.0)),
                               atol=1e-9)
    np.testing.assert_allclose(blended.residual_frames[1], 0.25, atol=1e-9)
    # reference frame 6 is view 1's 6.25, whose nearest frame was missed: nothing
    assert 6 not in set(blended.detections.loc[blended.detections["view"] == 1, "frame"])


def test_a_joint_only_the_farther_frame_has_is_left_out():
    fps, offsets = [30.0, 30.0], [0.0, -0.25 / 30]
    # reference frame 4 is view 1's 4.25: the nose missed in frame 4 (nearer), the left eye missed in frame 5
    table = _capture(fps, offsets, [10, 10], drop={(1, 4, 0), (1, 5, 1)})
    kp = _keypoints(apply_time_offsets(table, offsets, fps, interpolate=True).detections, 1, 4, 0)
    truth = _person(4 / 30.0, (100.0, 100.0))
    assert np.isnan(kp[0]).all()
    np.testing.assert_allclose(kp[1], _person(3.75 / 30.0, (100.0, 100.0))[1], atol=1e-9)  # frame 4 as it is
    np.testing.assert_allclose(kp[2:], truth[2:], atol=1e-9)


def test_view_at_times_rows_carry_their_remainders():
    table = _capture([30.0, 30.0], [0.0, 0.0], [6, 6])
    at = view_at_times(detections_to_dense(table), 1, np.array([0.5, np.nan, 2.0, 5.4]))
    assert sorted(set(at.detections.frame.tolist())) == [0, 2, 3]
    frame3 = at.detections.frame == 3
    np.testing.assert_allclose(at.remainder_frames[frame3], 0.4)  # frame 5 is the track's last
    assert at.interpolated[at.detections.frame == 0].all()
    assert not at.interpolated[at.detections.frame == 2].any()
    np.testing.assert_array_equal(at.used_frames, [0, 1, 2, 5])


def test_dense_to_detections_inverts_detections_to_dense():
    table = _capture([30.0], [0.0], [3], drop={(0, 1, 4)})
    back = dense_to_detections(detections_to_dense(table), "s")
    key = ["frame", "view", "det_id", "joint"]
    pd.testing.assert_frame_equal(back.sort_values(key).reset_index(drop=True),
                                  table.sort_values(key).reset_index(drop=True))


def test_two_sequences_are_refused():
    table = _capture([30.0, 30.0], [0.0, 0.1], [4, 4])
    table.loc[0, "sequence"] = "t"
    with pytest.raises(ValueError, match="one sequence"):
        apply_time_offsets(table, [0.0, 0.1], 30.0, interpolate=True)


def test_a_capture_with_given_offsets_is_interpolated_and_says_so():
    from humancal.sync.capture import synchronise_views

    table = _capture([30.0, 30.0], [0.0, -2.3 / 30], [20, 20])
    names = {"fps": "--fps", "view_fps": "--fps", "unsynced": "--unsynced", "time_offsets": "--time-offsets"}
    detections, sync = synchronise_views(table, ["a", "b"], fps=None, view_fps=(), unsynced=False,
                                         time_offsets_s=(("b", -2.3 / 30),), option_names=names)
    assert sync.interpolated == (0, 34)
    assert "34 detections interpolated between frames" in sync.view_text(1)
    assert "up to 0.30 frame rounded" in sync.view_text(1)  # reference frame 17: view 1's last frame, as it is
    np.testing.assert_allclose(_keypoints(detections, 1, 8, 1),
                               _person(8 / 30.0, (600.0, 300.0)), atol=1e-9)
    _, nearest = synchronise_views(table, ["a", "b"], fps=None, view_fps=(), unsynced=False,
                                   time_offsets_s=(("b", -2.3 / 30),), option_names=names, interpolate=False)
    assert nearest.interpolated == () and "interpolated" not in nearest.view_text(1)


def test_a_view_without_detections_and_an_empty_capture_pass_through():
    table = _capture([30.0, 30.0, 30.0], [0.0, 0.01, 0.02], [6, 6, 6])
    table = table[table["view"] != 1].reset_index(drop=True)
    applied = apply_time_offsets(table, [0.0, 0.01, 0.02], 30.0, interpolate=True)
    assert set(applied.detections["view"]) == {0, 2}
    assert applied.interpolated[1] == 0 and applied.dropped_frames[1] == 0
    empty = apply_time_offsets(table.iloc[:0], [0.0, 0.01, 0.02], 30.0, interpolate=True)
    assert len(empty.detections) == 0 and list(empty.detections.columns) == list(table.columns)
    at = view_at_times(detections_to_dense(table), 1, np.arange(6.0))
    assert len(at.detections) == 0 and len(at.used_frames) == 0
