"""Motion-prior weights as files: safetensors for the tensors, a JSON sidecar for everything else.

A trained prior is stored as two files with one stem::

    motion_prior.safetensors   the VAE's tensors (float32), loadable without running any pickled code
    motion_prior.json          format, configuration (variant included), training history, train / held-out
                               subjects, held-out figures, training seconds, data digest, weights digest

:func:`load_prior` checks everything before a model is returned: both files present and readable, the
configuration valid (and of the variant asked for), the tensor names and shapes exactly those of a
:class:`~humancal.prior.model.MotionVAE` of that configuration, and the weights digest equal to the sidecar's.
Any failure raises :class:`PriorWeightsError` naming the file and what is wrong.

The package ships the default prior (:data:`SHIPPED_PRIOR_STEM`), trained by ``scripts/train_prior.py`` on the
CMU mocap retargeted onto anny.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file

from humancal.prior.config import PriorConfig
from humancal.prior.model import MotionVAE
from humancal.prior.train import TrainedPrior
from humancal.weight_files import weights_pair_paths, write_atomically

__all__ = [
    "PRIOR_WEIGHTS_FORMAT",
    "SHIPPED_PRIOR_STEM",
    "SHIPPED_VARIANT_STEMS",
    "PriorWeightsError",
    "load_prior",
    "read_prior_info",
    "save_prior",
    "shipped_prior",
    "weights_digest",
]

PRIOR_WEIGHTS_FORMAT = "humancal.motion_prior/1"

SHIPPED_PRIOR_STEM = Path(__file__).resolve().parent.parent / "weights" / "motion_prior"
"""``humancal/weights/motion_prior``: the stem of the shipped ``.safetensors`` / ``.json`` pair."""

SHIPPED_VARIANT_STEMS = {
    "motion_prior": SHIPPED_PRIOR_STEM,
    "per_frame": SHIPPED_PRIOR_STEM.with_name("motion_prior_per_frame"),
    **{variant: SHIPPED_PRIOR_STEM.with_name(f"motion_prior_{variant}")
       for variant in ("no_skip", "unidirectional", "no_local_linear")},
}
"""The variants humancal ships weights for, and their stems: the default prior; the per-frame pose prior of the body
fit's ``per_frame_prior`` baseline; the ablations of the paper's Table VII (``no_skip``, ``unidirectional``,
``no_local_linear``), for the benchmark's method rows."""

_REQUIRED = ("format", "config", "digest", "history", "train_seconds", "train_subjects", "held_out_subjects",
             "held_out", "data_digest")


class PriorWeightsError(ValueError):
    """A motion-prior weights pair is missing, unreadable, of another variant or shape, or damaged."""




def weights_digest(state: dict[str, torch.Tensor], config: PriorConfig) -> str:
    """Hex SHA-256 of the tensors (names, shapes, float32 bytes, in name order) and the configuration."""
    digest = hashlib.sha256()
    for name in sorted(state):
        tensor = state[name].detach().cpu().to(torch.float32).contiguous()
        digest.update(name.encode())
        digest.update(str(tuple(tensor.shape)).encode())
        digest.update(tensor.numpy().tobytes())
    digest.update(json.dumps(config.to_dict(), sort_keys=True).encode())
    return digest.hexdigest()


def _finite(value: Any) -> Any:
    """JSON-safe copy: non-finite floats become None (JSON has no NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def save_prior(trained: TrainedPrior, path: str | Path, info: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write a trained prior as ``<stem>.safetensors`` + ``<stem>.json`` (atomically, each file).

    Args:
        trained: the result of :func:`humancal.prior.train.train_motion_prior`.
        path: the stem, or either file's path (the extension is replaced).
        info: extra JSON-serialisable facts for the sidecar (e.g. ``trained_with``: the command line).

    Returns:
        The sidecar dict as written.
    """
    tensors_path, sidecar_path = weights_pair_paths(path)
    tensors_path.parent.mkdir(parents=True, exist_ok=True)
    state = {name: t.detach().cpu().to(torch.float32).contiguous() for name, t in trained.model.state_dict().items()}
    sidecar = {
        "format": PRIOR_WEIGHTS_FORMAT,
        "config": trained.config.to_dict(),
        "digest": weights_digest(state, trained.config),
        "history": trained.history,
        "train_seconds": trained.train_seconds,
        "train_cpu_seconds": trained.train_cpu_seconds,
        "train_subjects": list(trained.train_subjects),
        "held_out_subjects": list(trained.held_out_subjects),
        "held_out": trained.held_out,
        "data_digest": trained.data_digest,
        "num_train_frames": trained.num_train_frames,
        "torch_version": torch.__version__,
    }
    sidecar.update(info or {})
    sidecar = _finite(sidecar)
    write_atomically(
        tensors_path,
        lambda p: save_file(state, str(p), metadata={"format": PRIOR_WEIGHTS_FORMAT, "digest": sidecar["digest"]}),
    )
    write_atomically(sidecar_path, lambda p: p.write_text(json.dumps(sidecar, indent=2, sort_keys=True) + "\n"))
    return sidecar


def read_prior_info(path: str | Path) -> dict[str, Any]:
    """The JSON sidecar of a weights pair (configuration, history, held-out figures, digests).

    Raises:
        PriorWeightsError: the sidecar is missing, not valid JSON, of another format, or lacks a field.
    """
    _, sidecar_path = weights_pair_paths(path)
    try:
        info = json.loads(sidecar_path.read_text())
    except FileNotFoundError:
        raise PriorWeightsError(f"{sidecar_path}: motion-prior weights sidecar not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise PriorWeightsError(f"{sidecar_path}: not a readable JSON sidecar ({err})") from None
    if not isinstance(info, dict):
        raise PriorWeightsError(f"{sidecar_path}: expected a JSON object, got {type(info).__name__}")
    missing = [key for key in _REQUIRED if key not in info]
    if missing:
        raise PriorWeightsError(f"{sidecar_path}: missing field(s) {missing}")
    if info["format"] != PRIOR_WEIGHTS_FORMAT:
        raise PriorWeightsError(
            f"{sidecar_path}: field 'format' is {info['format']!r}, expected {PRIOR_WEIGHTS_FORMAT!r}"
        )
    return info


def load_prior(path: str | Path, variant: str | None = None) -> tuple[MotionVAE, dict[str, Any]]:
    """Load a prior written by :func:`save_prior`, checking it thoroughly (module docstring).

    Args:
        path: the stem, or either file's path.
        variant: the variant expected (``PriorConfig.variant``); None accepts any.

    Returns:
        ``(model, info)``: the :class:`MotionVAE` in eval mode with gradients off (the fitting optimises latents,
        never the prior), and the sidecar dict.

    Raises:
        PriorWeightsError: a file is missing, truncated or unreadable; the configuration is invalid or of
            another variant; tensor names or shapes differ from the model's; the weights do not match the
            sidecar's digest.
    """
    tensors_path, sidecar_path = weights_pair_paths(path)
    info = read_prior_info(path)
    try:
        config = PriorConfig.from_dict(info["config"])
    except (TypeError, ValueError) as err:
        raise PriorWeightsError(f"{sidecar_path}: field 'config' is not a valid PriorConfig ({err})") from None
    if variant is not None and config.variant != variant:
        raise PriorWeightsError(
            f"{sidecar_path}: the weights are of variant {config.variant!r}, expected {variant!r}"
        )
    try:
        state = load_file(str(tensors_path))
    except FileNotFoundError:
        raise PriorWeightsError(f"{tensors_path}: motion-prior weights not found") from None
    except Exception as err:  # safetensors raises its own error type for truncated or damaged files
        raise PriorWeightsError(f"{tensors_path}: not a readable safetensors file ({err})") from None
    model = MotionVAE(config)
    expected = {name: tuple(t.shape) for name, t in model.state_dict().items()}
    found = {name: tuple(t.shape) for name, t in state.items()}
    missing, unexpected = sorted(set(expected) - set(found)), sorted(set(found) - set(expected))
    if missing or unexpected:
        raise PriorWeightsError(
            f"{tensors_path}: tensor names differ from a {config.variant!r} MotionVAE: missing {missing}, "
            f"unexpected {unexpected}"
        )
    wrong = {name: (found[name], expected[name]) for name in expected if found[name] != expected[name]}
    if wrong:
        details = ", ".join(f"{name} {got} (expected {want})" for name, (got, want) in sorted(wrong.items()))
        raise PriorWeightsError(f"{tensors_path}: wrong tensor shapes: {details}")
    digest = weights_digest(state, config)
    if digest != info["digest"]:
        raise PriorWeightsError(
            f"{tensors_path}: weights digest {digest[:16]} does not match field 'digest' {str(info['digest'])[:16]} "
            f"of {sidecar_path} (damaged or mismatched pair; restore both files)"
        )
    model.load_state_dict(state)
    model.eval()
    model.requires_grad_(False)
    return model, info


def shipped_prior(variant: str = "motion_prior") -> tuple[MotionVAE, dict[str, Any]]:
    """A prior shipped with the package: ``load_prior(SHIPPED_VARIANT_STEMS[variant], variant)``.

    Raises:
        PriorWeightsError: no weights of that variant ship (naming the ones that do), or the files are damaged.
    """
    if variant not in SHIPPED_VARIANT_STEMS:
        raise PriorWeightsError(f"no shipped weights of the prior variant {variant!r}; humancal ships "
                                f"{sorted(SHIPPED_VARIANT_STEMS)} (train others: humancal train prior --variant V)")
    return load_prior(SHIPPED_VARIANT_STEMS[variant], variant)
