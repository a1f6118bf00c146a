import numpy as np
import pandas as pd
import pytest

from humancal.fitting import FittingInputError, body_observations
from humancal.keypoints import CANONICAL_JOINTS
from humancal.tables.detections import DenseDetections
from humancal.tables.schemas import SCHEMAS


def _detections(rows):
    """rows: (frame, view, det_id) with 23 keypoints at (10 * view, frame) and score 0.9."""
    frame, view, det = (np.array(c, dtype=np.int64) for c in zip(*rows))
    keypoints = np.stack([np.full((23, 2), [10.0 * v, float(f)]) for f, v, _ in rows])
    return DenseDetections(frame, view, det, keypoints, np.full((len(rows), 23), 0.9))


def _associations(rows, people):
    frame, view, det = zip(*rows)
    return pd.DataFrame({"sequence": "s", "frame": frame, "view": view, "det_id": det, "person_id": people})


def _skeletons(person_frames):
    records = [{"sequence": "s", "frame": f, "person_id": p, "joint": j, "x_m": 0.0, "y_m": 0.0, "z_m": 1.0,
                "num_views": 2, "valid": True} for p, frames in person_frames.items() for f in frames
               for j in CANONICAL_JOINTS]
    return pd.DataFrame(records, columns=SCHEMAS["skeletons3d"].names)


def test_dense_observations_and_people_left_out_with_a_reason():
    rows, people = [], []
    for f in range(6):
        rows += [(f, 0, 0), (f, 1, 0)]
        people += [0, 0]  # person 0: two views, six frames
        rows += [(f, 0, 1)]
        people += [1]  # person 1: one view only
    rows += [(2, 1, 1), (3, 1, 1), (2, 0, 2), (3, 0, 2)]
    people += [2, 2, 2, 2]  # person 2: two views, two frames
    obs, warnings = body_observations(_detections(rows), _associations(rows, people),
                                      _skeletons({0: range(6), 2: [2, 3]}), num_views=2)
    assert obs.person_ids.tolist() == [0] and obs.num_frames == 6 and obs.keypoints_px.shape == (2, 1, 6, 23, 2)
    assert obs.present.all() and obs.joints_valid.all()
    np.testing.assert_allclose(obs.keypoints_px[1, 0, 4, 0], [10.0, 4.0])
    assert any("person 1 left out" in w and "1 view(s)" in w for w in warnings)
    assert any("person 2 left out" in w and "2 frame(s)" in w for w in warnings)


def test_bad_inputs_raise_clear_errors():
    rows = [(f, v, 0) for f in range(5) for v in range(2)]
    people = [0] * len(rows)
    detections = _detections(rows)
    with pytest.raises(FittingInputError, match="no detection belongs to a person"):
        body_observations(detections, _associations(rows, [-1] * len(rows)), _skeletons({}), num_views=2)
    with pytest.raises(FittingInputError, match="no person can be fitted: person 0 left out"):
        body_observations(detections, _associations(rows, people), _skeletons({0: range(5)}), num_views=2,
                          min_frames=10)
    broken = DenseDetections(detections.frame, detections.view, detections.det_id, detections.keypoints_px.copy(),
                             detections.scores)
    broken.keypoints_px[3, 5] = np.nan
    with pytest.raises(FittingInputError, match=r"frame 1, view 1, det_id 0 has a non-finite keypoint with score > 0"):
        body_observations(broken, _associations(rows, people), _skeletons({0: range(5)}), num_views=2)
    with pytest.raises(FittingInputError, match=r"persons \[0\] have no valid triangulated joint"):
        body_observations(detections, _associations(rows, people), _skeletons({}), num_views=2)
    with pytest.raises(FittingInputError, match=r"view numbers must be 0..0"):
        body_observations(detections, _associations(rows, people), _skeletons({0: range(5)}), num_views=1)


def test_detections_with_left_and_right_swapped_are_swapped_back():
    from humancal.camera import CameraRig
    from humancal.fitting import BodyObservations
    from humancal.fitting.observations import unswap_left_right
    from humancal.keypoints import FLIP_INDEX
    from tests.cameras import ring_of_cameras

    rng = np.random.default_rng(0)
    rig = CameraRig.from_cameras(ring_of_cameras(3, radius_m=4.0, height_m=2.0, focal_px=1000.0, width_px=1280,
                                                 height_px=720))
    joints = rng.normal(0, 0.3, (1, 4, 23, 3)) + [0.0, 0.0, 1.0]  # one person, four frames
    pixels, _ = rig.project(joints.reshape(-1, 3))
    keypoints = pixels.reshape(3, 1, 4, 23, 2) + rng.normal(0, 1.0, (3, 1, 4, 23, 2))
    keypoints[1, 0, 2] = keypoints[1, 0, 2][list(FLIP_INDEX)]  # view 1 saw frame 2 mirrored
    confidence = np.full((3, 1, 4, 23), 0.9)
    confidence[2, 0, 3] = 0.0  # view 2 missed frame 3
    obs = BodyObservations(np.array([0]), np.arange(4), keypoints, confidence, joints, np.ones((1, 4, 23), bool),
                           np.ones((1, 4), bool))
    fixed, swapped = unswap_left_right(obs, rig)
    assert swapped == 1
    error = np.linalg.norm(fixed.keypoints_px - pixels.reshape(3, 1, 4, 23, 2), axis=-1)
    assert error.max() < 6.0  # every detection agrees with the joints again
    assert np.array_equal(fixed.confidence, obs.confidence)  # uniform confidences: swapping keeps them
    again, swapped_again = unswap_left_right(fixed, rig)
    assert swapped_again == 0 and again is fixed
    with pytest.raises(ValueError, match="ratio"):
        unswap_left_right(obs, rig, ratio=1.5)
