"""Penetration measured on meshes: analytic spheres, then anny bodies through ``FittedMotions``."""

import numpy as np
import pytest
import torch
import trimesh

from evaluation.contact_metrics import evaluated_frames, pair_penetration, penetration_figures, skin_vertices
from humancal.fitting import INITIAL_PHENOTYPES, FittedMotions


@pytest.mark.parametrize("distance_m", [0.45, 0.8, 1.2])
def test_two_spheres_give_the_lens(distance_m):
    """Two balls of radius r, d apart: the deepest surface point of one inside the other is r - |d - r| deep, and
    they share the lens pi (4r + d)(2r - d)^2 / 12."""
    r = 0.5
    ball = trimesh.creation.icosphere(subdivisions=4, radius=r)
    vertices, faces = np.asarray(ball.vertices), np.asarray(ball.faces)
    skin = skin_vertices(faces, len(vertices))
    assert skin.all()
    depth, volume = pair_penetration(vertices, vertices + [distance_m, 0.0, 0.0], faces, skin, grid_m=0.02)
    expected_depth = max(r - abs(distance_m - r), 0.0) if distance_m < 2 * r else 0.0
    expected_volume = np.pi * (4 * r + distance_m) * (2 * r - distance_m) ** 2 / 12 if distance_m < 2 * r else 0.0
    assert depth == pytest.approx(expected_depth, abs=0.005)
    assert volume == pytest.approx(expected_volume, rel=0.03, abs=1e-9)


def test_evaluated_frames_need_two_people():
    present = np.array([[1, 1, 1, 0, 1, 1], [0, 1, 1, 1, 1, 1]], bool)
    np.testing.assert_array_equal(evaluated_frames(present, 10), [1, 2, 4, 5])
    np.testing.assert_array_equal(evaluated_frames(present, 2), [1, 5])


def _motions(body, shifts_m, present):
    """Two average adults in the reference pose, the second moved by ``shifts_m`` (T, 3) in each frame."""
    T = len(shifts_m)
    phenotypes = torch.tensor([INITIAL_PHENOTYPES] * 2, dtype=body.dtype)
    rotations = body.identity_pose(2, T)
    translation = torch.zeros(2, T, 3, dtype=body.dtype)
    translation[1] = torch.as_tensor(np.asarray(shifts_m), dtype=body.dtype)
    with torch.no_grad():
        keypoints = body.keypoints(body.rest_skeleton(phenotypes), rotations, translation)
    as_np = lambda t: t.double().numpy()  # noqa: E731
    return FittedMotions(person_ids=np.array([0, 1]), frames=np.arange(T), present=np.asarray(present, bool),
                         phenotypes=as_np(phenotypes), bone_rotmats_local=as_np(rotations),
                         root_translation_m=as_np(translation), keypoints_world_m=as_np(keypoints), fps=30.0)


def test_anny_bodies(body_model):
    # frame 0: 0.3 m beside itself; frame 1: 2 m apart; frame 2: beside itself, but the second person is absent
    shifts = [[0.3, 0.0, 0.0], [2.0, 0.0, 0.0], [0.3, 0.0, 0.0]]
    figures = penetration_figures(body_model, _motions(body_model, shifts, [[1, 1, 1], [1, 1, 0]]), grid_m=0.02)
    alone = penetration_figures(body_model, _motions(body_model, shifts[:1], [[1], [1]]), grid_m=0.02)
    assert figures["evaluated_frames"] == 2 and alone["evaluated_frames"] == 1
    # a body 0.3 m beside itself (arms through the other's arm and torso): centimetres deep, litres shared
    assert 30 < alone["penetration_depth_mm"] < 200 and 1e3 < alone["penetration_volume_cm3"] < 6e4
    assert figures["penetration_depth_mm"] == pytest.approx(alone["penetration_depth_mm"] / 2)
    assert figures["penetration_volume_cm3"] == pytest.approx(alone["penetration_volume_cm3"] / 2)
    apart = penetration_figures(body_model, _motions(body_model, shifts[1:2], [[1], [1]]), grid_m=0.02)
    assert apart["penetration_depth_mm"] == 0.0 and apart["penetration_volume_cm3"] == 0.0
    nobody = penetration_figures(body_model, _motions(body_model, shifts[:1], [[1], [0]]))
    assert nobody["evaluated_frames"] == 0 and np.isnan(nobody["penetration_depth_mm"])
