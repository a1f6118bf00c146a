"""Synthetic scenes with oracle (stand-in) lifted poses, shared by the calibration tests (built once per module)."""

import numpy as np
import pytest

from humancal.camera import Camera
from humancal.tables.detections import DenseDetections


@pytest.fixture(scope="session")
def ring_scene(body_model):
    """3 people, 4 views on a ring, 60 frames, default detector noise."""
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_people=3, num_views=4, num_frames=60, seed=11), body_model,
                          sequence="ring")


@pytest.fixture(scope="session")
def ring_stand_in(ring_scene):
    from evaluation.oracle import stand_in_lifted_poses

    return stand_in_lifted_poses(ring_scene, np.random.default_rng(0))


@pytest.fixture(scope="session")
def ring_true_groups(ring_scene, ring_stand_in):
    """(groups, points): the ring scene's groups of true identities (one person in one frame seen by >= 2 views),
    every 3rd frame, as arrays of detection rows, and the true (G, 23, 3) keypoints of each group."""
    d, pid = ring_stand_in.detections, ring_stand_in.person_id
    keys = {}
    for row in np.flatnonzero(pid >= 0):
        if d.frame[row] % 3 == 0:
            keys.setdefault((d.frame[row], pid[row]), []).append(row)
    groups = [np.array(g) for g in keys.values() if len(g) >= 2]
    return groups, np.stack([ring_scene.keypoints_world_m[pid[g[0]], d.frame[g[0]]] for g in groups])


@pytest.fixture(scope="session")
def simulate_views():
    """The :func:`simulate` helper."""
    return simulate


@pytest.fixture(scope="session")
def down_camera():
    """The :func:`look_down_camera` helper."""
    return look_down_camera


def simulate(scene, cameras: list[Camera], seed: int = 1):
    """Detections of ``scene``'s people seen by other ``cameras`` (the scene's noise model), with stand-in lifts.

    Returns:
        (DenseDetections, LiftedPoses, person_id)
    """
    from evaluation.oracle import lift_ground_truth
    from humancal.synthetic import simulate_detections

    out = simulate_detections(scene.keypoints_world_m, scene.height_m, cameras, scene.config.noise,
                              np.random.default_rng(seed))
    kp = np.where(out.present[..., None], out.keypoints_px, np.nan)
    dense = DenseDetections(out.frame, out.view, np.arange(len(out.frame)), kp, out.scores)
    lifted = lift_ground_truth(scene.keypoints_world_m, scene.height_m, cameras, out.frame, out.view, out.person_id,
                               out.flipped, np.random.default_rng(seed + 1))
    return dense, lifted, out.person_id


def look_down_camera(center_world_m, focal_px=1000.0, size=(1920, 1080)) -> Camera:
    """A camera looking straight down (image x = world x, image y = world -y)."""
    K = np.array([[focal_px, 0.0, size[0] / 2], [0.0, focal_px, size[1] / 2], [0.0, 0.0, 1.0]])
    R = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    return Camera.from_center(K, R, np.asarray(center_world_m, float), *size)
