"""Shelf (Belagiannis et al., CVPR 2014) as shipped by 4D Association: cameras, ground truth, OpenPose candidates.

The folder (``humancal.settings.dataset_dir("shelf_4dassoc")``) holds ``calibration.json`` (5 cameras),
``gt.txt`` (SHELF15 ground truth, 301 frames) and ``detection/<view>.txt`` (ungrouped OpenPose BODY_25 joint
candidates and part-affinity scores). :func:`load_shelf` reads everything, groups the candidates into people
(:mod:`humancal.grouping`) and returns canonical tables. File formats: ``docs/shelf.md``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from humancal.camera import CameraRig
from humancal.formats import FormatError, get_skeleton, read_cameras
from humancal.formats.detections.table import IMAGE_SIZE_ATTR
from humancal.grouping import CandidateFrame, GroupingConfig, group_detections
from humancal.grouping.body25 import BODY25_JOINTS, BODY25_LIMBS
from humancal.tables.schemas import validate_table

__all__ = [
    "SHELF15_JOINTS",
    "SHELF_SEQUENCE",
    "ShelfSequence",
    "load_shelf",
    "read_candidate_file",
    "read_shelf_gt",
    "shelf_gt_table",
]

logger = logging.getLogger(__name__)

SHELF_SEQUENCE = "test"
"""Sequence name of the 301 Shelf frames (the usual test range 300-600)."""

SHELF15_JOINTS: tuple[str, ...] = get_skeleton("shelf15").joints
"""SHELF15 joint names in the ground truth's array order (``bottom_head`` is the neck), from the skeleton registry:
right_ankle, right_knee, right_hip, left_hip, left_knee, left_ankle, right_wrist, right_elbow, right_shoulder,
left_shoulder, left_elbow, left_wrist, bottom_head, top_head, pelvis."""

NUM_GT_PERSONS = 4
"""Ground-truth person ids are 0..3."""

_BODY25_FILE_TYPE = 4
"""Skeleton type code of BODY_25 in 4D Association's files (SKEL19=0, SKEL17=1, SKEL15=2, COCO18=3, BODY25=4)."""


@dataclass(frozen=True)
class ShelfSequence:
    """The Shelf test sequence in canonical form.

    Attributes:
        detections: canonical ``detections`` table (sequence "test", frames 0..300, views 0..4), grouped people with
            the canonical 23 joints in pixels; only detected joints have rows; ``attrs["image_size_px"]`` holds
            ``{view: (width_px, height_px)}`` as the shared detection readers leave it.
        cameras: the rig of the 5 calibrated cameras, view order.
        gt_poses: canonical ``poses3d`` table of the ground truth, ``joint`` holding :data:`SHELF15_JOINTS` names,
            metres, world Z up.
        gt_joints_world_m: (frame, 4, 15, 3) the same ground truth as an array indexed by person id; NaN where a
            person is absent.
        gt_present: (frame, 4) whether person id p is annotated in the frame.
        image_size_px: per view (width, height) in pixels.
        sequence: the sequence name ("test").
    """

    detections: pd.DataFrame
    cameras: CameraRig
    gt_poses: pd.DataFrame
    gt_joints_world_m: np.ndarray
    gt_present: np.ndarray
    image_size_px: tuple[tuple[int, int], ...]
    sequence: str = SHELF_SEQUENCE

    @property
    def num_frames(self) -> int:
        """Number of frames."""
        return int(self.gt_present.shape[0])

    @property
    def num_views(self) -> int:
        """Number of views."""
        return len(self.cameras)


class _Tokens:
    """Whitespace-separated numbers of one text file, consumed in order, with errors that name the field."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"Shelf file {self.path} does not exist")
        self._text = self.path.read_text()
        self.tokens = self._text.split()
        try:
            self.values = np.array(self.tokens, dtype=np.float64)
        except ValueError:
            self.values = np.array([_to_float(t) for t in self.tokens], dtype=np.float64)
        self.pos = 0
        # Fast path: when every number is finite and >= 0, fields bounded below by 0 need no check of their own.
        self._all_non_negative = bool(np.isfinite(self.values).all() and (self.values >= 0).all())

    def take(self, n: int, field: str, *, low: float = -np.inf, high: float = np.inf) -> np.ndarray:
        """The next ``n`` numbers of ``field``, checked finite and within [low, high]."""
        left = len(self.values) - self.pos
        if n > left:
            raise FormatError(self.path, field, f"{n} value(s)", f"{left} before the end of the file (truncated?)")
        out = self.values[self.pos : self.pos + n]
        if self._all_non_negative and low <= 0 and high == np.inf:
            self.pos += n
            return out
        bad = ~(np.isfinite(out) & (out >= low) & (out <= high))
        if bad.any():
            i = self.pos + int(np.argmax(bad))
            if np.isinf(high):
                expected = "finite numbers" if np.isinf(low) else f"finite numbers >= {low:g}"
            else:
                expected = f"numbers in [{low:g}, {high:g}]"
            raise FormatError(self.path, f"{field} (line {self._line_of(i)})", expected, f"'{self.tokens[i]}'")
        self.pos += n
        return out

    def take_count(self, field: str) -> int:
        """The next number as a non-negative integer count."""
        if self.pos >= len(self.values):
            raise FormatError(self.path, field, "a count", "the end of the file (truncated?)")
        value = self.values[self.pos]
        if not (np.isfinite(value) and value >= 0 and value == int(value)):
            raise FormatError(
                self.path,
                f"{field} (line {self._line_of(self.pos)})",
                "a non-negative integer",
                f"'{self.tokens[self.pos]}'",
            )
        self.pos += 1
        return int(value)

    def finish(self, what: str) -> None:
        """Raise unless every number was consumed."""
        extra = len(self.values) - self.pos
        if extra:
            raise FormatError(
                self.path,
                f"line {self._line_of(self.pos)}",
                f"the end of the file after {what}",
                f"{extra} more value(s): the counts in the file do not match its contents",
            )

    def _line_of(self, token_index: int) -> int:
        counts = np.cumsum([len(line.split()) for line in self._text.splitlines()])
        return int(np.searchsorted(counts, token_index, side="right")) + 1


def _to_float(token: str) -> float:
    try:
        return float(token)
    except ValueError:
        return np.nan


def read_candidate_file(path: str | Path, width_px: int, height_px: int) -> list[CandidateFrame]:
    """Read one ``detection/<view>.txt``: BODY_25 joint candidates and PAF scores per frame.

    Layout (4D Association): a header ``4 <frames>`` (4 = BODY_25); per frame, for each of the 25 BODY_25 joints a
    count ``n`` and three rows of ``n`` values (x / image width, y / image height, score); then for each of the 26
    limbs of :data:`~humancal.grouping.body25.BODY25_LIMBS` an ``n_a x n_b`` row-major matrix of PAF scores.
    Every number of the file must be consumed exactly.

    Args:
        path: the text file.
        width_px: image width, pixels (normalized x is multiplied by it).
        height_px: image height, pixels.

    Returns:
        One :class:`CandidateFrame` per frame, positions in pixels, limbs :data:`BODY25_LIMBS`.

    Raises:
        ValueError: the image size is not positive.
        FileNotFoundError: the file does not exist.
        humancal.formats.FormatError: wrong header, truncated file, non-integer counts, non-numeric / NaN /
            negative values, or numbers left over; the message names the file, frame, field and expected form.
    """
    if not (width_px > 0 and height_px > 0):
        raise ValueError(f"read_candidate_file: image size must be positive, got {width_px} x {height_px} px")
    tokens = _Tokens(Path(path))
    skeleton = tokens.take_count("header skeleton type")
    if skeleton != _BODY25_FILE_TYPE:
        raise FormatError(tokens.path, "header skeleton type", f"{_BODY25_FILE_TYPE} (BODY_25)", f"{skeleton}")
    num_frames = tokens.take_count("header frame count")
    frames = []
    for f in range(num_frames):
        xy, score = [], []
        for j, name in enumerate(BODY25_JOINTS):
            field = f"frame {f}, joint {j} ({name})"
            n = tokens.take_count(f"{field} candidate count")
            x = tokens.take(n, f"{field} x row (x / image width)")
            y = tokens.take(n, f"{field} y row (y / image height)")
            s = tokens.take(n, f"{field} score row", low=0.0)
            positions = np.empty((n, 2))
            positions[:, 0], positions[:, 1] = x * width_px, y * height_px
            xy.append(positions)
            score.append(s.copy())
        paf = []
        for k, (a, b) in enumerate(BODY25_LIMBS):
            na, nb = len(score[a]), len(score[b])
            m = tokens.take(
                na * nb,
                f"frame {f}, limb {k} ({BODY25_JOINTS[a]}, {BODY25_JOINTS[b]}) PAF matrix ({na} x {nb})",
                low=0.0,
            )
            paf.append(m.reshape(na, nb).copy())
        frames.append(CandidateFrame(tuple(xy), tuple(score), tuple(paf), BODY25_LIMBS))
    tokens.finish(f"the {num_frames} frame(s) announced in the header")
    return frames


def read_shelf_gt(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read ``gt.txt``: SHELF15 ground-truth joints per frame and person id.

    Layout: a header ``15 <frames>``; per frame the number of people, then per person its id (0..3) and four rows of
    15 values: X, Y, Z (metres, world frame, Z up) and validity (0 or 1).

    Returns:
        joints_world_m: (frame, 4, 15, 3) joints by person id, metres; NaN where the person is not annotated.
        present: (frame, 4) bool, person id annotated in the frame.
        valid: (frame, 4, 15) bool, the file's validity row (False where the person is absent).

    Raises:
        FileNotFoundError: the file does not exist.
        humancal.formats.FormatError: wrong header, truncated file, bad counts or ids, repeated ids, non-finite
            values or numbers left over; the message names the file, frame, field and expected form.
    """
    tokens = _Tokens(Path(path))
    num_joints = tokens.take_count("header joint count")
    if num_joints != len(SHELF15_JOINTS):
        raise FormatError(tokens.path, "header joint count", f"{len(SHELF15_JOINTS)} (SHELF15)", f"{num_joints}")
    num_frames = tokens.take_count("header frame count")
    joints = np.full((num_frames, NUM_GT_PERSONS, num_joints, 3), np.nan)
    present = np.zeros((num_frames, NUM_GT_PERSONS), dtype=bool)
    valid = np.zeros((num_frames, NUM_GT_PERSONS, num_joints), dtype=bool)
    for f in range(num_frames):
        n = tokens.take_count(f"frame {f} person count")
        for i in range(n):
            pid = tokens.take_count(f"frame {f}, person {i} id")
            if pid >= NUM_GT_PERSONS or present[f, pid]:
                expected = f"an id in 0..{NUM_GT_PERSONS - 1}, once per frame"
                raise FormatError(tokens.path, f"frame {f}, person {i} id", expected, f"{pid}")
            for c, axis in enumerate("XYZ"):
                joints[f, pid, :, c] = tokens.take(num_joints, f"frame {f}, person id {pid} {axis} row (metres)")
            v = tokens.take(num_joints, f"frame {f}, person id {pid} validity row", low=0.0, high=1.0)
            present[f, pid] = True
            valid[f, pid] = v > 0.5
    tokens.finish(f"the {num_frames} frame(s) announced in the header")
    return joints, present, valid


def shelf_gt_table(
    joints_world_m: np.ndarray, present: np.ndarray, valid: np.ndarray, sequence: str = SHELF_SEQUENCE
) -> pd.DataFrame:
    """The canonical ``poses3d`` table of the Shelf ground truth, ``joint`` holding :data:`SHELF15_JOINTS` names.

    Args:
        joints_world_m: (frame, person, 15, 3) joints, metres, world Z up.
        present: (frame, person) which persons are annotated.
        valid: (frame, person, 15) per-joint validity.
        sequence: sequence name.

    Returns:
        One row per (frame, annotated person id, joint).
    """
    f, p = np.nonzero(present)
    n = len(SHELF15_JOINTS)
    xyz = joints_world_m[f, p].reshape(-1, 3)
    table = pd.DataFrame(
        {
            "sequence": sequence,
            "frame": np.repeat(f, n),
            "person_id": np.repeat(p, n),
            "joint": np.tile(np.array(SHELF15_JOINTS, dtype=object), len(f)),
            "x_m": xyz[:, 0],
            "y_m": xyz[:, 1],
            "z_m": xyz[:, 2],
            "valid": valid[f, p].reshape(-1),
        }
    )
    return validate_table(table, "poses3d", source="Shelf gt.txt")


def load_shelf(root: str | Path, config: GroupingConfig | None = None) -> ShelfSequence:
    """Read the Shelf folder: cameras, ground truth, and the OpenPose candidates grouped into people.

    Args:
        root: the ``shelf_4dassoc`` folder (``calibration.json``, ``gt.txt``, ``detection/0..4.txt``), e.g.
            ``humancal.settings.dataset_dir("shelf_4dassoc")``.
        config: grouping settings; defaults to :class:`~humancal.grouping.GroupingConfig`.

    Raises:
        FileNotFoundError: a file is missing.
        humancal.formats.FormatError: a file is malformed, or a detection file's frame count differs from gt.txt's.
    """
    root = Path(root)
    cameras = read_cameras(root / "calibration.json", format="shelf")
    joints, present, valid = read_shelf_gt(root / "gt.txt")
    candidates = []
    for v, cam in enumerate(cameras):
        path = root / "detection" / f"{v}.txt"
        frames = read_candidate_file(path, cam.width_px, cam.height_px)
        if len(frames) != len(present):
            raise FormatError(path, "header frame count", f"{len(present)} (as gt.txt)", f"{len(frames)}")
        candidates.extend((f, v, frame) for f, frame in enumerate(frames))
    detections = group_detections(candidates, SHELF_SEQUENCE, config)
    image_size_px = tuple((c.width_px, c.height_px) for c in cameras)
    detections.attrs[IMAGE_SIZE_ATTR] = dict(enumerate(image_size_px))
    logger.info(
        "Shelf: %d grouped detections in %d frames x %d views",
        detections.groupby(["frame", "view", "det_id"]).ngroups,
        len(present),
        len(cameras),
    )
    return ShelfSequence(
        detections=detections,
        cameras=cameras,
        gt_poses=shelf_gt_table(joints, present, valid),
        gt_joints_world_m=joints,
        gt_present=present,
        image_size_px=image_size_px,
    )
