"""Picture of a calibrated rig beside the ground truth, with the people's floor positions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from humancal.baselines import triangulate_identified
from humancal.calibration import plot_rigs
from humancal.camera import CameraRig

__all__ = ["people_floor_points_m", "plot_rig_comparison"]

_ANKLES = ("left_ankle", "right_ankle")


def people_floor_points_m(
    cameras: CameraRig, detections: pd.DataFrame, associations: pd.DataFrame, max_points: int = 3000,
    max_frames: int = 300,
) -> np.ndarray:
    """Floor positions (ankle midpoint with z = 0) of the identified people triangulated with ``cameras``, in at
    most ``max_frames`` frames evenly spread over the sequence (a picture needs no more).

    Returns:
        (N, 3) points in the cameras' world, metres, at most ``max_points`` (evenly subsampled).
    """
    ankle_rows = detections[detections["joint"].isin(_ANKLES)]  # each joint is triangulated on its own
    frames = np.unique(ankle_rows["frame"].to_numpy())
    if len(frames) > max_frames:
        kept = frames[np.linspace(0, len(frames) - 1, max_frames).round().astype(int)]
        ankle_rows = ankle_rows[ankle_rows["frame"].isin(kept)]
    poses = triangulate_identified(ankle_rows, associations, cameras, "")
    ankles = poses[poses["joint"].isin(_ANKLES) & poses["valid"]]
    both = ankles.groupby(["frame", "person_id"])[["x_m", "y_m", "z_m"]].agg(["mean", "count"])
    both = both[both[("x_m", "count")] == 2]
    points = np.stack([both[("x_m", "mean")], both[("y_m", "mean")], np.zeros(len(both))], axis=1)
    if len(points) > max_points:
        points = points[np.linspace(0, len(points) - 1, max_points).round().astype(int)]
    return points


def plot_rig_comparison(
    estimated: CameraRig,
    ground_truth: CameraRig,
    detections: pd.DataFrame,
    associations: pd.DataFrame,
    path_png: str | Path,
    title: str,
) -> Path:
    """PNG (top and side view) of the estimated rig, brought onto the ground truth by the similarity of the
    camera centres, beside the true rig; the people (ground-truth identities, evaluation only) triangulated
    with the estimated cameras are drawn on the floor."""
    floor = people_floor_points_m(estimated, detections, associations)
    return plot_rigs(estimated, ground_truth, floor, path_png, title=title)
