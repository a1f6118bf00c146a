"""The motion VAE: per-frame latent codes (T x latent_dim) for a motion of T frames, and back.

Architecture of the default ``motion_prior`` variant (after section III-D of the paper)::

    pose6d (B, T, 21, 6) -> x (B, T, 126)
    encoder: h = BiGRU(x) (B, T, 2H);  u = [h, x]  (skip connection)
             mu = Linear(GELU(Linear(u)));  logvar = Linear(GELU(Linear(u)))      each (B, T, latent_dim)
    decoder: g = BiGRU(z) (B, T, 2H);  v = [g, z]  (skip connection)
             pose6d = identity6d + Linear(GELU(Linear(v)))                           (B, T, 21, 6)

The mean and log-variance heads share their hidden layer. Variants (``humancal.prior.config.PRIOR_VARIANTS``):
``unidirectional`` uses forward-only GRUs (H features per frame); ``no_skip`` feeds the heads ``h`` / ``g``
alone; ``no_local_linear`` is this architecture trained without the local-linear term; ``per_frame`` replaces
each GRU by a two-layer per-frame MLP (width H), so that every frame is encoded and decoded on its own.
The decoder's output is an offset from the identity rotation, so an all-zero output is the reference pose.

6D convention: a rotation's 6D form is its first two columns, flattened row by row:
``R[..., :, :2].reshape(..., 6)`` = (R00, R01, R10, R11, R20, R21); back by Gram-Schmidt
(``roma.special_gramschmidt``). The bones are the posed bones 1..21 of ``humancal.body.bones`` (the root,
bone 0, is left out: its rotation is the body's global orientation), in anny's "local-ref" parameterization.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from humancal.geometry.rotations import sixd_to_rotmat
from humancal.prior.config import NUM_PRIOR_BONES, PriorConfig

__all__ = [
    "POSE6D_DIM",
    "MotionVAE",
    "VAEOutput",
    "rotmats_to_pose6d",
    "pose6d_to_rotmats",
    "identity_pose6d",
    "with_root",
]

POSE6D_DIM = NUM_PRIOR_BONES * 6
"""Features of one frame: 21 bones x 6D."""

_LOGVAR_RANGE = (-12.0, 6.0)


def rotmats_to_pose6d(bone_rotmats: Tensor) -> Tensor:
    """6D forms of rotations (first two columns, row by row).

    Args:
        bone_rotmats: (..., 3, 3) rotation matrices.

    Returns:
        (..., 6) = ``bone_rotmats[..., :, :2]`` flattened.
    """
    if bone_rotmats.shape[-2:] != (3, 3):
        raise ValueError(f"bone_rotmats must have shape (..., 3, 3), got {tuple(bone_rotmats.shape)}")
    return bone_rotmats[..., :, :2].reshape(*bone_rotmats.shape[:-2], 6)


def pose6d_to_rotmats(pose6d: Tensor) -> Tensor:
    """Rotation matrices from 6D forms (Gram-Schmidt; any input whose two columns are independent works).

    Args:
        pose6d: (..., 6) as written by :func:`rotmats_to_pose6d`.

    Returns:
        (..., 3, 3) rotation matrices (differentiable).
    """
    if pose6d.shape[-1] != 6:
        raise ValueError(f"pose6d must have shape (..., 6), got {tuple(pose6d.shape)}")
    return sixd_to_rotmat(pose6d.reshape(*pose6d.shape[:-1], 3, 2))


def identity_pose6d(dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu") -> Tensor:
    """(21, 6) 6D forms of the identity rotation (the reference pose)."""
    eye = torch.eye(3, dtype=dtype, device=device)
    return rotmats_to_pose6d(eye).expand(NUM_PRIOR_BONES, 6).clone()


def with_root(bone_rotmats: Tensor, root_rotmats: Tensor) -> Tensor:
    """The full posed-bone rotations of the body model from the prior's 21 bones and a root orientation.

    Args:
        bone_rotmats: (..., 21, 3, 3) rotations of posed bones 1..21 (e.g. ``pose6d_to_rotmats(decode(z))``).
        root_rotmats: (..., 3, 3) root (bone 0) rotations, the same leading shape.

    Returns:
        (..., 22, 3, 3), the ``bone_rotmats_local`` of ``humancal.body.BodyModel.keypoints``.
    """
    if bone_rotmats.shape[-3:] != (NUM_PRIOR_BONES, 3, 3) or root_rotmats.shape != (*bone_rotmats.shape[:-3], 3, 3):
        raise ValueError(
            f"with_root needs bone_rotmats (..., {NUM_PRIOR_BONES}, 3, 3) and root_rotmats (..., 3, 3) with the same "
            f"leading shape, got {tuple(bone_rotmats.shape)} and {tuple(root_rotmats.shape)}"
        )
    return torch.cat([root_rotmats.unsqueeze(-3), bone_rotmats], dim=-3)


@dataclass(frozen=True)
class VAEOutput:
    """One pass of :meth:`MotionVAE.forward`.

    Attributes:
        pose6d: (B, T, 21, 6) reconstruction.
        mu: (B, T, latent_dim) posterior mean.
        logvar: (B, T, latent_dim) posterior log-variance (natural log of sigma^2).
        z: (B, T, latent_dim) the latent decoded (a sample, or ``mu`` when not sampling).
    """

    pose6d: Tensor
    mu: Tensor
    logvar: Tensor
    z: Tensor


class _Sequence(nn.Module):
    """Per-frame features over time: a GRU (one or both directions) or, per frame, a two-layer MLP."""

    def __init__(self, in_dim: int, config: PriorConfig) -> None:
        super().__init__()
        self.temporal = config.temporal
        if self.temporal:
            self.gru = nn.GRU(in_dim, config.hidden_size, batch_first=True, bidirectional=config.bidirectional)
            self.out_dim = config.hidden_size * (2 if config.bidirectional else 1)
        else:
            self.mlp = nn.Sequential(
                nn.Linear(in_dim, config.hidden_size),
                nn.GELU(),
                nn.Linear(config.hidden_size, config.hidden_size),
                nn.GELU(),
            )
            self.out_dim = config.hidden_size

    def forward(self, x: Tensor) -> Tensor:
        if self.temporal:
            return self.gru(x)[0]
        return self.mlp(x)


class MotionVAE(nn.Module):
    """The motion prior's VAE (see the module docstring); any number of frames T >= 1.

    Args:
        config: the variant and sizes (``PriorConfig``); the training fields are not used here.

    Attributes:
        config: the configuration it was built from.
        latent_dim: size of one frame's latent code.
    """

    def __init__(self, config: PriorConfig) -> None:
        super().__init__()
        if not isinstance(config, PriorConfig):
            raise ValueError(f"MotionVAE needs a PriorConfig, got {type(config).__name__}")
        self.config = config
        self.latent_dim = config.latent_dim
        self.skip = config.skip
        width = config.head_width
        self.encoder = _Sequence(POSE6D_DIM, config)
        encoder_out = self.encoder.out_dim + (POSE6D_DIM if self.skip else 0)
        self.encoder_head = nn.Sequential(nn.Linear(encoder_out, width), nn.GELU())
        self.mu_head = nn.Linear(width, config.latent_dim)
        self.logvar_head = nn.Linear(width, config.latent_dim)
        self.decoder = _Sequence(config.latent_dim, config)
        decoder_out = self.decoder.out_dim + (config.latent_dim if self.skip else 0)
        self.decoder_head = nn.Sequential(nn.Linear(decoder_out, width), nn.GELU(), nn.Linear(width, POSE6D_DIM))
        self.register_buffer("_identity6d", identity_pose6d().reshape(POSE6D_DIM), persistent=False)

    def _check(self, value: Tensor, name: str, last: tuple[int, ...], meaning: str) -> None:
        ok = isinstance(value, Tensor) and value.ndim == 2 + len(last) and tuple(value.shape[2:]) == last
        if not ok or value.shape[1] < 1:
            shape = tuple(value.shape) if isinstance(value, Tensor) else type(value).__name__
            raise ValueError(f"{name} must have shape (B, T, {', '.join(map(str, last))}) ({meaning}), got {shape}")

    def encode(self, pose6d: Tensor) -> tuple[Tensor, Tensor]:
        """Posterior of the latent codes of a batch of motions.

        Args:
            pose6d: (B, T, 21, 6) 6D rotations of posed bones 1..21 (module docstring).

        Returns:
            ``(mu, logvar)``, each (B, T, latent_dim); ``logvar`` clamped to [-12, 6].

        Raises:
            ValueError: wrong shape.
        """
        self._check(pose6d, "pose6d", (NUM_PRIOR_BONES, 6), "motions x frames x bones x 6D")
        x = pose6d.flatten(2)
        features = self.encoder(x)
        if self.skip:
            features = torch.cat([features, x], dim=-1)
        hidden = self.encoder_head(features)
        return self.mu_head(hidden), self.logvar_head(hidden).clamp(*_LOGVAR_RANGE)

    def decode(self, z: Tensor) -> Tensor:
        """Motions from latent codes.

        Args:
            z: (B, T, latent_dim) latent codes.

        Returns:
            (B, T, 21, 6) 6D rotations (not normalised: map them with :func:`pose6d_to_rotmats`).

        Raises:
            ValueError: wrong shape.
        """
        self._check(z, "z", (self.latent_dim,), "motions x frames x latent")
        features = self.decoder(z)
        if self.skip:
            features = torch.cat([features, z], dim=-1)
        out = self.decoder_head(features) + self._identity6d
        return out.view(*z.shape[:2], NUM_PRIOR_BONES, 6)

    def decode_rotmats(self, z: Tensor) -> Tensor:
        """:meth:`decode` mapped to rotation matrices: (B, T, 21, 3, 3)."""
        return pose6d_to_rotmats(self.decode(z))

    def forward(self, pose6d: Tensor, sample: bool = True, generator: torch.Generator | None = None) -> VAEOutput:
        """Encode, draw latents (reparameterisation) and decode.

        Args:
            pose6d: (B, T, 21, 6) as in :meth:`encode`.
            sample: draw ``z = mu + sigma * eps``; otherwise decode ``mu``.
            generator: source of ``eps`` (default: torch's global generator).

        Returns:
            The :class:`VAEOutput`.
        """
        mu, logvar = self.encode(pose6d)
        if sample:
            eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype, device=mu.device)
            z = mu + torch.exp(0.5 * logvar) * eps
        else:
            z = mu
        return VAEOutput(pose6d=self.decode(z), mu=mu, logvar=logvar, z=z)
