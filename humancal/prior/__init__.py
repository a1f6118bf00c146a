"""The learned motion prior: a VAE over motions of the body model's 21 non-root bones (``docs/motion_prior.md``).

A motion of T frames maps to T x 32 latent codes and back (section III-D of the paper); trained here on the CMU
mocap retargeted onto anny, with the paper's augmentation (time resampling, reversal, left-right mirroring).

Example:
    >>> from humancal.prior import MotionVAE, PriorConfig, load_prior, pose6d_to_rotmats, save_prior
    >>> from humancal.prior import train_motion_prior
    >>> model = MotionVAE(PriorConfig.default())
    >>> mu, logvar = model.encode(pose6d)  # doctest: +SKIP
    >>> bone_rotmats = pose6d_to_rotmats(model.decode(mu))  # (B, T, 21, 3, 3)  # doctest: +SKIP
    >>> trained = train_motion_prior(retargeted_clips, PriorConfig.default(), BodyModel())  # doctest: +SKIP
    >>> save_prior(trained, "motion_prior"); model, info = load_prior("motion_prior")  # doctest: +SKIP
"""

from humancal.prior.config import NUM_PRIOR_BONES, PRIOR_VARIANTS, PriorConfig
from humancal.prior.data import (
    MIRROR_BONE_PERMUTATION,
    MotionClips,
    MotionWindows,
    clips_from_retargeted,
    mirror_bone_rotmats,
    sample_windows,
    slerp_rotmats,
)
from humancal.prior.losses import kl_divergence, local_linear, pose_keypoints_m, prior_losses
from humancal.prior.model import (
    POSE6D_DIM,
    MotionVAE,
    VAEOutput,
    identity_pose6d,
    pose6d_to_rotmats,
    rotmats_to_pose6d,
    with_root,
)
from humancal.prior.train import TrainedPrior, clip_rest_skeletons, reconstruction_mpjpe_mm, train_motion_prior
from humancal.prior.weights import (
    PRIOR_WEIGHTS_FORMAT,
    SHIPPED_PRIOR_STEM,
    SHIPPED_VARIANT_STEMS,
    PriorWeightsError,
    load_prior,
    read_prior_info,
    save_prior,
    shipped_prior,
    weights_digest,
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
    "MIRROR_BONE_PERMUTATION",
    "MotionClips",
    "MotionWindows",
    "clips_from_retargeted",
    "mirror_bone_rotmats",
    "sample_windows",
    "slerp_rotmats",
    "kl_divergence",
    "local_linear",
    "pose_keypoints_m",
    "prior_losses",
    "TrainedPrior",
    "clip_rest_skeletons",
    "reconstruction_mpjpe_mm",
    "train_motion_prior",
    "PRIOR_WEIGHTS_FORMAT",
    "SHIPPED_PRIOR_STEM",
    "SHIPPED_VARIANT_STEMS",
    "PriorWeightsError",
    "load_prior",
    "read_prior_info",
    "save_prior",
    "shipped_prior",
    "weights_digest",
]
