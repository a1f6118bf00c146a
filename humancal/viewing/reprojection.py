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
    projected: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    out_people: dict[int, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
    for person_id, (frames, keypoints) in keypoints_world_m.items():
        pixels, depth = project_points(camera, keypoints.reshape(-1, 3))
        pixels = pixels.reshape(len(frames), NUM_JOINTS, 2)
        in_front = depth.reshape(len(frames), NUM_JOINTS) > 0
        order = np.argsort(frames, kind="stable")
        projected[int(person_id)] = (np.asarray(frames, dtype=np.int64)[order], pixels[order], in_front[order])
        for frame, px, ok in zip(frames, pixels, in_front):
            out_people.setdefault(int(frame), {})[int(person_id)] = (px, ok)
    sums, counts = _error_sums(projected, view, detections, people)
    return {frame: FrameFit(fitted, sums[frame] / counts[frame] if frame in counts else float("nan"))
            for frame, fitted in out_people.items()}


def _error_sums(projected: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]], view: int,
                detections: pd.DataFrame, people: dict[tuple[int, int, int], int]
                ) -> tuple[dict[int, float], dict[int, int]]:
    """Per frame, the sum of the distances (pixels) between the confident detected keypoints of ``view`` and the
    same person's reprojected fitted keypoints (in front of the camera, finite), and their count; frames without
    any are left out. ``projected``: person id -> ((T,) increasing frames, (T, 23, 2) pixels, (T, 23) in front).
    Vectorised over the detection rows (a capture has hundreds of thousands)."""
    seen = detections[detections["score"] > 0]
    frame = seen["frame"].to_numpy(dtype=np.int64)
    det_id = seen["det_id"].to_numpy(dtype=np.int64)
    person = np.fromiter((people.get((f, view, d), -1) for f, d in zip(frame.tolist(), det_id.tolist())),
                         dtype=np.int64, count=len(seen))
    joint = joint_index(seen["joint"])
    detected_px = seen[["x_px", "y_px"]].to_numpy(dtype=np.float64)
    distance = np.full(len(seen), np.nan)
    for person_id, (frames, pixels, in_front) in projected.items():
        rows = np.flatnonzero(person == person_id)
        if len(frames) == 0 or len(rows) == 0:
            continue
        slot = np.searchsorted(frames, frame[rows]).clip(max=len(frames) - 1)
        fitted = frames[slot] == frame[rows]
        rows, slot = rows[fitted], slot[fitted]
        ok = in_front[slot, joint[rows]]
        distance[rows[ok]] = np.linalg.norm(pixels[slot[ok], joint[rows[ok]]] - detected_px[rows[ok]], axis=1)
    keep = np.isfinite(distance)
    unique, inverse = np.unique(frame[keep], return_inverse=True)
    sums = np.bincount(inverse, weights=distance[keep], minlength=len(unique))
    counts = np.bincount(inverse, minlength=len(unique))
    return ({int(f): float(s) for f, s in zip(unique, sums)}, {int(f): int(c) for f, c in zip(unique, counts)})
