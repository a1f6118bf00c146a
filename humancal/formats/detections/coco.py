"""COCO-style keypoint JSON (AlphaPose, MMPose, Detectron2 results), one file per view.

Two layouts are read:

* **results** (what AlphaPose writes and MMPose/COCO evaluation dump): a list of
  ``{"image_id": ..., "category_id": 1, "keypoints": [x0, y0, s0, x1, y1, s1, ...], "score": ...}``, one entry per
  detected person. ``image_id`` is an integer (MMPose, Detectron2) or the image file name (AlphaPose).
  No image size.
* **dataset** (COCO annotation files): ``{"images": [{"id", "file_name", "width", "height"}, ...],
  "annotations": [{"image_id", "keypoints", ...}, ...]}``. The third number of each keypoint is then COCO's
  visibility flag (0 not labelled, 1 labelled but occluded, 2 labelled and visible), read as score 1 for a
  labelled joint and 0 otherwise. The image size comes from ``images``.

J is 17 (COCO), 26 (Halpe, AlphaPose's full-body model) or 133 (COCO-WholeBody; only its body and foot points are
kept), told apart by the array length or given. Entries whose ``category_id`` is present and not 1 (person) are
skipped, and so are entries with an empty ``keypoints`` list (placeholders some trackers write; counted in the
table's ``attrs["skipped_placeholders"]``). det_id is the order of a person's entry among the kept entries of its
image.

Frame numbers (``frame_from``): ``"image_id"`` uses integer image ids as frames; ``"name_number"`` takes the last
number in the image's file name (``frame_000123.jpg`` -> 123); ``"name_order"`` ranks the distinct image names
(or ids) in sorted order, which shifts frames when some images have no entry; ``"auto"`` uses ``"image_id"`` for
the integer ids of a results list, otherwise ``"name_number"`` when every image name (``file_name`` in a dataset
file, the id itself in a results list) has a distinct number, else ``"name_order"``.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from humancal.formats._io import load_json
from humancal.formats.detections._keypoints import checked_keypoints, skeleton_of_length
from humancal.formats.detections.table import PLACEHOLDERS_ATTR, SKELETON_ATTR, detections_from_arrays
from humancal.formats.errors import FormatError, missing_field
from humancal.formats.joint_mapping import to_canonical
from humancal.formats.skeletons import Skeleton, get_skeleton

__all__ = ["COCO_SKELETONS", "read_coco_keypoints"]

logger = logging.getLogger(__name__)

COCO_SKELETONS = ("coco17", "halpe26", "coco_wholebody133")
"""Skeletons a COCO-style ``keypoints`` array may hold; told apart by length."""

FrameFrom = Literal["auto", "image_id", "name_number", "name_order"]

_LAST_NUMBER = re.compile(r"(\d+)(?!.*\d)")


def read_coco_keypoints(
    path: str | Path,
    *,
    view: int,
    sequence: str,
    skeleton: str | Skeleton | None = None,
    frame_from: FrameFrom = "auto",
) -> tuple[pd.DataFrame, tuple[int, int] | None]:
    """Read one view's COCO-style keypoint file into canonical detections.

    Args:
        path: the JSON file (results list or dataset dict).
        view: the view number written in every row.
        sequence: the sequence name written in every row.
        skeleton: ``"coco17"``, ``"halpe26"`` or ``"coco_wholebody133"``; ``None`` infers it from the length.
        frame_from: how frame numbers are found (module docstring).

    Returns:
        detections: the canonical detections table of this view (``attrs["skipped_placeholders"]`` =
            ``{view: placeholder entries skipped}``).
        image_size: (width_px, height_px) from a dataset file's ``images`` (all must agree), else ``None``.

    Raises:
        FormatError: invalid JSON; neither layout; an entry without ``image_id`` or ``keypoints``; a keypoint array
            of an unsupported length or mixed lengths; non-numeric, NaN or negative scores; non-finite coordinates of
            a scored joint; image ids unusable for ``frame_from``; images of different sizes.
    """
    path = Path(path)
    data = load_json(path)
    entries, images = _layout(data, path)
    skel = None if skeleton is None else get_skeleton(skeleton)
    names = {img_id: img.get("file_name", str(img_id)) for img_id, img in images.items()}
    rows: list[tuple[object, np.ndarray]] = []
    placeholders = 0
    for i, entry in enumerate(entries):
        field = f"{_entries_key(data)}[{i}]"
        if not isinstance(entry, dict):
            raise FormatError(path, field, "a JSON object with 'image_id' and 'keypoints'", type(entry).__name__)
        if "category_id" in entry and entry["category_id"] != 1:
            continue
        if "image_id" not in entry or "keypoints" not in entry:
            missing = [k for k in ("image_id", "keypoints") if k not in entry]
            raise missing_field(path, f"{field}.{missing[0]}")
        if images and entry["image_id"] not in images:
            raise FormatError(path, f"{field}.image_id", "the id of an entry of 'images'", repr(entry["image_id"]))
        flat = entry["keypoints"]
        if not isinstance(flat, list):
            raise FormatError(path, f"{field}.keypoints", "a list of x, y, score numbers", type(flat).__name__)
        if not flat:
            placeholders += 1
            continue
        skel = skeleton_of_length(len(flat), skel, COCO_SKELETONS, path, f"{field}.keypoints")
        person = checked_keypoints(flat, skel, path, f"{field}.keypoints")
        if isinstance(data, dict):  # a dataset file: visibility flags, not scores
            person = _visibility_to_score(person, skel, path, f"{field}.keypoints")
        rows.append((entry["image_id"], person))
    frames = _frames([r[0] for r in rows], names, frame_from, path)
    by_image: dict[int, list[np.ndarray]] = {}
    for (_, person), frame in zip(rows, frames):
        by_image.setdefault(frame, []).append(person)
    arrays = []
    for frame, people in sorted(by_image.items()):
        stacked = np.stack(people)
        kp, sc = to_canonical(stacked[..., :2], stacked[..., 2], skel)  # type: ignore[arg-type]
        arrays.append((frame, view, kp, sc))
    table = detections_from_arrays(arrays, sequence, source=str(path))
    if placeholders:
        logger.info("%s: skipped %d placeholder entries without keypoints", path, placeholders)
    table.attrs[PLACEHOLDERS_ATTR] = {view: placeholders}
    table.attrs[SKELETON_ATTR] = None if skel is None else skel.name
    return table, _image_size(images, path)


def _entries_key(data: object) -> str:
    return "annotations" if isinstance(data, dict) else ""


def _layout(data: object, path: Path) -> tuple[list, dict[object, dict]]:
    """(entries, images by id) of either layout."""
    if isinstance(data, list):
        return data, {}
    if isinstance(data, dict) and isinstance(data.get("annotations"), list):
        images = data.get("images", [])
        if not isinstance(images, list) or not all(isinstance(im, dict) and "id" in im for im in images):
            raise FormatError(path, "images", "a list of objects with 'id' (and 'file_name', 'width', 'height')")
        return data["annotations"], {im["id"]: im for im in images}
    expected = "a COCO results list [{image_id, keypoints, ...}] or a dataset object with 'annotations'"
    raise FormatError(path, None, expected, type(data).__name__)


def _visibility_to_score(person: np.ndarray, skel: Skeleton, path: Path, field: str) -> np.ndarray:
    """Dataset files: COCO visibility flags (0, 1, 2) to scores (0 for unlabelled, 1 for labelled)."""
    flags = person[:, 2]
    bad = ~np.isin(flags, (0.0, 1.0, 2.0))
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        where = f"{field} joint {j} ({skel.joints[j]}) visibility"
        raise FormatError(path, where, "a COCO visibility flag 0, 1 or 2", flags[j])
    out = person.copy()
    out[:, 2] = (flags > 0).astype(np.float64)
    return out


def _frames(image_ids: list, names: dict, frame_from: str, path: Path) -> list[int]:
    """Frame number of each entry's image."""
    if frame_from not in ("auto", "image_id", "name_number", "name_order"):
        raise ValueError(f"frame_from: expected 'auto', 'image_id', 'name_number' or 'name_order', got {frame_from!r}")
    if not image_ids:
        return []
    all_int = all(isinstance(i, int) and not isinstance(i, bool) for i in image_ids)
    if frame_from == "auto":
        if all_int and not names:
            frame_from = "image_id"
        else:
            frame_from = "name_number" if _numbers_of(image_ids, names) is not None else "name_order"
            logger.info("%s: frames from image names (%s)", path, frame_from)
    if frame_from == "image_id":
        if not all_int or any(i < 0 for i in image_ids):
            bad = next(i for i in image_ids if not isinstance(i, int) or isinstance(i, bool) or i < 0)
            expected = "non-negative integers (frame numbers) for frame_from='image_id'"
            raise FormatError(path, "image_id", expected, repr(bad))
        return [int(i) for i in image_ids]
    if frame_from == "name_number":
        numbers = _numbers_of(image_ids, names)
        if numbers is None:
            expected = "image names with one distinct number each for frame_from='name_number'"
            raise FormatError(path, "image_id", expected, "names without")
        return [numbers[i] for i in image_ids]
    order = {i: rank for rank, i in enumerate(sorted(set(image_ids), key=lambda i: str(names.get(i, i))))}
    return [order[i] for i in image_ids]


def _numbers_of(image_ids: list, names: dict) -> dict | None:
    """{image id: last number in its name} when every name has one and no two names share it, else None."""
    numbers = {}
    for i in set(image_ids):
        match = _LAST_NUMBER.search(Path(str(names.get(i, i))).stem)
        if match is None:
            return None
        numbers[i] = int(match.group(1))
    return numbers if len(set(numbers.values())) == len(numbers) else None


def _image_size(images: dict[object, dict], path: Path) -> tuple[int, int] | None:
    if not images:
        return None
    sizes = set()
    for img_id, img in images.items():
        w, h = img.get("width"), img.get("height")
        if not (isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0):
            raise FormatError(path, f"images[id={img_id!r}].width/height", "two positive integers", f"{[w, h]}")
        sizes.add((w, h))
    if len(sizes) > 1:
        raise FormatError(path, "images.width/height", "one image size per view", f"{sorted(sizes)}")
    return sizes.pop()
