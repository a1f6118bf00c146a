"""Configuration of the motion prior: variant, network, loss weights, augmentation and training.

One frozen dataclass validated on construction; a bad value raises a one-line ``ValueError`` naming the field,
the value and what is allowed. :meth:`PriorConfig.default` is the configuration of the shipped weights,
:meth:`PriorConfig.tiny` a seconds-long one for tests. ``to_dict`` / ``from_dict`` round-trip a config through
plain Python values (the form stored in the weights' json sidecar).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

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


def _number(name: str, value: Any, low: float, high: float, *, integer: bool = False) -> None:
    kinds = (int,) if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds) or not math.isfinite(value) or not low <= value <= high:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"PriorConfig.{name}={value!r} must be {kind} in [{low}, {high}]")


def _interval(name: str, value: Any, low: float, high: float) -> tuple[float, float]:
    ok = isinstance(value, (tuple, list)) and len(value) == 2
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok or not low <= value[0] <= value[1] <= high:
        raise ValueError(
            f"PriorConfig.{name}={value!r} must be a (min, max) pair with min <= max within [{low}, {high}]"
        )
    return float(value[0]), float(value[1])


@dataclass(frozen=True)
class PriorConfig:
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
    latent_dim: int = 32
    hidden_size: int = 128
    head_width: int = 256
    clip_frames: int = 16
    epochs: int = 36
    steps_per_epoch: int = 200
    batch_size: int = 128
    learning_rate: float = 2e-3
    final_lr_factor: float = 0.02
    weight_decay: float = 1e-5
    weight_6d: float = 1.0
    weight_keypoints: float = 100.0
    weight_kl: float = 1e-3
    kl_anneal_epochs: int = 5
    weight_local_linear: float = 0.1
    resample_prob: float = 0.5
    speed_range: tuple[float, float] = (0.5, 2.0)
    reverse_prob: float = 0.5
    mirror_prob: float = 0.5
    validation_windows: int = 1024
    seed: int = 0

    def __post_init__(self) -> None:
        if self.variant not in PRIOR_VARIANTS:
            raise ValueError(f"PriorConfig.variant={self.variant!r} must be one of {list(PRIOR_VARIANTS)}")
        _number("latent_dim", self.latent_dim, 1, 4096, integer=True)
        _number("hidden_size", self.hidden_size, 4, 8192, integer=True)
        _number("head_width", self.head_width, 4, 8192, integer=True)
        _number("clip_frames", self.clip_frames, 3, 10_000, integer=True)
        _number("epochs", self.epochs, 1, 100_000, integer=True)
        _number("steps_per_epoch", self.steps_per_epoch, 1, 10_000_000, integer=True)
        _number("batch_size", self.batch_size, 1, 1_000_000, integer=True)
        _number("learning_rate", self.learning_rate, 1e-7, 1.0)
        _number("final_lr_factor", self.final_lr_factor, 0.0, 1.0)
        _number("weight_decay", self.weight_decay, 0.0, 1.0)
        for name in ("weight_6d", "weight_keypoints", "weight_kl", "weight_local_linear"):
            _number(name, getattr(self, name), 0.0, 1e6)
        _number("kl_anneal_epochs", self.kl_anneal_epochs, 0, 100_000, integer=True)
        _number("resample_prob", self.resample_prob, 0.0, 1.0)
        object.__setattr__(self, "speed_range", _interval("speed_range", self.speed_range, 0.1, 10.0))
        _number("reverse_prob", self.reverse_prob, 0.0, 1.0)
        _number("mirror_prob", self.mirror_prob, 0.0, 1.0)
        _number("validation_windows", self.validation_windows, 1, 10_000_000, integer=True)
        _number("seed", self.seed, 0, 2**63 - 1, integer=True)

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

    def replace(self, **changes: Any) -> PriorConfig:
        """A validated copy with some fields changed.

        Raises:
            ValueError: an unknown field, or an invalid value.
        """
        unknown = sorted(set(changes) - {f.name for f in fields(self)})
        if unknown:
            raise ValueError(f"PriorConfig has no field(s) {unknown}")
        return replace(self, **changes)

    def digest(self) -> str:
        """Short hex digest of every field (names a configuration, e.g. in a code version)."""
        text = json.dumps(self.to_dict(), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the config (strings, ints, floats, lists: json-safe)."""
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
