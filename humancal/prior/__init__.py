"""The learned motion prior: a VAE over motions of the body model's 21 non-root bones (``docs/motion_prior.md``).

A motion of T frames maps to T x 32 latent codes and back (section III-D of the paper); trained here on the CMU
mocap retargeted onto anny, with the paper's augmentation (time resampling, reversal, left-right mirroring).

Example:
    >>> from humancal.prior import MotionVAE, PriorConfig, pose6d_to_rotmats
    >>> model = MotionVAE(PriorConfig.default())
    >>> mu, logvar = model.encode(pose6d)  # doctest: +SKIP
    >>> bone_rotmats = pose6d_to_rotmats(model.decode(mu))  # (B, T, 21, 3, 3)  # doctest: +SKIP
"""

from humancal.prior.config import NUM_PRIOR_BONES, PRIOR_VARIANTS, PriorConfig
from humancal.prior.model import (
    POSE6D_DIM,
    MotionVAE,
    VAEOutput,
    identity_pose6d,
    pose6d_to_rotmats,
    rotmats_to_pose6d,
    with_root,
)

__all__ = [
    "NUM_PRIOR_BONES",
    "POSE6D_DIM",
    "PRIOR_VARIANTS",
    "MotionVAE",
    "PriorConfig",
    "VAEOutput",
    "identity_pose6d",
    "pose6d_to_rotmats",
    "rotmats_to_pose6d",
    "with_root",
]
