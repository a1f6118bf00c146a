"""A picture of an association: the person ids over time, and one frame of every view with the 3D skeletons
reprojected by the cameras over the 2D detections (no images: a blank canvas of each image's size)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from humancal.association.tracking import AssociationResult
from humancal.camera import CameraRig
from humancal.keypoints import LIMB_INDEX
from humancal.plotting import pyplot, save_figure
from humancal.tables.detections import DenseDetections

__all__ = ["association_frame", "plot_association"]

_LIMBS = np.array(LIMB_INDEX)
_REJECTED_COLOUR = "0.55"
_COLUMNS = 4


def _colour(person: int, colours):
    return _REJECTED_COLOUR if person < 0 else colours(person % colours.N)


def association_frame(result: AssociationResult) -> int:
    """The frame with the most people in it (then the most associated detections; the earliest of equals):
    where the picture says most."""
    if len(result.skeleton_frame) == 0:
        return int(result.frame.min()) if len(result.frame) else 0
    frames, people = np.unique(result.skeleton_frame, return_counts=True)
    associated = result.frame[result.person_id >= 0]
    detections = np.array([(associated == f).sum() for f in frames]) if len(associated) else np.zeros(len(frames))
    order = np.lexsort((frames, -detections, -people))
    return int(frames[order[0]])


def _draw_pose(ax, points_px: np.ndarray, colour, **style) -> None:
    """Limbs (and joints) of one pose; NaN joints left out."""
    a, b = points_px[_LIMBS[:, 0]], points_px[_LIMBS[:, 1]]
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    for (xa, ya), (xb, yb) in zip(a[ok], b[ok]):
        ax.plot([xa, xb], [ya, yb], color=colour, **style)


def _draw_timeline(ax, result: AssociationResult, num_views: int, frame: int, colours, title: str | None) -> None:
    """Who is seen by which view when: a band per person id, one row per view (view 0 on top), a mark per (frame,
    id, view); the rejected detections on row -1; the frame drawn below marked."""
    person = result.person_id
    row_of_view = ((num_views - 1) / 2 - np.arange(num_views)) * (0.7 / num_views)
    seen = np.unique(np.stack([result.frame, person, result.view], axis=1), axis=0)
    for p in np.unique(seen[seen[:, 1] >= 0, 1]):
        mine = seen[seen[:, 1] == p]
        ax.scatter(mine[:, 0], p + row_of_view[mine[:, 2]], s=max(2.0, 12.0 / num_views),
                   color=_colour(int(p), colours), marker="s", linewidths=0)
    marks = np.unique(np.stack([result.frame, person], axis=1), axis=0)
    rejected = person < 0
    frames = marks[marks[:, 1] < 0, 0]
    ax.scatter(frames, np.full(len(frames), -1), s=10, color=_REJECTED_COLOUR, marker="x", linewidths=0.8,
               label=f"rejected ({int(rejected.sum())} detections)")
    ax.axvline(frame, color="k", linestyle=":", linewidth=1, label=f"frame {frame} (below)")
    ax.set_xlabel("frame")
    ax.set_ylabel("person id\n(a row per view)")
    ax.set_yticks(np.arange(-1, max(result.num_people, 1)))
    ax.set_ylim(-1.7, max(result.num_people, 1) - 0.3)
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
    ax.set_title(title or f"{result.num_people} people; {int((~rejected).sum())} of {len(person)} detections "
                 "associated", fontsize=10)


def _draw_view(ax, keypoints_px: np.ndarray, persons: np.ndarray, projected_px: np.ndarray,
               skeleton_persons: np.ndarray, size_px, colours) -> None:
    """One view at one frame: its detections ((D, 23, 2), thin; rejected dashed) and the skeletons of the frame
    projected ((S, 23, 2), thick, with joints and the person id), on a blank canvas of the image's size."""
    for points, p in zip(keypoints_px, persons):
        _draw_pose(ax, points, _colour(int(p), colours), linewidth=0.8, linestyle="--" if p < 0 else "-", alpha=0.8)
    for points, p in zip(projected_px, skeleton_persons):
        colour = _colour(int(p), colours)
        _draw_pose(ax, points, colour, linewidth=2.2, alpha=0.55)
        ax.scatter(points[:, 0], points[:, 1], s=5, color=colour)
        seen = points[np.isfinite(points).all(1)]
        if len(seen):
            ax.annotate(str(int(p)), seen.mean(axis=0), color=colour, fontsize=8, fontweight="bold",
                        xytext=(6, 0), textcoords="offset points")
    ax.set_xlim(0, size_px[0])
    ax.set_ylim(size_px[1], 0)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_association(
    result: AssociationResult,
    detections: DenseDetections,
    rig: CameraRig,
    path_png: str | Path,
    *,
    frame: int | None = None,
    max_views: int = 8,
    title: str | None = None,
) -> Path:
    """Draw who is who: a timeline of the person ids and one frame of the views.

    Top: who is seen by which view when: each person id is a band of one thin row per view (view 0 on top), a mark
    where that view has a detection of the person at that frame, coloured by id; the detections rejected as false
    positives on their own row (``-1``, grey crosses). Below: one panel per view (at most ``max_views``, those
    with the most detections in the frame), the image's size as a blank canvas, the 2D detections of the frame
    as thin lines (coloured by their id; rejected ones grey, dashed) and every person's 3D skeleton of the frame
    projected by the view's camera as thick lines with joints, in the same colour.

    Args:
        result: the association (:func:`~humancal.association.associate`).
        detections: the detections it was run on (row-aligned with ``result``).
        rig: the cameras it was run with (their image sizes set the canvases).
        path_png: the PNG to write.
        frame: the frame to draw the views of; default :func:`association_frame`.
        max_views: most view panels drawn (>= 1).
        title: the figure's title (default: counts of people and detections).

    Returns:
        The path written.

    Raises:
        ValueError: detections not row-aligned with the result, views outside the rig, or ``max_views`` < 1.
    """
    if len(detections) != len(result.frame) or not np.array_equal(detections.frame, result.frame) \
            or not np.array_equal(detections.view, result.view):
        raise ValueError(f"plot_association: the detections ({len(detections)} rows) must be row-aligned with the "
                         f"association result ({len(result.frame)} rows)")
    if len(result.view) and int(result.view.max()) >= len(rig):
        raise ValueError(f"plot_association: detections use view {int(result.view.max())} but the rig has "
                         f"{len(rig)} cameras")
    if isinstance(max_views, bool) or not isinstance(max_views, (int, np.integer)) or max_views < 1:
        raise ValueError(f"plot_association: max_views must be an integer >= 1, got {max_views!r}")
    plt = pyplot()
    colours = plt.get_cmap("tab10")
    frame = association_frame(result) if frame is None else int(frame)
    in_frame = result.frame == frame
    counts = np.bincount(result.view[in_frame], minlength=len(rig))
    views = np.sort(np.argsort(-counts, kind="stable")[:max_views])
    rows = int(np.ceil(len(views) / _COLUMNS))
    width_px, height_px = rig.image_size_px[views].max(axis=0)
    panel_h = 3.2 * height_px / width_px
    fig = plt.figure(figsize=(3.2 * _COLUMNS, 2.6 + rows * (panel_h + 0.4)))
    grid = fig.add_gridspec(1 + rows, _COLUMNS, height_ratios=[2.6] + [panel_h + 0.4] * rows)

    _draw_timeline(fig.add_subplot(grid[0, :]), result, len(rig), frame, colours, title)
    person = result.person_id

    skeletons = np.flatnonzero(result.skeleton_frame == frame)
    joints = result.joints_world_m[skeletons]  # (S, 23, 3)
    projected = rig.project(joints.reshape(-1, 3))[0].reshape(len(rig), len(skeletons), -1, 2) if len(skeletons) \
        else np.zeros((len(rig), 0, joints.shape[1] if joints.ndim == 3 else 0, 2))
    for k, v in enumerate(views):
        ax = fig.add_subplot(grid[1 + k // _COLUMNS, k % _COLUMNS])
        rows = np.flatnonzero(in_frame & (result.view == v))
        _draw_view(ax, detections.keypoints_px[rows], person[rows], projected[v],
                   result.skeleton_person[skeletons], rig.image_size_px[v], colours)
        ax.set_title(f"view {v}: {counts[v]} detections", fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path_png, dpi=80)
