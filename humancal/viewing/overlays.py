"""Overlays per view: the detections and the fitted people drawn in each camera's image, as MP4 files and a contact
sheet.

Each frame shows, in the view's image frame (on the view's footage when the capture has it, else on a dark
background):

* every detection's skeleton, thin, in its person's colour (grey where the association rejected it);
* the fitted body's keypoints reprojected as a thick skeleton in the same colour, with the person id at the head;
* the frame number, the view's name and its mean reprojection error of the frame (pixels).

Colours are :func:`humancal.viewing.recording.person_colour`, the same as in the 3D viewer.
:func:`distance_to_colour` measures a written frame: how far given points are from the pixels drawn in a colour.
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from humancal.keypoints import JOINT_INDEX, LIMB_INDEX
from humancal.viewing.footage import FootageReader
from humancal.viewing.recording import CaptureView, person_colour
from humancal.viewing.reprojection import FrameFit, detection_people, joint_index, reprojected_fit

__all__ = ["OverlayResult", "distance_to_colour", "draw_frame", "overlay_alignment", "write_overlays"]

_REJECTED = (150, 150, 150)
_BACKGROUND = (32, 32, 32)
_HEAD = JOINT_INDEX["nose"]


@dataclass(frozen=True)
class OverlayResult:
    """What :func:`write_overlays` wrote.

    Attributes:
        videos: one MP4 per view, in view order.
        contact_sheet: the PNG of views x a few frames.
        frames: the frame numbers drawn.
        median_error_px: per view, the median over frames of its mean reprojection error (NaN without a fit).
    """

    videos: list[Path]
    contact_sheet: Path
    frames: np.ndarray
    median_error_px: list[float]


def _bgr(rgb) -> tuple[int, int, int]:
    return int(rgb[2]), int(rgb[1]), int(rgb[0])


def _skeleton(image: np.ndarray, px: np.ndarray, ok: np.ndarray, colour, thickness: int, scale: float) -> None:
    for a, b in LIMB_INDEX:
        if ok[a] and ok[b] and np.isfinite(px[[a, b]]).all():
            cv2.line(image, tuple(np.round(px[a] * scale).astype(int)), tuple(np.round(px[b] * scale).astype(int)),
                     _bgr(colour), thickness, cv2.LINE_AA)


def draw_frame(size_px: tuple[int, int], detections: pd.DataFrame | None, fit: FrameFit | None, view: int, frame: int,
               people: dict, label: str, scale: float = 1.0, background: np.ndarray | None = None) -> np.ndarray:
    """One overlay image (BGR, ``scale`` times the camera's ``size_px`` = (width, height)).

    Args:
        size_px: the camera's image size, pixels.
        detections: this view's rows of ``raw_detections`` at this frame (None: none).
        fit: the reprojected fit at this frame (None: none).
        view, frame: where (the keys of ``people``).
        people: :func:`humancal.viewing.reprojection.detection_people`.
        label: the view's name.
        scale: drawing scale (smaller files for large images).
        background: the view's image at this frame (BGR, any size of the camera's aspect ratio: resized), or None
            (a plain dark background).
    """
    width, height = (int(round(s * scale)) for s in size_px)
    if background is None:
        image = np.full((height, width, 3), _BACKGROUND, dtype=np.uint8)
    else:
        image = cv2.resize(background, (width, height), interpolation=cv2.INTER_AREA)
    thin, thick = max(1, int(round(2 * scale))), max(2, int(round(5 * scale)))
    if detections is not None:
        for det_id, det in detections.groupby("det_id"):
            pid = people.get((frame, view, int(det_id)), -1)
            px = np.full((len(JOINT_INDEX), 2), np.nan)
            confident = det[det["score"] > 0]
            px[joint_index(confident["joint"])] = confident[["x_px", "y_px"]].to_numpy()
            _skeleton(image, px, np.isfinite(px).all(1), person_colour(pid) if pid >= 0 else _REJECTED, thin, scale)
    if fit is not None:
        for pid, (px, ok) in fit.people.items():
            _skeleton(image, px, ok, person_colour(pid), thick, scale)
            if ok[_HEAD] and np.isfinite(px[_HEAD]).all():
                x, y = np.round(px[_HEAD] * scale).astype(int)
                cv2.putText(image, str(pid), (int(x) + 6, int(y) - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                            _bgr(person_colour(pid)), 2, cv2.LINE_AA)
    error = "" if fit is None or not np.isfinite(fit.error_px) else f"  error {fit.error_px:.1f} px"
    cv2.putText(image, f"{label}  frame {frame}{error}", (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (230, 230, 230), 2,
                cv2.LINE_AA)
    return image


def write_overlays(view: CaptureView, out_dir: str | Path, *, frames: Sequence[int] | None = None,
                   show_detections: bool = True,
                   max_width_px: int = 960, sheet_frames: int = 4,
                   progress: Callable[[str], None] = lambda message: None) -> OverlayResult:
    """One MP4 per view (``<view>.mp4``) and ``contact_sheet.png`` under ``out_dir`` (module docstring).

    Args:
        view: the capture's tables (``cameras["final"]``, ``detections``, ``associations``, ``keypoints_world_m``)
            and its ``footage`` (drawn under the overlays where a view has it).
        out_dir: the folder (created); each file is written under a temporary name and renamed when complete.
        frames: the frame numbers to draw (default: every frame with a detection).
        show_detections: draw the detections (False: the reprojected fit only).
        max_width_px: images wider than this are drawn smaller.
        sheet_frames: frames per view in the contact sheet, evenly spread.
        progress: called with one line per view.

    Raises:
        ValueError: the view has no final cameras, or nothing to draw.
    """
    if "final" not in view.cameras:
        raise ValueError(f"{view.name}: no final cameras to draw in")
    detections = view.detections if view.detections is not None else pd.DataFrame(
        columns=["frame", "view", "det_id", "joint", "x_px", "y_px", "score"])
    drawn = np.asarray(sorted(detections["frame"].unique()) if frames is None else frames, dtype=np.int64)
    if len(drawn) == 0:
        raise ValueError(f"{view.name}: no frame to draw (no detections stored)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    people = detection_people(view.associations)
    sheet_at = set(drawn[np.linspace(0, len(drawn) - 1, min(sheet_frames, len(drawn))).round().astype(int)].tolist())
    videos, tiles, medians = [], [], []
    for v, (name, camera) in enumerate(zip(view.view_names, view.cameras["final"])):
        mine = detections[detections["view"] == v]
        fits = reprojected_fit(view.keypoints_world_m, v, camera, mine, people)
        by_frame = {int(f): rows for f, rows in mine.groupby("frame")}
        scale = min(1.0, max_width_px / camera.width_px)
        size = (int(round(camera.width_px * scale)), int(round(camera.height_px * scale)))
        path, partial = out / f"{name}.mp4", out / f".{name}.partial.mp4"  # OpenCV picks the container by suffix
        writer = cv2.VideoWriter(str(partial), cv2.VideoWriter_fourcc(*"mp4v"), float(view.fps), size)
        if not writer.isOpened():
            raise OSError(errno.EIO, "OpenCV cannot write an MP4 video here", str(partial))
        row = []
        reader = FootageReader(view.footage[v]) if view.footage and view.footage[v] is not None else None
        try:
            for frame in drawn:
                image = draw_frame((camera.width_px, camera.height_px),
                                   by_frame.get(int(frame)) if show_detections else None, fits.get(int(frame)),
                                   v, int(frame), people, name, scale,
                                   None if reader is None else reader.frame(int(frame)))
                writer.write(image)
                if int(frame) in sheet_at:
                    row.append(cv2.resize(image, (320, int(round(320 * size[1] / size[0])))))
        except BaseException:
            writer.release()
            partial.unlink(missing_ok=True)  # nothing half-written is left behind
            raise
        finally:
            if reader is not None:
                reader.close()
        writer.release()
        partial.replace(path)
        videos.append(path)
        errors = [f.error_px for f in fits.values() if np.isfinite(f.error_px)]
        medians.append(float(np.median(errors)) if errors else float("nan"))
        tiles.append(row)
        progress(f"{name}: {len(drawn)} frames -> {path} (median reprojection error {medians[-1]:.1f} px)")
    sheet = _contact_sheet(tiles)
    sheet_path = out / "contact_sheet.png"
    partial = out / ".contact_sheet.partial.png"
    cv2.imwrite(str(partial), sheet)
    partial.replace(sheet_path)
    return OverlayResult(videos, sheet_path, drawn, medians)


def _contact_sheet(rows: list[list[np.ndarray]]) -> np.ndarray:
    """Views as rows, frames as columns (tiles of different heights padded)."""
    height = max(tile.shape[0] for row in rows for tile in row)
    width = max(len(row) for row in rows) * 320
    sheet = np.full((height * len(rows), width, 3), _BACKGROUND, dtype=np.uint8)
    for r, row in enumerate(rows):
        for c, tile in enumerate(row):
            sheet[r * height : r * height + tile.shape[0], c * 320 : (c + 1) * 320] = tile
    return sheet


def distance_to_colour(image_bgr: np.ndarray, colour_rgb, points_px: np.ndarray, tolerance: int = 60) -> np.ndarray:
    """How far each point is from the nearest pixel drawn in ``colour_rgb`` (within ``tolerance``, the sum of the
    three channels' differences: video compression moves colours), pixels; inf where no pixel has the colour.

    Args:
        image_bgr: (H, W, 3) a written frame.
        colour_rgb: the drawn colour.
        points_px: (N, 2) positions in the image, pixels.
    """
    difference = np.abs(image_bgr.astype(np.int16) - np.array(colour_rgb[::-1], dtype=np.int16)).sum(2)
    mask = difference < tolerance
    points = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    if not mask.any():
        return np.full(len(points), np.inf)
    distance = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    height, width = mask.shape
    out = np.full(len(points), np.inf)
    inside = np.isfinite(points).all(1)
    inside[inside] = ((points[inside] >= 0) & (points[inside] < [width, height])).all(1)
    x, y = np.floor(points[inside]).astype(int).T
    out[inside] = distance[y, x]
    return out


def overlay_alignment(view: CaptureView, result: OverlayResult) -> pd.DataFrame:
    """How well written overlays sit on the detections, measured on the video frames: per view, the fit's median
    reprojection error and, for every confident joint of a detection the association gave a person, the distance
    to the nearest pixel drawn in that person's colour (write the overlays with ``show_detections=False`` so that
    only the fit carries the colours).

    Returns:
        One row per view: ``view``, ``frames``, ``joints``, ``fit_error_px`` (median over frames),
        ``distance_px`` (median over joints), ``distance_p90_px``, ``within_error_plus_3px`` (fraction).

    Raises:
        OSError: a video has fewer frames than ``result.frames``.
    """
    people = detection_people(view.associations)
    rows = []
    for v, (name, camera, path) in enumerate(zip(view.view_names, view.cameras["final"], result.videos)):
        mine = view.detections[(view.detections["view"] == v) & (view.detections["score"] > 0)]
        fits = reprojected_fit(view.keypoints_world_m, v, camera, mine, people)
        by_frame = {int(f): rows_ for f, rows_ in mine.groupby("frame")}
        capture = cv2.VideoCapture(str(path))
        distances, errors = [], []
        try:
            for frame in result.frames:
                ok, image = capture.read()
                if not ok:
                    raise OSError(errno.EIO, f"frame {frame} missing", str(path))
                fit = fits.get(int(frame))
                if fit is None:
                    continue
                if np.isfinite(fit.error_px):
                    errors.append(fit.error_px)
                detections = by_frame.get(int(frame))
                for det_id, det in ([] if detections is None else detections.groupby("det_id")):
                    person_id = people.get((int(frame), v, int(det_id)), -1)
                    if person_id in fit.people:
                        scale = image.shape[1] / camera.width_px
                        distances += (distance_to_colour(image, person_colour(person_id),
                                                         det[["x_px", "y_px"]].to_numpy() * scale) / scale).tolist()
        finally:
            capture.release()
        distances = np.asarray(distances)
        error = float(np.median(errors)) if errors else float("nan")
        rows.append({"view": name, "frames": len(result.frames), "joints": len(distances), "fit_error_px": error,
                     "distance_px": float(np.median(distances)) if len(distances) else float("nan"),
                     "distance_p90_px": float(np.percentile(distances, 90)) if len(distances) else float("nan"),
                     "within_error_plus_3px": float(np.mean(distances <= error + 3.0)) if len(distances)
                     else float("nan")})
    return pd.DataFrame(rows)
