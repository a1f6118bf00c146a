"""The fitted bodies seen from each camera: their keypoints reprojected, and how far they fall from the detections
the association gave them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.camera import Camera, project_points
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

__all__ = ["FrameFit", "detection_people", "fitted_keypoints", "joint_index", "reprojected_fit"]


def joint_index(joints: pd.Series) -> np.ndarray:
    """(N,) canonical joint indices of a table's ``joint`` column (names, as the tables store them)."""
    return joints.map(JOINT_INDEX).to_numpy(dtype=np.int64)


def fitted_keypoints(motions) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """person id -> ((T,) frames where present, (T, 23, 3) keypoints, world metres) of a
    :class:`humancal.fitting.FittedMotions`."""
    return {int(person_id): (motions.frames[motions.present[i]], motions.keypoints_world_m[i, motions.present[i]])
            for i, person_id in enumerate(motions.person_ids)}


def detection_people(associations: pd.DataFrame | None) -> dict[tuple[int, int, int], int]:
    """(frame, view, det_id) -> person id (-1: rejected) of an ``associations`` table (empty without one)."""
    if associations is None or len(associations) == 0:
        return {}
    return {(int(f), int(v), int(d)): int(p) for f, v, d, p in associations[
        ["frame", "view", "det_id", "person_id"]].itertuples(index=False)}


@dataclass(frozen=True)
class FrameFit:
    """One view at one frame.

    Attributes:
        people: person id -> ((23, 2) reprojected fitted keypoints, pixels; (23,) in front of the camera).
        error_px: mean distance between those keypoints and the confident keypoints of the detections associated
            with the same person in this view, pixels (NaN where none).
    """

    people: dict[int, tuple[np.ndarray, np.ndarray]]
    error_px: float


def reprojected_fit(keypoints_world_m: dict[int, tuple[np.ndarray, np.ndarray]], view: int, camera: Camera,
                    detections: pd.DataFrame, people: dict[tuple[int, int, int], int]) -> dict[int, FrameFit]:
    """frame -> :class:`FrameFit` of one view.

    Args:
        keypoints_world_m: person id -> ((T,) frames, (T, 23, 3) fitted keypoints, world metres).
        view: the view's index (its rows of ``detections`` and keys of ``people``).
        camera: the view's camera (its distortion is applied).
        detections: the view's rows of a ``raw_detections`` table.
        people: :func:`detection_people` of the association.
    """
    by_frame = {int(f): rows for f, rows in detections.groupby("frame")}
    per_frame: dict[int, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
    for person_id, (frames, keypoints) in keypoints_world_m.items():
        pixels, depth = project_points(camera, keypoints.reshape(-1, 3))
        pixels = pixels.reshape(len(frames), NUM_JOINTS, 2)
        in_front = depth.reshape(len(frames), NUM_JOINTS) > 0
        for frame, px, ok in zip(frames, pixels, in_front):
            per_frame.setdefault(int(frame), {})[int(person_id)] = (px, ok)
    out = {}
    for frame, fitted in per_frame.items():
        errors: list[float] = []
        rows = by_frame.get(frame)
        if rows is not None:
            for det_id, det in rows.groupby("det_id"):
                person_id = people.get((frame, view, int(det_id)))
                if person_id not in fitted:
                    continue
                px, ok = fitted[person_id]
                seen = det[det["score"] > 0]
                index = joint_index(seen["joint"])
                distance = np.linalg.norm(px[index] - seen[["x_px", "y_px"]].to_numpy(), axis=1)
                errors += distance[np.isfinite(distance) & ok[index]].tolist()
        out[frame] = FrameFit(fitted, float(np.mean(errors)) if errors else float("nan"))
    return out
