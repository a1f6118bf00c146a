import numpy as np
import pytest

from humancal.fitting import FittedMotions


def _motions(P=2, T=6, seed=0):
    rng = np.random.default_rng(seed)
    rot = np.tile(np.eye(3), (P, T, 22, 1, 1))
    present = np.ones((P, T), bool)
    present[1, :2] = False  # person 1 arrives at the third frame
    return FittedMotions(person_ids=np.array([3, 7]), frames=np.arange(10, 10 + T), present=present,
                         phenotypes=rng.uniform(0, 1, (P, 6)), bone_rotmats_local=rot,
                         root_translation_m=rng.normal(size=(P, T, 3)),
                         keypoints_world_m=rng.normal(size=(P, T, 23, 3)), fps=25.0)


def test_table_round_trip_keeps_present_rows_only():
    motions = _motions()
    table = motions.to_table("s")
    assert len(table) == motions.present.sum()
    back = FittedMotions.from_table(table, fps=25.0)
    assert np.array_equal(back.person_ids, motions.person_ids) and np.array_equal(back.frames, motions.frames)
    assert np.array_equal(back.present, motions.present)
    keep = motions.present
    np.testing.assert_allclose(back.keypoints_world_m[keep], motions.keypoints_world_m[keep])
    np.testing.assert_allclose(back.root_translation_m[keep], motions.root_translation_m[keep])
    np.testing.assert_allclose(back.phenotypes, motions.phenotypes)
    one = motions.person(7)
    assert one.num_people == 1 and np.array_equal(one.frames, np.arange(12, 16))


def test_bad_motions_name_the_field():
    motions = _motions()
    with pytest.raises(ValueError, match=r"FittedMotions.root_translation_m must be a numpy array of shape \(2, 6, 3\)"):
        FittedMotions(**{**motions.__dict__, "root_translation_m": np.zeros((2, 5, 3))})
    with pytest.raises(ValueError, match="person_ids must be unique"):
        FittedMotions(**{**motions.__dict__, "person_ids": np.array([3, 3])})
    table = motions.to_table("s")
    with pytest.raises(ValueError, match=r"\(person_id, frame\) appears twice"):
        FittedMotions.from_table(table.iloc[[0, 0]], fps=25.0)
    changed = table.copy()
    changed.at[0, "phenotypes"] = np.zeros(6)
    with pytest.raises(ValueError, match="phenotypes of person 3 change"):
        FittedMotions.from_table(changed, fps=25.0)
