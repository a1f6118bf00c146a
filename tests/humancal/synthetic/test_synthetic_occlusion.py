"""The capsule occlusion model: against a plain loop reference, and on clear-cut layouts."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.camera import Camera, project_points
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS
from humancal.synthetic.occlusion import CAPSULES, occlusion_degree
from humancal.camera import intrinsic_matrix, look_at

# A standing person facing -y (anny's reference keypoints rounded, feet on the floor), metres.
_STANDING = np.array(
    [
        [0.0, -0.14, 1.47], [0.03, -0.12, 1.50], [-0.03, -0.12, 1.50], [0.074, -0.04, 1.48], [-0.074, -0.04, 1.48],
        [0.154, -0.01, 1.30], [-0.154, -0.01, 1.30], [0.21, -0.03, 1.04], [-0.21, -0.03, 1.04],
        [0.25, -0.09, 0.82], [-0.25, -0.09, 0.82], [0.088, -0.01, 0.82], [-0.088, -0.01, 0.82],
        [0.138, -0.03, 0.45], [-0.138, -0.03, 0.45], [0.172, 0.0, 0.08], [-0.172, 0.0, 0.08],
        [0.154, -0.19, 0.0], [-0.154, -0.19, 0.0], [0.211, -0.15, 0.0], [-0.211, -0.15, 0.0],
        [0.175, 0.04, 0.01], [-0.175, 0.04, 0.01],
    ]
)


def _camera_at(center, target=(0.0, 0.0, 1.0)):
    R = look_at(np.asarray(center, float), np.asarray(target, float))
    return Camera.from_center(intrinsic_matrix(1200.0, 1200.0, 1920 / 2.0, 1080 / 2.0), R, np.asarray(center, float), 1920, 1080)


def _reference(pixels, depth, focal):
    """Straightforward loops over every target joint, occluder and capsule."""
    def extra(pts):  # neck, pelvis, ear midpoint
        return np.concatenate([pts] + [pts[pair].mean(0, keepdims=True) for pair in ([5, 6], [11, 12], [3, 4])])

    num_people, num_frames = pixels.shape[:2]
    out = np.zeros((num_people, num_frames, NUM_JOINTS))
    for f in range(num_frames):
        for p in range(num_people):
            for q in range(num_people):
                pts, z = extra(pixels[q, f]), extra(depth[q, f][:, None])[:, 0]
                for a, b, radius, own in CAPSULES:
                    if q == p and not own:
                        continue
                    for j in range(NUM_JOINTS):
                        ab, ap = pts[b] - pts[a], pixels[p, f, j] - pts[a]
                        s = np.clip(ap @ ab / max(ab @ ab, 1e-9), 0.0, 1.0)
                        dist = np.linalg.norm(ap - s * ab)
                        zc = z[a] + s * (z[b] - z[a])
                        if not (0 < zc < depth[p, f, j] - 0.06):
                            continue
                        r = focal * radius / zc
                        out[p, f, j] = max(out[p, f, j], np.clip((1.25 * r - dist) / (0.5 * r), 0.0, 1.0))
    return out


def test_matches_the_loop_reference_on_random_crowds():
    rng = np.random.default_rng(0)
    num_people, num_frames = 4, 6
    yaw = rng.uniform(-np.pi, np.pi, (num_people, num_frames))
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((num_people, num_frames, 3, 3))
    rot[..., 0, 0], rot[..., 0, 1], rot[..., 1, 0], rot[..., 1, 1], rot[..., 2, 2] = c, -s, s, c, 1.0
    position = np.zeros((num_people, num_frames, 3))
    position[..., :2] = rng.uniform(-0.8, 0.8, (num_people, num_frames, 2))
    keypoints = np.einsum("pfij,kj->pfki", rot, _STANDING) + position[:, :, None, :]
    camera = _camera_at([0.0, -5.0, 1.6])
    pixels, depth = project_points(camera, keypoints)
    fast = occlusion_degree(pixels, depth, camera.K[0, 0])
    slow = _reference(pixels, depth, camera.K[0, 0])
    np.testing.assert_allclose(fast, slow, atol=1e-12)
    assert fast.max() == 1.0 and fast.min() == 0.0  # the crowd does occlude


def test_person_behind_another_is_hidden_and_side_by_side_is_not():
    camera = _camera_at([0.0, -6.0, 1.2], target=(0.0, 0.0, 1.0))
    front = _STANDING + [0.0, -1.0, 0.0]
    behind = _STANDING + [0.0, 1.0, 0.0]
    beside = _STANDING + [1.5, -1.0, 0.0]
    pixels, depth = project_points(camera, np.stack([front, behind, beside])[:, None])
    occ = occlusion_degree(pixels, depth, camera.K[0, 0])[:, 0]
    torso = [JOINT_INDEX[n] for n in ("left_shoulder", "right_shoulder", "left_hip", "right_hip")]
    assert np.all(occ[1, torso] == 1.0)  # the one behind: trunk hidden
    assert np.all(occ[0] == 0.0)  # the one in front: nothing hides it (it faces the camera)
    assert np.all(occ[2] == 0.0)


def test_far_side_is_self_occluded_seen_from_the_side():
    # Seen from the person's right (+x is the body's left), the left shoulder and hip are behind the trunk.
    camera = _camera_at([-5.0, 0.0, 1.2])
    pixels, depth = project_points(camera, _STANDING[None, None])
    occ = occlusion_degree(pixels, depth, camera.K[0, 0])[0, 0]
    assert occ[JOINT_INDEX["left_shoulder"]] == pytest.approx(1.0)
    assert occ[JOINT_INDEX["left_hip"]] == pytest.approx(1.0)
    assert occ[JOINT_INDEX["right_shoulder"]] == 0.0 and occ[JOINT_INDEX["right_hip"]] == 0.0
    # Seen from behind, the face is hidden by the head.
    back = _camera_at([0.0, 5.0, 1.5], target=(0.0, 0.0, 1.4))
    pixels, depth = project_points(back, _STANDING[None, None])
    occ = occlusion_degree(pixels, depth, back.K[0, 0])[0, 0]
    assert occ[JOINT_INDEX["nose"]] == pytest.approx(1.0)
