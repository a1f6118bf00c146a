"""Analytic pose initialisation: hierarchical weighted Kabsch, root first, every frame at once.

Going down the posed-bone tree, each bone's world rotation ``G_b`` is the rotation that best maps the rest
positions of the points it carries (relative to its head) onto their targets (relative to its head as placed by
its parent), in the weighted least-squares sense (``roma.special_procrustes``); the root also solves for its
translation (``roma.rigid_points_registration``). A bone whose own points do not spread in two directions borrows
its children's points (as if those children were at rest) with a lower weight when that makes them spread, which
fixes the twist of a limb from the next joint and the pitch of the pelvis; a small pull towards the parent's
rotation picks the least rotation where the points leave freedom (the twist of the spine bones).
This is no optimum (children are assumed at rest, skinned keypoints rigid), only a start close enough for the
L-BFGS refinement to need few iterations and to fall into the right basin (e.g. elbows bending forwards).
"""

from __future__ import annotations

import numpy as np
import roma
import torch
from torch import Tensor

from humancal.retarget.points import PointCoefficients, PointModel

__all__ = ["analytic_pose_init"]

_PARENT_PULL = 1e-3
"""Weight of the pull towards the parent's rotation, relative to the summed point moments ``sum w |x| |v|``."""

_MIN_SPREAD_RATIO = 0.3
"""A bone's own points fix its rotation only if they spread in two directions: second / first singular value of
their weighted rest vectors at least this. Otherwise (one point; points on a line, like the hip joints and the
pelvis centre before the offsets are learned) the children's points are borrowed: without them the rotation about
that line is arbitrary, and a pelvis turned upside down is a local minimum that the offsets then lock in."""


_MIN_BORROWED_SPREAD_RATIO = 0.1
"""Borrowed points must spread at least this much to be used. Measured on anny's rest pose (ratios): upper arm
with the wrist 0.17, clavicle with the elbow 0.22, shin with the toe 0.13, neck with the head's points 0.16,
chest with the shoulders 0.67 (borrowed); thigh with the ankle 0.04, lower spine bones 0.02-0.06 (not: points
nearly on one line, whose small sideways rest offsets would only turn the bone about that line at random)."""


def _spread_ratio(vectors: Tensor, weights: Tensor) -> float:
    """Second over first singular value of ``sqrt(w) * vectors`` (0 for fewer than two non-zero vectors)."""
    if vectors.shape[0] < 2:
        return 0.0
    singular = torch.linalg.svdvals(vectors * weights.sqrt()[:, None])
    return float(singular[1] / singular[0]) if singular[0] > 0 else 0.0


def analytic_pose_init(
    points: PointModel,
    coefficients: PointCoefficients,
    targets_m: Tensor,
    child_weight: float,
) -> tuple[Tensor, Tensor]:
    """Bone rotations and root translations that roughly put the mapped points on their targets.

    Args:
        points: the mapped-point model.
        coefficients: the person's mapped-point coefficients (:meth:`PointModel.coefficients`, offsets included).
        targets_m: (F, M, 3) mocap positions of the mapped points, metres.
        child_weight: weight factor of children's points for bones that carry fewer than two points.

    Returns:
        bone_rotmats_local: (F, B, 3, 3) local-ref rotations, float64.
        root_translation_m: (F, 3) root head positions, metres, float64.
    """
    f64 = torch.float64
    with torch.no_grad():
        coefficients = coefficients.to(f64)
        rest_points = points.rest_points_m(coefficients)
        num_bones = len(points.parents)
        identity = torch.eye(3, dtype=f64, device=rest_points.device).expand(1, num_bones, 3, 3)
        heads = points.world_transforms(coefficients, identity, rest_points.new_zeros(1, 3))[1][0]
        targets = targets_m.to(f64)
        weights = points.weight.to(f64)
        carrier = points.resolved.carrier
        parents = points.parents
        num_frames = targets.shape[0]
        children = [[c for c in range(num_bones) if parents[c] == b] for b in range(num_bones)]
        world_rot: list[Tensor | None] = [None] * num_bones
        world_head: list[Tensor | None] = [None] * num_bones
        local = torch.empty(num_frames, num_bones, 3, 3, dtype=f64, device=targets.device)
        for b in range(num_bones):

            def spread(rows: np.ndarray, w: Tensor, b: int = b) -> float:
                # The root also solves for its translation: its points must spread about their centroid.
                if len(rows) == 0:
                    return 0.0
                reference = (w[:, None] * rest_points[rows]).sum(0) / w.sum() if b == 0 else heads[b]
                return _spread_ratio(rest_points[rows] - reference, w)

            own = np.flatnonzero(carrier == b)
            rows, w = own, weights[own]
            if spread(own, weights[own]) < _MIN_SPREAD_RATIO:
                borrowed = np.flatnonzero(np.isin(carrier, children[b]))
                with_children = np.concatenate([own, borrowed])
                w_children = torch.cat([weights[own], child_weight * weights[borrowed]])
                # Borrow only what makes the set spread (a limb bent at the next joint, the pelvis with the spine
                # and knees); points along the same line (the spine) would turn the bone about that line by
                # however far their small sideways rest offsets happen to reach: keep the least rotation then.
                if spread(with_children, w_children) >= _MIN_BORROWED_SPREAD_RATIO:
                    rows, w = with_children, w_children
            x = rest_points[rows] - heads[b]
            if b == 0:
                if len(rows) < 3 or spread(rows, w) < _MIN_SPREAD_RATIO:
                    raise ValueError(
                        "the joint correspondence needs at least 3 points spread in two directions, carried by the "
                        f"root bone or its children, to place the body; got rows {rows.tolist()}"
                    )
                rot, trans = roma.rigid_points_registration(
                    x.expand(num_frames, -1, -1), targets[:, rows], weights=w.expand(num_frames, -1)
                )
                world_rot[0], world_head[0] = rot, trans
                local[:, 0] = rot
            else:
                parent_rot = world_rot[parents[b]]
                v = targets[:, rows] - world_head[b][:, None]
                moment = torch.einsum("n,fni,nj->fij", w, v, x)
                scale = (w * x.norm(dim=-1)).sum() * v.norm(dim=-1).mean(dim=0).max() if len(rows) else 0.0
                moment = moment + (_PARENT_PULL * scale + 1e-12) * parent_rot
                rot = roma.special_procrustes(moment)
                world_rot[b] = rot
                local[:, b] = parent_rot.transpose(-1, -2) @ rot
            for c in children[b]:
                world_head[c] = world_head[b] + (world_rot[b] @ (heads[c] - heads[b]))
        return local, world_head[0]
