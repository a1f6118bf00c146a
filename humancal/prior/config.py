"""Configuration of the motion prior: variant, network, loss weights, augmentation and training.

One frozen dataclass validated on construction; a bad value raises a one-line ``ValueError`` naming the field,
the value and what is allowed. :meth:`PriorConfig.default` is the configuration of the shipped weights,
:meth:`PriorConfig.tiny` a seconds-long one for tests. ``to_dict`` / ``from_dict`` round-trip a config through
plain Python values (the form stored in the weights' json sidecar).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any

from humancal.config import Config, in_range, ordered_pair

__all__ = ["PRIOR_VARIANTS", "NUM_PRIOR_BONES", "PriorConfig"]

PRIOR_VARIANTS: tuple[str, ...] = ("motion_prior", "unidirectional", "no_skip", "no_local_linear", "per_frame")
"""The variants one code base trains (the paper's ablations and a per-frame baseline):

- ``motion_prior``: bidirectional GRUs, skip connections, local-linear latent term (the paper's prior);
- ``unidirectional``: the GRUs run forward in time only (a frame sees only its past);
- ``no_skip``: the heads see only the GRU features (no per-frame input next to them);
- ``no_local_linear``: the local-linear latent term has weight 0;
- ``per_frame``: an MLP VAE applied to each frame on its own (no dynamics at all; the stand-in for the
  paper's VPoser-t baseline).
"""

NUM_PRIOR_BONES = 21
"""Bones the prior models: the 22 posed bones of ``humancal.body.bones`` without the root (bone 0)."""


@dataclass(frozen=True)
class PriorConfig(Config):
    """Network, losses, augmentation and optimisation of one motion-prior training run (``humancal.prior.train``).

    Attributes:
        variant: one of :data:`PRIOR_VARIANTS`.
        latent_dim: size of the latent code of one frame.
        hidden_size: GRU hidden size per direction (the per-frame variant: width of its MLPs).
        head_width: width of the hidden layer of the mean / log-variance heads and of the decoder's output head.
        clip_frames: frames of one training window.
        epochs: passes of ``steps_per_epoch`` optimisation steps (36: with 20 the held-out error was still
            falling when the learning rate ran out, 17.5 mm against 13.8 with 40; 36 is what two workers train
            within 15 minutes on 2 cores; `docs/motion_prior.md`).
        steps_per_epoch: optimisation steps per epoch (each draws a fresh batch of augmented windows).
        batch_size: windows per optimisation step.
        learning_rate: peak AdamW learning rate.
        final_lr_factor: the learning rate decays (cosine, per step) to ``learning_rate * final_lr_factor``.
        weight_decay: AdamW weight decay.
        weight_6d: weight of the mean squared 6D reconstruction error (per coordinate).
        weight_keypoints: weight of the mean squared keypoint reconstruction error, per coordinate, in metres^2
            (the 23 canonical keypoints through the body model's fast keypoint path; ``humancal.prior.losses``).
        weight_kl: weight of the KL divergence to N(0, I), per latent coordinate, after annealing.
        kl_anneal_epochs: the KL weight grows linearly from 0 to ``weight_kl`` over these first epochs.
        weight_local_linear: weight of the local-linear term ``||z[t+1] - 2 z[t] + z[t-1]||^2`` on the sampled
            latents (mean per coordinate); forced to 0 by the ``no_local_linear`` and ``per_frame`` variants.
        resample_prob: probability that a training window is resampled in time.
        speed_range: (min, max) playback speed factor of a resampled window (2 = twice as fast: the window
            covers 2 x ``clip_frames`` source frames; 0.5 = half as fast); drawn log-uniformly.
        reverse_prob: probability that a training window is played backwards.
        mirror_prob: probability that a training window is mirrored left-right.
        validation_windows: held-out windows drawn once (without augmentation) to score each epoch.
        seed: seeds every random choice (windows, augmentation, initialisation, reparameterisation noise).
    """

    variant: str = "motion_prior"
    latent_dim: int = field(default=32, metadata=in_range(1, 4096, integer=True))
    hidden_size: int = field(default=128, metadata=in_range(4, 8192, integer=True))
    head_width: int = field(default=256, metadata=in_range(4, 8192, integer=True))
    clip_frames: int = field(default=16, metadata=in_range(3, 10_000, integer=True))
    epochs: int = field(default=36, metadata=in_range(1, 100_000, integer=True))
    steps_per_epoch: int = field(default=200, metadata=in_range(1, 10_000_000, integer=True))
    batch_size: int = field(default=128, metadata=in_range(1, 1_000_000, integer=True))
    learning_rate: float = field(default=2e-3, metadata=in_range(1e-7, 1.0))
    final_lr_factor: float = field(default=0.02, metadata=in_range(0.0, 1.0))
    weight_decay: float = field(default=1e-5, metadata=in_range(0.0, 1.0))
    weight_6d: float = field(default=1.0, metadata=in_range(0.0, 1e6))
    weight_keypoints: float = field(default=100.0, metadata=in_range(0.0, 1e6))
    weight_kl: float = field(default=1e-3, metadata=in_range(0.0, 1e6))
    kl_anneal_epochs: int = field(default=5, metadata=in_range(0, 100_000, integer=True))
    weight_local_linear: float = field(default=0.1, metadata=in_range(0.0, 1e6))
    resample_prob: float = field(default=0.5, metadata=in_range(0.0, 1.0))
    speed_range: tuple[float, float] = (0.5, 2.0)
    reverse_prob: float = field(default=0.5, metadata=in_range(0.0, 1.0))
    mirror_prob: float = field(default=0.5, metadata=in_range(0.0, 1.0))
    validation_windows: int = field(default=1024, metadata=in_range(1, 10_000_000, integer=True))
    seed: int = field(default=0, metadata=in_range(0, 2**63 - 1, integer=True))

    def __post_init__(self) -> None:
        if self.variant not in PRIOR_VARIANTS:
            raise ValueError(f"PriorConfig.variant={self.variant!r} must be one of {list(PRIOR_VARIANTS)}")
        super().__post_init__()
        object.__setattr__(self, "speed_range", ordered_pair("PriorConfig", "speed_range", self.speed_range, 0.1, 10.0))

    # ------------------------------------------------------------------ variant switches

    @property
    def temporal(self) -> bool:
        """Whether the model has GRUs over time (every variant but ``per_frame``)."""
        return self.variant != "per_frame"

    @property
    def bidirectional(self) -> bool:
        """Whether the GRUs run both ways in time."""
        return self.variant not in ("unidirectional", "per_frame")

    @property
    def skip(self) -> bool:
        """Whether the heads see the per-frame input next to the GRU features."""
        return self.variant != "no_skip"

    @property
    def local_linear_weight(self) -> float:
        """The weight of the local-linear term actually used (0 for ``no_local_linear`` and ``per_frame``)."""
        return 0.0 if self.variant in ("no_local_linear", "per_frame") else self.weight_local_linear

    # ------------------------------------------------------------------ presets

    @classmethod
    def default(cls, variant: str = "motion_prior", seed: int = 0) -> PriorConfig:
        """The configuration of the shipped weights (or of one variant trained the same way)."""
        return cls(variant=variant, seed=seed)

    @classmethod
    def tiny(cls, variant: str = "motion_prior", seed: int = 0) -> PriorConfig:
        """A seconds-long configuration for tests: small networks, a few steps."""
        return cls(
            variant=variant,
            latent_dim=8,
            hidden_size=16,
            head_width=16,
            clip_frames=8,
            epochs=2,
            steps_per_epoch=3,
            batch_size=8,
            kl_anneal_epochs=1,
            validation_windows=8,
            seed=seed,
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the config (strings, ints, floats, lists: json-safe; also what :meth:`digest` hashes)."""
        values = asdict(self)
        values["speed_range"] = list(values["speed_range"])
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PriorConfig:
        """Rebuild a config written by :meth:`to_dict`.

        Raises:
            ValueError: unknown, missing-type or invalid fields.
        """
        if not isinstance(values, dict):
            raise ValueError(f"not a PriorConfig dict: {type(values).__name__}")
        unknown = sorted(set(values) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"not a PriorConfig dict: unknown field(s) {unknown}")
        values = dict(values)
        if isinstance(values.get("speed_range"), list):
            values["speed_range"] = tuple(values["speed_range"])
        return cls(**values)
