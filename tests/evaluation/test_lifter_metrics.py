"""Lifter metrics on a synthetic scene: a lifter made from the ground truth, then with known errors."""

import numpy as np
import pandas as pd
import pytest

from evaluation.lifter_metrics import lifter_metrics_table, shelf_heights_m, true_heights_m
from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX
from humancal.lifter import LiftedPoses, R_crop_from_cam, lifted_to_table, normalize_detections
from humancal.tables.detections import detections_to_dense
from humancal.tables.schemas import empty_table, validate_table

UPRIGHT_FRAMES = 5
_HIPS = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]
_SHELF_SHARED = [f"{side}_{part}" for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")
                 for side in ("left", "right")]


@pytest.fixture(scope="module")
def scene(body_model):
    """2 people, 3 views, 12 frames, default detector noise (false positives included)."""
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_people=2, num_views=3, num_frames=12, seed=5), body_model,
                          sequence="lm")


def _person_of_detection(scene, dense):
    ids = scene.associations.set_index(["frame", "view", "det_id"])["person_id"]
    return ids.reindex(pd.MultiIndex.from_arrays([dense.frame, dense.view, dense.det_id])).to_numpy(np.int64)


def _perfect_lift(scene, scale=1.0, offset_m=(0.0, 0.0, 0.0)):
    """The ``lifted_detections`` table of a lifter that knows the truth, optionally scaled or offset.

    True joints moved into the detection's camera, relative to the hip midpoint, turned into its crop frame;
    heights the true ones; stored upright scores 1 in the first ``UPRIGHT_FRAMES`` frames, 0.2 after. ``scale``
    multiplies the pose and the height; ``offset_m`` (crop frame) is added to every joint but the hips.
    False positives get a wild pose (they must be ignored).
    """
    dense = detections_to_dense(scene.detections)
    person = _person_of_detection(scene, dense)
    norm = normalize_detections(dense.keypoints_px, dense.scores)
    index = {p: i for i, p in enumerate(scene.person_ids)}
    src = np.array([index.get(p, 0) for p in person])
    world = scene.keypoints_world_m[src, dense.frame]
    world = world - world[:, _HIPS].mean(axis=1, keepdims=True)
    R = np.stack([c.R_cam_from_world for c in scene.rig])[dense.view]
    K = np.stack([c.K for c in scene.rig])[dense.view]
    cam = np.einsum("dij,dkj->dki", R, world)
    crop = np.einsum("dij,dkj->dki", R_crop_from_cam(norm.box_centre_px, K), cam) * scale
    not_hips = np.setdiff1d(np.arange(len(CANONICAL_JOINTS)), _HIPS)
    crop[:, not_hips] += np.asarray(offset_m)
    height = scale * scene.height_m[src]
    fp = person < 0
    crop[fp] = 3.0 * np.random.default_rng(0).normal(size=crop[fp].shape)
    crop[~norm.valid] = np.nan
    upright = np.where(dense.frame < UPRIGHT_FRAMES, 1.0, 0.2)  # stored scores: what the /upright rows read
    lifted = LiftedPoses(crop, np.where(norm.valid, height, np.nan), np.where(norm.valid, upright, np.nan),
                         norm.valid, norm.box_centre_px, "crop")
    return validate_table(lifted_to_table(scene.sequence, dense, lifted), "lifted_detections")


def _metrics(scene, lifted, associations=None, gt=None, people=None):
    table = lifter_metrics_table("synthetic", scene.sequence, lifted,
                                 scene.associations if associations is None else associations,
                                 scene.poses3d if gt is None else gt, scene.cameras,
                                 scene.people if people is None else people)
    names = [n if pd.isna(v) else f"{n}@{v}" for n, v in zip(table["metric"], table["view"])]
    return pd.Series(table["value"].to_numpy(), index=names)  # per-view rows as "<metric>@<view>"


def _evaluated_count(lifted, associations):
    per_det = lifted.drop_duplicates(["frame", "view", "det_id"])
    merged = per_det.merge(associations, on=["frame", "view", "det_id"], how="left")
    return int((merged["lifted"] & (merged["person_id"].fillna(-1) >= 0)).sum())


def _shelf_like_gt(scene):
    """The scene's truth as Shelf gives it: 12 shared joints under SHELF15 names, plus neck, head top, pelvis.

    The head top sits ``height - 7 cm`` above the lower ankle (so the Shelf height rule recovers the true height
    exactly) and the pelvis 10 cm off the hip midpoint (it must not be the root).
    """
    g = scene.poses3d
    shared = g[g["joint"].isin(_SHELF_SHARED)]
    wide = g.pivot_table(index=["frame", "person_id"], columns="joint", values=["x_m", "y_m", "z_m"])
    xyz = lambda j: np.stack([wide[(c, j)].to_numpy() for c in ("x_m", "y_m", "z_m")], axis=1)  # noqa: E731
    neck = 0.5 * (xyz("left_shoulder") + xyz("right_shoulder"))
    height = scene.people.set_index("person_id")["height_m"].reindex(wide.index.get_level_values(1)).to_numpy()
    top = neck.copy()
    top[:, 2] = np.minimum(xyz("left_ankle")[:, 2], xyz("right_ankle")[:, 2]) + height - 0.07
    pelvis = 0.5 * (xyz("left_hip") + xyz("right_hip")) + [0.1, 0.0, 0.0]
    extra = []
    for name, X in (("bottom_head", neck), ("top_head", top), ("pelvis", pelvis)):
        extra.append(pd.DataFrame({"sequence": scene.sequence, "frame": wide.index.get_level_values(0),
                                   "person_id": wide.index.get_level_values(1), "joint": name,
                                   "x_m": X[:, 0], "y_m": X[:, 1], "z_m": X[:, 2], "valid": True}))
    return validate_table(pd.concat([shared, *extra], ignore_index=True), "poses3d")


def test_a_lifter_that_knows_the_truth_has_no_error(scene):
    lifted = _perfect_lift(scene)
    m = _metrics(scene, lifted)
    assert m["mpjpe_mm"] < 1e-6 and m["pa_mpjpe_mm"] < 1e-4
    assert m["height_error_mm"] < 1e-9 and abs(m["height_bias_mm"]) < 1e-9
    n = _evaluated_count(lifted, scene.associations)
    assert m["num_detections"] == n and n > 50
    views = sorted(k for k in m.index if k.startswith("num_detections@"))
    assert views == [f"num_detections@{v}" for v in range(3)]
    assert sum(m[k] for k in views) == n
    assert all(m[f"mpjpe_mm@{v}"] < 1e-6 for v in range(3))
    early = scene.associations[(scene.associations["person_id"] >= 0) & (scene.associations["frame"] < UPRIGHT_FRAMES)]
    assert m["num_detections/upright"] == len(early) and 0 < len(early) < n
    assert m["mpjpe_mm/upright"] < 1e-6
    table = lifter_metrics_table("synthetic", "lm", lifted, scene.associations, scene.poses3d, scene.cameras,
                                 scene.people)
    assert (table["method"] == "lifter").all() and np.isfinite(table["value"]).all()
    assert set(table.loc[table["metric"].str.startswith("num_detections"), "unit"]) == {"count"}


def test_an_offset_of_every_joint_but_the_hips_gives_the_expected_mpjpe(scene):
    # 5 cm on 21 of the 23 joints (the hips, hence the root, stay): 50 * 21 / 23 mm, whatever the rotation
    # from crop frame to camera frame
    m = _metrics(scene, _perfect_lift(scene, offset_m=(0.05, 0.0, 0.0)))
    expected = 50.0 * 21 / 23
    assert m["mpjpe_mm"] == pytest.approx(expected, abs=1e-6)
    assert all(m[f"mpjpe_mm@{v}"] == pytest.approx(expected, abs=1e-6) for v in range(3))
    assert m["pa_mpjpe_mm"] < m["mpjpe_mm"]
    assert m["height_error_mm"] < 1e-9  # the height column was not touched
    assert m["mpjpe_mm/upright"] == pytest.approx(expected, abs=1e-6)


def test_a_scaled_pose_costs_mpjpe_in_proportion_and_nothing_after_procrustes(scene):
    s = 1.1
    lifted = _perfect_lift(scene, scale=s)
    m = _metrics(scene, lifted)
    # expected: (s - 1) times the mean distance of the true joints from the hip midpoint, over evaluated ones
    per_det = lifted.drop_duplicates(["frame", "view", "det_id"])
    ev = per_det.merge(scene.associations, on=["frame", "view", "det_id"])
    ev = ev[ev["lifted"] & (ev["person_id"] >= 0)]
    index = {p: i for i, p in enumerate(scene.person_ids)}
    X = scene.keypoints_world_m[[index[p] for p in ev["person_id"]], ev["frame"].to_numpy()]
    X = X - X[:, _HIPS].mean(axis=1, keepdims=True)
    assert m["mpjpe_mm"] == pytest.approx(1000.0 * (s - 1) * np.linalg.norm(X, axis=-1).mean(), rel=1e-9)
    assert m["pa_mpjpe_mm"] < 1e-4
    true_h = scene.height_m[[index[p] for p in ev["person_id"]]]
    assert m["height_bias_mm"] == pytest.approx(1000.0 * (s - 1) * true_h.mean(), rel=1e-9)
    assert m["height_error_mm"] == pytest.approx(m["height_bias_mm"], rel=1e-9)


def test_false_positives_unmatched_and_unlifted_detections_are_ignored(scene):
    lifted = _perfect_lift(scene)
    assoc = scene.associations
    assert (assoc["person_id"] < 0).any()  # the wild poses of false positives are in the table, and ignored
    n = _metrics(scene, lifted)["num_detections"]
    matched = assoc[assoc["person_id"] >= 0][["frame", "view", "det_id"]].to_numpy()
    # three matched detections not lifted (wild poses and heights left in their rows), two more made false
    # positives, one more dropped from the associations
    key = lambda k: (lifted["frame"] == k[0]) & (lifted["view"] == k[1]) & (lifted["det_id"] == k[2])  # noqa: E731
    lifted = lifted.copy()
    for k in matched[:3]:
        lifted.loc[key(k), ["x_crop_m", "y_crop_m", "z_crop_m", "height_m", "lifted"]] = [9.0, 9.0, 9.0, 9.0, False]
    changed = assoc.copy()
    for k in matched[3:5]:
        changed.loc[(changed["frame"] == k[0]) & (changed["view"] == k[1]) & (changed["det_id"] == k[2]),
                    "person_id"] = -1
        lifted.loc[key(k), ["x_crop_m", "height_m"]] = [5.0, 3.0]
    k = matched[5]
    changed = changed[~((changed["frame"] == k[0]) & (changed["view"] == k[1]) & (changed["det_id"] == k[2]))]
    lifted.loc[key(k), ["y_crop_m", "height_m"]] = [-5.0, 0.5]
    m = _metrics(scene, lifted, associations=changed)
    assert m["num_detections"] == n - 6
    assert m["mpjpe_mm"] < 1e-6 and m["height_error_mm"] < 1e-9


def test_nothing_matched_gives_an_empty_table(scene):
    lifted = _perfect_lift(scene)
    nobody = scene.associations.assign(person_id=-1)
    for table in (
        lifter_metrics_table("synthetic", "lm", lifted, nobody, scene.poses3d, scene.cameras, scene.people),
        lifter_metrics_table("synthetic", "lm", lifted.iloc[:0], scene.associations, scene.poses3d, scene.cameras,
                             scene.people),
        lifter_metrics_table("synthetic", "lm", lifted.assign(lifted=False), scene.associations, scene.poses3d,
                             scene.cameras, scene.people),
    ):
        assert len(table) == 0
        assert list(table.columns) == ["dataset", "sequence", "method", "metric", "view", "value", "unit",
                                       "failed_checks"]


def test_shelf_style_ground_truth_compares_the_12_shared_joints_about_the_hip_midpoint(scene):
    gt = _shelf_like_gt(scene)
    people = empty_table("people")
    m = _metrics(scene, _perfect_lift(scene), gt=gt, people=people)
    assert m["mpjpe_mm"] < 1e-6 and m["pa_mpjpe_mm"] < 1e-4  # the pelvis joint is not the root
    assert m["height_error_mm"] < 1e-6  # heights from head top and ankles
    # 5 cm on every joint but the hips: 10 of the 12 compared joints move
    m = _metrics(scene, _perfect_lift(scene, offset_m=(0.0, 0.05, 0.0)), gt=gt, people=people)
    assert m["mpjpe_mm"] == pytest.approx(50.0 * 10 / 12, abs=1e-6)


def test_true_heights_come_from_the_people_table_then_from_the_poses(scene):
    gt = _shelf_like_gt(scene)
    expected = scene.people.set_index("person_id")["height_m"]
    pd.testing.assert_series_equal(shelf_heights_m(gt), expected, check_exact=False, rtol=1e-9,
                                   check_index_type=False, check_dtype=False)
    # a people row wins over the poses; a person without one falls back to them
    people = scene.people.iloc[:1].assign(height_m=2.5)
    h = true_heights_m(gt, people)
    assert h[expected.index[0]] == 2.5 and h[expected.index[1]] == pytest.approx(expected.iloc[1], rel=1e-9)
    # canonical truth without people rows: the median of the lifter's height rule over frames (within 5 cm)
    h = true_heights_m(scene.poses3d, empty_table("people"))
    assert np.allclose(h.to_numpy(), expected.to_numpy(), atol=0.05)
    # frames where the head top is missing are skipped
    shifted = gt.copy()
    shifted.loc[(shifted["joint"] == "top_head") & (shifted["frame"] < 11), "valid"] = False
    assert np.allclose(shelf_heights_m(shifted).to_numpy(), expected.to_numpy())
