"""What a body fit sees: each person's 2D keypoints in every view, and their triangulated 3D joints.

Built from the association's output (``associations``: the person of every detection; ``skeletons3d``: each
person's triangulated joints), never from ground truth. Arrays are dense over (view, person, frame) so that the
fit is one batched computation; absent observations have confidence 0.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from humancal.camera import CameraRig
from humancal.keypoints import FLIP_INDEX, JOINT_INDEX, NUM_JOINTS
from humancal.tables.associations import Associations
from humancal.tables.detections import DenseDetections

__all__ = ["BodyObservations", "FittingInputError", "body_observations", "unswap_left_right"]


class FittingInputError(ValueError):
    """The inputs of a body fit cannot give a fit (no people, a person seen in one view only, non-finite values);
    the message names the table, the person and what is wrong."""


@dataclass(frozen=True)
class BodyObservations:
    """The detections of P tracked people over T frames, seen by V views.

    Attributes:
        person_ids: (P,) the association's person ids.
        frames: (T,) consecutive frame numbers, the first to the last frame any person was seen.
        keypoints_px: (V, P, T, 23, 2) canonical keypoints in pixels (0 where not observed).
        confidence: (V, P, T, 23) detector confidence in [0, 1]; 0 where not observed.
        joints_world_m: (P, T, 23, 3) triangulated joints (``skeletons3d``), world metres (0 where not valid).
        joints_valid: (P, T, 23) True where ``joints_world_m`` holds a triangulated (or gap-filled) joint.
        present: (P, T) True from each person's first to last frame with a detection.
    """

    person_ids: np.ndarray
    frames: np.ndarray
    keypoints_px: np.ndarray
    confidence: np.ndarray
    joints_world_m: np.ndarray
    joints_valid: np.ndarray
    present: np.ndarray

    @property
    def num_views(self) -> int:
        return int(self.keypoints_px.shape[0])

    @property
    def num_people(self) -> int:
        return int(len(self.person_ids))

    @property
    def num_frames(self) -> int:
        return int(len(self.frames))

    def select_people(self, rows: np.ndarray) -> BodyObservations:
        """The observations of a subset of the people (``rows`` index the person axis)."""
        rows = np.asarray(rows)
        return BodyObservations(self.person_ids[rows], self.frames, self.keypoints_px[:, rows],
                                self.confidence[:, rows], self.joints_world_m[rows], self.joints_valid[rows],
                                self.present[rows])

    def every_other_frame(self) -> BodyObservations:
        """The observations of frames 0, 2, 4, ... (``frames`` then steps by 2): the sequence at half its rate."""
        return self.every_nth_frame(2)

    def every_nth_frame(self, n: int) -> BodyObservations:
        """The observations of frames 0, n, 2n, ... (``frames`` then steps by ``n`` >= 1)."""
        return BodyObservations(self.person_ids, self.frames[::n], self.keypoints_px[:, :, ::n],
                                self.confidence[:, :, ::n], self.joints_world_m[:, ::n], self.joints_valid[:, ::n],
                                self.present[:, ::n])


def body_observations(detections: DenseDetections, associations: pd.DataFrame, skeletons3d: pd.DataFrame,
                      num_views: int, *, min_views: int = 2, min_frames: int = 3) -> tuple[BodyObservations, list[str]]:
    """Dense per-person observations from the association's tables.

    People who are seen in fewer than ``min_views`` views over the whole sequence, or in fewer than ``min_frames``
    frames, cannot be fitted reliably (a single view leaves depth unknown; three frames give a motion prior
    nothing): they are left out, with a warning naming them.

    Args:
        detections: every detection of the sequence (2D keypoints and confidences).
        associations: ``associations`` table (the person of each detection, -1 rejected).
        skeletons3d: ``skeletons3d`` table (each person's triangulated joints).
        num_views: V, the number of cameras.
        min_views: fewest distinct views a person must be seen in.
        min_frames: fewest frames a person must be seen in.

    Returns:
        The observations and the warnings (people left out, and why).

    Raises:
        FittingInputError: no person remains, a detection's keypoints are not finite where confident, or the
            skeletons name a person the associations do not.
    """
    person_of = Associations.from_table(associations).person_of_detections(detections)
    people = _people_to_fit(detections, person_of, min_views, min_frames)
    index = _dense_index(detections, person_of, people.person_ids, num_views)
    keypoints, confidence, present = _dense_detections(detections, index, num_views)
    joints, joints_valid = _dense_joints(skeletons3d, people, index)
    observations = BodyObservations(people.person_ids, index.frames, keypoints, confidence, joints, joints_valid,
                                    present)
    return observations, list(people.warnings)


@dataclass(frozen=True)
class _PeopleToFit:
    """Who a body fit takes.

    Attributes:
        person_ids: (P,) int64 ids of the people fitted, ascending.
        associated: ids of every person some detection belongs to (fitted or left out), ascending.
        warnings: the people left out, and why.
    """

    person_ids: np.ndarray
    associated: np.ndarray
    warnings: tuple[str, ...]


def _people_to_fit(detections: DenseDetections, person_of: np.ndarray, min_views: int,
                   min_frames: int) -> _PeopleToFit:
    """The people seen in at least ``min_views`` views and ``min_frames`` frames (``person_of``: (D,) the person
    of each detection, -1 none); a warning names each one left out.

    Raises:
        FittingInputError: no detection belongs to a person, or no person is seen enough.
    """
    used = person_of >= 0
    if not used.any():
        raise FittingInputError("associations: no detection belongs to a person (every person_id is -1): "
                                "nothing to fit")
    warnings: list[str] = []
    candidates = np.unique(person_of[used])
    keep = []
    for pid in candidates.tolist():
        mine = person_of == pid
        views, frames = np.unique(detections.view[mine]), np.unique(detections.frame[mine])
        if len(views) < min_views or len(frames) < min_frames:
            warnings.append(f"person {pid} left out of the body fit: seen in {len(views)} view(s) over {len(frames)} "
                            f"frame(s) (needs >= {min_views} views and >= {min_frames} frames)")
            continue
        keep.append(pid)
    if not keep:
        raise FittingInputError(f"no person can be fitted: {'; '.join(warnings)}")
    return _PeopleToFit(np.asarray(keep, dtype=np.int64), candidates, tuple(warnings))


@dataclass(frozen=True)
class _DenseIndex:
    """Where the fitted people's detections go in the dense (view, person, frame) arrays.

    Attributes:
        rows: (D,) the rows of those detections in the detections.
        view, person, frame: (D,) their view v, person p and frame t indices in the dense arrays.
        frames: (T,) consecutive frame numbers, the first to the last frame any fitted person was seen
            (``t = frame number - frames[0]``).
        num_people: P.
    """

    rows: np.ndarray
    view: np.ndarray
    person: np.ndarray
    frame: np.ndarray
    frames: np.ndarray
    num_people: int


def _dense_index(detections: DenseDetections, person_of: np.ndarray, person_ids: np.ndarray,
                 num_views: int) -> _DenseIndex:
    """The dense index of every detection of the people ``person_ids`` (``person_of``: (D,) the person of each
    detection).

    Raises:
        FittingInputError: a view number outside ``0 .. num_views - 1``.
    """
    rows = np.flatnonzero(np.isin(person_of, person_ids))
    first, last = int(detections.frame[rows].min()), int(detections.frame[rows].max())
    frames = np.arange(first, last + 1)
    if (detections.view[rows] >= num_views).any() or (detections.view[rows] < 0).any():
        raise FittingInputError(f"detections: view numbers must be 0..{num_views - 1} (the cameras), got "
                                f"{sorted(set(detections.view[rows].tolist()))}")
    return _DenseIndex(rows=rows, view=detections.view[rows], person=np.searchsorted(person_ids, person_of[rows]),
                       frame=detections.frame[rows] - first, frames=frames, num_people=len(person_ids))


def _dense_detections(detections: DenseDetections, index: _DenseIndex,
                      num_views: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (V, P, T, 23, 2) keypoints in pixels and (V, P, T, 23) confidences of the fitted people (0 where not
    observed; of two detections of a person in one view and frame, the more confident), and (P, T) ``present``:
    each person's first to last frame with a detection.

    Raises:
        FittingInputError: a keypoint with a score > 0 is not finite.
    """
    P, T = index.num_people, len(index.frames)
    rows = index.rows
    keypoints = np.zeros((num_views, P, T, NUM_JOINTS, 2))
    confidence = np.zeros((num_views, P, T, NUM_JOINTS))
    scores = np.where(detections.valid[rows], detections.scores[rows], 0.0)
    points = detections.keypoints_px[rows]
    bad = (scores > 0) & ~np.isfinite(points).all(-1)
    if bad.any():
        r = rows[np.argwhere(bad)[0][0]]
        raise FittingInputError(f"detections: frame {detections.frame[r]}, view {detections.view[r]}, det_id "
                                f"{detections.det_id[r]} has a non-finite keypoint with score > 0 (x_px, y_px must "
                                f"be finite numbers wherever score > 0)")
    v_idx, p_idx, t_idx = index.view, index.person, index.frame
    # One detection per (view, person, frame): where the association gave a person two, keep the more confident.
    order = np.argsort(scores.sum(-1), kind="stable")
    keypoints[v_idx[order], p_idx[order], t_idx[order]] = np.nan_to_num(points[order])
    confidence[v_idx[order], p_idx[order], t_idx[order]] = np.clip(scores[order], 0.0, 1.0)
    present = np.zeros((P, T), bool)
    seen = np.zeros((P, T), bool)
    seen[p_idx, t_idx] = True
    for p in range(P):
        on = np.flatnonzero(seen[p])
        present[p, on[0]: on[-1] + 1] = True
    return keypoints, confidence, present


def _dense_joints(skeletons3d: pd.DataFrame, people: _PeopleToFit,
                  index: _DenseIndex) -> tuple[np.ndarray, np.ndarray]:
    """The fitted people's (P, T, 23, 3) triangulated joints, world metres, and their (P, T, 23) validity (valid
    rows with finite coordinates; 0 and False elsewhere).

    Raises:
        FittingInputError: the skeletons name a person no detection belongs to, or a fitted person has no valid
            joint.
    """
    person_ids, P, T = people.person_ids, index.num_people, len(index.frames)
    first, last = int(index.frames[0]), int(index.frames[-1])
    joints = np.zeros((P, T, NUM_JOINTS, 3))
    joints_valid = np.zeros((P, T, NUM_JOINTS), bool)
    sk = skeletons3d[skeletons3d["person_id"].isin(person_ids) & skeletons3d["frame"].between(first, last)]
    unknown = sorted(set(skeletons3d["person_id"].unique().tolist()) - set(people.associated.tolist()))
    if unknown:
        raise FittingInputError(f"skeletons3d: person ids {unknown[:5]} are in no association")
    if len(sk):
        sp = np.searchsorted(person_ids, sk["person_id"].to_numpy())
        st = sk["frame"].to_numpy() - first
        sj = sk["joint"].map(JOINT_INDEX).to_numpy()
        xyz = sk[["x_m", "y_m", "z_m"]].to_numpy(np.float64)
        ok = sk["valid"].to_numpy(bool) & np.isfinite(xyz).all(-1)
        joints[sp[ok], st[ok], sj[ok]] = xyz[ok]
        joints_valid[sp[ok], st[ok], sj[ok]] = True
    no_3d = [int(person_ids[p]) for p in range(P) if not joints_valid[p].any()]
    if no_3d:
        raise FittingInputError(f"skeletons3d: persons {no_3d} have no valid triangulated joint: a body cannot be "
                                f"placed without one")
    return joints, joints_valid


MIN_SWAP_JOINTS = 6
"""Joints a detection must share with its person's triangulated joints to be compared with them."""


def unswap_left_right(observations: BodyObservations, rig: CameraRig, *, min_error_px: float = 15.0,
                      ratio: float = 0.5) -> tuple[BodyObservations, int]:
    """Swap back the left and right joints of the detections the detector mirrored.

    A detector sometimes labels a person's left joints as right and the other way round. The association keeps
    such a detection with its person (the triangulation drops its swapped joints view by view), but a body fit
    would be pulled toward the mirrored pose. A detection is swapped back when, against its person's triangulated
    joints projected by ``rig``, its median reprojection error is above ``min_error_px`` as it is and below
    ``ratio`` times that with its left and right joints swapped (median over the joints it shares with the
    triangulated ones, at least ``MIN_SWAP_JOINTS``).

    Args:
        observations: the people's detections and triangulated joints (:func:`body_observations`).
        rig: the V cameras of the detections.
        min_error_px: a detection closer than this as it is is left alone, pixels.
        ratio: how much closer the swapped detection must be, in (0, 1).

    Returns:
        The observations with those detections swapped, and how many were.
    """
    if not 0.0 < ratio < 1.0:
        raise ValueError(f"unswap_left_right: ratio must lie in (0, 1), got {ratio}")
    V, P, T = observations.confidence.shape[:3]
    if V != len(rig):
        raise FittingInputError(f"unswap_left_right: detections of {V} views, but {len(rig)} cameras")
    projected, _ = rig.project(observations.joints_world_m.reshape(-1, 3))  # (V, P*T*23, 2)
    projected = projected.reshape(V, P, T, NUM_JOINTS, 2)
    flip = list(FLIP_INDEX)

    def median_error(points: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        shared = (confidence > 0) & observations.joints_valid[None] & np.isfinite(projected).all(-1)
        error = np.where(shared, np.linalg.norm(projected - points, axis=-1), np.nan)
        enough = shared.sum(-1) >= MIN_SWAP_JOINTS
        out = np.full(enough.shape, np.nan)
        out[enough] = np.nanmedian(error[enough], axis=-1)
        return out, enough

    as_is, enough = median_error(observations.keypoints_px, observations.confidence)
    swapped, enough_swapped = median_error(observations.keypoints_px[..., flip, :],
                                           observations.confidence[..., flip])
    swap = enough & enough_swapped & (as_is > min_error_px) & (swapped < ratio * as_is)
    if not swap.any():
        return observations, 0
    keypoints = observations.keypoints_px.copy()
    confidence = observations.confidence.copy()
    keypoints[swap] = keypoints[swap][:, flip]
    confidence[swap] = confidence[swap][:, flip]
    return replace(observations, keypoints_px=keypoints, confidence=confidence), int(swap.sum())
