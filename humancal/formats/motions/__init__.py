"""Exports of fitted motions (:class:`humancal.fitting.FittedMotions`) for other tools.

==========  ===============================================  ==============================================
format      files                                            content
==========  ===============================================  ==============================================
``bvh``     ``person_<id>.bvh``, one per person              22-bone anny skeleton, Y up, metres
``gltf``    ``<sequence>.glb``, one per sequence             skinned anny meshes + bone animation, glTF Y up
``npz``     ``<sequence>.npz``, one per sequence             every parameter, joints and keypoints (Z up)
``obj``     ``person_<id>/frame_<frame>.obj``                one mesh per person per frame (Z up)
==========  ===============================================  ==============================================

Axes, units and frames of each format: ``docs/formats.md`` (section "Fitted motions").
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from humancal.body import BodyModel
from humancal.fitting import FittedMotions
from humancal.formats.errors import FormatError
from humancal.formats.motions._common import R_YUP_FROM_ZUP, check_motions, person_spans
from humancal.formats.motions.bvh import bvh_text, write_bvh
from humancal.formats.motions.gltf import write_gltf
from humancal.formats.motions.meshes import mesh_selection, write_meshes
from humancal.formats.motions.npz import motions_arrays, write_npz

__all__ = [
    "MOTION_FORMATS",
    "R_YUP_FROM_ZUP",
    "bvh_text",
    "check_motions",
    "export_motions",
    "mesh_selection",
    "motions_arrays",
    "person_spans",
    "write_bvh",
    "write_gltf",
    "write_meshes",
    "write_npz",
]

MOTION_FORMATS = ("bvh", "gltf", "npz", "obj")
"""The formats :func:`export_motions` writes."""


def export_motions(
    motions: FittedMotions,
    body: BodyModel,
    fmt: str,
    out_dir: str | Path,
    *,
    sequence: str | None = None,
    frames: slice | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[Path]:
    """Write fitted motions in one of :data:`MOTION_FORMATS`.

    Args:
        motions: the people's fitted motions of one sequence.
        body: the body model the motions were fitted with (shapes, rig, mesh).
        fmt: ``"bvh"``, ``"gltf"``, ``"npz"`` or ``"obj"``.
        out_dir: output folder (created when missing).
        sequence: names the one-file formats (``<sequence>.glb``, ``<sequence>.npz``; default ``motions``).
        frames: ``obj`` only: the sequence frame numbers to write (a slice over frame numbers).
        progress: ``obj`` only: called with the person-frames done after each chunk.

    Returns:
        The files written.

    Raises:
        FormatError: an unknown format (listing the known ones), ``frames`` for a format other than ``obj``, or bad
            motions (naming the field and the expected form). Writes are atomic: nothing half-written is left.
    """
    if fmt not in MOTION_FORMATS:
        raise FormatError(None, "format", f"one of {', '.join(MOTION_FORMATS)}", repr(fmt))
    if frames is not None and fmt != "obj":
        raise FormatError(None, "frames", "no frame selection (only the obj export writes a subset of frames)", frames)
    if fmt == "bvh":
        return write_bvh(motions, body, out_dir)
    if fmt == "gltf":
        return write_gltf(motions, body, out_dir, sequence)
    if fmt == "npz":
        return write_npz(motions, body, out_dir, sequence)
    return write_meshes(motions, body, out_dir, frames, progress)
