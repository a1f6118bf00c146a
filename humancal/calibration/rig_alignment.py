"""Similarity alignment of camera rigs (Umeyama's least-squares solution, ``humancal.geometry.alignment``).

Used to compare a calibrated rig with a reference one (evaluation, plots): a self-calibrated rig is only
defined up to the choice of world frame, so it is first brought onto the reference by the similarity
(scale, rotation, translation) that best maps its camera centres onto the reference centres.
"""

from __future__ import annotations

import numpy as np

from humancal.camera import CameraRig
from humancal.geometry.alignment import Similarity, fit_similarity

__all__ = ["Similarity", "rig_alignment_points", "align_rig"]


def rig_alignment_points(cameras: CameraRig, length: float, with_axes: bool = False) -> np.ndarray:
    """Camera centres, plus (for fewer than three cameras, or ``with_axes``) a point ``length`` ahead on each
    optical axis.

    With two cameras the centres alone leave the rotation about their baseline free; the points on the optical
    axes fix it. With three, the centres fix it only as well as their triangle's shape is right.
    """
    centres = np.stack([c.center_world_m for c in cameras])
    if len(cameras) >= 3 and not with_axes:
        return centres
    ahead = np.stack([c.center_world_m + length * c.R_cam_from_world[2] for c in cameras])
    return np.concatenate([centres, ahead])


def align_rig(estimated: CameraRig, reference: CameraRig) -> Similarity:
    """Similarity mapping the estimated rig's world onto the reference world, fitted on the camera centres.

    For two cameras, points on the optical axes at the baseline length of each rig are added (see
    :func:`rig_alignment_points`).

    Raises:
        ValueError: the rigs have different numbers of cameras.
    """
    if len(estimated) != len(reference):
        raise ValueError(f"rigs differ in size: {len(estimated)} estimated vs {len(reference)} reference cameras")
    c_est = np.stack([c.center_world_m for c in estimated])
    c_ref = np.stack([c.center_world_m for c in reference])
    base_est = float(np.linalg.norm(c_est - c_est.mean(0), axis=1).mean()) or 1.0
    base_ref = float(np.linalg.norm(c_ref - c_ref.mean(0), axis=1).mean()) or 1.0
    return fit_similarity(rig_alignment_points(estimated, base_est), rig_alignment_points(reference, base_ref))
