"""Picture of a lifter training run: losses and held-out errors per epoch."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from humancal.plotting import pyplot, save_figure

__all__ = ["plot_training_history"]


def plot_training_history(history: Sequence[dict[str, Any]], path_png: str | Path, *, title: str = "lifter") -> Path:
    """Write a PNG of the per-epoch records of :func:`~humancal.lifter.train.train_lifter`.

    Left: training loss and validation MPJPE / PA-MPJPE (mm) per epoch; right: validation height MAE (mm).

    Returns:
        The path written.
    """
    plt = pyplot()

    epochs = np.array([r["epoch"] for r in history])
    fig, (ax, ax_h) = plt.subplots(1, 2, figsize=(11, 4))
    ax.plot(epochs, [1000 * r["train_loss_m"] for r in history], "o-", ms=3, label="train loss (MPJPE)")
    ax.plot(epochs, [r["val_mpjpe_mm"] for r in history], "o-", ms=3, label="held-out MPJPE")
    ax.plot(epochs, [r["val_pa_mpjpe_mm"] for r in history], "o-", ms=3, label="held-out PA-MPJPE")
    finite = [v for r in history[1:] for v in (1000 * r["train_loss_m"], r["val_mpjpe_mm"])]
    if finite:
        ax.set_ylim(0, 1.3 * max(finite))  # epoch 0 (untrained) would flatten the curve
    ax.set_xlabel("epoch")
    ax.set_ylabel("mm")
    ax.grid(True, lw=0.3)
    ax.legend()
    ax_h.plot(epochs, [r["val_height_mae_mm"] for r in history], "o-", ms=3, color="tab:purple")
    heights = [r["val_height_mae_mm"] for r in history[1:]]
    if heights:
        ax_h.set_ylim(0, 1.3 * max(heights))
    ax_h.set_xlabel("epoch")
    ax_h.set_ylabel("held-out height MAE [mm]")
    ax_h.grid(True, lw=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path_png, dpi=100)
