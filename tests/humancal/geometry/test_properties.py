"""Properties of the geometry that must hold for every input, checked on inputs hypothesis draws (derandomized: the
same examples on every run): rotation conversions, the rotation distance, similarity alignment, projection with lens
distortion (against OpenCV) and triangulation."""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from humancal.camera import Camera
from humancal.camera.projection import project_points_np, undistort_points_px
from humancal.geometry.alignment import fit_similarity
from humancal.geometry.rotations import (
    project_to_rotmat,
    rotation_angle_deg,
    rotation_distance_deg,
    rotmat_a_to_b,
    rotmat_to_6d,
    rotmat_to_rotvec,
    rotvec_to_rotmat,
    sixd_to_rotmat,
)
from humancal.geometry.triangulation import triangulate_dlt

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True)

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vectors = arrays(np.float64, 3, elements=finite)
rotvecs = vectors.map(lambda v: v * 3.0).filter(lambda v: np.linalg.norm(v) < np.pi - 1e-3)
rotations = rotvecs.map(rotvec_to_rotmat)
directions = vectors.filter(lambda v: np.linalg.norm(v) > 1e-2)


def _is_rotation(R: np.ndarray) -> bool:
    return np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.isclose(np.linalg.det(R), 1.0, atol=1e-9)


@PROPERTY
@given(rotvecs)
def test_rotation_vectors_round_trip_through_matrices(rotvec):
    R = rotvec_to_rotmat(rotvec)
    assert _is_rotation(R)
    np.testing.assert_allclose(rotmat_to_rotvec(R), rotvec, atol=1e-8)
    np.testing.assert_allclose(rotation_angle_deg(R), np.degrees(np.linalg.norm(rotvec)), atol=1e-6)


@PROPERTY
@given(rotations)
def test_the_6d_representation_round_trips(R):
    np.testing.assert_allclose(sixd_to_rotmat(rotmat_to_6d(R)), R, atol=1e-10)


@PROPERTY
@given(rotations, rotations, rotations)
def test_the_rotation_distance_is_a_metric(A, B, C):
    d_ab, d_ba = rotation_distance_deg(A, B), rotation_distance_deg(B, A)
    assert np.isclose(d_ab, d_ba, atol=1e-6) and 0.0 <= d_ab <= 180.0
    assert np.isclose(rotation_distance_deg(A, A), 0.0, atol=1e-4)
    assert rotation_distance_deg(A, C) <= d_ab + rotation_distance_deg(B, C) + 1e-6
    np.testing.assert_allclose(d_ab, rotation_angle_deg(A @ B.T), atol=1e-6)


@PROPERTY
@given(rotations, arrays(np.float64, (3, 3), elements=st.floats(-0.05, 0.05)))
def test_projection_onto_rotations_keeps_rotations_and_repairs_small_noise(R, noise):
    assert _is_rotation(project_to_rotmat(R + noise))
    np.testing.assert_allclose(project_to_rotmat(R), R, atol=1e-10)
    assert rotation_distance_deg(project_to_rotmat(R + noise), R) < 10.0


@PROPERTY
@given(directions, directions)
def test_the_rotation_from_a_to_b_takes_a_onto_b(a, b):
    a_unit, b_unit = a / np.linalg.norm(a), b / np.linalg.norm(b)
    assume(a_unit @ b_unit > -0.99)  # opposite directions have no unique smallest rotation
    R = rotmat_a_to_b(a, b)
    assert _is_rotation(R)
    np.testing.assert_allclose(R @ a_unit, b_unit, atol=1e-9)
    # the smallest such rotation: its angle is the angle between the directions
    np.testing.assert_allclose(rotation_angle_deg(R), np.degrees(np.arccos(np.clip(a_unit @ b_unit, -1, 1))),
                               atol=1e-5)


@PROPERTY
@given(arrays(np.float64, (8, 3), elements=st.floats(-2.0, 2.0)), rotations, st.floats(0.2, 5.0),
       arrays(np.float64, 3, elements=st.floats(-10.0, 10.0)))
def test_a_similarity_is_recovered_from_exact_correspondences(points, R, scale, t):
    centred = points - points.mean(0)
    assume(np.linalg.svd(centred, compute_uv=False)[1] > 0.1)  # not (nearly) collinear
    similarity = fit_similarity(points, scale * points @ R.T + t)
    assert np.isclose(similarity.scale, scale, rtol=1e-8)
    np.testing.assert_allclose(similarity.R, R, atol=1e-8)
    np.testing.assert_allclose(similarity.t, t, atol=1e-7)
    np.testing.assert_allclose(similarity.inverse().apply(similarity.apply(points)), points, atol=1e-8)


def _camera_at(center: np.ndarray, focal_px: float, distortion: np.ndarray | None = None) -> Camera:
    """A 1280x720 camera at ``center`` looking at the origin, world z up."""
    z = -center / np.linalg.norm(center)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[focal_px, 0.0, 640.0], [0.0, focal_px, 360.0], [0.0, 0.0, 1.0]])
    return Camera(K, R, -R @ center, 1280, 720, np.zeros(5) if distortion is None else distortion)


centres = st.tuples(st.floats(0.0, 2 * np.pi), st.floats(-0.3, 1.2), st.floats(3.0, 8.0)).map(
    lambda a: a[2] * np.array([np.cos(a[0]) * np.cos(a[1]), np.sin(a[0]) * np.cos(a[1]), np.sin(a[1])]))
lenses = st.tuples(st.floats(-0.35, 0.1), st.floats(-0.05, 0.15), st.floats(-2e-3, 2e-3), st.floats(-2e-3, 2e-3),
                   st.floats(-0.02, 0.02)).map(np.array)
scene_points = arrays(np.float64, (12, 3), elements=st.floats(-0.8, 0.8))


@PROPERTY
@given(centres, st.floats(500.0, 2000.0), lenses, scene_points)
def test_projection_with_distortion_agrees_with_opencv_and_undistorts_back(center, focal_px, distortion, points):
    camera = _camera_at(center, focal_px, distortion)
    pixels, depth = project_points_np(points, camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m,
                                      camera.distortion)
    assert (depth > 0).all()
    expected, _ = cv2.projectPoints(points, cv2.Rodrigues(camera.R_cam_from_world)[0], camera.t_cam_from_world_m,
                                    camera.K, camera.distortion)
    np.testing.assert_allclose(pixels, expected.reshape(-1, 2), atol=1e-6)
    pinhole, _ = project_points_np(points, camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m)
    np.testing.assert_allclose(undistort_points_px(pixels, camera.K, camera.distortion), pinhole, atol=1e-3)


@PROPERTY
@given(st.lists(centres, min_size=2, max_size=5), st.floats(600.0, 1800.0), scene_points)
def test_triangulation_recovers_the_points_its_cameras_see(centers, focal_px, points):
    directions = np.stack([c / np.linalg.norm(c) for c in centers])
    # two cameras looking along (nearly) one line cannot place a point on it
    assume(max(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))) for a in directions for b in directions) > 10.0)
    cameras = [_camera_at(c, focal_px) for c in centers]
    pixels = np.stack([project_points_np(points, c.K, c.R_cam_from_world, c.t_cam_from_world_m)[0] for c in cameras])
    recovered, used = triangulate_dlt(cameras, pixels, np.ones(pixels.shape[:2]))
    assert (used == len(cameras)).all()
    np.testing.assert_allclose(recovered, points, atol=1e-6)
