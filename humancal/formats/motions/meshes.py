"""Fitted motions to per-frame meshes: one Wavefront OBJ per person per frame (anny's full skinned mesh)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import trimesh

from humancal.body import BodyModel
from humancal.fitting import FittedMotions
from humancal.formats.errors import FormatError
from humancal.formats.motions._common import atomic_write_bytes, check_motions, person_spans

__all__ = ["CHUNK_FRAMES", "mesh_file_name", "write_meshes"]

CHUNK_FRAMES = 32
"""Frames per call of anny's full forward (about 0.16 MB of vertices per frame, a few times that in flight)."""


def mesh_file_name(person_id: int, frame: int) -> str:
    """``person_<id>/frame_<frame:06d>.obj``: one folder per person, the sequence's frame number."""
    return f"person_{person_id}/frame_{frame:06d}.obj"


def write_meshes(
    motions: FittedMotions,
    body: BodyModel,
    out_dir: str | Path,
    frames: slice | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[Path]:
    """Write each person's mesh at each frame of their first..last present span as an OBJ file.

    Vertices are world metres, Z up (humancal's world, as is: OBJ has no axis convention), triangles as
    anny's faces (1-based in the file). Each file is written atomically; on an error the files of the frames
    already done stay (each complete).

    Args:
        motions: the fitted motions.
        body: the body model.
        out_dir: output folder; files go to ``person_<id>/frame_<frame:06d>.obj`` below it.
        frames: which sequence frame numbers to write, as a slice over frame numbers (``slice(0, 300, 10)``:
            every 10th frame below 300); None: all. Intersected with each person's span.
        progress: called with the number of person-frames done after each chunk (e.g. ``tqdm.update``).

    Returns:
        The files written.

    Raises:
        FormatError: bad motions, or a ``frames`` slice with a step < 1.
    """
    motions = check_motions(motions)
    if frames is not None and frames.step is not None and frames.step < 1:
        raise FormatError(None, "frames", "a slice of frame numbers with step >= 1", frames)
    faces = body.faces.cpu().numpy()
    written: list[Path] = []
    for span, selected in mesh_selection(motions, frames):
        phenotypes = torch.as_tensor(motions.phenotypes[span.index : span.index + 1], dtype=body.dtype)
        for start in range(0, len(selected), CHUNK_FRAMES):
            chunk = selected[start : start + CHUNK_FRAMES]
            with torch.no_grad():
                vertices = body.reference_forward(
                    phenotypes, torch.as_tensor(motions.bone_rotmats_local[span.index, chunk][None], dtype=body.dtype),
                    torch.as_tensor(motions.root_translation_m[span.index, chunk][None], dtype=body.dtype),
                )["vertices"][0].cpu().double().numpy()
            for t, frame_vertices in zip(chunk, vertices):
                text = trimesh.exchange.obj.export_obj(
                    trimesh.Trimesh(frame_vertices, faces, process=False), include_normals=False, include_texture=False,
                    header=f"humancal person {span.person_id} frame {int(motions.frames[t])}: world metres, Z up",
                )
                path = Path(out_dir) / mesh_file_name(span.person_id, int(motions.frames[t]))
                written.append(atomic_write_bytes(path, text.encode("utf-8")))
            if progress is not None:
                progress(len(chunk))
    return written


def mesh_selection(motions: FittedMotions, frames: slice | None = None) -> list[tuple[object, np.ndarray]]:
    """Per person with a span, the frame indices that :func:`write_meshes` writes (their count drives progress)."""
    out = []
    for span in person_spans(motions):
        indices = np.arange(span.first, span.last + 1)
        if frames is not None:
            numbers = motions.frames[indices]
            start = numbers[0] if frames.start is None else frames.start
            stop = numbers[-1] + 1 if frames.stop is None else frames.stop
            keep = (numbers >= start) & (numbers < stop) & ((numbers - start) % (frames.step or 1) == 0)
            indices = indices[keep]
        out.append((span, indices))
    return out
