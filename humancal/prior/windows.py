"""Overlapping windows of frames: a long motion's latent codes as a batch of short sequences.

A recurrent prior decodes a T-frame sequence in T sequential steps; cut into W windows of L frames and
decoded as one batch it takes L steps. Consecutive windows share ``overlap`` frames; each frame's pose is
taken from the window whose centre is nearest (its *owner*), and a seam term keeps the other window's
decoding of a shared frame equal to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

__all__ = ["WindowLayout", "reconstruct_in_windows", "window_layout"]


@dataclass(frozen=True)
class WindowLayout:
    """Where the frames of a sequence sit in its windows.

    Attributes:
        num_frames: T.
        length: L, frames per window (T when the sequence fits one window).
        starts: (W,) first frame of each window; the last window ends at frame T - 1.
        owner_window: (T,) the window each frame's pose is taken from.
        owner_offset: (T,) the frame's position in its owner window.
        seam_a, seam_b: (S, 2) (window, offset) pairs of the same frame in two consecutive windows.
    """

    num_frames: int
    length: int
    starts: np.ndarray
    owner_window: np.ndarray
    owner_offset: np.ndarray
    seam_a: np.ndarray
    seam_b: np.ndarray

    @property
    def num_windows(self) -> int:
        return int(len(self.starts))

    def window_frames(self) -> np.ndarray:
        """(W, L) the frame of every window position."""
        return self.starts[:, None] + np.arange(self.length)[None, :]

    def assemble(self, windowed: Tensor) -> Tensor:
        """Per-frame values from per-window ones.

        Args:
            windowed: (P, W, L, ...) values of every window position.

        Returns:
            (P, T, ...) each frame's value from its owner window.
        """
        return windowed[:, torch.as_tensor(self.owner_window), torch.as_tensor(self.owner_offset)]

    def split(self, per_frame: Tensor) -> Tensor:
        """(P, T, ...) -> (P, W, L, ...): every window's frames (the inverse of :meth:`assemble` on owned frames)."""
        return per_frame[:, torch.as_tensor(self.window_frames())]

    def seam_difference(self, windowed: Tensor) -> Tensor:
        """(P, S, ...) the difference between two windows' values of each shared frame (empty with one window)."""
        a, b = self.seam_a, self.seam_b
        return windowed[:, torch.as_tensor(a[:, 0]), torch.as_tensor(a[:, 1])] - \
            windowed[:, torch.as_tensor(b[:, 0]), torch.as_tensor(b[:, 1])]


def window_layout(num_frames: int, length: int, overlap: int) -> WindowLayout:
    """Cut T frames into windows of ``length`` frames overlapping by at least ``overlap``.

    Args:
        num_frames: T >= 1.
        length: L >= 4; T <= L gives one window of T frames.
        overlap: frames shared by consecutive windows, 0 <= overlap < L / 2 (the last window may share more, so
            that it ends at the last frame).

    Raises:
        ValueError: arguments out of range.
    """
    if num_frames < 1 or length < 4 or not 0 <= overlap < length // 2:
        raise ValueError(f"window_layout: need num_frames >= 1, length >= 4 and 0 <= overlap < length / 2, got "
                         f"{num_frames}, {length}, {overlap}")
    if num_frames <= length:
        length = num_frames
        starts = np.zeros(1, np.int64)
    else:
        stride = length - overlap
        starts = np.arange(0, num_frames - length, stride, dtype=np.int64)
        starts = np.append(starts, num_frames - length)
    centres = starts + (length - 1) / 2.0
    frames = np.arange(num_frames)
    inside = (frames[:, None] >= starts[None, :]) & (frames[:, None] < starts[None, :] + length)
    distance = np.where(inside, np.abs(frames[:, None] - centres[None, :]), np.inf)
    owner = distance.argmin(axis=1)
    seam_a, seam_b = [], []
    for w in range(len(starts) - 1):
        shared = np.arange(starts[w + 1], starts[w] + length)
        seam_a += [(w, t - starts[w]) for t in shared]
        seam_b += [(w + 1, t - starts[w + 1]) for t in shared]
    empty = np.zeros((0, 2), np.int64)
    return WindowLayout(num_frames, int(length), starts, owner, frames - starts[owner],
                        np.asarray(seam_a, np.int64).reshape(-1, 2) if seam_a else empty,
                        np.asarray(seam_b, np.int64).reshape(-1, 2) if seam_b else empty)


def reconstruct_in_windows(prior, pose6d: Tensor, length: int, overlap: int) -> Tensor:
    """Encode (posterior means) and decode a motion window by window, as the body fit applies the prior.

    The recurrent prior is trained on short windows; long sequences are cut by :func:`window_layout` and each
    frame's decoding is taken from its owner window.

    Args:
        prior: a :class:`~humancal.prior.model.MotionVAE`.
        pose6d: (B, T, 21, 6) body poses (6D rotations).
        length, overlap: the windows (:func:`window_layout`).

    Returns:
        (B, T, 21, 6) the decoded poses.
    """
    layout = window_layout(int(pose6d.shape[1]), length, overlap)
    windows = layout.split(pose6d)  # (B, W, L, 21, 6)
    B, W, L = windows.shape[:3]
    mu, _ = prior.encode(windows.reshape(B * W, L, *windows.shape[3:]))
    return layout.assemble(prior.decode(mu).reshape(B, W, L, *pose6d.shape[2:]))
