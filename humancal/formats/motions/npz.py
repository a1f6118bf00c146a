"""Fitted motions to one NumPy ``.npz`` archive: every parameter, the joints and the keypoints, named with units."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from humancal.body import PHENOTYPE_NAMES, BodyModel
from humancal.fitting import FittedMotions
from humancal.formats.motions._common import atomic_write_with, check_motions
from humancal.keypoints import CANONICAL_JOINTS

__all__ = ["NPZ_CONVENTIONS", "motions_arrays", "write_npz"]

NPZ_CONVENTIONS = (
    "humancal fitted motions. World: metres, right-handed, Z up. bone_rotmats_local: anny 'local-ref' rotations "
    "(world-aligned axes of the reference pose about each bone's head, composed child after parent: "
    "G_b = G_parent @ D_b; bone 0 = root = global orientation). root_translation_m: world position of the root "
    "bone head. joints_world_m: posed-bone heads; keypoints_world_m: canonical 23 keypoints (keypoint_names). "
    "Values outside present are filled from the nearest present frame. See docs/formats.md."
)
"""The ``conventions`` string stored in every archive."""


def motions_arrays(motions: FittedMotions, body: BodyModel) -> dict[str, np.ndarray]:
    """The arrays of the archive (see ``docs/formats.md`` for the table of names, shapes and units)."""
    rest = body.rest_skeleton(torch.as_tensor(motions.phenotypes, dtype=body.dtype, device=body.device))
    with torch.no_grad():
        joints = body.joints(rest, torch.as_tensor(motions.bone_rotmats_local, dtype=body.dtype, device=body.device),
                             torch.as_tensor(motions.root_translation_m, dtype=body.dtype, device=body.device))
    return {
        "person_ids": motions.person_ids.astype(np.int64),
        "frames": motions.frames.astype(np.int64),
        "present": motions.present.astype(bool),
        "fps": np.float64(motions.fps),
        "phenotypes": motions.phenotypes.astype(np.float64),
        "phenotype_names": np.array(PHENOTYPE_NAMES),
        "bone_names": np.array(body.posed_bones),
        "bone_parents": np.array(body.posed_parents, dtype=np.int64),
        "bone_offsets_reference_m": rest.chain_offsets_m.detach().cpu().double().numpy(),
        "bone_rotmats_local": motions.bone_rotmats_local.astype(np.float64),
        "root_translation_m": motions.root_translation_m.astype(np.float64),
        "joints_world_m": joints.cpu().double().numpy(),
        "keypoint_names": np.array(CANONICAL_JOINTS),
        "keypoints_world_m": motions.keypoints_world_m.astype(np.float64),
        "conventions": np.array(NPZ_CONVENTIONS),
    }


def npz_file_name(sequence: str | None) -> str:
    """``<sequence>.npz`` (``motions.npz`` without a name)."""
    return f"{sequence or 'motions'}.npz"


def write_npz(motions: FittedMotions, body: BodyModel, out_dir: str | Path, sequence: str | None = None) -> list[Path]:
    """Write ``<out_dir>/<sequence>.npz`` (compressed; every frame of the sequence, with ``present``).

    Strings are stored as NumPy unicode arrays, so ``np.load(path)`` needs no ``allow_pickle``.

    Raises:
        FormatError: bad motions (see ``check_motions``); nothing is written then.
    """
    arrays = motions_arrays(check_motions(motions), body)
    path = Path(out_dir) / npz_file_name(sequence)
    return [atomic_write_with(path, lambda handle: np.savez_compressed(handle, **arrays))]
