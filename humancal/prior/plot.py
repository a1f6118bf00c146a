"""Pictures of the motion prior: its training curves, an interpolation between two latent codes, samples.

Poses are drawn as the 23 canonical keypoints and their limbs (``humancal.keypoints.LIMBS``) of the body
model with the root at the identity orientation and the origin, seen from the front (world x right, z up;
the reference pose faces -y) and, lighter, from the side (world y).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from humancal.body import BodyModel
from humancal.keypoints import LIMB_INDEX
from humancal.plotting import pyplot, save_figure
from humancal.prior.model import MotionVAE, pose6d_to_rotmats, with_root

__all__ = ["plot_training_history", "plot_latent_interpolation", "plot_prior_samples", "decoded_keypoints"]


def plot_training_history(history: Sequence[dict[str, Any]], path_png: str | Path, *, title: str = "motion prior") -> Path:
    """Write a PNG of the per-epoch records of ``humancal.prior.train_motion_prior``.

    Left: training loss (log scale); middle: training keypoint error and held-out reconstruction MPJPE (mm);
    right: training and held-out KL per latent coordinate.

    Returns:
        The path written.

    Raises:
        ValueError: an empty history.
    """
    if not history:
        raise ValueError("plot_training_history needs at least one record")
    plt = pyplot()

    def column(name: str) -> np.ndarray:
        return np.array([float(r.get(name, np.nan)) for r in history])

    epochs = column("epoch")
    fig, (ax_loss, ax_mm, ax_kl) = plt.subplots(1, 3, figsize=(14, 4))
    ax_loss.semilogy(epochs, column("train_loss"), "o-", ms=3)
    ax_loss.set_ylabel("training loss")
    ax_mm.plot(epochs, column("train_keypoint_error_mm"), "o-", ms=3, label="training keypoint error")
    ax_mm.plot(epochs, column("val_mpjpe_mm"), "o-", ms=3, label="held-out reconstruction MPJPE")
    later = [v for v in np.concatenate([column("train_keypoint_error_mm")[1:], column("val_mpjpe_mm")[1:]]) if np.isfinite(v)]
    if later:
        ax_mm.set_ylim(0, 1.3 * max(later))  # epoch 0 (untrained) would flatten the curve
    ax_mm.set_ylabel("mm")
    ax_mm.legend()
    ax_kl.plot(epochs, column("train_kl"), "o-", ms=3, label="training")
    ax_kl.plot(epochs, column("val_kl"), "o-", ms=3, label="held-out")
    ax_kl.set_ylabel("KL per latent coordinate")
    ax_kl.legend()
    for ax in (ax_loss, ax_mm, ax_kl):
        ax.set_xlabel("epoch")
        ax.grid(True, lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path_png, dpi=100)


@torch.no_grad()
def decoded_keypoints(prior: MotionVAE, body: BodyModel, z: Tensor, phenotypes: Tensor | None = None) -> np.ndarray:
    """Keypoints of decoded latents, root at the identity and the origin.

    Args:
        prior: the motion VAE.
        body: the body model.
        z: (B, T, latent_dim) latent codes.
        phenotypes: (6,) the body's shape (default: 0.5 for every phenotype).

    Returns:
        (B, T, 23, 3) keypoints, metres.
    """
    to = dict(dtype=body.dtype, device=body.device)
    prior = prior.to(**to).eval()
    B, T = z.shape[:2]
    shape = torch.full((6,), 0.5, **to) if phenotypes is None else torch.as_tensor(phenotypes, **to)
    rest = body.rest_skeleton(shape.expand(B, 6).contiguous())
    eye = torch.eye(3, **to).expand(B, T, 3, 3)
    rotmats = with_root(pose6d_to_rotmats(prior.decode(z.to(**to))), eye)
    return body.keypoints(rest, rotmats, torch.zeros(B, T, 3, **to)).double().cpu().numpy()


def _draw(ax, keypoints_m: np.ndarray, offset_m: float, color) -> None:
    """Front (x, z) view of one pose, shifted right by ``offset_m``, with a lighter side (y, z) view behind it."""
    from matplotlib.collections import LineCollection

    limbs = np.array(LIMB_INDEX)
    front = keypoints_m[:, [0, 2]] + [offset_m, 0.0]
    side = keypoints_m[:, [1, 2]] + [offset_m + 0.45, 0.0]
    ax.add_collection(LineCollection(side[limbs], colors="0.8", linewidths=1.0))
    ax.add_collection(LineCollection(front[limbs], colors=[color], linewidths=1.6))
    ax.plot(front[:, 0], front[:, 1], ".", color=color, ms=3)


def _poses_figure(rows: list[np.ndarray], labels: list[str], columns: list[str], path_png: str | Path, title: str) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(len(rows), 1, figsize=(2.0 * len(rows[0]) + 1, 3.0 * len(rows)), squeeze=False)
    colors = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(rows[0])))
    for ax, poses, label in zip(axes[:, 0], rows, labels):
        for i, pose in enumerate(poses):
            _draw(ax, pose, 1.4 * i, colors[i])
            ax.text(1.4 * i, -1.2, columns[i], ha="center", fontsize=8)
        ax.set_aspect("equal")
        ax.set_xlim(-0.8, 1.4 * len(poses))
        ax.set_ylim(-1.3, 0.9)
        ax.set_ylabel(label)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path_png, dpi=90)


def plot_latent_interpolation(prior: MotionVAE, body: BodyModel, z_start: Tensor, z_end: Tensor, path_png: str | Path,
                              *, steps: int = 7, title: str = "latent interpolation") -> Path:
    """Decode a motion through ``steps`` codes interpolated linearly from ``z_start`` to ``z_end`` and draw it.

    Args:
        prior: the motion VAE.
        body: the body model.
        z_start, z_end: (latent_dim,) two latent codes (e.g. posterior means of two held-out frames).
        path_png: where to write the PNG.
        steps: poses drawn (the decoded sequence has this many frames).

    Returns:
        The path written.
    """
    if z_start.shape != (prior.latent_dim,) or z_end.shape != (prior.latent_dim,) or steps < 2:
        raise ValueError(f"plot_latent_interpolation needs two ({prior.latent_dim},) codes and steps >= 2, "
                         f"got {tuple(z_start.shape)}, {tuple(z_end.shape)}, steps={steps}")
    alpha = torch.linspace(0.0, 1.0, steps, dtype=z_start.dtype)[:, None]
    z = ((1.0 - alpha) * z_start + alpha * z_end)[None]
    poses = decoded_keypoints(prior, body, z)[0]
    return _poses_figure([poses], ["decoded"], [f"alpha {a:.2f}" for a in alpha[:, 0].tolist()], path_png, title)


def plot_prior_samples(prior: MotionVAE, body: BodyModel, path_png: str | Path, *, samples: int = 3, frames: int = 30,
                       shown: int = 6, seed: int = 0, title: str = "samples from the prior") -> Path:
    """Decode ``samples`` latent sequences drawn from N(0, I) (``frames`` frames each) and draw ``shown`` frames
    of each, evenly spread over the sequence, one sample per row.

    Returns:
        The path written.
    """
    generator = torch.Generator().manual_seed(seed)
    z = torch.randn(samples, frames, prior.latent_dim, generator=generator)
    poses = decoded_keypoints(prior, body, z)
    picked = np.linspace(0, frames - 1, shown).round().astype(int)
    rows = [poses[s, picked] for s in range(samples)]
    return _poses_figure(rows, [f"sample {s + 1}" for s in range(samples)], [f"frame {f}" for f in picked], path_png, title)
