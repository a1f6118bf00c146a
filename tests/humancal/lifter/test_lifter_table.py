"""The lifted_detections table, the held-out split and report."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.keypoints import NUM_JOINTS
from humancal.lifter import (
    HELD_OUT_CMU_SUBJECTS,
    held_out_report,
    lift_detections,
    lift_detections_table,
    lifted_from_table,
    load_lifter,
    split_held_out,
)
from humancal.tables.detections import detections_to_dense
from humancal.tables.schemas import validate_table


@pytest.fixture(scope="module")
def scene(body_model):
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("tiny"), body_model, sequence="tiny")


def test_table_round_trips_the_lifted_poses(tiny_training, scene):
    lifter = load_lifter(tiny_training[0])
    table = validate_table(lift_detections_table(lifter, scene.detections, "synthetic__tiny"), "lifted_detections")
    dense = detections_to_dense(scene.detections)
    assert len(table) == NUM_JOINTS * len(dense)
    back_dense, back = lifted_from_table(table.sample(frac=1.0, random_state=0))  # row order does not matter
    direct = lift_detections(lifter, dense.keypoints_px, dense.scores)
    np.testing.assert_array_equal(back_dense.frame, dense.frame)
    np.testing.assert_array_equal(back_dense.scores, dense.scores)
    present = dense.scores > 0
    np.testing.assert_allclose(back_dense.keypoints_px[present], dense.keypoints_px[present])
    assert np.isnan(back_dense.keypoints_px[~present]).all()
    np.testing.assert_array_equal(back.valid, direct.valid)
    np.testing.assert_allclose(back.joints_cam_m[back.valid], direct.joints_cam_m[direct.valid])
    np.testing.assert_allclose(back.height_m[back.valid], direct.height_m[direct.valid])
    np.testing.assert_allclose(back.box_centre_px, direct.box_centre_px)
    assert back.frame == "crop"


def test_table_needs_each_joint_once(tiny_training, scene):
    table = lift_detections_table(load_lifter(tiny_training[0]), scene.detections, "s")
    with pytest.raises(ValueError, match="multiple of 23"):
        lifted_from_table(table.iloc[1:])
    twice = table.copy()
    twice.loc[twice.index[1], "joint"] = twice["joint"].iloc[0]  # nose twice, left_eye missing
    with pytest.raises(ValueError, match="each of the 23 canonical joints once"):
        lifted_from_table(twice)


def test_held_out_split_and_report(tiny_training, motion_clips):
    clips = [("02" if i == 4 else "14" if i == 5 else s, kp) for i, (s, kp) in enumerate(motion_clips)]
    train, val = split_held_out(clips)
    assert {s for s, _ in val} == set(HELD_OUT_CMU_SUBJECTS) and len(train) == 4
    with pytest.raises(ValueError, match="no training or no held-out"):
        split_held_out(motion_clips)
    report = held_out_report(load_lifter(tiny_training[0]), val, num_samples=400)
    assert report.loc["all", "num_samples"] == 400
    assert report["share_pct"].loc["all"] == 100.0
    assert (report["pa_mpjpe_mm"] <= report["mpjpe_mm"]).all()
