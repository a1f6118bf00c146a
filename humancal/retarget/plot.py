"""A picture of a retarget: the mocap skeleton and the body model's skeleton, front and side, a few frames."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from humancal.keypoints import CANONICAL_JOINTS, LIMB_INDEX
from humancal.mocap import MocapClip
from humancal.plotting import pyplot, save_figure
from humancal.retarget.clips import RetargetedClip

__all__ = ["plot_retarget"]

_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
"""Parents of the 22 posed bones (``BodyModel.posed_parents``; fixed by ``humancal.body.bones``)."""


def _limb_colour(name_a: str, name_b: str) -> str:
    if name_a.startswith("left_") and name_b.startswith("left_"):
        return "tab:blue"
    if name_a.startswith("right_") and name_b.startswith("right_"):
        return "tab:red"
    return "tab:green"


def _heading_rad(rotmat_root: np.ndarray) -> float:
    """Yaw that turns the body's facing direction (-y in the reference pose) into the world."""
    facing = -rotmat_root[:, 1]
    return float(np.arctan2(facing[0], -facing[1]))


def plot_retarget(
    clip: MocapClip,
    retargeted: RetargetedClip,
    frame_indices: Sequence[int],
    path_png: str | Path,
) -> Path:
    """Draw the mocap skeleton and the retargeted body model over each other, front and side view.

    Each row is one frame of ``retargeted`` (the mocap frame at the same time is taken from ``clip``, which may
    have another frame rate). The scene is turned about z so that the body faces the viewer in the front view
    and looks to the right in the side view, and centred on the root.

    Args:
        clip: the original mocap clip.
        retargeted: its retarget.
        frame_indices: frames of ``retargeted`` to draw (one row each).
        path_png: the PNG to write (its folder must exist).

    Returns:
        The path written.

    Raises:
        ValueError: no frames, a frame outside the retargeted clip, or clips of different names.
    """
    plt = pyplot()

    if clip.name != retargeted.name:
        raise ValueError(f"plot_retarget: mocap clip {clip.name!r} and retargeted clip {retargeted.name!r} differ")
    frames = [int(f) for f in frame_indices]
    if not frames:
        raise ValueError("plot_retarget: no frames to draw")
    bad = [f for f in frames if not 0 <= f < retargeted.frames]
    if bad:
        raise ValueError(f"plot_retarget: frames {bad} outside the {retargeted.frames} frames of {retargeted.name!r}")
    fig, axes = plt.subplots(len(frames), 2, figsize=(8.0, 4.2 * len(frames)), squeeze=False)
    for row, frame in enumerate(frames):
        mocap_frame = min(int(round(frame / retargeted.fps * clip.fps)), clip.frames - 1)
        psi = _heading_rad(retargeted.bone_rotmats_local[frame, 0])
        turn = np.array([[np.cos(psi), np.sin(psi), 0.0], [-np.sin(psi), np.cos(psi), 0.0], [0.0, 0.0, 1.0]])
        centre = retargeted.root_translation_m[frame] * np.array([1.0, 1.0, 0.0])

        def view(points: np.ndarray) -> np.ndarray:
            return (points - centre) @ turn.T

        mocap = view(clip.positions_world_m[mocap_frame])
        keypoints = view(retargeted.keypoints_world_m[frame])
        joints = view(retargeted.joints_world_m[frame]) if retargeted.joints_world_m is not None else None
        residual = (
            f", median residual {np.median(retargeted.residual_mm[frame]):.1f} mm"
            if retargeted.residual_mm.size else ""
        )
        for col, (axis_index, sign, title) in enumerate(((0, 1.0, "front"), (1, -1.0, "side (facing right)"))):
            ax = axes[row, col]
            for j, p in enumerate(clip.parents):
                if p >= 0:
                    ax.plot(sign * mocap[[p, j], axis_index], mocap[[p, j], 2], color="0.35", lw=1.0, zorder=1)
            ax.scatter(sign * mocap[:, axis_index], mocap[:, 2], s=4, color="0.2", zorder=2)
            if joints is not None:
                for j, p in enumerate(_PARENTS):
                    if p >= 0:
                        ax.plot(sign * joints[[p, j], axis_index], joints[[p, j], 2], color="tab:orange", lw=1.0,
                                ls="--", zorder=3)
            for a, b in LIMB_INDEX:
                ax.plot(sign * keypoints[[a, b], axis_index], keypoints[[a, b], 2], lw=2.0, alpha=0.8, zorder=4,
                        color=_limb_colour(CANONICAL_JOINTS[a], CANONICAL_JOINTS[b]))
            ax.set_aspect("equal")
            ax.set_xlabel("x (m)" if col == 0 else "-y (m), body frame")
            ax.set_ylabel("z (m)")
            ax.set_title(f"{retargeted.name} frame {frame} ({frame / retargeted.fps:.2f} s), {title}{residual}",
                         fontsize=8)
            ax.grid(alpha=0.3)
    handles = [
        plt.Line2D([], [], color="0.35", lw=1.0, label="mocap skeleton"),
        plt.Line2D([], [], color="tab:orange", lw=1.0, ls="--", label="body model bones"),
        plt.Line2D([], [], color="tab:blue", lw=2.0, label="body model keypoints (left)"),
        plt.Line2D([], [], color="tab:red", lw=2.0, label="body model keypoints (right)"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return save_figure(fig, path_png, dpi=110)
