"""Tracking over time: pairwise precision and recall against the true identities, one id per person for the whole
sequence (close passes, a gap in every view), false positives rejected, the number of people, the triangulation,
the tables and bad input (small synthetic scenes lifted by the shipped lifter)."""

from dataclasses import replace

import numpy as np
import pytest

from humancal.association import (
    SKELETONS3D_SCHEMA,
    TrackingConfig,
    associate,
    to_associations_table,
    to_skeletons_table,
)
from humancal.association.cluster_triangulation import triangulate_clusters
from humancal.association.track_smoothing import SmoothingConfig
from humancal.camera import CameraRig
from humancal.geometry.triangulation import triangulate_dlt
from humancal.keypoints import NUM_JOINTS
from humancal.tables.detections import DenseDetections
from tests.cameras import ring_of_cameras

# --- metric helpers (identity metrics of the evaluation package come later; these stay here) --------------------


def pairwise_scores(truth: np.ndarray, found: np.ndarray, frame: np.ndarray, view: np.ndarray) -> tuple[float, float]:
    """(precision, recall) of the same-person pairs among the pairs of detections of one frame in different views."""
    same, said = [], []
    for f in np.unique(frame):
        rows = np.flatnonzero(frame == f)
        a, b = np.triu_indices(len(rows), 1)
        a, b = rows[a], rows[b]
        keep = view[a] != view[b]
        a, b = a[keep], b[keep]
        same.append((truth[a] == truth[b]) & (truth[a] >= 0))
        said.append((found[a] == found[b]) & (found[a] >= 0))
    same, said = np.concatenate(same), np.concatenate(said)
    return float((same & said).sum() / max(said.sum(), 1)), float((same & said).sum() / max(same.sum(), 1))


def identity_switches(truth: np.ndarray, found: np.ndarray, frame: np.ndarray) -> int:
    """Changes of the id given to each true person between its consecutive frames (majority id of each frame)."""
    switches = 0
    for person in np.unique(truth[truth >= 0]):
        mine = (truth == person) & (found >= 0)
        ids = [np.bincount(found[mine & (frame == f)]).argmax() for f in np.unique(frame[mine])]
        switches += int((np.diff(ids) != 0).sum())
    return switches


def id_of_each_person(truth: np.ndarray, found: np.ndarray) -> dict[int, set[int]]:
    """The ids given to the detections of each true person (-1 left out)."""
    return {int(p): set(found[(truth == p) & (found >= 0)].tolist()) for p in np.unique(truth[truth >= 0])}


def f1(precision: float, recall: float) -> float:
    return 2 * precision * recall / max(precision + recall, 1e-12)


# --- scenes ------------------------------------------------------------------------------------------------------


def _inputs(config, body_model, sequence):
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene
    from humancal.tables.associations import Associations
    from humancal.tables.detections import detections_to_dense

    scene = generate_scene(config, body_model, sequence=sequence)
    dense = detections_to_dense(scene.detections)
    truth = Associations.from_table(scene.associations).person_of_detections(dense)
    rig = CameraRig.from_cameras(scene.rig)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                             K=rig.K[dense.view])
    return scene, dense, lifted, rig, truth


@pytest.fixture(scope="module")
def scene3(body_model):
    """3 people, 4 views, 60 frames, the generator's default noise (false positives, flips)."""
    from humancal.synthetic import preset

    return _inputs(preset("demo", num_people=3, num_views=4, num_frames=60, seed=11), body_model, "tracking")


@pytest.fixture(scope="module")
def result3(scene3):
    _, dense, lifted, rig, _ = scene3
    return associate(dense, lifted, rig)


def subset(dense: DenseDetections, keep: np.ndarray) -> DenseDetections:
    return DenseDetections(dense.frame[keep], dense.view[keep], dense.det_id[keep], dense.keypoints_px[keep],
                           dense.scores[keep])


# --- accuracy ----------------------------------------------------------------------------------------------------


def test_pairwise_precision_and_recall(scene3, result3):
    _, dense, _, _, truth = scene3
    precision, recall = pairwise_scores(truth, result3.person_id, dense.frame, dense.view)
    # measured: 1.0000 / 0.9989
    assert precision >= 0.98 and recall >= 0.98, (precision, recall)


def test_one_id_per_person_and_people_counted(scene3, result3):
    _, dense, _, _, truth = scene3
    ids = id_of_each_person(truth, result3.person_id)
    assert all(len(v) == 1 for v in ids.values()), ids
    assert len(set.union(*ids.values())) == len(ids), ids  # different people, different ids
    assert result3.num_people == len(ids) == 3
    assert identity_switches(truth, result3.person_id, dense.frame) == 0


def test_false_positives_rejected(scene3, result3):
    _, _, _, _, truth = scene3
    fp = truth < 0
    assert fp.sum() >= 5  # the scene has false positives to reject
    assert (result3.person_id[fp] < 0).mean() >= 0.95, result3.person_id[fp]


def test_skeletons_near_the_truth(scene3, result3):
    scene, dense, _, _, truth = scene3
    # the true person of each id (majority), then the joint errors of the triangulated skeletons
    owner = {i: np.bincount(truth[(result3.person_id == i) & (truth >= 0)]).argmax()
             for i in range(result3.num_people)}
    true = scene.keypoints_world_m[[owner[int(p)] for p in result3.skeleton_person], result3.skeleton_frame]
    error = np.linalg.norm(result3.joints_world_m - true, axis=-1)
    valid = np.isfinite(error)
    assert valid.mean() > 0.8
    assert np.median(error[valid]) < 0.05, np.median(error[valid])  # measured: about 1 cm
    assert (result3.joint_views[~valid] == 0).all()
    # joints no view triangulated in a frame, filled from the neighbouring frames of the track: few, and close
    filled = valid & (result3.joint_views == 0)
    assert (result3.joint_views[valid & ~filled] >= 2).all()
    assert filled.mean() < 0.05 and (not filled.any() or np.median(error[filled]) < 0.1)
    assert (np.diff(result3.skeleton_frame) >= 0).all()
    assert set(result3.stage_seconds) >= {"affinity", "matching", "triangulation", "tracking", "temporal",
                                          "smoothing", "total"}


def test_smoothing_lowers_the_skeleton_error(scene3, result3):
    """The temporal refinement against the frame-by-frame triangulation (the same association without it)."""
    scene, dense, lifted, rig, truth = scene3
    plain = associate(dense, lifted, rig, TrackingConfig(smoothing=SmoothingConfig(enabled=False)))
    np.testing.assert_array_equal(plain.person_id, result3.person_id)

    def median_error(result):
        owner = {i: np.bincount(truth[(result.person_id == i) & (truth >= 0)]).argmax()
                 for i in range(result.num_people)}
        true = scene.keypoints_world_m[[owner[int(p)] for p in result.skeleton_person], result.skeleton_frame]
        error = np.linalg.norm(result.joints_world_m - true, axis=-1)
        return np.nanmean(error), np.isfinite(error).mean()

    (smooth, covered), (raw, raw_covered) = median_error(result3), median_error(plain)
    assert smooth < 0.8 * raw, (smooth, raw)
    assert covered >= raw_covered


def test_close_passes_keep_their_ids(body_model):
    """People passing within ~0.7 m of each other (the generator keeps them that far apart) keep their ids."""
    from humancal.synthetic import preset

    scene, dense, lifted, rig, truth = _inputs(
        preset("demo", num_people=3, num_views=4, num_frames=90, seed=5, area_size_m=(3.0, 2.0)), body_model,
        "close")
    hips = scene.keypoints_world_m[:, :, 11:13].mean(2)[..., :2]
    gaps = np.linalg.norm(hips[:, None] - hips[None], axis=-1)[np.triu_indices(3, 1)]
    assert (gaps.min(1) < 0.8).all()  # every pair passes close
    result = associate(dense, lifted, rig)
    ids = id_of_each_person(truth, result.person_id)
    assert all(len(v) == 1 for v in ids.values()) and len(set.union(*ids.values())) == 3, ids
    assert identity_switches(truth, result.person_id, dense.frame) == 0
    assert result.num_people == 3


def test_a_person_missing_from_every_view_gets_the_same_id_back(scene3):
    _, dense, lifted, rig, truth = scene3
    gone = (truth == 0) & (dense.frame >= 20) & (dense.frame < 40)  # 0.67 s in no view at all
    keep = ~gone
    result = associate(subset(dense, keep), lifted.subset(keep), rig)
    ids = id_of_each_person(truth[keep], result.person_id)
    assert all(len(v) == 1 for v in ids.values()) and len(set.union(*ids.values())) == 3, ids
    assert result.num_people == 3
    # with a re-identification window shorter than the gap and no stitching, the person comes back as someone new
    short = associate(subset(dense, keep), lifted.subset(keep), rig,
                      TrackingConfig(reid_window_s=0.2, stitch_window_s=0.0))
    assert len(id_of_each_person(truth[keep], short.person_id)[0]) == 2
    assert short.num_people == 4
    # and the stitching of tracks that share bone lengths gives the id back
    stitched = associate(subset(dense, keep), lifted.subset(keep), rig, TrackingConfig(reid_window_s=0.2))
    assert all(len(v) == 1 for v in id_of_each_person(truth[keep], stitched.person_id).values())
    assert stitched.num_people == 3


def test_num_people_given_merges_the_surplus(scene3):
    _, dense, lifted, rig, truth = scene3
    gone = (truth == 0) & (dense.frame >= 20) & (dense.frame < 40)
    keep = ~gone
    result = associate(subset(dense, keep), lifted.subset(keep), rig,
                       TrackingConfig(reid_window_s=0.2, num_people=3))
    ids = id_of_each_person(truth[keep], result.person_id)
    assert all(len(v) == 1 for v in ids.values()) and result.num_people == 3, ids


def test_num_people_smaller_than_the_truth_keeps_that_many(scene3):
    _, dense, lifted, rig, _ = scene3
    result = associate(dense, lifted, rig, TrackingConfig(num_people=2))
    assert result.num_people == 2
    assert set(np.unique(result.person_id)) <= {-1, 0, 1}


def test_without_lifted_poses(scene3):
    _, dense, _, rig, truth = scene3
    result = associate(dense, None, rig)
    precision, recall = pairwise_scores(truth, result.person_id, dense.frame, dense.view)
    assert precision >= 0.98 and recall >= 0.98 and result.num_people == 3


# --- triangulation -----------------------------------------------------------------------------------------------


def test_triangulation_agrees_with_triangulate_dlt():
    rng = np.random.default_rng(0)
    cameras = ring_of_cameras(5, radius_m=5.0, height_m=2.5)
    C = 40
    points = rng.normal(size=(C, NUM_JOINTS, 3)) * [0.5, 0.5, 0.5] + [0, 0, 1]
    pixels = np.stack([np.stack([c.P @ np.r_[p, 1] for p in points.reshape(-1, 3)]) for c in cameras])
    pixels = pixels[..., :2] / pixels[..., 2:] + rng.normal(size=(5, C * NUM_JOINTS, 2))
    wrong = rng.random((5, C * NUM_JOINTS)) < 0.05
    pixels[wrong] += 80.0  # outlier views
    scores = rng.uniform(0.3, 1.0, (5, C * NUM_JOINTS)) * (rng.random((5, C * NUM_JOINTS)) > 0.2)
    # clusters: every view has one detection per cluster
    view = np.repeat(np.arange(5), C)
    cluster = np.tile(np.arange(C), 5)
    keypoints = pixels.reshape(5, C, NUM_JOINTS, 2).reshape(5 * C, NUM_JOINTS, 2)
    weights = scores.reshape(5 * C, NUM_JOINTS)
    X, used = triangulate_clusters(cluster, C, view, keypoints, weights, cameras, 25.0)
    ref, ref_used = triangulate_dlt(cameras, pixels, scores, min_views=2, outlier_threshold_px=25.0)
    ref = ref.reshape(C, NUM_JOINTS, 3)
    both = np.isfinite(ref).all(-1)
    assert (np.isfinite(X).all(-1) == both).all()
    assert (used.reshape(-1) == ref_used).mean() > 0.99
    assert np.median(np.linalg.norm(X - ref, axis=-1)[both]) < 1e-4
    assert np.median(np.linalg.norm(X - points, axis=-1)[both]) < 0.01


# --- tables ------------------------------------------------------------------------------------------------------


def test_tables(scene3, result3):
    _, dense, _, _, _ = scene3
    table = to_associations_table(result3, "tracking")
    assert list(table.columns) == ["sequence", "frame", "view", "det_id", "person_id"]
    assert len(table) == len(dense) and (table["sequence"] == "tracking").all()
    from humancal.tables.associations import Associations

    np.testing.assert_array_equal(Associations.from_table(table).person_of_detections(dense), result3.person_id)
    skeletons = to_skeletons_table(result3, "tracking")
    assert list(skeletons.columns) == SKELETONS3D_SCHEMA.names
    assert len(skeletons) == len(result3.skeleton_frame) * NUM_JOINTS
    assert (skeletons["valid"] == np.isfinite(skeletons[["x_m", "y_m", "z_m"]]).all(axis=1)).all()
    assert (skeletons.loc[skeletons["num_views"] > 0, "valid"]).all()  # 0 views and valid: filled over time
    assert (skeletons["num_views"] == 0).mean() < 0.2


# --- bad input ---------------------------------------------------------------------------------------------------


def test_one_camera_is_an_error(scene3):
    _, dense, lifted, rig, _ = scene3
    one = CameraRig(rig.K[:1], rig.R_cam_from_world[:1], rig.t_cam_from_world_m[:1], rig.distortion[:1],
                    rig.image_size_px[:1])
    keep = dense.view == 0
    with pytest.raises(ValueError, match="at least 2 cameras"):
        associate(subset(dense, keep), lifted.subset(keep), one)


def test_detections_of_one_view_only_is_an_error(scene3):
    _, dense, lifted, rig, _ = scene3
    keep = dense.view == 1
    with pytest.raises(ValueError, match="view 1.*at least 2 views"):
        associate(subset(dense, keep), lifted.subset(keep), rig)


def test_no_detections_is_an_error(scene3):
    _, dense, lifted, rig, _ = scene3
    keep = np.zeros(len(dense), bool)
    with pytest.raises(ValueError, match="no detections"):
        associate(subset(dense, keep), lifted.subset(keep), rig)


def test_a_view_without_detections_is_labelled(scene3):
    _, dense, lifted, rig, truth = scene3
    keep = dense.view != 2
    result = associate(subset(dense, keep), lifted.subset(keep), rig)
    assert "view 2 has no detections" in result.warnings
    precision, recall = pairwise_scores(truth[keep], result.person_id, dense.frame[keep], dense.view[keep])
    assert precision >= 0.98 and recall >= 0.95 and result.num_people == 3


def test_frames_without_people(scene3):
    _, dense, lifted, rig, truth = scene3
    # frames 10-14: only the false positives (if any) are left; frame 30: nothing at all
    keep = ~(((dense.frame >= 10) & (dense.frame < 15) & (truth >= 0)) | (dense.frame == 30))
    result = associate(subset(dense, keep), lifted.subset(keep), rig)
    assert not np.isin(result.skeleton_frame, [10, 11, 12, 13, 14, 30]).any()
    assert (result.person_id[(dense.frame[keep] >= 10) & (dense.frame[keep] < 15)] == -1).all()
    ids = id_of_each_person(truth[keep], result.person_id)
    assert all(len(v) == 1 for v in ids.values()) and result.num_people == 3, ids


def test_only_false_positives(scene3):
    _, dense, lifted, rig, truth = scene3
    keep = truth < 0
    assert len(np.unique(dense.view[keep])) >= 2
    result = associate(subset(dense, keep), lifted.subset(keep), rig)
    assert result.num_people == 0 and (result.person_id == -1).all() and len(result.skeleton_frame) == 0
    assert any("no person found" in w for w in result.warnings)


def test_more_people_asked_than_exist(scene3):
    _, dense, lifted, rig, _ = scene3
    result = associate(dense, lifted, rig, TrackingConfig(num_people=6))
    assert result.num_people == 3
    assert any("num_people=6" in w and "only 3" in w for w in result.warnings)


def test_rows_in_any_order(scene3, result3):
    _, dense, lifted, rig, _ = scene3
    order = np.random.default_rng(1).permutation(len(dense))
    shuffled = associate(subset(dense, order), lifted.subset(order), rig)
    np.testing.assert_array_equal(shuffled.frame, dense.frame[order])
    # the same partition of the detections (people first seen in one frame may be numbered in another order)
    before, after = result3.person_id[order], shuffled.person_id
    assert ((before < 0) == (after < 0)).all()
    pairs = set(zip(before[before >= 0].tolist(), after[after >= 0].tolist()))
    assert len(pairs) == len({a for a, _ in pairs}) == len({b for _, b in pairs}) == result3.num_people


@pytest.mark.parametrize("change", [dict(match_threshold=1.5), dict(fps=0.0), dict(reid_window_s=-1.0),
                                    dict(min_views=1), dict(num_people=0), dict(num_people=2.5),
                                    dict(assign_distance_m=float("nan")), dict(affinity=None)])
def test_config_validation(change):
    with pytest.raises(ValueError, match="TrackingConfig"):
        replace(TrackingConfig(), **change)


# --- seeded scenes (slow): the figures of docs/association.md ----------------------------------------------------

SWEEP = [(2, 3, 1), (3, 4, 2), (4, 5, 3), (5, 6, 4), (6, 6, 5), (8, 8, 6)]


@pytest.mark.slow
@pytest.mark.parametrize("people,views,seed", SWEEP)
def test_seeded_scenes(body_model, people, views, seed):
    from humancal.synthetic import preset

    extra = {"area_size_m": (6.0, 6.0)} if people > 5 else {}
    _, dense, lifted, rig, truth = _inputs(
        preset("demo", num_people=people, num_views=views, num_frames=300, seed=seed, **extra), body_model, "sweep")
    result = associate(dense, lifted, rig)
    precision, recall = pairwise_scores(truth, result.person_id, dense.frame, dense.view)
    switches = identity_switches(truth, result.person_id, dense.frame)
    true_people = len(np.unique(truth[truth >= 0]))
    print(f"\n{people} people, {views} views, seed {seed}: pairwise P {precision:.4f} R {recall:.4f} "
          f"F1 {f1(precision, recall):.4f}; switches {switches}; people {result.num_people} (true {true_people}); "
          f"false positives rejected {(result.person_id[truth < 0] < 0).mean():.3f}; "
          f"{result.stage_seconds['total']:.2f} s")
    assert f1(precision, recall) > 0.97
    assert abs(result.num_people - true_people) <= 1


def test_stitching_joins_only_the_same_body_within_reach():
    """Unit rule of the stitching: a track that starts after another ended continues it only with the same bone
    lengths, within the window, and within walking distance."""
    from humancal.association.tracks import _stitch_tracks

    rng = np.random.default_rng(0)
    body = rng.normal(0, 0.3, (NUM_JOINTS, 3)) + [0.0, 0.0, 1.0]
    fps = 30.0

    def run(second_body, start, offset_m, config=TrackingConfig(fps=fps)):
        frames = np.r_[np.arange(0, 30), np.arange(start, start + 30)]
        joints = np.concatenate([np.repeat(body[None], 30, 0), np.repeat(second_body[None] + offset_m, 30, 0)])
        track_of = np.r_[np.zeros(30, np.int64), np.ones(30, np.int64)]
        return _stitch_tracks(track_of, frames, joints, config)

    assert set(run(body, 60, [0.5, 0.0, 0.0])) == {0}  # same body, 1 s later, 0.5 m away: one person
    assert set(run(1.3 * (body - body.mean(0)) + body.mean(0), 60, 0.0)) == {0, 1}  # a bigger body: someone else
    assert set(run(body, 60, [4.0, 0.0, 0.0])) == {0, 1}  # 4 m in 1 s: too far to walk
    assert set(run(body, 30 + 25 * 30, 0.0)) == {0, 1}  # back after 25 s: beyond the 20 s window
    assert set(run(body, 60, 0.0, TrackingConfig(fps=fps, stitch_window_s=0.0))) == {0, 1}  # stitching off


def test_a_person_split_into_two_clusters_is_merged():
    """Unit rule of the merge: two clusters of one frame without a common view are merged when their skeletons lie
    together, a mirrored one included (detections with left and right swapped in two views), and the larger one
    reprojects onto the smaller one's detections; a cluster of another person 0.6 m away is not merged."""
    from humancal.association.cluster_repair import merge_split_clusters
    from humancal.association.cycle_matching import FrameMatching
    from humancal.keypoints import FLIP_INDEX

    rng = np.random.default_rng(1)
    cameras = ring_of_cameras(6, radius_m=6.0, height_m=2.5)
    body = rng.normal(0, 0.25, (NUM_JOINTS, 3)) + [0.0, 0.0, 1.0]
    other = body + [0.6, 0.0, 0.0]
    assert np.median(np.linalg.norm(body - body[list(FLIP_INDEX)], axis=-1)) > 0.4  # mirrored: not close as it is

    def seen(points, v, flipped=False):
        px = cameras[v].P @ np.c_[points, np.ones(NUM_JOINTS)].T
        px = (px[:2] / px[2]).T + rng.normal(0, 1.0, (NUM_JOINTS, 2))
        return px[list(FLIP_INDEX)] if flipped else px

    def run(second, flipped):
        """Person A in views 0-3 (cluster 0) and ``second`` in views 4-5 (cluster 1): merged?"""
        view = np.array([0, 1, 2, 3, 4, 5])
        keypoints = np.stack([seen(body, v) for v in range(4)] + [seen(second, v, flipped) for v in (4, 5)])
        scores = np.ones((6, NUM_JOINTS))
        cluster = np.array([0, 0, 0, 0, 1, 1])
        joints, _ = triangulate_clusters(cluster, 2, view, keypoints, scores, cameras, 25.0)
        matchings = [FrameMatching(cluster.copy(), np.eye(6), np.zeros((6, 6)), 0.0, 0, True)]
        config = TrackingConfig()  # the defaults
        merges = merge_split_clusters(matchings, np.array([0, 6]), cluster, np.array([0, 0]), joints, view,
                                      keypoints, scores, cameras, distance_m=config.merge_distance_m,
                                      threshold_px=config.outlier_threshold_px)
        return merges, matchings[0].cluster

    merges, labels = run(body, flipped=True)  # A's detections with left and right swapped in views 4 and 5
    assert merges == 1 and (labels == 0).all()
    merges, labels = run(body, flipped=False)
    assert merges == 1 and (labels == 0).all()
    merges, labels = run(other, flipped=False)  # someone else, 0.6 m away: two people
    assert merges == 0 and list(labels) == [0, 0, 0, 0, 1, 1]


def test_a_lone_detection_joins_the_cluster_it_fits():
    """Unit rule of the completion: a detection no cluster took joins the one cluster of its frame that lacks its
    view and reprojects onto it (left and right swapped or not); another person's stays alone."""
    from humancal.association.cluster_repair import complete_clusters
    from humancal.association.cycle_matching import FrameMatching
    from humancal.keypoints import FLIP_INDEX

    rng = np.random.default_rng(2)
    cameras = ring_of_cameras(5, radius_m=6.0, height_m=2.5)
    body = rng.normal(0, 0.25, (NUM_JOINTS, 3)) + [0.0, 0.0, 1.0]

    def seen(points, v, flipped=False):
        px = cameras[v].P @ np.c_[points, np.ones(NUM_JOINTS)].T
        px = (px[:2] / px[2]).T + rng.normal(0, 1.0, (NUM_JOINTS, 2))
        return px[list(FLIP_INDEX)] if flipped else px

    def run(lone_points, lone_view, flipped):
        view = np.array([0, 1, 2, 3, lone_view])
        keypoints = np.stack([seen(body, v) for v in range(4)] + [seen(lone_points, lone_view, flipped)])
        scores = np.ones((5, NUM_JOINTS))
        cluster = np.array([0, 0, 0, 0, -1])
        joints, _ = triangulate_clusters(cluster, 1, view, keypoints, scores, cameras, 25.0)
        matchings = [FrameMatching(cluster.copy(), np.eye(5), np.zeros((5, 5)), 0.0, 0, True)]
        grown = complete_clusters(matchings, np.array([0, 5]), cluster, np.array([0]), joints, view, keypoints,
                                  scores, cameras, threshold_px=TrackingConfig().outlier_threshold_px)
        return grown.tolist(), matchings[0].cluster[-1]

    assert run(body, 4, flipped=True) == ([0], 0)  # the person's detection with left and right swapped
    assert run(body, 4, flipped=False) == ([0], 0)
    assert run(body + [0.6, 0.0, 0.0], 4, flipped=False) == ([], -1)  # someone else
    assert run(body, 2, flipped=False) == ([], -1)  # the cluster has a detection of that view already


def test_frames_scored_and_matched_in_chunks_give_the_same_association(scene3, result3, monkeypatch):
    """Memory bounded by chunks of frames (``MAX_CHUNK_PAIRS``) changes nothing: every frame is matched alone."""
    import humancal.association.tracking as tracking

    _, dense, lifted, rig, _ = scene3
    per_frame = np.bincount(np.unique(dense.frame, return_inverse=True)[1]) ** 2
    monkeypatch.setattr(tracking, "MAX_CHUNK_PAIRS", int(per_frame.max()) * 3)  # about three frames a chunk
    chunked = associate(dense, lifted, rig)
    assert len(tracking._chunk_bounds(per_frame, tracking.MAX_CHUNK_PAIRS)) >= len(per_frame) // 3
    np.testing.assert_array_equal(chunked.person_id, result3.person_id)
    np.testing.assert_array_equal(chunked.skeleton_frame, result3.skeleton_frame)
    np.testing.assert_array_equal(chunked.joints_world_m, result3.joints_world_m)


def test_chunk_bounds_cover_every_item_once_within_the_budget():
    from humancal.association.tracking import _chunk_bounds

    costs = np.array([3, 3, 3, 9, 1, 1, 12, 2])
    bounds = _chunk_bounds(costs, 7)
    assert bounds == [(0, 2), (2, 3), (3, 4), (4, 6), (6, 7), (7, 8)]
    assert _chunk_bounds(costs[:0], 7) == []
