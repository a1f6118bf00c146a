"""The body fit's schedule: its stages in order, and the half-rate start of the first one.

The first stage (``fit3d``) may run its first steps on every other frame (``BodyFitConfig.half_rate_fraction_3d``);
its variables are then brought to every frame by linear interpolation in time (:func:`upsample_frames`).
"""

from __future__ import annotations

import torch
from torch import Tensor

from humancal.fitting.config import BodyFitConfig

__all__ = ["half_rate_steps", "stage_schedule", "upsample_frames"]


def upsample_frames(values: Tensor, num_frames: int) -> Tensor:
    """(P, Tc, ...) values of frames 0, 2, 4, ... -> (P, num_frames, ...), linear in time (the last odd frame of an
    even-length sequence takes the last value)."""
    position = torch.arange(num_frames, device=values.device) / 2.0
    low = position.floor().long().clamp(max=values.shape[1] - 1)
    high = (low + 1).clamp(max=values.shape[1] - 1)
    weight = (position - low).clamp(0.0, 1.0).to(values.dtype).reshape(1, -1, *([1] * (values.dim() - 2)))
    return values[:, low] * (1.0 - weight) + values[:, high] * weight


def half_rate_steps(config: BodyFitConfig, num_frames: int) -> int:
    """How many ``fit3d`` steps run on every other frame first (``BodyFitConfig.half_rate_fraction_3d``)."""
    if num_frames < 2 * config.window_frames:
        return 0
    return int(round(config.half_rate_fraction_3d * config.iterations_3d))


def stage_schedule(config: BodyFitConfig, cameras_move: bool, half_rate: int = 0) -> list[tuple[str, int]]:
    """The stages in order with their iterations on every frame (``humancal.fitting.fit``'s docstring; ``half_rate``
    of fit3d's steps ran before, on every other frame)."""
    rounds = [("global", config.iterations_global), ("body", config.iterations_body)]
    fit3d = ("fit3d", config.iterations_3d - half_rate)
    if not cameras_move:
        return [fit3d, *rounds]
    return [fit3d] + [("cameras", config.iterations_cameras), *rounds] * config.rounds
