"""The asset pages' pictures of a capture: people per view over time, and the fit's error per view over time."""

from __future__ import annotations

import numpy as np
import pandas as pd

from humancal.camera import cameras_from_table
from humancal.fitting import FittedMotions
from humancal.synthetic import generate_scene, preset
from humancal.viewing.pictures import people_per_view_frame, plot_detections_over_time, plot_reprojection_errors
from humancal.viewing.reprojection import fitted_keypoints


def _person(frame: int, view: int, det_id: int, joints: int) -> pd.DataFrame:
    return pd.DataFrame({"sequence": "s", "frame": frame, "view": view, "det_id": det_id,
                         "joint": [f"j{j}" for j in range(6)], "x_px": 1.0, "y_px": 1.0,
                         "score": [0.9] * joints + [0.0] * (6 - joints)})


def test_people_are_counted_per_view_and_frame_with_enough_joints():
    table = pd.concat([_person(3, 0, 0, 6), _person(3, 0, 1, 5), _person(3, 1, 0, 3),  # view 1: too few joints
                       _person(5, 1, 0, 4), _person(6, 0, 2, 6)])
    frames, people = people_per_view_frame(table, 3)
    assert frames.tolist() == [3, 4, 5, 6]
    assert people.tolist() == [[2, 0, 0, 1], [0, 0, 1, 0], [0, 0, 0, 0]]  # view 2 saw nobody: a row of zeros
    assert people_per_view_frame(table.iloc[:0], 2)[1].shape == (2, 0)


def test_pictures_of_a_synthetic_capture(body_model, tmp_path):
    import cv2

    scene = generate_scene(preset("tiny", num_frames=8, num_people=2, num_views=3, seed=2), body_model, sequence="p")
    names = ["north", "east", "south"]
    path = plot_detections_over_time(scene.detections, names, tmp_path / "detections.png")
    keypoints = fitted_keypoints(FittedMotions.from_table(scene.motions, scene.config.fps))
    errors = plot_reprojection_errors(keypoints, cameras_from_table(scene.cameras), scene.detections,
                                      scene.associations, names, tmp_path / "errors.png")
    for png in (path, errors):
        image = cv2.imread(str(png))
        assert image is not None and image.shape[1] > 600 and image.std() > 5  # drawn, not blank
        assert png.stat().st_size < 150_000  # small enough for the asset page
    assert np.isfinite(people_per_view_frame(scene.detections, 3)[1]).all()
