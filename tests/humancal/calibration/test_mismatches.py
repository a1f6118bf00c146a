"""Detections matched to the wrong person are found after the bundle adjustment and taken out of their groups."""

import numpy as np
import pytest

from humancal.calibration.matching import drop_mismatched_detections
from humancal.calibration.bundle import bundle_adjust


@pytest.fixture(scope="module")
def mismatched(ring_scene, ring_stand_in, ring_true_groups):
    """The ring scene's true groups with, in every 4th group that has one, view 1's detection replaced by that of
    another person of the same frame (a neighbour matched by mistake); returns the problem and a mask of the
    swapped entries of ``np.concatenate(groups)``."""
    d, pid = ring_stand_in.detections, ring_stand_in.person_id
    groups, points = ring_true_groups
    swapped, out = [], []  # swapped: one mask per group
    for k, g in enumerate(groups):
        g, flags = g.copy(), np.zeros(len(g), bool)
        mine = np.flatnonzero(d.view[g] == 1)
        if k % 4 == 0 and len(mine):
            row = g[mine[0]]
            others = np.flatnonzero((d.frame == d.frame[row]) & (d.view == 1) & (pid >= 0) & (pid != pid[row]))
            if len(others):
                g[mine[0]] = others[0]
                flags[mine[0]] = True
        out.append(g)
        swapped.append(flags)
    rig = list(ring_scene.rig)
    return dict(d=d, lifted=ring_stand_in.lifted, groups=out, points=points, swapped=np.concatenate(swapped),
                R=np.stack([c.R_cam_from_world for c in rig]), t=np.stack([c.t_cam_from_world_m for c in rig]),
                f=np.array([c.K[0, 0] for c in rig]), pp=np.stack([c.K[:2, 2] for c in rig]))


def _adjust(p, groups, points):
    f0 = p["f"] * np.array([1.0, 1.1, 0.9, 1.05])
    return bundle_adjust(p["d"], p["lifted"], groups, points, f0, f0, p["pp"], p["R"], p["t"], shape_std_m=0.5,
                         group_scale_std=0.1)


def test_wrong_matches_stand_out_and_are_taken_out(mismatched):
    p = mismatched
    assert p["swapped"].sum() >= 5
    result = _adjust(p, p["groups"], p["points"])
    rows = np.concatenate(p["groups"])
    error = result.detection_error_sigma
    assert error.shape == rows.shape
    is_swapped = p["swapped"]
    # the wrong ones are tens of stds off, the right ones about one
    assert np.nanmin(error[is_swapped]) > 10.0, np.sort(error[is_swapped])
    assert np.nanmedian(error[~is_swapped]) < 2.0 and np.mean(error[~is_swapped] > 10.0) < 0.01
    kept, index, dropped = drop_mismatched_detections(p["groups"], error, 10.0, 0.2)
    swapped_of_group = np.split(is_swapped, np.cumsum([len(g) for g in p["groups"]])[:-1])
    assert dropped >= is_swapped.sum()
    for g, k in zip(kept, index):  # no kept group holds its wrong detection
        assert not np.isin(g, p["groups"][k][swapped_of_group[k]]).any()
    assert all(len(g) >= 2 for g in kept) and len(index) == len(kept)
    again = _adjust(p, kept, p["points"][index])
    assert np.all(np.abs(again.fx_px / p["f"] - 1) < 0.02), again.fx_px / p["f"]
    assert np.nanmax(again.detection_error_sigma) < 10.0


def test_nothing_is_dropped_when_the_rig_itself_is_off():
    groups = [np.array([0, 1]), np.array([2, 3, 4])]
    error = np.array([30.0, 40.0, 1.0, 50.0, 0.5])  # 3 of 5 over the threshold: the rig, not the matches
    kept, index, dropped = drop_mismatched_detections(groups, error, 10.0, 0.2)
    assert dropped == 0 and index.tolist() == [0, 1]
    kept, index, dropped = drop_mismatched_detections(groups, np.array([1.0, 40.0, 1.0, 50.0, 0.5]), 10.0, 0.5)
    # group 0 keeps one detection: dropped as a group; group 1 loses one of three
    assert dropped == 2 and index.tolist() == [1] and kept[0].tolist() == [2, 4]
    with pytest.raises(ValueError, match="error_sigma"):
        drop_mismatched_detections(groups, np.ones(4), 10.0, 0.2)


@pytest.mark.parametrize("change", [dict(mismatch_threshold_sigma=-1.0), dict(mismatch_max_fraction=0.0),
                                    dict(mismatch_rounds=-1)])
def test_mismatch_settings_are_validated(change):
    from humancal.calibration import ExtrinsicsConfig

    with pytest.raises(ValueError, match=next(iter(change))):
        ExtrinsicsConfig(**change)
