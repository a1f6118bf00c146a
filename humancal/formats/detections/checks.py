"""Checks of a capture's detections against what the user declared: the image size of each view, and the views.

Each check raises :class:`InputCheckError` (a ``ValueError``) for input that cannot be right and returns warnings
(one line each) for input that is probably wrong. Messages name the view as ``view 2 (cam3)`` and the option by
the name the caller gives (``--image-size`` on the command line, ``image_size`` in a datasets file).

**Image size** (:func:`check_image_sizes`). Per view, over every detected joint (before off-image joints are
dropped):

* error when more than :data:`MAX_OFF_IMAGE_FRACTION` (10 %) of the joints, and at least
  :data:`MIN_OFF_IMAGE_JOINTS` (20), lie outside the declared image (beyond half a pixel past the edge pixel
  centres). Trackers extrapolate a few joints past the edge; a swapped or wrong size puts a large share of them
  there. The message gives the span of the joints (the central 99 %: 0.5th to 99.5th percentile, so stray
  extrapolations do not widen it) and a size that holds it: the transposed size when it does (portrait cameras
  declared landscape), else the smallest of :data:`COMMON_SIZES` (and their transposes) that does, else the
  span's own size.
* warning when the joints stay within the top-left quarter of the image (detections made on a smaller video),
  or, for a portrait size, when they fit the transposed (landscape) size and reach less than
  :data:`MIN_LONG_SIDE_COVER` (60 %) of the height (a landscape camera declared portrait whose people stay out of
  its right part). Both need at least :data:`MIN_JOINTS_FOR_COVER` joints.

**Views** (:func:`check_view_paths`, :func:`check_views`):

* error: fewer than two views (one camera cannot be calibrated), the same path given twice, two views with
  identical detections (one folder copied under two names), a view without any detection, or a view none of
  whose frames has a detection in another view (videos out of sync, or frame numbers counted differently).
* warning: a view sharing fewer than :data:`MIN_SHARED_FRAMES` (10) frames with the other views.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from humancal.keypoints import JOINT_INDEX

__all__ = ["COMMON_SIZES", "InputCheckError", "MAX_OFF_IMAGE_FRACTION", "MIN_OFF_IMAGE_JOINTS", "MIN_SHARED_FRAMES",
           "check_image_sizes", "check_view_paths", "check_views", "off_image", "view_label"]

PIXEL_EDGE_PX = 0.5
"""Pixel centres run from 0 to width - 1: a joint beyond half a pixel outside that range is off the image."""

MAX_OFF_IMAGE_FRACTION = 0.10
"""Largest share of a view's joints that may lie off its declared image (trackers' extrapolations)."""

MIN_OFF_IMAGE_JOINTS = 20
"""Fewest off-image joints that make a view's size an error (a handful in a tiny capture says nothing)."""

MIN_JOINTS_FOR_COVER = 200
"""Fewest joints of a view for the coverage warnings."""

MIN_LONG_SIDE_COVER = 0.6
"""Smallest share of a declared portrait height the joints reach before the transposed size is suspected."""

MIN_SHARED_FRAMES = 10
"""Fewest frames a view should share with the other views (a detection in both)."""

COMMON_SIZES: tuple[tuple[int, int], ...] = (
    (640, 480), (1280, 720), (1280, 1024), (1920, 1080), (1920, 1088), (1920, 1200), (2048, 1536),
    (2560, 1440), (2704, 1520), (3840, 2160), (4096, 2160),
)  # fmt: skip
"""Video sizes (width, height) proposed when a view's joints spill out of its declared image (also transposed)."""

_SPAN_PERCENTILES = (0.5, 99.5)


class InputCheckError(ValueError):
    """Input that cannot be right (the message names the view and the option to change)."""


def view_label(view: int, names: Sequence[str]) -> str:
    """``view 2 (cam3)``: the view's number and, when known, its name."""
    return f"view {view} ({names[view]})" if view < len(names) and names[view] else f"view {view}"


def off_image(x_px: np.ndarray, y_px: np.ndarray, width_px: np.ndarray, height_px: np.ndarray) -> np.ndarray:
    """(N,) True where a joint lies more than half a pixel outside its image (pixel centres 0 .. size - 1)."""
    return ((x_px < -PIXEL_EDGE_PX) | (y_px < -PIXEL_EDGE_PX) | (x_px > width_px - 1 + PIXEL_EDGE_PX)
            | (y_px > height_px - 1 + PIXEL_EDGE_PX))


def check_image_sizes(detections: pd.DataFrame, sizes: Mapping[int, tuple[int, int]], names: Sequence[str],
                      option: str = "image_size") -> list[str]:
    """Check each view's declared image size against where its joints lie (module docstring).

    Args:
        detections: canonical detections table, off-image joints included.
        sizes: {view: (width_px, height_px)} as declared.
        names: (V,) view names for the messages.
        option: the name of the image size option in messages.

    Returns:
        Warnings, one line each.

    Raises:
        InputCheckError: too many joints of a view lie off its image (the message proposes a size).
    """
    warnings = []
    for view, group in detections.groupby("view", sort=True):
        w, h = sizes[int(view)]
        x, y = group["x_px"].to_numpy(), group["y_px"].to_numpy()
        off = int(off_image(x, y, w, h).sum())
        (x_lo, x_hi), (y_lo, y_hi) = np.percentile(x, _SPAN_PERCENTILES), np.percentile(y, _SPAN_PERCENTILES)
        span = f"{math.floor(x_lo)}-{math.ceil(x_hi)} x {math.floor(y_lo)}-{math.ceil(y_hi)} px"
        where = view_label(int(view), names)
        if off > MAX_OFF_IMAGE_FRACTION * len(x) and off >= MIN_OFF_IMAGE_JOINTS:
            raise InputCheckError(
                f"{where}: {100 * off / len(x):.0f} % of the joints lie outside the declared {w}x{h} image; the "
                f"detections span {span}: {_proposal((x_lo, x_hi), (y_lo, y_hi), (w, h))} ({option})?"
            )
        if len(x) < MIN_JOINTS_FOR_COVER:
            continue
        if x_hi < 0.5 * w and y_hi < 0.5 * h:
            warnings.append(f"{where}: the joints span {span}, within the top-left quarter of the declared {w}x{h} "
                            f"image: were the detections made on a smaller video ({option})?")
        elif h > w and _holds((x_lo, x_hi), (y_lo, y_hi), (h, w)) and y_hi < MIN_LONG_SIDE_COVER * h:
            warnings.append(f"{where}: the joints span {span}, only the top {100 * y_hi / h:.0f} % of the declared "
                            f"{w}x{h} image: is the image {h}x{w} ({option})?")
    return warnings


def _holds(x_span: tuple[float, float], y_span: tuple[float, float], size: tuple[int, int]) -> bool:
    lo_ok = x_span[0] >= -PIXEL_EDGE_PX and y_span[0] >= -PIXEL_EDGE_PX
    return lo_ok and x_span[1] <= size[0] - 1 + PIXEL_EDGE_PX and y_span[1] <= size[1] - 1 + PIXEL_EDGE_PX


def _proposal(x_span: tuple[float, float], y_span: tuple[float, float], declared: tuple[int, int]) -> str:
    """The question ending the image size error: which size holds the joints' span."""
    w, h = declared
    if min(x_span[0], y_span[0]) < -PIXEL_EDGE_PX:
        return "are they pixels of this view's video, and is the image size right"
    if w != h and _holds(x_span, y_span, (h, w)):
        return f"is the image {h}x{w}"
    candidates = sorted({*COMMON_SIZES, *((b, a) for a, b in COMMON_SIZES)}, key=lambda s: (s[0] * s[1], s))
    for size in candidates:
        if size != (w, h) and _holds(x_span, y_span, size):
            return f"is the image {size[0]}x{size[1]}"
    return f"is the image at least {math.ceil(x_span[1] + PIXEL_EDGE_PX)}x{math.ceil(y_span[1] + PIXEL_EDGE_PX)}"


def check_view_paths(views: Sequence[Path], option: str = "views") -> None:
    """Two views at least, each path once.

    Args:
        views: (V,) the views' folders or files, in view order.
        option: the name of the views option in messages.

    Raises:
        InputCheckError: fewer than two views, or a path given twice (the message names both view numbers).
    """
    if len(views) < 2:
        raise InputCheckError(f"{option}: expected two views or more (one camera cannot be calibrated: the method "
                              f"needs people seen by several cameras at once), got {len(views)}")
    seen: dict[Path, int] = {}
    for v, path in enumerate(views):
        key = Path(path).expanduser().resolve()
        if key in seen:
            raise InputCheckError(f"{option}: views {seen[key]} and {v} are the same path ({path}): give each "
                                  "camera's folder or file once")
        seen[key] = v


def check_views(detections: pd.DataFrame, names: Sequence[str], option: str = "views") -> list[str]:
    """Check that the views hold distinct detections that share frames (module docstring).

    Args:
        detections: canonical detections table (on-image joints).
        names: (V,) view names, in view order (V is the number of views).
        option: the name of the views option in messages.

    Returns:
        Warnings, one line each.

    Raises:
        InputCheckError: two views with identical detections, a view without detections, a view sharing no frame
            with the others.
    """
    V = len(names)
    by_view = {v: g for v, g in detections.groupby("view", sort=True)}
    _check_identical(by_view, names, option)
    frames = {v: set(by_view[v]["frame"].tolist()) if v in by_view else set() for v in range(V)}
    warnings = []
    for v in range(V):
        if not frames[v]:
            raise InputCheckError(f"{view_label(v, names)}: no detection in any of its files: is it the right "
                                  f"folder or file ({option})?")
        others = set().union(*(frames[u] for u in range(V) if u != v))
        shared = frames[v] & others
        if not shared:
            raise InputCheckError(
                f"{view_label(v, names)}: none of its frames ({_frame_range(frames[v])}) has detections in another "
                f"view (frames {_frame_range(others)}): are the videos in sync, and do the file names count frames "
                "the same way?"
            )
        if len(shared) < MIN_SHARED_FRAMES:
            warnings.append(f"{view_label(v, names)} shares only {len(shared)} frame(s) with the other views "
                            f"({_frame_range(shared)}): the calibration needs people seen by several views at once")
    return warnings


def _frame_range(frames: set[int]) -> str:
    return "none" if not frames else f"{min(frames)}-{max(frames)}" if len(frames) > 1 else f"{min(frames)}"


def _check_identical(by_view: Mapping[int, pd.DataFrame], names: Sequence[str], option: str) -> None:
    """Raise when two views hold the same detections (frames, people, joints, pixels and scores)."""
    signatures: dict[bytes, int] = {}
    for v, group in by_view.items():
        rows = np.column_stack([
            group["frame"].to_numpy(np.float64), group["det_id"].to_numpy(np.float64),
            group["joint"].map(JOINT_INDEX).to_numpy(np.float64), group["x_px"].to_numpy(np.float64),
            group["y_px"].to_numpy(np.float64), group["score"].to_numpy(np.float64),
        ])
        key = rows[np.lexsort(rows.T[::-1])].tobytes()
        if key in signatures:
            u = signatures[key]
            raise InputCheckError(
                f"{view_label(u, names)} and {view_label(v, names)} hold identical detections: the same camera's "
                f"files given twice ({option})?"
            )
        signatures[key] = v
