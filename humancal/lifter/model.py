"""The lifting network: a residual MLP from a box-normalised 2D detection to a root-relative 3D pose.

Architecture (after Martinez et al., "A simple yet effective baseline for 3d human pose estimation", 2017,
with LayerNorm instead of BatchNorm so that a sample's output never depends on its batch)::

    input (23 x 3: x, y, confidence) -> flatten 69
    Linear(69, W) -> LayerNorm -> ReLU -> Dropout
    num_blocks x [ h + (Linear(W, W) -> LayerNorm -> ReLU -> Dropout) x 2 ]
    Linear(W, 69) -> reshape (23, 3) -> subtract the hip midpoint

The output is the pose in the detection's crop frame (``humancal.lifter.features``), metres, relative to the
hip midpoint; the last step makes the root exactly zero. W = 512 and 3 blocks give 1.7 M parameters.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from humancal.keypoints import NUM_JOINTS
from humancal.lifter.features import ROOT_JOINTS

__all__ = ["LifterNet"]

_IN_CHANNELS = 3


class _Block(nn.Module):
    def __init__(self, width: int, dropout: float) -> None:
        super().__init__()
        self.layers = nn.Sequential(
            nn.Linear(width, width),
            nn.LayerNorm(width),
            nn.ReLU(),
            nn.Dropout(dropout),
            nn.Linear(width, width),
            nn.LayerNorm(width),
            nn.ReLU(),
            nn.Dropout(dropout),
        )

    def forward(self, h: Tensor) -> Tensor:
        return h + self.layers(h)


class LifterNet(nn.Module):
    """Residual MLP lifter (see the module docstring).

    Args:
        width: hidden width W.
        num_blocks: residual blocks.
        dropout: dropout probability (active in training mode only).
    """

    def __init__(self, width: int = 512, num_blocks: int = 3, dropout: float = 0.1) -> None:
        super().__init__()
        if width < 1 or num_blocks < 0 or not 0.0 <= dropout < 1.0:
            raise ValueError(
                f"LifterNet needs width >= 1, num_blocks >= 0, dropout in [0, 1); got {width}, {num_blocks}, {dropout}"
            )
        self.width, self.num_blocks, self.dropout = width, num_blocks, dropout
        self.stem = nn.Sequential(
            nn.Linear(NUM_JOINTS * _IN_CHANNELS, width), nn.LayerNorm(width), nn.ReLU(), nn.Dropout(dropout)
        )
        self.blocks = nn.Sequential(*[_Block(width, dropout) for _ in range(num_blocks)])
        self.head = nn.Linear(width, NUM_JOINTS * 3)
        self.register_buffer("_root", torch.tensor(ROOT_JOINTS), persistent=False)

    def forward(self, features: Tensor) -> Tensor:
        """Lift a batch.

        Args:
            features: (B, 23, 3) box-normalised x, y and confidence.

        Returns:
            (B, 23, 3) root-relative joints in the crop frame, metres.
        """
        if features.ndim != 3 or features.shape[1:] != (NUM_JOINTS, _IN_CHANNELS):
            raise ValueError(f"features must have shape (B, {NUM_JOINTS}, {_IN_CHANNELS}), got {tuple(features.shape)}")
        h = self.blocks(self.stem(features.flatten(1)))
        joints = self.head(h).view(-1, NUM_JOINTS, 3)
        return joints - joints[:, self._root].mean(dim=1, keepdim=True)
