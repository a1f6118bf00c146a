"""What the people do (``SceneConfig.behaviour``): the default scenes are unchanged, seated people never stand,
"low" scenes keep people off their feet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from humancal.keypoints import JOINT_INDEX
from humancal.lifter import standing_score
from humancal.synthetic import ACTIVITIES, generate_scene, preset
from humancal.synthetic.motions import FOOT_JOINTS

GOLDEN = Path(__file__).parent / "golden" / "default_scenes.npz"
"""Arrays of ``preset("tiny")`` and ``preset("demo", num_frames=60)`` recorded with the generator as it was
before the behaviour, portrait, lens-distortion and camera-tilt options existed."""
_FEET = [JOINT_INDEX[name] for name in FOOT_JOINTS]


def _mid(keypoints: np.ndarray, a: str, b: str) -> np.ndarray:
    return 0.5 * (keypoints[..., JOINT_INDEX[a], :] + keypoints[..., JOINT_INDEX[b], :])


def _angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cos = (u * v).sum(-1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _knee_angles_deg(keypoints: np.ndarray) -> np.ndarray:
    """(..., 2) bend of each knee (0: straight leg), degrees."""
    angles = []
    for side in ("left", "right"):
        hip, knee, ankle = (keypoints[..., JOINT_INDEX[f"{side}_{j}"], :] for j in ("hip", "knee", "ankle"))
        angles.append(_angle_deg(knee - hip, ankle - knee))
    return np.stack(angles, axis=-1)


def _trunk_from_vertical_deg(keypoints: np.ndarray) -> np.ndarray:
    trunk = _mid(keypoints, "left_shoulder", "right_shoulder") - _mid(keypoints, "left_hip", "right_hip")
    return _angle_deg(trunk, np.array([0.0, 0.0, 1.0]))


@pytest.mark.parametrize("name", ["tiny", "demo60"])
def test_default_scenes_are_unchanged(body_model, name):
    golden = np.load(GOLDEN)
    g = {key[len(name) + 1 :]: golden[key] for key in golden.files if key.startswith(name + "_")}
    config = preset("tiny") if name == "tiny" else preset("demo", num_frames=60)
    assert config.behaviour == "mixed" and config.distortion_k1_range == (0.0, 0.0)
    scene = generate_scene(config, body_model, sequence=name)
    frames = g.get("frames", np.arange(config.num_frames))
    np.testing.assert_allclose(scene.keypoints_world_m[:, frames], g["keypoints_world_m"], atol=2e-5, rtol=0)
    np.testing.assert_array_equal(scene.activity, g["activity"])
    np.testing.assert_allclose(np.stack([c.K for c in scene.rig]), g["K"], rtol=1e-12)
    np.testing.assert_allclose(np.stack([c.R_cam_from_world for c in scene.rig]), g["R"], atol=1e-12)
    np.testing.assert_allclose(np.stack([c.t_cam_from_world_m for c in scene.rig]), g["t"], atol=1e-12)
    assert all(not c.distortion.any() for c in scene.rig)
    d = scene.detector
    for key, value in (("det_frame", d.frame), ("det_view", d.view), ("det_person", d.person_id),
                       ("det_id", scene.det_id), ("det_present", d.present)):
        np.testing.assert_array_equal(value, g[key], err_msg=key)
    if "det_keypoints_px" in g:
        np.testing.assert_allclose(d.keypoints_px, g["det_keypoints_px"], atol=1e-3, rtol=0)
        np.testing.assert_allclose(d.scores, g["det_scores"], atol=1e-6, rtol=0)
    else:
        first = g["det_keypoints_px_first200"]
        np.testing.assert_allclose(d.keypoints_px[: len(first)], first, atol=1e-3, rtol=0)


@pytest.fixture(scope="module")
def seated_scene(body_model):
    config = preset("tiny", behaviour="seated", num_people=3, num_views=3, num_frames=240, seed=4)
    return generate_scene(config, body_model, sequence="seated")


def test_seated_people_sit_all_the_time(seated_scene):
    kp = seated_scene.keypoints_world_m
    assert np.all(seated_scene.activity == ACTIVITIES.index("sit"))
    pelvis_z = _mid(kp, "left_hip", "right_hip")[..., 2]
    assert np.all((pelvis_z > 0.35) & (pelvis_z < 0.65)), (pelvis_z.min(), pelvis_z.max())
    np.testing.assert_allclose(kp[..., _FEET, 2].min(axis=-1), 0.0, atol=1e-4)
    # Feet flat and both down: every foot point within 13 cm of the floor (ankles are about 8 cm up).
    assert kp[..., _FEET, 2].max() < 0.13
    knees = _knee_angles_deg(kp)
    assert np.all((knees > 75.0) & (knees < 105.0)), (knees.min(), knees.max())
    # Thighs about horizontal.
    for side in ("left", "right"):
        thigh = kp[..., JOINT_INDEX[f"{side}_knee"], :] - kp[..., JOINT_INDEX[f"{side}_hip"], :]
        elevation = np.degrees(np.arcsin(thigh[..., 2] / np.linalg.norm(thigh, axis=-1)))
        assert np.all(np.abs(elevation) < 15.0), np.abs(elevation).max()
    scores = standing_score(kp.reshape(-1, *kp.shape[2:]))
    assert np.all(scores < 0.5), scores.max()


def test_seated_people_keep_their_seats_and_move_their_upper_body(seated_scene):
    kp = seated_scene.keypoints_world_m
    ankles = _mid(kp, "left_ankle", "right_ankle")[..., :2]
    assert np.all(np.linalg.norm(ankles - ankles[:, :1], axis=-1) < 0.15)  # small seat shifts only
    spots = ankles.mean(axis=1)
    gaps = np.linalg.norm(spots[:, None] - spots[None], axis=-1)[np.triu_indices(len(spots), 1)]
    assert gaps.min() > 0.8
    # The poses vary: the trunk leans by different amounts and the hands move relative to the pelvis.
    lean = _trunk_from_vertical_deg(kp)
    assert np.all(lean.max(axis=1) - lean.min(axis=1) > 3.0)
    assert np.all(lean < 35.0)
    wrists = kp[..., [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]], :] - _mid(kp, "left_hip", "right_hip")[
        ..., None, :
    ]
    assert np.all(wrists.std(axis=1).max(axis=(-1, -2)) > 0.03)


def test_low_scenes_sit_crouch_and_bend(body_model):
    config = preset("tiny", behaviour="low", num_people=4, num_views=2, num_frames=450, seed=3)
    scene = generate_scene(config, body_model, sequence="low")
    kp, activity = scene.keypoints_world_m, scene.activity
    kinds = {ACTIVITIES[a] for a in np.unique(activity)}
    assert {"sit", "crouch", "bend"} <= kinds <= {"sit", "crouch", "bend", "walk", "stand"}
    upright = np.isin(activity, [ACTIVITIES.index("walk"), ACTIVITIES.index("stand")])
    assert upright.mean() < 0.4
    np.testing.assert_allclose(kp[..., _FEET, 2].min(axis=-1), 0.0, atol=1e-4)
    # Each bend reaches a trunk bent 55-110 degrees from vertical with nearly straight knees.
    bend = activity == ACTIVITIES.index("bend")
    trunk = _trunk_from_vertical_deg(kp)
    knees = _knee_angles_deg(kp).max(axis=-1)
    for p in range(config.num_people):
        frames = np.nonzero(bend[p])[0]
        if len(frames) < 2 * config.fps:
            continue
        deepest = frames[np.argmax(trunk[p, frames])]
        assert 55.0 < trunk[p, deepest] < 110.0
        assert knees[p, deepest] < 25.0
    # Seated and crouching frames away from transitions do not look like standing.
    settled = np.isin(activity, [ACTIVITIES.index("sit"), ACTIVITIES.index("crouch")])
    settled[:, 1:-1] &= settled[:, :-2] & settled[:, 2:]
    lag = int(config.fps)
    steady = settled.copy()
    for shift in range(1, lag + 1):
        steady[:, shift:] &= settled[:, :-shift]
    assert steady.sum() > 60
    assert np.all(standing_score(kp[steady]) < 0.5)
