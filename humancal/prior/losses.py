"""Loss terms of the motion prior (section III-D of the paper) and the keypoints they compare.

``total = weight_6d L_6d + weight_keypoints L_kp + w_kl L_kl + weight_local_linear L_linear`` with

- ``L_6d``: mean squared error of the 6D rotations (per coordinate);
- ``L_kp``: mean squared error of the keypoints, metres^2 per coordinate. The paper compares SMPL vertices;
  here the points are the **23 canonical keypoints** (COCO-17 + 6 foot points, ``humancal.keypoints``) of the
  body model's fast keypoint path (:meth:`humancal.body.BodyModel.keypoints`, exactly anny's skinned mesh + COCO
  regressor), with each window's clip's own rest skeleton (its phenotypes), the root (bone 0) rotation at
  identity and the root translation at zero: root-relative body points of the pose alone;
- ``L_kl``: KL divergence of the posterior N(mu, sigma^2) from N(0, I), mean per latent coordinate;
- ``L_linear``: the local-linear term ``||z[t+1] - 2 z[t] + z[t-1]||^2`` on the **sampled** latents (those
  decoded), mean per coordinate and frame triple. The paper writes the norm unsquared; the square is smooth
  at zero and is what the fitting uses too.
"""

from __future__ import annotations

import torch
from torch import Tensor

from humancal.body.rest import RestSkeleton
from humancal.prior.model import VAEOutput, pose6d_to_rotmats, with_root

__all__ = ["pose_keypoints_m", "kl_divergence", "local_linear", "prior_losses"]


def pose_keypoints_m(body_model, rest: RestSkeleton, bone_rotmats: Tensor) -> Tensor:
    """The 23 canonical keypoints of poses of posed bones 1..21, root at the origin with identity rotation.

    Args:
        body_model: a ``humancal.body.BodyModel``.
        rest: rest skeletons of the B motions (``BodyModel.rest_skeleton``; ``rest.select`` per window).
        bone_rotmats: (B, T, 21, 3, 3) rotations of posed bones 1..21.

    Returns:
        (B, T, 23, 3) keypoints, metres, in the root's (reference pose) frame: facing -y, left at +x, Z up.
    """
    batch, frames = bone_rotmats.shape[:2]
    eye = torch.eye(3, dtype=bone_rotmats.dtype, device=bone_rotmats.device).expand(batch, frames, 3, 3)
    translation = bone_rotmats.new_zeros(batch, frames, 3)
    return body_model.keypoints(rest, with_root(bone_rotmats, eye), translation)


def kl_divergence(mu: Tensor, logvar: Tensor) -> Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)), mean per coordinate (scalar)."""
    return 0.5 * (mu.square() + logvar.exp() - 1.0 - logvar).mean()


def local_linear(z: Tensor) -> Tensor:
    """Mean squared second difference along time of (B, T, D) latents (scalar; 0 when T < 3)."""
    if z.shape[1] < 3:
        return z.new_zeros(())
    return (z[:, 2:] - 2.0 * z[:, 1:-1] + z[:, :-2]).square().mean()


def prior_losses(
    output: VAEOutput,
    target_pose6d: Tensor,
    target_keypoints_m: Tensor,
    body_model,
    rest: RestSkeleton,
    *,
    weight_6d: float,
    weight_keypoints: float,
    weight_kl: float,
    weight_local_linear: float,
) -> dict[str, Tensor]:
    """Every term of the module docstring and their weighted sum.

    Args:
        output: the model's pass over the targets.
        target_pose6d: (B, T, 21, 6) the input motions.
        target_keypoints_m: (B, T, 23, 3) :func:`pose_keypoints_m` of the input motions.
        body_model, rest: as in :func:`pose_keypoints_m`.
        weight_6d, weight_keypoints, weight_kl, weight_local_linear: the weights (``weight_kl`` after annealing).

    Returns:
        dict with scalar tensors ``total``, ``pose6d``, ``keypoints_m2``, ``kl``, ``local_linear`` (unweighted
        terms) and ``keypoint_error_m`` (mean Euclidean keypoint error, for reporting).
    """
    pose6d = (output.pose6d - target_pose6d).square().mean()
    keypoints = pose_keypoints_m(body_model, rest, pose6d_to_rotmats(output.pose6d))
    difference = keypoints - target_keypoints_m
    keypoints_m2 = difference.square().mean()
    kl = kl_divergence(output.mu, output.logvar)
    linear = local_linear(output.z)
    total = weight_6d * pose6d + weight_keypoints * keypoints_m2 + weight_kl * kl + weight_local_linear * linear
    with torch.no_grad():
        error = torch.linalg.vector_norm(difference, dim=-1).mean()
    return {
        "total": total,
        "pose6d": pose6d,
        "keypoints_m2": keypoints_m2,
        "kl": kl,
        "local_linear": linear,
        "keypoint_error_m": error,
    }
