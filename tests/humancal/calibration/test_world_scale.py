"""The world's scale from the people's limbs: a rig scaled by any factor is brought back to the reference adult's."""

import numpy as np

from humancal.calibration.world_scale import REFERENCE_LIMB_SUM_M, SCALE_LIMBS, limb_sums_m, people_scale_factor


def test_limb_sums_and_the_factor_that_restores_the_reference(ring_scene):
    people = ring_scene.keypoints_world_m.reshape(-1, 23, 3)  # every person in every frame
    true = limb_sums_m(people)
    assert np.all((true > 2.0) & (true < 3.2))  # adults: 1.5-1.95 m tall
    a, b = np.array(SCALE_LIMBS).T
    limbs = np.median(np.linalg.norm(people[:, a] - people[:, b], axis=-1), axis=0).sum()  # each limb's median
    for scale in (0.5, 1.0, 3.0):
        factor, measured = people_scale_factor(scale * people)
        assert measured == len(people)
        # whatever the rig's scale, the factor brings the people's limbs to the reference's
        np.testing.assert_allclose(factor * scale * limbs, REFERENCE_LIMB_SUM_M, rtol=1e-9)


def test_a_flipped_joint_does_not_lengthen_the_measure(ring_scene):
    people = ring_scene.keypoints_world_m.reshape(-1, 23, 3).copy()
    clean, _ = people_scale_factor(people)
    people[::7, 9] += 0.5  # every seventh person's left wrist half a metre off
    assert abs(people_scale_factor(people)[0] / clean - 1) < 0.01


def test_too_few_people_with_all_limbs_leave_the_scale(ring_scene):
    people = ring_scene.keypoints_world_m[0, :2].copy()
    assert people_scale_factor(people) == (1.0, 2)
    people[:, 7] = np.nan  # a missing elbow: that limb measured nowhere
    assert people_scale_factor(np.repeat(people, 3, axis=0)) == (1.0, 0)
