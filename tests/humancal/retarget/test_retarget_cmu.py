"""Real CMU clips (2 s of walking and running, subject 02): small residuals and a plausible body (skip without data)."""

import numpy as np
import pytest
import roma
import torch

from humancal.keypoints import JOINT_INDEX
from humancal.retarget import RetargetConfig, clips_to_motions_table, residual_summary, retarget_clips


@pytest.fixture(scope="module")
def retargeted(body_model, cmu_clips):
    return retarget_clips(cmu_clips, body_model, RetargetConfig.tiny())


def test_cmu_residuals_are_small(retargeted):
    summary = residual_summary(retargeted)
    assert list(summary["clip"]) == ["02_01", "02_03"]
    assert list(summary["frames"]) == [60, 42]  # 240 frames at 120 fps -> 60 at 30 fps; the run is shorter
    assert (summary["median_mm"] <= 30.0).all(), summary  # the target; measured about 2 mm
    assert (summary["p95_mm"] <= 60.0).all(), summary
    assert len(clips_to_motions_table(retargeted)) == 102
    np.testing.assert_array_equal(retargeted[0].phenotypes, retargeted[1].phenotypes)  # one shape per subject


def test_cmu_poses_are_plausible(body_model, retargeted):
    """Guards against fits that match the points with folded bones (a neck bent down and the head turned back)."""
    walk = retargeted[0]
    rotations = torch.tensor(walk.bone_rotmats_local)
    angles_deg = torch.rad2deg(roma.rotmat_to_rotvec(rotations).norm(dim=-1)).numpy()
    non_root = angles_deg[:, 1:]
    assert np.percentile(non_root, 99) < 100.0, dict(zip(body_model.posed_bones[1:], non_root.max(0).round()))
    for bone in ("head", "neck01", "spine01", "spine03", "spine05", "foot.L", "wrist.R"):
        assert np.median(angles_deg[:, body_model.posed_bones.index(bone)]) < 35.0, bone
    up = rotations[:, 0, 2, 2].numpy()  # z component of the pelvis' up axis
    assert up.min() > 0.9
    # Knees flex (about +x in the local-ref axes), never hyper-extend by much.
    knee = roma.rotmat_to_rotvec(rotations[:, body_model.posed_bones.index("lowerleg01.L")]).numpy()
    assert np.median(knee[:, 0]) > 0.1 and knee[:, 0].min() > -0.15
    # The feet stay on the floor: the lowest foot keypoint of each frame is within a few cm of z = 0.
    feet = [JOINT_INDEX[n] for n in ("left_heel", "right_heel", "left_big_toe", "right_big_toe")]
    lowest = walk.keypoints_world_m[:, feet, 2].min(axis=1)
    assert np.abs(np.median(lowest)) < 0.05
