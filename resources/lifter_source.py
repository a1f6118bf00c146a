"""Which lifter weights the graph uses: the ones shipped with humancal, or the ones trained here.

The rule, stated once: when the artifacts root holds a ``lifter_trained`` checkpoint (written by
``humancal train lifter`` or the retraining schedule), it is the active lifter; otherwise the weights shipped
in the package (``humancal/weights/lifter.safetensors``) are. ``humancal train lifter --discard`` deletes the
trained checkpoint and returns to the shipped weights. Every run states which one it used (the
``lifter_checkpoint`` asset's log and metadata, and the ``humancal`` commands' first line).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from upath import UPath

from humancal.lifter import checkpoint_digest, read_lifter_weights, shipped_info
from humancal.lifter.weights import SHIPPED_LIFTER_STEM, LifterWeightsError
from resources.io_managers import partition_path, read_checkpoint_file

__all__ = ["ActiveLifter", "active_lifter", "trained_lifter_path"]

TRAINED_ASSET = "lifter_trained"


def trained_lifter_path(storage_root: str | UPath) -> UPath:
    """Where the checkpoint IO manager stores ``lifter_trained`` under ``storage_root``."""
    return partition_path(storage_root, TRAINED_ASSET, None, ".pt")


@dataclass(frozen=True)
class ActiveLifter:
    """The lifter weights in force.

    Attributes:
        source: ``"shipped"`` (the package's weights) or ``"trained"`` (``lifter_trained`` under the artifacts root).
        path: the weights file.
        digest: :func:`humancal.lifter.checkpoint_digest` of the checkpoint (hex).
        info: facts for the user: held-out figures, subjects, how it was trained.
    """

    source: Literal["shipped", "trained"]
    path: Path | UPath
    digest: str
    info: dict[str, Any]

    def load(self) -> dict[str, Any]:
        """The checkpoint dict (``humancal.lifter.load_lifter`` builds the network from it)."""
        if self.source == "shipped":
            return read_lifter_weights(SHIPPED_LIFTER_STEM)
        return _load_trained(self.path)

    def describe(self) -> str:
        """One line for logs: which weights, their digest and held-out figure."""
        pa = self.info.get("val_pa_mpjpe_mm")
        held_out = self.info.get("val_subjects", "?")
        figure = f", PA-MPJPE {pa:.1f} mm on held-out subjects {held_out}" if isinstance(pa, (int, float)) else ""
        what = "the lifter shipped with humancal" if self.source == "shipped" else f"the lifter trained here ({self.path})"
        return f"lifter: {what}, digest {self.digest[:12]}, trained on CMU subjects {self.info.get('train_subjects', '?')}{figure}"


def _load_trained(path: Path | UPath) -> dict[str, Any]:
    return read_checkpoint_file(path, lambda why: LifterWeightsError(
        f"{path}: the trained lifter is not a readable checkpoint ({why}); run `humancal train lifter` again, or "
        "`humancal train lifter --discard` to use the shipped weights"))


def active_lifter(storage_root: str | UPath) -> ActiveLifter:
    """The lifter in force for ``storage_root`` (see the module docstring for the rule).

    Raises:
        LifterWeightsError: the weights in force are unreadable or do not match their recorded digest.
    """
    trained = trained_lifter_path(storage_root)
    if trained.exists():
        checkpoint = _load_trained(trained)
        metrics = checkpoint.get("val_metrics", {})
        info = {
            "train_subjects": ", ".join(checkpoint.get("train_subjects", [])),
            "val_subjects": ", ".join(checkpoint.get("val_subjects", [])),
            "val_pa_mpjpe_mm": metrics.get("pa_mpjpe_mm"),
        }
        return ActiveLifter("trained", trained, checkpoint_digest(checkpoint), info)
    shipped = shipped_info()
    # the held-out report of the sidecar (20,000 fresh samples) when present, else the training's validation
    held_out = (shipped.get("held_out") or {}).get("all") or shipped.get("val_metrics") or {}
    info = {
        "train_subjects": ", ".join(shipped["train_subjects"]),
        "val_subjects": ", ".join(shipped["val_subjects"]),
        "val_pa_mpjpe_mm": held_out.get("pa_mpjpe_mm"),
    }
    return ActiveLifter("shipped", SHIPPED_LIFTER_STEM.with_suffix(".safetensors"), shipped["digest"], info)
