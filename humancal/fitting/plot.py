"""Pictures of a body fit: the fitted meshes reprojected over the detections of every view (no images: a blank
canvas of each image's size), and the 3D scene with the people and the cameras."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from humancal.body import BodyModel
from humancal.camera import CameraRig
from humancal.fitting.motions import FittedMotions
from humancal.fitting.observations import BodyObservations
from humancal.keypoints import LIMB_INDEX
from humancal.plotting import pyplot, save_figure

__all__ = ["fit_frame", "frame_vertices", "plot_fit_reprojection", "plot_fit_scene"]

_LIMBS = np.array(LIMB_INDEX)
_COLUMNS = 3
_VERTEX_STRIDE = 7  # every 7th vertex: ~2,000 points a body, enough to see the mesh's outline


def fit_frame(motions: FittedMotions) -> int:
    """Index (into ``motions.frames``) of the frame with the most people present (the earliest of equals)."""
    return int(np.argmax(motions.present.sum(0)))


def frame_vertices(body: BodyModel, motions: FittedMotions, index: int) -> list[np.ndarray]:
    """(V, 3) mesh vertices, world metres, of every person present at frame index ``index`` (one full forward)."""
    people = np.flatnonzero(motions.present[:, index])
    if people.size == 0:
        return []
    as_t = lambda a: torch.as_tensor(a, dtype=body.dtype, device=body.device)  # noqa: E731
    with torch.no_grad():
        out = body.reference_forward(as_t(motions.phenotypes[people]),
                                     as_t(motions.bone_rotmats_local[people, index:index + 1]),
                                     as_t(motions.root_translation_m[people, index:index + 1]))
    return [v for v in out["vertices"][:, 0].double().cpu().numpy()]


def plot_fit_reprojection(body: BodyModel, motions: FittedMotions, observations: BodyObservations, rig: CameraRig,
                          path_png: str | Path, *, title: str = "") -> Path:
    """Every view at the busiest frame: the detections (grey limbs), the fitted meshes (dots) and keypoints (limbs)
    reprojected, coloured by person.

    Args:
        body: the body model (one full mesh per present person).
        motions: the fit.
        observations: the detections it was fitted to (same people and frames).
        rig: the cameras it was fitted with.
        path_png: where to write the PNG.
        title: figure title.
    """
    plt = pyplot()
    index = fit_frame(motions)
    people = np.flatnonzero(motions.present[:, index])
    vertices = frame_vertices(body, motions, index)
    colours = plt.get_cmap("tab10")
    V = len(rig)
    rows = int(np.ceil(V / _COLUMNS))
    fig, axes = plt.subplots(rows, min(V, _COLUMNS), figsize=(4.2 * min(V, _COLUMNS), 3.0 * rows), squeeze=False)
    for v, ax in enumerate(axes.ravel()):
        if v >= V:
            ax.axis("off")
            continue
        camera = rig[v]
        drawn = []
        for k, p in enumerate(people):
            colour = colours(int(motions.person_ids[p]) % colours.N)
            seen = observations.confidence[v, p, index] > 0
            if seen.any():
                detected = np.where(seen[:, None], observations.keypoints_px[v, p, index], np.nan)
                _draw_limbs(ax, detected, "0.55", linewidth=2.5, alpha=0.6)
            pixels, _ = rig.project(vertices[k][::_VERTEX_STRIDE])  # NaN behind the camera
            ax.scatter(pixels[v, :, 0], pixels[v, :, 1], s=0.4, color=colour, alpha=0.35, linewidths=0)
            drawn.append(pixels[v])
            keypoints, _ = rig.project(motions.keypoints_world_m[p, index])
            _draw_limbs(ax, keypoints[v], colour, linewidth=1.2)
        # the people's region of the image (with a margin), so that the fit can be judged; the whole image if empty
        points = np.concatenate(drawn) if drawn else np.zeros((0, 2))
        points = points[np.isfinite(points).all(1)]
        low, high = np.array([0.0, 0.0]), np.array([camera.width_px, camera.height_px], dtype=float)
        if len(points):
            margin = 0.15 * (points.max(0) - points.min(0)).max() + 20.0
            low, high = np.maximum(points.min(0) - margin, low), np.minimum(points.max(0) + margin, high)
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(high[1], low[1])
        ax.set_aspect("equal")
        ax.set_title(f"view {v}", fontsize=9)
        ax.tick_params(labelsize=6)
    fig.suptitle(title or f"frame {int(motions.frames[index])}: fitted meshes (dots) and keypoints over the "
                          f"detections (grey)", fontsize=10)
    return save_figure(fig, path_png)


def _draw_limbs(ax, points_px: np.ndarray, colour, **style) -> None:
    a, b = points_px[_LIMBS[:, 0]], points_px[_LIMBS[:, 1]]
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    for (xa, ya), (xb, yb) in zip(a[ok], b[ok]):
        ax.plot([xa, xb], [ya, yb], color=colour, **style)


def plot_fit_scene(body: BodyModel, motions: FittedMotions, rig: CameraRig, path_png: str | Path, *,
                   title: str = "") -> Path:
    """The 3D scene at the busiest frame: every present person's mesh (subsampled vertices), each person's root
    path over the whole sequence, and the cameras (centre and viewing direction), world Z up."""
    plt = pyplot()
    index = fit_frame(motions)
    people = np.flatnonzero(motions.present[:, index])
    vertices = frame_vertices(body, motions, index)
    colours = plt.get_cmap("tab10")
    fig = plt.figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    points = []
    for k, p in enumerate(people):
        colour = colours(int(motions.person_ids[p]) % colours.N)
        mesh = vertices[k][::_VERTEX_STRIDE]
        ax.scatter(mesh[:, 0], mesh[:, 1], mesh[:, 2], s=0.3, color=colour, alpha=0.5, linewidths=0)
        points.append(mesh)
    for p in range(motions.num_people):
        path = motions.root_translation_m[p, motions.present[p]]
        colour = colours(int(motions.person_ids[p]) % colours.N)
        ax.plot(path[:, 0], path[:, 1], np.zeros(len(path)), color=colour, linewidth=0.8,
                label=f"person {int(motions.person_ids[p])}")
        points.append(path)
    centres = rig.centers_world_m
    scale = 0.12 * max(1.0, float(np.ptp(centres, axis=0).max()))
    for v, (centre, R) in enumerate(zip(centres, rig.R_cam_from_world)):
        forward = R[2]  # the camera's z axis in the world
        ax.quiver(*centre, *(forward * scale * 2), color="k", linewidth=1.0)
        ax.scatter(*centre, color="k", s=12)
        ax.text(*centre, f" {v}", fontsize=8)
    points.append(centres)
    every = np.concatenate(points)
    middle, half = (every.max(0) + every.min(0)) / 2, (every.max(0) - every.min(0)).max() / 2 + 0.2
    ax.set_xlim(middle[0] - half, middle[0] + half)
    ax.set_ylim(middle[1] - half, middle[1] + half)
    ax.set_zlim(max(middle[2] - half, -0.5), middle[2] + half)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(title or f"frame {int(motions.frames[index])}: fitted people, their paths and the cameras",
                 fontsize=10)
    return save_figure(fig, path_png)
