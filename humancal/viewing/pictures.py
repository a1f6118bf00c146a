"""Pictures of one capture for the asset pages: who the views saw over time, and how far the fit lands from the
detections in each view over time."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from humancal.camera import CameraRig
from humancal.plotting import pyplot, save_figure
from humancal.viewing.reprojection import detection_people, reprojected_fit

__all__ = ["people_per_view_frame", "plot_detections_over_time", "plot_reprojection_errors"]


def people_per_view_frame(detections: pd.DataFrame, num_views: int, min_joints: int = 4
                          ) -> tuple[np.ndarray, np.ndarray]:
    """(F,) the frames from the first to the last, and (V, F) how many people each view detected in each (at least
    ``min_joints`` joints with a positive score)."""
    if not len(detections):
        return np.zeros(0, np.int64), np.zeros((num_views, 0), np.int64)
    seen = detections[detections["score"] > 0].groupby(["frame", "view", "det_id"]).size()
    people = seen[seen >= min_joints].groupby(level=["view", "frame"]).size().unstack("frame", fill_value=0)
    frames = np.arange(int(detections["frame"].min()), int(detections["frame"].max()) + 1)
    return frames, people.reindex(index=range(num_views), columns=frames, fill_value=0).to_numpy(np.int64)


def plot_detections_over_time(detections: pd.DataFrame, view_names: Sequence[str], path_png: str | Path, *,
                              min_joints: int = 4, title: str = "") -> Path:
    """Views (rows) x frames (columns): how many people each view detected in each frame (at least ``min_joints``
    confident joints), so that a camera that stopped, started late or sees nobody stands out.

    Args:
        detections: a ``detections`` table (long form: one row per joint).
        view_names: (V,) the views' names, in view order.
        path_png: where to write the PNG.
    """
    plt = pyplot()
    frames, grid = people_per_view_frame(detections, len(view_names), min_joints)
    if not len(frames):
        frames, grid = np.zeros(1, np.int64), np.zeros((len(view_names), 1), np.int64)
    fig, ax = plt.subplots(figsize=(9.0, 0.45 * len(view_names) + 1.6))
    image = ax.imshow(grid, aspect="auto", interpolation="nearest", cmap="viridis",
                      extent=(frames[0] - 0.5, frames[-1] + 0.5, len(view_names) - 0.5, -0.5),
                      vmin=0, vmax=max(1, int(grid.max())))
    ax.set_yticks(range(len(view_names)), [str(n) for n in view_names])
    ax.set_xlabel("frame")
    fig.colorbar(image, ax=ax, label="people detected", pad=0.01)
    ax.set_title(title or f"detections per view over time ({len(frames)} frames)")
    fig.tight_layout()
    return save_figure(fig, path_png)


def plot_reprojection_errors(keypoints_world_m: dict[int, tuple[np.ndarray, np.ndarray]], cameras: CameraRig,
                             detections: pd.DataFrame, associations: pd.DataFrame, view_names: Sequence[str],
                             path_png: str | Path, *, title: str = "") -> Path:
    """Per view over time: the mean distance between the fitted keypoints reprojected and the detections the
    association gave the same people (:func:`humancal.viewing.reprojection.reprojected_fit`), with each view's median
    in the legend. A view far above the others for the whole capture is a camera to question.

    Args:
        keypoints_world_m: person id -> ((T,) frames, (T, 23, 3) fitted keypoints, world metres).
        cameras: the rig of the V cameras the fit is seen through.
        detections: a ``detections`` table.
        associations: the ``associations`` table (person id per detection).
        view_names: (V,) the views' names.
        path_png: where to write the PNG.
    """
    plt = pyplot()
    people = detection_people(associations)
    fig, ax = plt.subplots(figsize=(9.0, 3.6))
    colours = plt.get_cmap("tab10")
    for v, (name, camera) in enumerate(zip(view_names, cameras)):
        mine = detections[detections["view"] == v]
        fits = reprojected_fit(keypoints_world_m, v, camera, mine, people)
        frames = np.array(sorted(fits))
        errors = np.array([fits[f].error_px for f in frames])
        if not np.isfinite(errors).any():
            continue
        ax.plot(frames, errors, lw=0.9, color=colours(v % colours.N),
                label=f"{name}: median {np.nanmedian(errors):.1f} px")
    ax.set_xlabel("frame")
    ax.set_ylabel("reprojection error (px)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2, loc="upper right")
    ax.set_title(title or "per-view reprojection error of the fit over time")
    fig.tight_layout()
    return save_figure(fig, path_png)
