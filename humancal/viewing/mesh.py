"""The fitted bodies' meshes for viewing (:func:`fitted_meshes`), and a lighter mesh: vertex clustering on a grid,
computed once per person and applied to every frame (:func:`decimation`)."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["decimation", "fitted_meshes"]


def fitted_meshes(body, motions, chunk: int = 64) -> tuple[dict[int, tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Every person's anny mesh at every frame where present.

    Args:
        body: the :class:`humancal.body.BodyModel`.
        motions: a :class:`humancal.fitting.FittedMotions` (fitted, or a synthetic scene's true ones).
        chunk: frames per forward pass (memory).

    Returns:
        person id -> ((T,) frames, (T, V, 3) vertices, world metres), and the (F, 3) triangles.
    """
    out = {}
    for index, person_id in enumerate(motions.person_ids):
        present = np.flatnonzero(motions.present[index])
        phenotypes = torch.as_tensor(motions.phenotypes[index : index + 1], dtype=body.dtype)
        parts = []
        for start in range(0, len(present), chunk):
            frames = present[start : start + chunk]
            with torch.no_grad():
                parts.append(body.reference_forward(
                    phenotypes, torch.as_tensor(motions.bone_rotmats_local[index, frames][None], dtype=body.dtype),
                    torch.as_tensor(motions.root_translation_m[index, frames][None], dtype=body.dtype),
                )["vertices"][0].cpu().float().numpy())
        out[int(person_id)] = (motions.frames[present], np.concatenate(parts) if parts else np.zeros((0, 0, 3)))
    return out, body.faces.cpu().numpy()


def decimation(vertices_m: np.ndarray, faces: np.ndarray, cell_m: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: the vertices of each ``cell_m`` cube become their first member, the triangles that
    collapse are dropped.

    The clusters come from one pose (``vertices_m``) and are reused for every frame of the person: the kept
    vertices follow the body as anny poses it (a frame's decimated mesh is ``frame_vertices[keep]`` with ``faces``).

    Args:
        vertices_m: (V, 3) one pose's vertices, metres.
        faces: (F, 3) triangle vertex indices.
        cell_m: cluster size, metres (> 0).

    Returns:
        keep (K,) the kept vertex indices, and the (F', 3) triangles as indices into ``keep``.
    """
    if cell_m <= 0:
        raise ValueError(f"decimation: cell_m must be positive, got {cell_m}")
    cells = np.floor(np.asarray(vertices_m, dtype=np.float64) / cell_m).astype(np.int64)
    _, first, cluster = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    cluster = cluster.reshape(-1)
    remapped = cluster[np.asarray(faces)]
    distinct = (remapped[:, 0] != remapped[:, 1]) & (remapped[:, 1] != remapped[:, 2]) & (remapped[:, 0] != remapped[:, 2])
    triangles = np.unique(np.sort(remapped[distinct], axis=1), axis=0)
    # np.sort loses the winding: take each kept triangle's original orientation
    order = {tuple(t): i for i, t in enumerate(triangles)}
    oriented = np.empty_like(triangles)
    for tri in remapped[distinct]:
        key = tuple(np.sort(tri))
        oriented[order[key]] = tri
    return first, oriented
