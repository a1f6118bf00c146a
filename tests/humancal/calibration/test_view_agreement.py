"""Each view judged by the people the other views triangulate: a right rig agrees, a turned or wrongly focused camera
disagrees (and is named), a two-view rig cannot be judged; a camera placed again by PnP against the others' people,
identities and focal unknown."""

import numpy as np
import pytest

from humancal.calibration.reregister import reregister_view
from humancal.calibration.view_agreement import (
    AgreementConfig,
    agreement_with_people,
    person_clusters,
    view_agreement,
)
from humancal.camera import Camera
from humancal.geometry.rotations import rotation_distance_deg, rotvec_to_rotmat


def _turned(camera: Camera, degrees: float) -> Camera:
    R = rotvec_to_rotmat(np.radians([0.0, degrees, 0.0])) @ camera.R_cam_from_world
    return Camera.from_center(camera.K, R, camera.center_world_m, camera.width_px, camera.height_px)


def _refocused(camera: Camera, factor: float) -> Camera:
    K = camera.K.copy()
    K[0, 0] *= factor
    K[1, 1] *= factor
    return Camera(K, camera.R_cam_from_world, camera.t_cam_from_world_m, camera.width_px, camera.height_px)


@pytest.fixture(scope="module")
def truth(ring_scene, ring_stand_in, ring_true_groups):
    return list(ring_scene.rig), ring_stand_in.detections, ring_true_groups[0]


def test_the_true_rig_agrees_with_itself(truth):
    rig, detections, groups = truth
    table = view_agreement(rig, detections, groups, people=groups)
    assert (table["verdict"] == "ok").all(), table
    assert (table["loo_median_sigma"] < 2.5).all() and (table["explained_fraction"] > 0.9).all()
    assert (table["behind_fraction"] == 0).all() and (table["compared"] > 500).all()


@pytest.mark.parametrize("broken", [lambda c: _turned(c, 6.0), lambda c: _refocused(c, 1.4)],
                         ids=["turned 6 deg", "focal 40 % off"])
def test_a_wrong_camera_disagrees_and_the_others_agree_without_it(truth, broken):
    rig, detections, groups = truth
    rig = list(rig)
    rig[2] = broken(rig[2])
    table = view_agreement(rig, detections, groups, people=groups)
    assert table.loc[2, "verdict"] == "disagrees" and "stds from the people the other views place" in \
        table.loc[2, "reason"]
    # judged by the views that agree, the others agree again and the wrong one still does not
    again = view_agreement(rig, detections, groups, reference_views=[0, 1, 3], people=groups)
    assert again["verdict"].tolist() == ["ok", "ok", "disagrees", "ok"]


def test_two_views_cannot_be_judged(truth):
    rig, detections, groups = truth
    keep = np.isin(detections.view, [0, 1])
    two = [g[keep[g]] for g in groups if keep[g].sum() == 2]
    table = view_agreement(rig[:2], detections, two, people=two)
    assert (table["verdict"] == "unchecked").all() and "cannot be checked" in table.loc[0, "reason"]


def test_the_association_s_people_are_clusters_per_person_and_frame(truth, ring_stand_in):
    rig, detections, _ = truth
    clusters = person_clusters(detections, ring_stand_in.person_id, max_frames=10)
    frames = {int(detections.frame[c[0]]) for c in clusters}
    assert len(frames) == 10 and all(len(np.unique(detections.view[c])) == len(c) >= 2 for c in clusters)
    assert all(len(set(ring_stand_in.person_id[c])) == 1 for c in clusters)
    table = agreement_with_people(rig, detections, ring_stand_in.person_id)
    assert (table["verdict"] == "ok").all()


def test_thresholds_are_checked():
    with pytest.raises(ValueError, match="min_explained"):
        AgreementConfig(min_explained=1.5)


def test_a_camera_is_placed_again_against_the_others_people(truth, ring_stand_in, ring_true_groups):
    rig, detections, groups = truth
    points = ring_true_groups[1]
    people: dict[int, list] = {}
    for rows, X in zip(groups, points):
        people.setdefault(int(detections.frame[rows[0]]), []).append(X)
    people = {f: np.stack(p) for f, p in people.items()}
    v = 1
    truth_camera = rig[v]
    found = reregister_view(np.flatnonzero(detections.view == v), detections, people, truth_camera.K[:2, 2],
                            truth_camera.width_px, truth_camera.height_px, (300.0, 6000.0))
    assert found is not None and found.explained_fraction > 0.9
    assert abs(found.camera.K[0, 0] / truth_camera.K[0, 0] - 1) < 0.02
    assert rotation_distance_deg(found.camera.R_cam_from_world[None], truth_camera.R_cam_from_world[None])[0] < 0.3
    assert np.linalg.norm(found.camera.center_world_m - truth_camera.center_world_m) < 0.1
