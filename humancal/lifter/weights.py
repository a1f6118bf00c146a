"""Lifter weights as files: safetensors for the tensors, a JSON sidecar for everything else.

A trained lifter is stored as two files with one stem::

    lifter.safetensors   the network's tensors (float32), loadable without running any pickled code
    lifter.json          format, training configuration, train / held-out subjects, held-out metrics,
                         training time, how it was trained, and the digest of the whole checkpoint

The digest is :func:`humancal.lifter.train.checkpoint_digest` of the checkpoint (weights, configuration and
subjects). :func:`read_lifter_weights` recomputes it and refuses files that do not match their sidecar, so a
damaged or mixed-up pair never lifts anything.

The package ships one such pair (:data:`SHIPPED_LIFTER_STEM`), trained by ``scripts/train_lifter.py`` on the
CMU mocap: :func:`shipped_checkpoint` is what the graph uses until a lifter is trained locally.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from safetensors.torch import load_file, save_file

from humancal.lifter.infer import CHECKPOINT_FORMAT
from humancal.lifter.train import checkpoint_digest
from humancal.weight_files import weights_pair_paths, write_atomically

__all__ = ["SHIPPED_LIFTER_STEM", "LifterWeightsError", "write_lifter_weights", "read_lifter_weights",
           "read_lifter_info", "shipped_checkpoint", "shipped_info"]

SHIPPED_LIFTER_STEM = Path(__file__).resolve().parent.parent / "weights" / "lifter"
"""``humancal/weights/lifter``: the stem of the shipped ``.safetensors`` / ``.json`` pair."""

_SIDECAR_KEYS = ("format", "config", "train_subjects", "val_subjects", "val_metrics", "training_time_s")


class LifterWeightsError(ValueError):
    """A lifter weights pair is missing, unreadable, or does not match its recorded digest."""




def write_lifter_weights(checkpoint: dict[str, Any], stem: str | Path, info: dict[str, Any] | None = None) -> dict:
    """Write a checkpoint of :func:`humancal.lifter.train.train_lifter` as ``<stem>.safetensors`` + ``<stem>.json``.

    Args:
        checkpoint: the checkpoint dict (``format``, ``state_dict``, ``config``, subjects, ``val_metrics``, ...).
        stem: path without extension (an extension ``.safetensors`` or ``.json`` is dropped).
        info: extra JSON-serializable facts for the sidecar (e.g. ``held_out`` metrics, ``trained_with``).

    Returns:
        The sidecar dict as written (with ``digest``).
    """
    tensors_path, sidecar_path = weights_pair_paths(stem)
    tensors_path.parent.mkdir(parents=True, exist_ok=True)
    state = {name: t.detach().cpu().contiguous() for name, t in checkpoint["state_dict"].items()}
    sidecar = {key: checkpoint[key] for key in _SIDECAR_KEYS if key in checkpoint}
    sidecar["digest"] = checkpoint_digest(checkpoint)
    sidecar.update(info or {})
    write_atomically(tensors_path, lambda p: save_file(state, str(p), metadata={"format": CHECKPOINT_FORMAT,
                                                                              "digest": sidecar["digest"]}))
    write_atomically(sidecar_path, lambda p: p.write_text(json.dumps(sidecar, indent=2, sort_keys=True) + "\n"))
    return sidecar


def read_lifter_info(stem: str | Path) -> dict[str, Any]:
    """The JSON sidecar of a weights pair (configuration, subjects, metrics, digest).

    Raises:
        LifterWeightsError: the sidecar is missing or not valid JSON.
    """
    _, sidecar_path = weights_pair_paths(stem)
    try:
        info = json.loads(sidecar_path.read_text())
    except FileNotFoundError:
        raise LifterWeightsError(f"{sidecar_path}: lifter weights sidecar not found") from None
    except json.JSONDecodeError as err:
        raise LifterWeightsError(f"{sidecar_path}: not valid JSON ({err})") from None
    missing = [k for k in ("format", "config", "train_subjects", "val_subjects", "digest") if k not in info]
    if missing:
        raise LifterWeightsError(f"{sidecar_path}: missing field(s) {missing}")
    if info["format"] != CHECKPOINT_FORMAT:
        raise LifterWeightsError(f"{sidecar_path}: field 'format' is {info['format']!r}, expected {CHECKPOINT_FORMAT!r}")
    return info


def read_lifter_weights(stem: str | Path) -> dict[str, Any]:
    """The checkpoint dict of a weights pair, as :func:`humancal.lifter.train.train_lifter` returns it.

    Raises:
        LifterWeightsError: a file is missing or unreadable, or the weights do not match the sidecar's digest.
    """
    tensors_path, sidecar_path = weights_pair_paths(stem)
    info = read_lifter_info(stem)
    try:
        state = load_file(str(tensors_path))
    except FileNotFoundError:
        raise LifterWeightsError(f"{tensors_path}: lifter weights not found") from None
    except Exception as err:  # safetensors raises its own error type for damaged headers
        raise LifterWeightsError(f"{tensors_path}: not a readable safetensors file ({err})") from None
    checkpoint = {key: info[key] for key in _SIDECAR_KEYS if key in info}
    checkpoint["state_dict"] = state
    digest = checkpoint_digest(checkpoint)
    if digest != info["digest"]:
        raise LifterWeightsError(
            f"{tensors_path}: weights digest {digest[:16]} does not match field 'digest' {info['digest'][:16]} of "
            f"{sidecar_path} (damaged or mismatched pair; restore both files)"
        )
    return checkpoint


def shipped_info() -> dict[str, Any]:
    """The sidecar of the shipped lifter (how it was trained, its held-out figures, its digest)."""
    return read_lifter_info(SHIPPED_LIFTER_STEM)


def shipped_checkpoint() -> dict[str, Any]:
    """The lifter shipped with the package, as a checkpoint dict (``load_lifter(shipped_checkpoint())``)."""
    return read_lifter_weights(SHIPPED_LIFTER_STEM)
