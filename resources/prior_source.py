"""Which motion prior the body fit uses: the one shipped with humancal, or the one trained here.

The rule, stated once (as for the lifter, :mod:`resources.lifter_source`): when the artifacts root holds the
default variant's ``motion_prior_trained`` checkpoint (written by ``humancal train prior``, the weekly schedule or
the mocap-change sensor), it is the prior in force; otherwise the weights shipped in the package are. The
``motion_prior_checkpoint`` asset serves the prior in force, and its code version names it: training a new prior
makes that asset stale, and through its data version every fitted motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from upath import UPath

from humancal.prior import read_prior_info, shipped_prior
from humancal.prior.weights import SHIPPED_VARIANT_STEMS, PriorWeightsError
from resources.io_managers import checkpoint_content_version, partition_path, read_checkpoint_file

__all__ = ["ActivePrior", "active_prior", "shipped_active_prior", "trained_prior_path", "TRAINED_PRIOR_ASSET", "FIT_VARIANT"]

TRAINED_PRIOR_ASSET = "motion_prior_trained"
FIT_VARIANT = "motion_prior"
"""The variant the body fit uses (the others are ablations, scored by ``prior_metrics`` and ``method_tables``)."""


def trained_prior_path(storage_root: str | UPath, variant: str = FIT_VARIANT) -> UPath:
    """Where the checkpoint IO manager stores ``motion_prior_trained[variant]`` under ``storage_root``."""
    return partition_path(storage_root, TRAINED_PRIOR_ASSET, variant, ".pt")


@dataclass(frozen=True)
class ActivePrior:
    """The motion prior in force.

    Attributes:
        source: ``"shipped"`` (the package's weights) or ``"trained"`` (``motion_prior_trained`` under the root).
        path: the weights file.
        digest: content digest of the weights (hex; the shipped sidecar's, or the trained checkpoint's).
        info: facts for the user: training and held-out subjects, held-out reconstruction error.
    """

    source: Literal["shipped", "trained"]
    path: Path | UPath
    digest: str
    info: dict[str, Any]

    def load(self) -> dict[str, Any]:
        """The checkpoint dict (``state_dict``, ``config``, ``train_subjects``, ``val_subjects``; the format of
        ``assets.motion_prior.prior_checkpoint``)."""
        if self.source == "trained":
            return _load_trained(self.path)
        model, info = shipped_prior(FIT_VARIANT)
        return {
            "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
            "config": model.config.to_dict(),
            "train_subjects": list(info["train_subjects"]),
            "val_subjects": list(info["held_out_subjects"]),
        }

    def describe(self) -> str:
        """One line for logs: which weights, their digest and held-out figure."""
        what = "the prior shipped with humancal" if self.source == "shipped" else f"the prior trained here ({self.path})"
        mpjpe = self.info.get("held_out_mpjpe_mm")
        figure = f", held-out reconstruction {mpjpe:.1f} mm" if isinstance(mpjpe, (int, float)) else ""
        return (f"motion prior: {what}, digest {self.digest[:12]}, trained on CMU subjects "
                f"{self.info.get('train_subjects', '?')}{figure}")


def _load_trained(path: Path | UPath) -> dict[str, Any]:
    return read_checkpoint_file(path, lambda why: PriorWeightsError(
        f"{path}: the trained motion prior is not a readable checkpoint ({why}); run `humancal train prior` again, "
        "or delete the file to use the shipped weights"))


def active_prior(storage_root: str | UPath) -> ActivePrior:
    """The motion prior in force for ``storage_root`` (module docstring).

    Raises:
        PriorWeightsError: the weights in force are unreadable.
    """
    trained = trained_prior_path(storage_root)
    if trained.exists():
        checkpoint = _load_trained(trained)
        info = {"train_subjects": ", ".join(checkpoint.get("train_subjects", [])),
                "held_out_mpjpe_mm": (checkpoint.get("held_out") or {}).get("mpjpe_mm")}
        return ActivePrior("trained", trained, checkpoint_content_version(checkpoint), info)
    return shipped_active_prior()


def shipped_active_prior() -> ActivePrior:
    """The shipped prior as the one in force."""
    stem = SHIPPED_VARIANT_STEMS[FIT_VARIANT]
    shipped = read_prior_info(stem)
    info = {"train_subjects": ", ".join(shipped["train_subjects"]),
            "held_out_mpjpe_mm": (shipped.get("held_out") or {}).get("mpjpe_mm")}
    return ActivePrior("shipped", stem.with_suffix(".safetensors"), str(shipped["digest"]), info)
