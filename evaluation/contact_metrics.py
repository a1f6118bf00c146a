"""Interpenetration of the fitted people, measured on their full anny meshes (not on the fit's sphere proxy).

For each evaluated frame (evenly spread over the frames where at least two people are present) every present
person's skinned mesh is built (``BodyModel.reference_forward``), and for every pair of present people:

* ``depth``: the skin vertices of one body inside the other body, each at its distance to the other body's
  surface; the frame's depth is the largest over both directions and all pairs;
* ``volume``: the volume inside both bodies, counted on a regular grid of ``grid_m`` cells (cell centres inside
  both) over the bounding box of the vertices of either body inside the other, padded (the intersection is bounded
  by those parts of the two surfaces); the frame's volume is the sum over pairs. A pair with no vertex inside the
  other counts no volume (an intersection thinner than the mesh's edges).

Inside test. anny's mesh is closed: ``trimesh.Trimesh(...).is_watertight`` holds for the whole mesh and for
each of its four connected components (the skin, two eyes, the mouth's inside: the last three sit inside the
head). Only the skin (the largest component, :func:`skin_vertices`) is used. A posed mesh may still intersect
itself (linear blend skinning folds at the armpits, knees, elbows), where ray-parity and pseudo-normal sign
tests fail; so the inside test is the generalized winding number (``>= 0.5`` inside), which stays right on
self-intersecting and nested surfaces: NVIDIA warp's ``mesh_query_point_sign_winding_number`` on a BVH of the
other body (its fast, dipole-approximated winding number, accuracy 2), which also gives the closest surface point
for the depth. (trimesh's own ``contains`` and ``proximity`` need ``rtree``, which humancal does not install.) The
warp kernel runs on the CPU; it is compiled once (a few seconds) into warp's kernel cache.

Figures (:func:`penetration_figures`): ``penetration_depth_mm`` (the mean over evaluated frames of the frame's
depth, 0 for a frame where nobody touches), ``penetration_volume_cm3`` (the mean over evaluated frames of the
frame's volume) and ``evaluated_frames``. Both figures are NaN when no frame has two people.
"""

from __future__ import annotations

import numpy as np
import torch
import warp as wp
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from humancal.body import BodyModel
from humancal.fitting import FittedMotions

__all__ = ["GRID_M", "evaluated_frames", "pair_penetration", "penetration_figures", "skin_vertices"]

GRID_M = 0.01
"""Cell size of the volume grid, metres (1 cm^3 per cell)."""
_FAR_M = wp.constant(1.0e3)
"""Search radius of the closest-point queries, metres (anything in a scene)."""
_BOX_PAD_M = 0.04
"""Margin around the vertices inside the other body that bounds the volume grid, metres (above half anny's longest
skin edges)."""


def skin_vertices(faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V,) bool: the vertices of the mesh's largest connected component (anny: the skin, without the eyes and
    the inside of the mouth)."""
    faces = np.asarray(faces, dtype=np.int64)
    rows = faces.reshape(-1)
    cols = np.roll(faces, 1, axis=1).reshape(-1)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(num_vertices, num_vertices))
    _, label = connected_components(graph, directed=False)
    return label == np.bincount(label).argmax()


@wp.kernel
def _query_kernel(mesh: wp.uint64, points: wp.array(dtype=wp.vec3), inside: wp.array(dtype=wp.int32),
                  depth: wp.array(dtype=wp.float32)):
    i = wp.tid()
    p = points[i]
    q = wp.mesh_query_point_sign_winding_number(mesh, p, _FAR_M, 2.0, 0.5)
    inside[i] = 0
    depth[i] = 0.0
    if q.result:
        if q.sign < 0.0:
            inside[i] = 1
            depth[i] = wp.length(p - wp.mesh_eval_position(mesh, q.face, q.u, q.v))


class _Mesh:
    """One posed body's skin as a warp BVH (CPU), with its bounding box."""

    def __init__(self, vertices_m: np.ndarray, faces: np.ndarray) -> None:
        self.vertices_m = np.ascontiguousarray(vertices_m, dtype=np.float32)
        self.lower, self.upper = self.vertices_m.min(0), self.vertices_m.max(0)
        self._points = wp.array(self.vertices_m, dtype=wp.vec3, device="cpu")
        self._faces = wp.array(np.ascontiguousarray(faces, dtype=np.int32).reshape(-1), dtype=wp.int32, device="cpu")
        self.mesh = wp.Mesh(points=self._points, indices=self._faces, support_winding_number=True)

    def query(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) inside (bool) and depth below the surface (metres, 0 outside) of (N, 3) points."""
        n = len(points_m)
        if n == 0:
            return np.zeros(0, bool), np.zeros(0)
        points = wp.array(np.ascontiguousarray(points_m, dtype=np.float32), dtype=wp.vec3, device="cpu")
        inside = wp.zeros(n, dtype=wp.int32, device="cpu")
        depth = wp.zeros(n, dtype=wp.float32, device="cpu")
        wp.launch(_query_kernel, dim=n, inputs=[self.mesh.id, points, inside, depth], device="cpu")
        return inside.numpy().astype(bool), depth.numpy().astype(np.float64)


def _in_box(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    return np.all((points >= lower) & (points <= upper), axis=-1)


def _inside(vertices_m: np.ndarray, other: _Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The (M, 3) points of ``vertices_m`` (N, 3) inside the ``other`` body, and their (M,) depths, metres."""
    near = np.flatnonzero(_in_box(vertices_m, other.lower, other.upper))
    inside, depth = other.query(vertices_m[near])
    return vertices_m[near[inside]], depth[inside]


def _intersection_volume_m3(a: _Mesh, b: _Mesh, lower: np.ndarray, upper: np.ndarray, grid_m: float) -> float:
    """Volume inside both bodies within the box [lower, upper], by the cells of a regular grid, cubic metres."""
    lower, upper = np.maximum(lower, np.maximum(a.lower, b.lower)), np.minimum(upper, np.minimum(a.upper, b.upper))
    axes = [np.arange(lo + grid_m / 2, hi, grid_m) for lo, hi in zip(lower, upper)]
    if any(len(x) == 0 for x in axes):
        return 0.0
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    in_a, _ = a.query(points)
    in_b, _ = b.query(points[in_a])
    return float(in_b.sum()) * grid_m**3


def pair_penetration(vertices_a_m: np.ndarray, vertices_b_m: np.ndarray, faces: np.ndarray, skin: np.ndarray,
                     grid_m: float = GRID_M) -> tuple[float, float]:
    """How far two posed bodies interpenetrate.

    The intersection of the two bodies is bounded by the part of each surface inside the other, so its volume is
    counted on the grid only over the bounding box of the skin vertices inside the other body (padded by
    ``_BOX_PAD_M`` for the surface between vertices): much less than the boxes' overlap when people touch.
    Bodies with no vertex inside the other count no volume (an intersection thinner than the mesh's edges).

    Args:
        vertices_a_m, vertices_b_m: (V, 3) the two bodies' mesh vertices, metres.
        faces: (F, 3) the mesh's triangles.
        skin: (V,) bool, :func:`skin_vertices` (the vertices and triangles used).
        grid_m: cell size of the volume grid, metres.

    Returns:
        (depth_m, volume_m3): the deepest skin vertex of either body inside the other (metres, 0 if none) and
        the volume inside both (cubic metres).
    """
    skin_faces = faces[skin[faces].all(axis=1)]
    a, b = _Mesh(vertices_a_m, skin_faces), _Mesh(vertices_b_m, skin_faces)
    if np.any(np.minimum(a.upper, b.upper) < np.maximum(a.lower, b.lower)):  # boxes apart: nothing can touch
        return 0.0, 0.0
    a_in_b, depth_a = _inside(a.vertices_m[skin], b)
    b_in_a, depth_b = _inside(b.vertices_m[skin], a)
    depths = np.concatenate([depth_a, depth_b])
    if depths.size == 0:
        return 0.0, 0.0
    boundary = np.concatenate([a_in_b, b_in_a])
    volume = _intersection_volume_m3(a, b, boundary.min(0) - _BOX_PAD_M, boundary.max(0) + _BOX_PAD_M, grid_m)
    return float(depths.max()), volume


def evaluated_frames(present: np.ndarray, max_frames: int) -> np.ndarray:
    """Indices (into the frame axis) of at most ``max_frames`` frames, evenly spread over those where at least two
    people are present (all of them when there are fewer)."""
    candidates = np.flatnonzero(np.asarray(present).sum(axis=0) >= 2)
    if len(candidates) <= max_frames:
        return candidates
    return candidates[np.unique(np.round(np.linspace(0, len(candidates) - 1, max_frames)).astype(np.int64))]


def penetration_figures(body: BodyModel, motions: FittedMotions, max_frames: int = 30,
                        grid_m: float = GRID_M) -> dict[str, float]:
    """Penetration of the people of ``motions`` into one another, on their full meshes (module docstring).

    Args:
        body: the body model (its meshes and faces).
        motions: the people's phenotypes and poses (fitted, or the ground truth in the same form).
        max_frames: at most this many frames are evaluated (a mesh per person and frame is costly).
        grid_m: cell size of the volume grid, metres.

    Returns:
        ``penetration_depth_mm`` (mean over the evaluated frames of the deepest vertex inside another body),
        ``penetration_volume_cm3`` (mean over the evaluated frames of the summed pairwise intersection volume),
        ``evaluated_frames``; NaN figures when no frame has two people present.
    """
    if max_frames < 1:
        raise ValueError(f"max_frames={max_frames} must be >= 1")
    frames = evaluated_frames(motions.present, max_frames)
    if len(frames) == 0:
        return {"penetration_depth_mm": float("nan"), "penetration_volume_cm3": float("nan"), "evaluated_frames": 0.0}
    faces = body.faces.cpu().numpy()
    skin = skin_vertices(faces, body.num_vertices)
    as_t = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=body.dtype, device=body.device)  # noqa: E731
    depths, volumes = [], []
    for t in frames:
        people = np.flatnonzero(motions.present[:, t])
        with torch.no_grad():
            vertices = body.reference_forward(as_t(motions.phenotypes[people]),
                                              as_t(motions.bone_rotmats_local[people, t:t + 1]),
                                              as_t(motions.root_translation_m[people, t:t + 1]))["vertices"]
        vertices = vertices[:, 0].double().cpu().numpy()
        depth, volume = 0.0, 0.0
        for i in range(len(people)):
            for j in range(i + 1, len(people)):
                d, v = pair_penetration(vertices[i], vertices[j], faces, skin, grid_m)
                depth, volume = max(depth, d), volume + v
        depths.append(depth)
        volumes.append(volume)
    return {"penetration_depth_mm": 1e3 * float(np.mean(depths)),
            "penetration_volume_cm3": 1e6 * float(np.mean(volumes)), "evaluated_frames": float(len(frames))}
