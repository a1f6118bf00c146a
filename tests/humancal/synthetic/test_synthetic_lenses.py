"""Scenes through portrait images and radially distorted lenses: detections inside the images, projected
through the lens exactly as OpenCV does."""

from __future__ import annotations

import cv2
import numpy as np

from humancal.camera import Camera, look_at, project_points
from humancal.keypoints import NUM_JOINTS
from humancal.synthetic import DetectorNoise, generate_scene, preset, simulate_detections


def test_portrait_detections_are_inside_the_image_and_everyone_is_seen(body_model):
    config = preset("tiny", image_size_px=(1080, 1920), num_people=3, num_views=3, num_frames=30, seed=6)
    scene = generate_scene(config, body_model, sequence="portrait")
    det = scene.detections
    assert len(det) > 0
    assert det["x_px"].between(0, 1080, inclusive="left").all() and det["y_px"].between(0, 1920, inclusive="left").all()
    assert det["y_px"].max() > 1080  # the tall image is used beyond a landscape one's height
    assert set(scene.cameras["width_px"]) == {1080} and set(scene.cameras["height_px"]) == {1920}
    detected = scene.detector.detected  # (V, P, F)
    assert np.all(detected.any(axis=0).mean(axis=-1) > 0.9)  # every person seen by some view in most frames
    assert np.all(detected.any(axis=(0, 2)))


def test_k1_detections_follow_the_lens(body_model):
    config = preset("tiny_clean", num_people=2, num_views=3, num_frames=10, distortion_k1_range=(-0.3, -0.1), seed=2)
    scene = generate_scene(config, body_model, sequence="k1")
    k1 = np.array([c.distortion[0] for c in scene.rig])
    assert np.all((k1 >= -0.3) & (k1 <= -0.1))
    table_k1 = np.array([d[0] for d in scene.cameras.sort_values("view")["distortion"]])
    np.testing.assert_allclose(table_k1, k1)  # the ground-truth cameras keep the k1
    d = scene.detector
    true_dets = d.person_id >= 0
    assert true_dets.sum() > 20
    largest_shift_px = 0.0
    for n in np.nonzero(true_dets)[0]:
        cam = scene.rig[d.view[n]]
        points = scene.keypoints_world_m[d.person_id[n], d.frame[n]]
        rvec, _ = cv2.Rodrigues(cam.R_cam_from_world)
        expected, _ = cv2.projectPoints(points, rvec, cam.t_cam_from_world_m, cam.K, cam.distortion)
        present = d.present[n]
        np.testing.assert_allclose(d.keypoints_px[n][present], expected[:, 0][present], atol=1e-6)
        pinhole = Camera(cam.K, cam.R_cam_from_world, cam.t_cam_from_world_m, cam.width_px, cam.height_px)
        plain, _ = project_points(pinhole, points)
        largest_shift_px = max(largest_shift_px, float(np.abs(plain - expected[:, 0])[present].max()))
    assert largest_shift_px > 5.0
    assert d.present.shape[1] == NUM_JOINTS


def test_barrel_lens_never_folds_far_points_into_the_image(tiny_scene):
    # k1 = -0.5 stops growing at a normalised radius of 1 / sqrt(1.5) = 0.82 and maps 1.2 back to 0.34: a person
    # 1.2 depths off the axis would land near the image centre. The detector must not see them there.
    person = tiny_scene.keypoints_world_m[:1, :1].copy()
    person[..., 0] += 1.2 * 5.0 - person[..., 0].mean()
    person[..., 1] -= person[..., 1].mean()
    K = np.array([[500.0, 0.0, 960.0], [0.0, 500.0, 540.0], [0.0, 0.0, 1.0]])
    R = look_at(np.array([0.0, -5.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    pinhole = Camera.from_center(K, R, np.array([0.0, -5.0, 1.0]), 1920, 1080)
    barrel = Camera(pinhole.K, pinhole.R_cam_from_world, pinhole.t_cam_from_world_m, 1920, 1080,
                    np.array([-0.5, 0.0, 0.0, 0.0, 0.0]))
    folded, _ = project_points(barrel, person[0, 0])
    assert np.all((folded[:, 0] > 0) & (folded[:, 0] < 1920))  # where a folding lens model would put them
    out = simulate_detections(person, tiny_scene.height_m[:1], [pinhole, barrel], DetectorNoise.none(),
                              np.random.default_rng(0))
    assert out.in_image[0].any() and out.detected[0].all()  # the pinhole (wide, 500 px) sees the person
    assert not out.in_image[1].any() and not out.detected[1].any()
