"""The fitted keypoints seen from one camera, and their distance to the detections the association gave them."""

from __future__ import annotations

import numpy as np
import pandas as pd

from humancal.camera import Camera, project_points
from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.viewing.reprojection import reprojected_fit


def _camera() -> Camera:
    """A camera 4 m in front of the origin, looking along world +y."""
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return Camera(K=np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]), R_cam_from_world=R,
                  t_cam_from_world_m=np.array([0.0, 0.0, 4.0]), width_px=640, height_px=480)


def _rows(frame: int, det_id: int, pixels: np.ndarray, scores: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"frame": frame, "view": 0, "det_id": det_id, "joint": list(CANONICAL_JOINTS),
                         "x_px": pixels[:, 0], "y_px": pixels[:, 1], "score": scores})


def test_each_frame_s_error_is_the_mean_over_the_confident_keypoints_of_its_own_people():
    rng = np.random.default_rng(0)
    camera = _camera()
    frames = np.array([12, 10, 11])  # not in order: the function may not assume it
    keypoints = {7: (frames, rng.normal(0.0, 0.3, (3, NUM_JOINTS, 3))),
                 9: (frames[:1], rng.normal(0.0, 0.3, (1, NUM_JOINTS, 3)))}
    truth = {pid: project_points(camera, kp.reshape(-1, 3))[0].reshape(len(f), NUM_JOINTS, 2)
             for pid, (f, kp) in keypoints.items()}
    scores = np.ones(NUM_JOINTS)
    scores[:5] = 0.0  # not confident: left out
    shift = np.zeros((NUM_JOINTS, 2))
    shift[:, 0] = np.arange(NUM_JOINTS)  # joint j is j px off
    detections = pd.concat([
        _rows(10, 0, truth[7][1] + shift, scores),  # person 7 at frame 10
        _rows(12, 0, truth[7][0] + 2 * shift, scores),  # person 7 at frame 12, twice as far
        _rows(12, 1, truth[9][0] + 100.0, np.ones(NUM_JOINTS)),  # person 9 at frame 12, 100 sqrt(2) px off
        _rows(12, 2, truth[7][0] + 500.0, np.ones(NUM_JOINTS)),  # rejected by the association: left out
        _rows(11, 5, truth[7][2] + 50.0, np.ones(NUM_JOINTS)),  # a person without a fit: left out
    ], ignore_index=True)
    people = {(10, 0, 0): 7, (12, 0, 0): 7, (12, 0, 1): 9, (12, 0, 2): -1, (11, 0, 5): 3}

    fits = reprojected_fit(keypoints, 0, camera, detections, people)

    assert sorted(fits) == [10, 11, 12]
    confident = np.arange(5, NUM_JOINTS, dtype=float)
    assert np.isclose(fits[10].error_px, confident.mean())
    assert np.isnan(fits[11].error_px)  # nobody fitted there has a detection
    expected_12 = (np.sum(2 * confident) + NUM_JOINTS * 100.0 * np.sqrt(2.0)) / (len(confident) + NUM_JOINTS)
    assert np.isclose(fits[12].error_px, expected_12)
    assert sorted(fits[12].people) == [7, 9] and sorted(fits[10].people) == [7]
    np.testing.assert_allclose(fits[10].people[7][0], truth[7][1])
