"""Views placed a period of the people's motion off together: the pairs' epipolar geometry finds the group and moves
it back, leaves right offsets alone, and the period comes from the pairs that took the other peak."""

import numpy as np
import pandas as pd
import pytest

from humancal.sync import PairOffset, TimeOffsets, misplaced_period_s, regroup_by_period
from humancal.sync.capture import check_and_regroup

FPS = 30.0
PERIOD_FRAMES = 30  # a second: about a gait cycle


@pytest.fixture(scope="module")
def walking_scene(body_model):
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_views=6, num_people=3, num_frames=150, seed=7), body_model,
                          sequence="walk")


def _started_late(detections: pd.DataFrame, views: list[int], frames: int) -> pd.DataFrame:
    """View ``v``'s frame ``n`` renumbered ``n - frames``: it started ``frames`` frames after the others (its true
    offset is ``+frames / FPS``)."""
    out = detections.copy()
    late = out["view"].isin(views)
    out.loc[late, "frame"] -= frames
    return out[out["frame"] >= 0]


def test_a_group_of_views_a_period_off_is_moved_back(walking_scene):
    group = [2, 4, 5]
    detections = _started_late(walking_scene.detections, group, PERIOD_FRAMES)
    # the offsets as the correlation placed them: the group a period early (at 0 instead of +1 s), consistently
    search = regroup_by_period(detections, np.zeros(6), np.full(6, FPS), PERIOD_FRAMES / FPS)
    np.testing.assert_array_equal(search.shift_periods, [0, 0, 1, 0, 1, 1])
    np.testing.assert_allclose(search.offset_s, np.isin(np.arange(6), group) * PERIOD_FRAMES / FPS)
    assert search.moved == group and search.gain > 0
    # nearly every pair across the groups is best supported at the shift that undoes it, nearly every pair inside
    # at none (a pair whose views share few people supports no shift much)
    right = [int(np.nanargmax(search.support[a, b])) - 2 == int(b in group) - int(a in group)
             for a in range(6) for b in range(a + 1, 6)]
    assert sum(right) >= 12, search.support


def test_right_offsets_are_left_alone(walking_scene):
    detections = _started_late(walking_scene.detections, [3], 12)
    offsets = np.array([0, 0, 0, 12, 0, 0]) / FPS
    search = regroup_by_period(detections, offsets, np.full(6, FPS), PERIOD_FRAMES / FPS)
    np.testing.assert_array_equal(search.shift_periods, np.zeros(6))
    assert search.moved == [] and search.gain == 0.0
    np.testing.assert_allclose(search.offset_s, offsets)


def _estimate(pairs: list[tuple[int, int, float, bool]], V: int = 4) -> TimeOffsets:
    return TimeOffsets(np.zeros(V), np.zeros(V), np.ones(V), ("ok",) * V, np.full(V, FPS),
                       tuple(PairOffset(a, b, lag, 0.5, 0.2, clear) for a, b, lag, clear in pairs))


def test_the_period_is_how_far_the_pairs_that_took_another_peak_miss():
    offsets = np.array([0.0, 0.5, 1.0, -0.2])
    estimate = _estimate([(0, 1, 0.5, True), (0, 2, -0.05, True), (1, 2, -0.52, False), (0, 3, 0.88, True),
                          (1, 3, -2.8, True), (2, 3, -1.2 + 1 / FPS, True)])
    # misses of 1.05, 1.02 (a pair that is not clear counts too), 1.08 and 2.1 s (two periods of 1.05); 0 for the
    # pair that agrees, a frame for (2, 3): under the 5 frames
    assert misplaced_period_s(estimate, offsets) == pytest.approx(1.05)
    # a stray miss (0.4 s) that explains no other is left out: 1.08 and 2.1 s (two of 1.05) make the period
    stray = _estimate([(0, 1, 0.5, True), (0, 2, 1.4, False), (0, 3, 0.88, True), (1, 3, -2.8, True)])
    assert misplaced_period_s(stray, offsets) == pytest.approx(1.065)
    # a lone miss is the period (the search proposes, the cameras decide)
    assert misplaced_period_s(_estimate([(0, 2, 1.4, True)]), offsets) == pytest.approx(0.4)
    agreeing = _estimate([(0, 1, 0.5 + 1 / FPS, True), (1, 3, -0.7 + 2 / FPS, False)])
    assert misplaced_period_s(agreeing, offsets) is None


@pytest.mark.slow
def test_a_capture_whose_cameras_all_disagree_is_regrouped_and_then_agrees(walking_scene):
    """The whole path: cameras calibrated on the offsets with a group a period off disagree; the group moved back,
    cameras calibrated again agree, and the offsets kept are the true ones."""
    from humancal.lifter import load_lifter, shipped_checkpoint

    group = [2, 4, 5]
    detections = _started_late(walking_scene.detections, group, PERIOD_FRAMES)
    sizes = [(c.width_px, c.height_px) for c in walking_scene.rig]
    checked = check_and_regroup(detections, np.zeros(6), np.full(6, FPS), sizes, load_lifter(shipped_checkpoint()),
                                PERIOD_FRAMES / FPS)
    assert checked.first_check is not None and "disagrees" in checked.first_check.status
    assert checked.regrouped and checked.period_search.moved == group
    assert "disagrees" not in checked.check.status
    np.testing.assert_allclose(checked.offset_s, np.isin(np.arange(6), group) * PERIOD_FRAMES / FPS)
