"""OpenPose per-frame JSON: one folder per view, one JSON file per frame.

A file is ``{"version": ..., "people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...], ...}, ...]}`` with
J = 25 (BODY_25 or the experimental BODY_25B model, two different joint orders) or 18 (COCO model) joints in
pixels; a joint OpenPose did not find is written as ``0, 0, 0``. OpenPose names the files
``<video name>_<frame:012d>_keypoints.json`` (frames from 0); other tools write e.g. ``cam01.0000.json``. The
files carry no image size.

Reading: every ``*.json`` file of a view folder is one frame. Its frame number is the number in the file name
that changes from file to file (so the ``01`` of ``cam01_000000000007_keypoints.json`` or ``cam01.0007.json``,
the same in every file, is not taken for the frame); with a single file, the last number of its name
(``frame_from="name_number"``). When names carry no distinct numbers, frames are the sorted file order
(``frame_from="name_order"``); ``"auto"`` picks the first that applies. Views may have different frames (a camera
started late, a file missing): frames are matched by number, and an image without a file has no detections (the
counts are logged); without frame numbers in the names the views must have the same number of files.
det_id is a person's index among the entries of ``people`` that carry keypoints: an entry with an empty
``pose_keypoints_2d`` list (a placeholder some trackers write) is skipped and counted (the table's
``attrs["skipped_placeholders"]``, ``{view: count}``). Joints with confidence 0 have no row. A 25-point array
fits two skeletons: ``skeleton=`` is then required ("body25" or "body25b"), never guessed.

Writing: every table frame gets a file per view (frames with no detection get ``"people": []``), people in det_id
order, so det_ids are renumbered 0..P-1 per image when the table has gaps. Canonical joints are mapped to the
target skeleton with :func:`humancal.formats.joint_mapping.from_canonical` (neck and mid-hip derived as the
shoulder and hip midpoints); absent joints are written as ``0, 0, 0``.
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from humancal.formats._io import atomic_write_text, load_json
from humancal.formats.detections._keypoints import checked_keypoints, skeleton_of_length
from humancal.formats.detections.table import (
    PLACEHOLDERS_ATTR,
    SKELETON_ATTR,
    detections_from_arrays,
    detections_to_arrays,
)
from humancal.formats.errors import FormatError
from humancal.formats.joint_mapping import from_canonical, to_canonical
from humancal.formats.skeletons import Skeleton, get_skeleton
from humancal.keypoints import NUM_JOINTS

__all__ = ["OPENPOSE_SKELETONS", "frame_numbers_in_names", "list_openpose_frames", "read_openpose_file", "read_openpose", "write_openpose"]

logger = logging.getLogger(__name__)

OPENPOSE_SKELETONS = ("body25", "body25b", "coco18")
"""Skeletons an OpenPose ``pose_keypoints_2d`` array may hold (BODY_25 and BODY_25B share a length)."""

_NUMBER = re.compile(r"\d+")
_SUFFIX = "_keypoints.json"

FrameFrom = Literal["auto", "name_number", "name_order"]


def frame_numbers_in_names(names: list[str]) -> list[int] | None:
    """The frame number in each file name, or None when the names carry no distinct frame numbers.

    The frame is the number that varies between names at the same position (the camera number in
    ``cam01_000000000007_keypoints.json`` stays the same); with one file, or names that do not share a layout,
    the last number of each name.
    """
    groups = [_NUMBER.findall(Path(n).stem) for n in names]
    if not groups or any(not g for g in groups):
        return None
    numbers = [int(g[-1]) for g in groups]
    if len({len(g) for g in groups}) == 1:
        varying = [i for i in range(len(groups[0])) if len({g[i] for g in groups}) > 1]
        if varying:
            numbers = [int(g[varying[-1]]) for g in groups]
    return numbers if len(set(numbers)) == len(numbers) else None


def _list_frames(folder: Path, frame_from: str) -> tuple[list[tuple[int, Path]], bool]:
    """(frame number, file) pairs in frame order, and whether the numbers came from the names."""
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such folder (expected one OpenPose JSON folder per view)")
    if frame_from not in ("auto", "name_number", "name_order"):
        raise ValueError(f"frame_from: expected 'auto', 'name_number' or 'name_order', got {frame_from!r}")
    files = sorted(p for p in folder.iterdir() if p.suffix == ".json" and not p.name.startswith(".") and p.is_file())
    if not files:
        raise FormatError(folder, None, "OpenPose JSON files ('<video>_<frame:012d>_keypoints.json' or '*.json')", "none")
    numbers = frame_numbers_in_names([p.name for p in files])
    if frame_from == "name_number" or (frame_from == "auto" and numbers is not None):
        if numbers is None:
            bad = next((p.name for p in files if not _NUMBER.search(p.stem)), None)
            if bad is not None:
                raise FormatError(folder / bad, None, "a file name with a frame number ('<name>_<frame>_keypoints.json')",
                                  repr(bad))
            raise FormatError(folder, None, "one file per frame number", "repeated frame numbers in the file names")
        return sorted(zip(numbers, files)), True
    if frame_from == "auto":
        logger.info("%s: file names carry no distinct frame numbers; frames numbered in sorted file order", folder)
    return list(enumerate(files)), False


def list_openpose_frames(folder: str | Path, frame_from: FrameFrom = "auto") -> list[tuple[int, Path]]:
    """The JSON files of one view's folder with their frame numbers, in frame order.

    Args:
        folder: one view's folder.
        frame_from: ``"name_number"``: the number in the file name that varies from file to file (module
            docstring); ``"name_order"``: the index in the sorted file list; ``"auto"``: ``"name_number"`` when
            every name has one and no number repeats, else ``"name_order"``.

    Raises:
        FileNotFoundError: the folder does not exist.
        FormatError: no JSON file; a name without a number (``"name_number"``); a repeated frame number.
    """
    return _list_frames(Path(folder), frame_from)[0]


def _read_people(path: Path, skeleton: Skeleton | None) -> tuple[np.ndarray, Skeleton | None, int]:
    """(people (P, J, 3), skeleton, number of placeholder entries skipped) of one file."""
    data = load_json(path)
    if not isinstance(data, dict) or not isinstance(data.get("people"), list):
        got = "no 'people' key" if isinstance(data, dict) else type(data).__name__
        raise FormatError(path, "people", "a JSON object with a 'people' list", got)
    skel, people, placeholders = skeleton, [], 0
    for p, person in enumerate(data["people"]):
        field = f"people[{p}].pose_keypoints_2d"
        flat = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        if not isinstance(flat, list):
            raise FormatError(path, field, "a list of x, y, confidence numbers", "nothing")
        if not flat:
            placeholders += 1
            continue
        skel = skeleton_of_length(len(flat), skel, OPENPOSE_SKELETONS, path, field)
        people.append(checked_keypoints(flat, skel, path, field, score_name="confidence"))
    if not people:
        return np.zeros((0, 0 if skel is None else skel.num_joints, 3)), skel, placeholders
    return np.stack(people), skel, placeholders


def read_openpose_file(path: str | Path, skeleton: str | Skeleton | None = None) -> tuple[np.ndarray, Skeleton | None]:
    """The people of one OpenPose JSON file.

    Args:
        path: the JSON file.
        skeleton: ``"body25"``, ``"body25b"`` or ``"coco18"`` (or a Skeleton); ``None`` infers it from the array
            length, which works for 18 points only (25 points fit two skeletons).

    Returns:
        people: (P, J, 3) x_px, y_px, confidence (P may be 0; placeholder entries with an empty keypoint list are
            left out).
        skeleton: the skeleton of the arrays (``None`` when the file has no people and none was given).

    Raises:
        FormatError: invalid JSON; no ``people`` list; a person without a ``pose_keypoints_2d`` list of 3J numbers
            for a supported J; 25 points and no skeleton given; people of different skeletons; non-numeric, NaN or
            negative confidences; non-finite coordinates of a joint with positive confidence.
    """
    people, skel, placeholders = _read_people(Path(path), None if skeleton is None else get_skeleton(skeleton))
    if placeholders:
        logger.info("%s: skipped %d placeholder person entries without keypoints", path, placeholders)
    return people, skel


def read_openpose(
    folders_by_view: Sequence[str | Path] | Mapping[int, str | Path],
    *,
    sequence: str,
    skeleton: str | Skeleton | None = None,
    frame_from: FrameFrom = "auto",
) -> pd.DataFrame:
    """Read one OpenPose JSON folder per view into the canonical detections table.

    Args:
        folders_by_view: folders in view order (views 0..V-1), or a mapping view -> folder.
        sequence: the sequence name written in every row.
        skeleton: ``"body25"``, ``"body25b"`` or ``"coco18"``; ``None`` infers it from the array length (18 points
            only; all files must agree).
        frame_from: how frame numbers are found (:func:`list_openpose_frames`).

    Returns:
        The canonical detections table (no image size: OpenPose files do not carry it; see
        :func:`humancal.formats.detections.read_detections`), with ``attrs["skipped_placeholders"]`` =
        ``{view: placeholder entries skipped}``.

    Raises:
        FormatError: a bad file (:func:`read_openpose_file`); view folders with different numbers of files whose
            names carry no frame numbers (the message names both folders).
    """
    folders = _by_view(folders_by_view)
    listings, numbered = {}, {}
    for v, folder in folders.items():
        listings[v], numbered[v] = _list_frames(folder, frame_from)
    _check_frames_line_up(folders, listings, numbered)
    skel = None if skeleton is None else get_skeleton(skeleton)
    images, placeholders = [], {}
    for v, frames in listings.items():
        placeholders[v] = 0
        for frame, path in frames:
            people, file_skel, skipped = _read_people(path, skel)
            placeholders[v] += skipped
            if file_skel is None:
                continue
            skel = file_skel
            kp, sc = to_canonical(people[..., :2], people[..., 2], skel)
            images.append((frame, v, kp, sc))
    for v, count in placeholders.items():
        if count:
            logger.info("%s: skipped %d placeholder person entries without keypoints", folders[v], count)
    table = detections_from_arrays(images, sequence, source=f"OpenPose folders {[str(f) for f in folders.values()]}")
    table.attrs[PLACEHOLDERS_ATTR] = placeholders
    table.attrs[SKELETON_ATTR] = None if skel is None else skel.name
    return table


def _check_frames_line_up(folders: dict[int, Path], listings: dict, numbered: dict[int, bool]) -> None:
    """Views with different frames are fine when frames are numbered in the names; otherwise they must agree."""
    first_view = min(listings)
    ref = listings[first_view]
    all_frames = set().union(*({n for n, _ in frames} for frames in listings.values()))
    for v, frames in listings.items():
        if len(frames) == len(ref) and {n for n, _ in frames} == {n for n, _ in ref}:
            continue
        if not (numbered[v] and numbered[first_view]):
            raise FormatError(
                folders[v],
                None,
                f"as many files as view {first_view} ({folders[first_view]}: {len(ref)} files), since the file "
                "names carry no frame numbers to match them by",
                f"{len(frames)} files",
            )
    counts = {v: len(frames) for v, frames in listings.items()}
    if len(set(counts.values())) > 1 or any(len(f) != len(all_frames) for f in listings.values()):
        logger.warning(
            "views have different frames (files per view %s, %d frames in all): an image without a file has no "
            "detections", counts, len(all_frames),
        )


def write_openpose(
    detections: pd.DataFrame,
    root: str | Path,
    *,
    skeleton: str | Skeleton = "body25",
    frames: Iterable[int] | None = None,
    views: Iterable[int] | None = None,
    overwrite: bool = False,
) -> dict[int, Path]:
    """Write a canonical detections table as OpenPose JSON, one folder per view.

    Files are ``<root>/view_<view:02d>/<sequence>_<frame:012d>_keypoints.json``, each written atomically.

    Args:
        detections: canonical detections of one sequence.
        root: folder receiving the view folders (created when missing).
        skeleton: ``"body25"`` (default) or ``"coco18"``.
        frames: frames to write (default: every frame from the table's first to its last).
        views: views to write (default: the table's views).
        overwrite: replace existing ``*_keypoints.json`` files in the view folders (only those files are removed);
            when False, a view folder that already holds some is an error.

    Returns:
        ``{view: folder}``.

    Raises:
        FormatError: several sequences in the table, nothing to write, an unsupported skeleton, existing files.
    """
    skel = get_skeleton(skeleton)
    if skel.name not in OPENPOSE_SKELETONS:
        raise FormatError(None, "skeleton", f"one of {list(OPENPOSE_SKELETONS)}", repr(skel.name))
    sequences = sorted(set(detections["sequence"])) if len(detections) else []
    if len(sequences) > 1:
        raise FormatError(None, "sequence", "detections of one sequence", f"{sequences}")
    arrays = detections_to_arrays(detections, source="detections to write as OpenPose")
    table_frames = {k[0] for k in arrays}
    table_views = {k[1] for k in arrays}
    if frames is not None:
        frame_list = sorted({int(f) for f in frames})
    elif table_frames:
        frame_list = list(range(min(table_frames), max(table_frames) + 1))
    else:
        frame_list = []
    view_list = sorted({int(v) for v in views}) if views is not None else sorted(table_views)
    left_out = sorted(table_frames - set(frame_list)), sorted(table_views - set(view_list))
    if left_out[0] or left_out[1]:
        raise FormatError(
            None, "frames/views", "frames= and views= covering every frame and view of the table",
            f"table frames {left_out[0][:5]} / views {left_out[1]} left out",
        )
    if not frame_list or not view_list:
        expected = "at least one frame and one view to write (pass frames= and views=)"
        raise FormatError(None, "detections", expected, "none")
    sequence = sequences[0] if sequences else "detections"
    root = Path(root)
    folders = {v: root / f"view_{v:02d}" for v in view_list}
    for folder in folders.values():
        existing = sorted(folder.glob(f"*{_SUFFIX}")) if folder.is_dir() else []
        if existing and not overwrite:
            expected = "a folder without '*_keypoints.json' files (or overwrite=True)"
            raise FormatError(folder, None, expected, f"{len(existing)} files")
        for old in existing:
            old.unlink()
    empty = np.zeros((0,), dtype=np.int64), np.zeros((0, NUM_JOINTS, 2)), np.zeros((0, NUM_JOINTS))
    for v, folder in folders.items():
        for frame in frame_list:
            _, kp, sc = arrays.get((frame, v), empty)
            out_kp, out_sc = from_canonical(kp, sc, skel)
            text = json.dumps({"version": 1.3, "people": [_person(k, s) for k, s in zip(out_kp, out_sc)]})
            atomic_write_text(folder / f"{sequence}_{frame:012d}{_SUFFIX}", text)
    return folders


def _person(keypoints: np.ndarray, scores: np.ndarray) -> dict:
    present = scores > 0
    flat = np.zeros((len(scores), 3))
    flat[present, :2] = keypoints[present]
    flat[present, 2] = scores[present]
    return {
        "person_id": [-1],
        "pose_keypoints_2d": [float(x) for x in flat.reshape(-1)],
        "face_keypoints_2d": [],
        "hand_left_keypoints_2d": [],
        "hand_right_keypoints_2d": [],
        "pose_keypoints_3d": [],
        "face_keypoints_3d": [],
        "hand_left_keypoints_3d": [],
        "hand_right_keypoints_3d": [],
    }


def _by_view(paths: Sequence[str | Path] | Mapping[int, str | Path]) -> dict[int, Path]:
    items = paths.items() if isinstance(paths, Mapping) else enumerate(paths)
    out = {int(v): Path(p) for v, p in items}
    if not out:
        raise ValueError("expected at least one view folder, got none")
    return dict(sorted(out.items()))
