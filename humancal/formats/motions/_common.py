"""What every motion writer shares: input checks, the people's frame spans, axes, atomic binary writes."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humancal.body.bones import POSED_BONE_NAMES
from humancal.fitting import FittedMotions
from humancal.formats._io import atomic_write_with
from humancal.formats.errors import FormatError

__all__ = [
    "R_YUP_FROM_ZUP",
    "PersonSpan",
    "atomic_write_bytes",
    "atomic_write_with",
    "check_motions",
    "person_spans",
]

logger = logging.getLogger(__name__)

R_YUP_FROM_ZUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""(3, 3) proper rotation (-90 deg about x) from humancal's world (Z up) to the Y-up axes of BVH and glTF:
``(x, y, z) -> (x, z, -y)``. The body's left stays +x, up becomes +y and the reference pose, facing -y in
humancal's world, faces +z (the usual BVH and glTF facing). Blender's BVH and glTF importers apply its inverse
with their default axis options, so an imported file lands exactly in humancal's world."""

ROTATION_TOLERANCE = 1e-4
"""Largest ``|R R^T - I|`` accepted for a bone rotation (Euler angles and quaternions need rotations)."""


@dataclass(frozen=True)
class PersonSpan:
    """The frames written for one person: from their first to their last present frame.

    Attributes:
        index: row of the person in the :class:`FittedMotions` arrays.
        person_id: the person's id.
        first: index (into ``motions.frames``) of the first present frame.
        last: index of the last present frame (inclusive).
    """

    index: int
    person_id: int
    first: int
    last: int

    @property
    def slice(self) -> slice:
        """The span as a slice of the frame axis."""
        return slice(self.first, self.last + 1)

    @property
    def num_frames(self) -> int:
        """Frames in the span."""
        return self.last - self.first + 1


def person_spans(motions: FittedMotions) -> list[PersonSpan]:
    """First..last present frame of every person with a present frame (others are skipped, with a warning).

    Frames inside a span where ``present`` is False (a hand-built motion with a gap) are written too, with the
    values the fit filled in: a person who leaves and comes back stays one person, in one file / one node.
    """
    spans = []
    for p, person_id in enumerate(motions.person_ids.tolist()):
        present = np.flatnonzero(motions.present[p])
        if present.size == 0:
            logger.warning("person %d has no present frame: nothing is written for them", person_id)
            continue
        spans.append(PersonSpan(p, int(person_id), int(present[0]), int(present[-1])))
    return spans


def check_motions(motions: object) -> FittedMotions:
    """Check what the writers rely on beyond :class:`FittedMotions`' own shape checks.

    Raises:
        FormatError: not a ``FittedMotions``, non-finite values, phenotypes outside [0, 1], a ``present`` that is
            not boolean, bone rotations that are not rotation matrices, or nobody present; the message names the
            field and the expected form.
    """
    if not isinstance(motions, FittedMotions):
        raise FormatError(None, "motions", "a humancal.fitting.FittedMotions", type(motions).__name__)
    for name in ("phenotypes", "bone_rotmats_local", "root_translation_m", "keypoints_world_m"):
        value = getattr(motions, name)
        if not np.all(np.isfinite(value)):
            bad = np.argwhere(~np.isfinite(value))[0].tolist()
            raise FormatError(None, f"FittedMotions.{name}", "finite numbers", f"{value[tuple(bad)]} at index {bad}")
    if motions.present.dtype != np.bool_:
        raise FormatError(None, "FittedMotions.present", "a boolean array", f"dtype {motions.present.dtype}")
    if motions.phenotypes.size and (motions.phenotypes.min() < 0.0 or motions.phenotypes.max() > 1.0):
        raise FormatError(None, "FittedMotions.phenotypes", "values in [0, 1]",
                          f"values in [{motions.phenotypes.min():.3g}, {motions.phenotypes.max():.3g}]")
    rot = motions.bone_rotmats_local
    if rot.size:
        error = np.abs(rot @ np.swapaxes(rot, -1, -2) - np.eye(3)).max(axis=(-1, -2))
        det = np.linalg.det(rot)
        if error.max() > ROTATION_TOLERANCE or det.min() <= 0.0:
            p, t, b = np.unravel_index(np.argmax(error + (det <= 0.0)), error.shape)
            raise FormatError(
                None, "FittedMotions.bone_rotmats_local",
                f"rotation matrices (orthonormal within {ROTATION_TOLERANCE:g}, det +1)",
                f"max |R R^T - I| = {error[p, t, b]:.3g}, det = {det[p, t, b]:.3g} at person {motions.person_ids[p]}, "
                f"frame {motions.frames[t]}, bone {POSED_BONE_NAMES[b]}",
            )
    if not motions.present.any():
        raise FormatError(None, "FittedMotions.present", "at least one present (person, frame)", "none")
    return motions


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write_with`)."""
    return atomic_write_with(path, lambda handle: handle.write(data))
