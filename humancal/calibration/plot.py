"""Top and side views of an estimated camera rig beside the ground truth, with the people's floor positions."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from humancal.calibration.rig_alignment import align_rig
from humancal.camera import CameraRig
from humancal.plotting import pyplot, save_figure

__all__ = ["plot_rigs"]


def _draw(ax, cameras: CameraRig, axes: tuple[int, int], color: str, label: str, length: float) -> None:
    centres = np.stack([c.center_world_m for c in cameras])
    ax.scatter(centres[:, axes[0]], centres[:, axes[1]], c=color, marker="^", s=40, label=label, zorder=3)
    for v, (c, p) in enumerate(zip(cameras, centres)):
        tip = p + length * c.R_cam_from_world[2]  # the optical axis (camera z) in the world
        ax.plot([p[axes[0]], tip[axes[0]]], [p[axes[1]], tip[axes[1]]], color=color, lw=1.2)
        ax.annotate(str(v), (p[axes[0]], p[axes[1]]), color=color, fontsize=8, xytext=(3, 3),
                    textcoords="offset points")


def plot_rigs(
    estimated: CameraRig,
    ground_truth: CameraRig | None,
    floor_points: np.ndarray | None,
    path_png: str | Path,
    *,
    title: str = "camera rigs",
) -> Path:
    """Write a PNG with the top (x-y) and side (x-z) views of the rigs.

    When ``ground_truth`` is given, the estimated rig (and ``floor_points``, which live in its world) is first
    brought onto it by the similarity of the camera centres (:func:`~humancal.calibration.rig_alignment.align_rig`).

    Args:
        estimated: the calibrated rig.
        ground_truth: the true rig (same views) or None.
        floor_points: (N, 3) people's floor positions in the estimated world, metres (or None).
        path_png: output file.
        title: figure title.

    Returns:
        The path written.
    """
    plt = pyplot()

    est = CameraRig.of(estimated)
    truth = None if ground_truth is None else CameraRig.of(ground_truth)
    points = None if floor_points is None else np.asarray(floor_points, dtype=np.float64).reshape(-1, 3)
    if truth is not None:
        sim = align_rig(est, truth)
        est = CameraRig.from_cameras([sim.apply_to_camera(c) for c in est])
        points = None if points is None else sim.apply(points)
    centres = np.stack([c.center_world_m for c in est])
    length = 0.15 * float(np.ptp(centres[:, :2], axis=0).max() or 1.0)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
    for ax, dims, name in ((axes[0], (0, 1), "top view (x, y)"), (axes[1], (0, 2), "side view (x, z)")):
        if points is not None and len(points):
            ax.scatter(points[:, dims[0]], points[:, dims[1]], s=2, c="0.6", alpha=0.5, label="people on the floor")
        if truth is not None:
            _draw(ax, truth, dims, "tab:green", "ground truth", length)
        _draw(ax, est, dims, "tab:red", "estimated" + (" (aligned)" if truth is not None else ""), length)
        ax.set_title(name)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]" if dims[1] == 1 else "z [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, lw=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path_png, dpi=110)
