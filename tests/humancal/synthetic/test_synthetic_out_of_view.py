"""People out of every view for a while (``SceneConfig.out_of_view_spells``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from humancal.synthetic import generate_scene, preset
from humancal.synthetic.config import OUT_OF_VIEW_DURATION_S


@pytest.fixture(scope="module")
def scenes(body_model):
    config = preset("tiny", num_people=3, num_frames=240, seed=4)
    return (generate_scene(config, body_model, sequence="present"),
            generate_scene(config.replace(out_of_view_spells=1.0), body_model, sequence="away"))


def test_spells_leave_people_undetected_in_every_view(scenes):
    present, away = scenes
    seen_before = present.detector.detected.any(axis=0)  # (P, F)
    seen = away.detector.detected.any(axis=0)
    gone = seen_before & ~seen
    assert gone.sum() > 0.1 * gone.size, "the spells hid almost nothing"
    assert seen.sum() > 0.3 * seen.size, "the spells hid almost everyone"
    # no view sees, nor even has in its image, a person while away
    assert not away.detector.in_image[:, gone].any()
    shortest = int(np.round(OUT_OF_VIEW_DURATION_S[0] * away.config.fps))
    for person in range(gone.shape[0]):
        runs = np.diff(np.flatnonzero(np.diff(np.r_[0, ~seen[person], 0].astype(int)) != 0))[::2]
        inner = runs[1:-1] if len(runs) > 2 else []
        assert all(r >= shortest for r in inner), f"person {person}: a spell shorter than {shortest} frames"
    # the ground truth and every person's identity of the remaining detections are unchanged
    pd.testing.assert_frame_equal(present.poses3d.drop(columns="sequence"), away.poses3d.drop(columns="sequence"))
    truth = away.associations
    assert set(truth["person_id"].unique()) - {-1} == {0, 1, 2}


def test_default_scene_is_unchanged(body_model, scenes):
    present, _ = scenes
    again = generate_scene(present.config.replace(out_of_view_spells=0.0), body_model, sequence="present")
    pd.testing.assert_frame_equal(present.detections, again.detections)


@pytest.mark.parametrize("value", [-0.5, 6.0, float("nan")])
def test_out_of_view_spells_validated(value):
    with pytest.raises(ValueError, match="out_of_view_spells"):
        preset("tiny", out_of_view_spells=value)
