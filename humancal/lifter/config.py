"""Configuration of the lifter: virtual cameras, training-sample synthesis, network and training.

Frozen dataclasses validated on construction; a bad value raises a one-line ``ValueError`` naming the field,
the value and what is allowed. :meth:`LifterConfig.default` is the configuration of the shipped checkpoint,
:meth:`LifterConfig.tiny` a seconds-long one for tests. ``to_dict`` / ``from_dict`` round-trip a config
through plain Python values (the form stored in checkpoints).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from humancal.config import Config, in_range, ordered_pair
from humancal.synthetic.config import FOCAL_LIMITS_PX, IMAGE_SIZE_LIMITS_PX, DetectorNoise

__all__ = ["VirtualCameraRanges", "SampleConfig", "LifterConfig", "training_noise"]


def training_noise() -> DetectorNoise:
    """The detector model of the training samples: the synthetic scenes' default, without false positives.

    False positives and missed people have no 3D target, so they are switched off (the other rates are those
    of ``DetectorNoise()``: jitter 0.8 % of the apparent height, 2 % missing clear joints, 2 % flips, ...).
    """
    return DetectorNoise(person_miss_rate=0.0, false_positives_per_image=0.0)


@dataclass(frozen=True)
class VirtualCameraRanges(Config):
    """Random virtual cameras like those of real rigs (``humancal.lifter.cameras``).

    Attributes:
        image_sizes_px: candidate (width, height) image sizes, pixels, each within 640x480 .. 1920x1080.
        focal_range_px: (min, max) focal length fx = fy, pixels, within [500, 2500].
        horizontal_fov_range_deg: (min, max) horizontal field of view, degrees; with the image width it narrows
            the focal range (a 640 px image with a 2500 px focal length would be a 15 deg telephoto).
        distance_range_m: (min, max) horizontal distance from the camera centre to the person, metres.
        camera_height_range_m: (min, max) height of the camera centre above the floor, metres.
        steep_fraction: fraction of the cameras that look down steeply (ceiling, balcony and crane cameras):
            their pitch below the horizon is drawn from ``steep_pitch_range_deg`` and the distance is measured
            along the line of sight instead of the floor, which sets the camera height. From the height and
            distance ranges alone fewer than 3 % of the cameras look down 45 degrees or more, and the lifter
            trained on them tilted the poses such cameras see by about 6 degrees about the camera's x axis
            (``docs/results/lifter.md``).
        steep_pitch_range_deg: (min, max) pitch of the steep cameras below the horizon, degrees.
        apparent_height_range: (min, max) of the person's height in the image as a fraction of the image
            height; with the focal length it narrows the distance range.
        roll_std_deg: std of the roll about the optical axis, degrees.
        truncation_prob: probability that a camera places the person anywhere (pelvis uniform in the image
            grown by ``centre_margin_frac`` on every side, so the body may be partly outside); otherwise the
            pelvis lands uniformly where the whole body fits in the image.
        centre_margin_frac: see ``truncation_prob``, fraction of the image size.
    """

    image_sizes_px: tuple[tuple[int, int], ...] = (
        (640, 480),
        (800, 600),
        (1024, 768),
        (1280, 720),
        (1280, 960),
        (1920, 1080),
    )
    focal_range_px: tuple[float, float] = (500.0, 2500.0)
    horizontal_fov_range_deg: tuple[float, float] = (30.0, 100.0)
    distance_range_m: tuple[float, float] = (2.0, 10.0)
    camera_height_range_m: tuple[float, float] = (0.5, 4.0)
    steep_fraction: float = field(default=0.25, metadata=in_range(0.0, 1.0))
    steep_pitch_range_deg: tuple[float, float] = (30.0, 75.0)
    apparent_height_range: tuple[float, float] = (0.1, 0.9)
    roll_std_deg: float = field(default=4.0, metadata=in_range(0.0, 45.0))
    truncation_prob: float = field(default=0.2, metadata=in_range(0.0, 1.0))
    centre_margin_frac: float = field(default=0.1, metadata=in_range(0.0, 1.0))

    def __post_init__(self) -> None:
        super().__post_init__()
        owner = "VirtualCameraRanges"
        (w_lo, h_lo), (w_hi, h_hi) = IMAGE_SIZE_LIMITS_PX
        sizes = self.image_sizes_px
        ok = isinstance(sizes, (tuple, list)) and len(sizes) > 0
        ok = ok and all(
            isinstance(s, (tuple, list))
            and len(s) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in s)
            and w_lo <= s[0] <= w_hi
            and h_lo <= s[1] <= h_hi
            for s in sizes
        )
        if not ok:
            raise ValueError(
                f"{owner}.image_sizes_px={sizes!r} must be a non-empty list of integer (width, height) pairs "
                f"from {w_lo}x{h_lo} to {w_hi}x{h_hi}"
            )
        object.__setattr__(self, "image_sizes_px", tuple((int(w), int(h)) for w, h in sizes))
        for name, low, high in (
            ("focal_range_px", *FOCAL_LIMITS_PX),
            ("horizontal_fov_range_deg", 5.0, 150.0),
            ("distance_range_m", 0.5, 50.0),
            ("camera_height_range_m", 0.0, 20.0),
            ("steep_pitch_range_deg", 0.0, 89.0),
            ("apparent_height_range", 0.01, 5.0),
        ):
            object.__setattr__(self, name, ordered_pair(owner, name, getattr(self, name), low, high))


@dataclass(frozen=True)
class SampleConfig(Config):
    """How training samples are made from 3D motion (``humancal.lifter.data``).

    Attributes:
        cameras: the virtual camera ranges.
        noise: the simulated detector (``humancal.synthetic.DetectorNoise``); false positives and missed people
            are discarded anyway (they have no 3D target).
        frames_per_group: frames drawn from one clip and seen together by ``cameras_per_group`` cameras.
        cameras_per_group: virtual cameras per group.
        mirror_prob: probability of mirroring a frame left-right (a mirrored body with swapped labels is another
            plausible body).
        root_offset_std_m: std of the random horizontal offset of each frame's root from the point the cameras
            are aimed at, metres.
        score_scale_range: (min, max) of a per-detection factor on all confidences (clipped to 1), so the network
            does not rely on the synthetic detector's exact confidence level.
        min_joints: a detection needs at least this many joints to be lifted (also used at inference).
    """

    cameras: VirtualCameraRanges = field(default_factory=VirtualCameraRanges)
    noise: DetectorNoise = field(default_factory=training_noise)
    frames_per_group: int = field(default=64, metadata=in_range(1, 100_000, integer=True))
    cameras_per_group: int = field(default=16, metadata=in_range(1, 1_000, integer=True))
    mirror_prob: float = field(default=0.5, metadata=in_range(0.0, 1.0))
    root_offset_std_m: float = field(default=0.3, metadata=in_range(0.0, 5.0))
    score_scale_range: tuple[float, float] = (0.6, 1.15)
    min_joints: int = field(default=4, metadata=in_range(2, 23, integer=True))

    def __post_init__(self) -> None:
        super().__post_init__()
        owner = "SampleConfig"
        if not isinstance(self.cameras, VirtualCameraRanges):
            raise ValueError(f"{owner}.cameras must be a VirtualCameraRanges, got {type(self.cameras).__name__}")
        if not isinstance(self.noise, DetectorNoise):
            raise ValueError(f"{owner}.noise must be a DetectorNoise, got {type(self.noise).__name__}")
        scale = ordered_pair(owner, "score_scale_range", self.score_scale_range, 0.01, 10.0)
        object.__setattr__(self, "score_scale_range", scale)


@dataclass(frozen=True)
class LifterConfig(Config):
    """Network, optimisation and data of one lifter training run (``humancal.lifter.train``).

    Attributes:
        width: hidden width of the residual MLP.
        num_blocks: residual blocks (two linear layers each).
        dropout: dropout probability inside the blocks.
        epochs: passes over ``samples_per_epoch`` samples.
        samples_per_epoch: training samples per epoch.
        sample_reuse: each synthesised sample set serves this many consecutive epochs (reshuffled); 1 draws
            fresh samples every epoch. Synthesising a sample costs about as much as a training pass over it.
        batch_size: samples per optimisation step.
        learning_rate: peak AdamW learning rate.
        final_lr_factor: the learning rate decays (cosine, per step) to ``learning_rate * final_lr_factor``.
        weight_decay: AdamW weight decay.
        validation_samples: held-out samples synthesised once from the validation clips.
        seed: seeds every random choice (samples, initialisation, dropout, batch order).
        log_every_steps: a progress record every this many optimisation steps.
        samples: how samples are synthesised.
    """

    width: int = field(default=512, metadata=in_range(8, 8192, integer=True))
    num_blocks: int = field(default=2, metadata=in_range(0, 32, integer=True))
    dropout: float = field(default=0.0, metadata=in_range(0.0, 0.9))
    epochs: int = field(default=40, metadata=in_range(1, 10_000, integer=True))
    samples_per_epoch: int = field(default=150_000, metadata=in_range(1, 100_000_000, integer=True))
    sample_reuse: int = field(default=3, metadata=in_range(1, 10_000, integer=True))
    batch_size: int = field(default=256, metadata=in_range(1, 1_000_000, integer=True))
    learning_rate: float = field(default=2e-3, metadata=in_range(1e-7, 1.0))
    final_lr_factor: float = field(default=0.01, metadata=in_range(0.0, 1.0))
    weight_decay: float = field(default=1e-4, metadata=in_range(0.0, 1.0))
    validation_samples: int = field(default=8192, metadata=in_range(1, 10_000_000, integer=True))
    seed: int = field(default=0, metadata=in_range(0, 2**63 - 1, integer=True))
    log_every_steps: int = field(default=100, metadata=in_range(1, 10_000_000, integer=True))
    samples: SampleConfig = field(default_factory=lambda: SampleConfig(frames_per_group=128))

    def __post_init__(self) -> None:
        super().__post_init__()
        owner = "LifterConfig"
        if not isinstance(self.samples, SampleConfig):
            raise ValueError(f"{owner}.samples must be a SampleConfig, got {type(self.samples).__name__}")

    @classmethod
    def default(cls) -> LifterConfig:
        """The configuration of the reported checkpoint (about 11 minutes on one CPU thread)."""
        return cls()

    @classmethod
    def tiny(cls, seed: int = 0) -> LifterConfig:
        """A seconds-long configuration for tests: a narrow network on a few thousand samples."""
        return cls(
            width=64,
            num_blocks=1,
            dropout=0.0,
            epochs=3,
            samples_per_epoch=3072,
            sample_reuse=1,
            batch_size=128,
            learning_rate=3e-3,
            final_lr_factor=0.1,
            validation_samples=512,
            seed=seed,
            log_every_steps=10,
            samples=SampleConfig(frames_per_group=32, cameras_per_group=8),
        )

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> LifterConfig:
        """Rebuild a config written by :meth:`to_dict`.

        Raises:
            ValueError: unknown or invalid fields.
        """
        try:
            values = dict(values)
            sample_values = dict(values.pop("samples"))
            cameras = VirtualCameraRanges(**sample_values.pop("cameras"))
            noise = DetectorNoise(**sample_values.pop("noise"))
            samples = SampleConfig(cameras=cameras, noise=noise, **sample_values)
            return cls(samples=samples, **values)
        except (KeyError, TypeError) as error:
            raise ValueError(f"not a LifterConfig dict: {error}") from error
