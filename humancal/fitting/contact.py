"""Interpenetration of different people, from their 23 canonical keypoints only (issue 14, item 2).

Proxy: every body is a fixed set of spheres placed on its keypoint skeleton (:func:`body_spheres`): a 4 x 3 grid
on the torso quad (shoulders to hips), one on the head, one on the neck, chains along the upper arms, forearms,
thighs, shins and feet, and eleven small ones along each hand (S = 118 in all). Two people overlap where a sphere
of one and a sphere of the other overlap; the penalty (:func:`interpenetration`) is the squared overlap depth
``relu(r_i + r_j - |c_i - c_j|)^2``.

Why spheres on the keypoints rather than a signed distance field on a grid or tests on the meshes:

* cost: the fit never builds meshes per frame (13,718 skinned vertices per person-frame against 23 keypoints
  from the compact keypoint path: about 100x more work, before any inside test); a sphere set is a fixed linear
  map of the keypoints, and a pair of people costs one S x S distance matrix per frame (S = 118 spheres);
* exact, analytic depth: the overlap of two spheres is a closed form, with no grid resolution and no
  inside/outside test; it is zero exactly when the proxies do not touch, so people apart cost nothing;
* smooth gradient: the squared hinge is C1 in the keypoints (its gradient goes to zero as the overlap does),
  which suits L-BFGS; an SDF sampled on a grid has piecewise-constant or piecewise-linear gradients.

The price is a coarse body: spheres of fixed radii (metres, :data:`SEGMENT_RADII_M`) that fit an average adult.
They were measured on anny's mesh of the fit's initial body (``humancal.fitting.INITIAL_PHENOTYPES``) in the
reference pose by :func:`measure_segment_radii`: every skin vertex (the mesh's largest connected component,
without the eyes and the mouth's inside) goes to the nearest element of the sphere skeleton (the head centre, the
neck, limb, hand and foot axes, the torso quad), and a segment's radius is the mean distance of its vertices to
its element, so the spheres reach the skin on average; except the hands, whose radius is their half-thickness
(the mean distance of a hand's vertices to its own plane): a flat hand with spread fingers is no tube, and the
mean distance to its axis (5.3 cm) made the hands of two people walking side by side overlap while their meshes
did not. On that body the skin vertices lie a median 8 mm outside the proxy's surface (10th and 90th
percentiles: 15 mm inside, 51 mm outside; the farthest are the fingers and the palms' edges), and 69-89% of each
segment's sphere volume is inside the mesh. ``tests/humancal/fitting/test_contact.py`` checks that the constants
still match that measurement.

Cost, in two exact prunings (the penalty is unchanged by them), vectorised over pairs and frames: the pairs of
people whose proxies' axis-aligned bounding boxes are apart in a frame cannot overlap and are left out (boxes
rather than bounding spheres around the pelvis: for upright people a bounding sphere reaches from the head to the
feet, about 1 m, and keeps pairs 2 m apart); the S x S sphere distances of the remaining pair-frames are
computed without a graph, and only the sphere pairs that overlap enter the differentiable penalty, so its
backward pass costs nothing when nobody touches and little when people do. Forward and backward for P = 4 people
over T = 900 frames (float32, 2 threads): about 7 ms with the people 2 m apart, about 0.23 s with every neighbouring
pair overlapping in every frame (side by side 0.45 m apart).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

__all__ = [
    "SEGMENT_RADII_M",
    "SPHERE_SEGMENTS",
    "body_spheres",
    "interpenetration",
    "measure_segment_radii",
]

SEGMENT_RADII_M: dict[str, float] = {
    "head": 0.073,
    "neck": 0.075,
    "torso": 0.092,
    "upper_arm": 0.052,
    "forearm": 0.033,
    "hand": 0.010,
    "thigh": 0.082,
    "shin": 0.050,
    "foot": 0.029,
}
"""Sphere radius of each body segment, metres (measured by :func:`measure_segment_radii`; module docstring)."""

_TORSO_ROWS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
"""Rows of the torso grid: 0 on the shoulder line, 1 on the hip line."""
_TORSO_COLUMNS = (1.0 / 6.0, 0.5, 5.0 / 6.0)
"""Columns of the torso grid: 0 on the left (shoulder, hip), 1 on the right."""
_HEAD_TOWARDS_NOSE = 0.3
"""The head centre: from the midpoint of the ears this fraction of the way to the nose."""
_HAND_SPAN = (0.1, 0.5)
"""The hand's chain: from / to beyond the wrist by these fractions of the forearm (elbow to wrist), along it."""
_CHAIN_SPHERES = {"upper_arm": 7, "forearm": 9, "hand": 11, "thigh": 6, "shin": 10, "foot": 9, "neck": 1}
"""Spheres per chain segment, spread evenly from its first to its last point (ends included; the neck: one at
the middle): one more than the segment's length over its radius on the average adult, so that consecutive
spheres are about one radius apart (the chain's surface dips by at most ~13% of the radius between them)."""


def _idx(name: str) -> int:
    return JOINT_INDEX[name]


def _build_sphere_map() -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The linear map keypoints -> sphere centres (S, 23) (each row sums to 1), the (S,) radii, the segment names.

    Every centre is an affine combination of the keypoints (weights summing to 1), so the spheres move with the
    body and translate with it exactly.
    """
    rows: list[np.ndarray] = []
    segments: list[str] = []

    def point(weights: dict[str, float], segment: str) -> None:
        row = np.zeros(NUM_JOINTS)
        for name, w in weights.items():
            row[_idx(name)] += w
        rows.append(row)
        segments.append(segment)

    def chain(a: dict[str, float], b: dict[str, float], segment: str) -> None:
        n = _CHAIN_SPHERES[segment]
        steps = [0.5] if n == 1 else np.linspace(0.0, 1.0, n)
        for s in steps:
            weights: dict[str, float] = {}
            for name, w in a.items():
                weights[name] = weights.get(name, 0.0) + (1.0 - s) * w
            for name, w in b.items():
                weights[name] = weights.get(name, 0.0) + s * w
            point(weights, segment)

    ears = {"left_ear": 0.5, "right_ear": 0.5}
    head = {k: (1.0 - _HEAD_TOWARDS_NOSE) * w for k, w in ears.items()} | {"nose": _HEAD_TOWARDS_NOSE}
    point(head, "head")
    chain({"left_shoulder": 0.5, "right_shoulder": 0.5}, ears, "neck")
    for v in _TORSO_ROWS:
        for u in _TORSO_COLUMNS:
            point({"left_shoulder": (1 - v) * (1 - u), "right_shoulder": (1 - v) * u,
                   "left_hip": v * (1 - u), "right_hip": v * u}, "torso")
    for side in ("left", "right"):
        shoulder, elbow, wrist = f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"
        chain({shoulder: 1.0}, {elbow: 1.0}, "upper_arm")
        chain({elbow: 1.0}, {wrist: 1.0}, "forearm")
        chain(*({wrist: 1.0 + s, elbow: -s} for s in _HAND_SPAN), "hand")
        chain({f"{side}_hip": 1.0}, {f"{side}_knee": 1.0}, "thigh")
        chain({f"{side}_knee": 1.0}, {f"{side}_ankle": 1.0}, "shin")
        chain({f"{side}_heel": 1.0}, {f"{side}_big_toe": 0.5, f"{side}_small_toe": 0.5}, "foot")
    weights = np.stack(rows)
    radii = np.array([SEGMENT_RADII_M[s] for s in segments])
    return weights, radii, tuple(segments)


_SPHERE_WEIGHTS, _SPHERE_RADII_M, SPHERE_SEGMENTS = _build_sphere_map()
"""``SPHERE_SEGMENTS``: (S,) the segment of each sphere of :func:`body_spheres`, in order."""
_MARGIN_M = 1e-3
"""Sphere pairs closer than the sum of their radii plus this are kept for the exact, differentiable penalty."""
_CHUNK_PAIR_FRAMES = 2048
"""Pair-frames whose S x S sphere distances are computed at once (about 115 MB of float32 with S = 118)."""


def body_spheres(keypoints_m: Tensor) -> tuple[Tensor, Tensor]:
    """The sphere proxy of bodies (module docstring).

    Args:
        keypoints_m: (..., 23, 3) canonical keypoints, metres.

    Returns:
        ``centres`` (..., S, 3) metres (differentiable: a fixed linear map of the keypoints) and ``radii`` (S,)
        metres (constants), S = ``len(SPHERE_SEGMENTS)``.
    """
    if keypoints_m.shape[-2:] != (NUM_JOINTS, 3):
        raise ValueError(f"keypoints_m must be (..., {NUM_JOINTS}, 3), got {tuple(keypoints_m.shape)}")
    weights = torch.as_tensor(_SPHERE_WEIGHTS, dtype=keypoints_m.dtype, device=keypoints_m.device)
    centres = torch.einsum("sk,...kd->...sd", weights, keypoints_m)
    return centres, torch.as_tensor(_SPHERE_RADII_M, dtype=keypoints_m.dtype, device=keypoints_m.device)


def interpenetration(keypoints_m: Tensor, present: Tensor) -> Tensor:
    """Squared overlap depth of the sphere proxies of different people.

    Args:
        keypoints_m: (P, T, 23, 3) canonical keypoints of P people over T frames, world metres.
        present: (P, T) bool, frames where a person exists (absent ones take part in no pair).

    Returns:
        A scalar: the sum over pairs of people (p < q), over present frames and over sphere pairs of
        ``relu(r_i + r_j - |c_i - c_j|)^2``, divided by T (the mean over frames), m^2. Exactly 0 when no two
        proxies overlap (with a zero gradient), and for P < 2 (then a constant, without a graph).
    """
    if keypoints_m.ndim != 4 or keypoints_m.shape[2:] != (NUM_JOINTS, 3):
        raise ValueError(f"keypoints_m must be (P, T, {NUM_JOINTS}, 3), got {tuple(keypoints_m.shape)}")
    P, T = keypoints_m.shape[:2]
    present = torch.as_tensor(present, device=keypoints_m.device).bool()
    if present.shape != (P, T):
        raise ValueError(f"present must be (P, T) = ({P}, {T}), got {tuple(present.shape)}")
    if P < 2 or T == 0:
        return keypoints_m.new_zeros(())
    centres, radii = body_spheres(keypoints_m)  # (P, T, S, 3), (S,)
    person, other, frame, i, j = _overlapping_spheres(centres.detach(), radii, present)
    gap = centres[person, frame, i] - centres[other, frame, j]  # (K, 3)
    distance = (gap**2).sum(-1).clamp(min=1e-12).sqrt()  # no infinite slope at coincident centres
    return (torch.relu(radii[i] + radii[j] - distance) ** 2).sum() / T


@torch.no_grad()
def _overlapping_spheres(centres: Tensor, radii: Tensor, present: Tensor) -> tuple[Tensor, ...]:
    """Every (person, other person, frame, sphere, other's sphere) whose spheres may overlap (five (K,) index
    tensors; a superset by ``_MARGIN_M`` of the overlapping ones, so the penalty on them is exact).

    Pairs of present people whose proxies' bounding boxes are apart in a frame are left out first (the cheap,
    exact pruning); the sphere distances of the rest are computed without a graph, in chunks of pair-frames.
    """
    P = centres.shape[0]
    lower = (centres - radii[:, None]).amin(dim=2)  # (P, T, 3) bounding box of each proxy
    upper = (centres + radii[:, None]).amax(dim=2)
    p_idx, q_idx = torch.triu_indices(P, P, offset=1, device=centres.device)
    close = ((lower[p_idx] <= upper[q_idx]) & (lower[q_idx] <= upper[p_idx])).all(dim=-1)
    close &= present[p_idx] & present[q_idx]
    pair, frame = torch.nonzero(close, as_tuple=True)  # (N,) each
    reach = radii[:, None] + radii[None, :] + _MARGIN_M
    found: list[Tensor] = []
    for start in range(0, len(pair), _CHUNK_PAIR_FRAMES):
        pr, fr = pair[start:start + _CHUNK_PAIR_FRAMES], frame[start:start + _CHUNK_PAIR_FRAMES]
        a, b = centres[p_idx[pr], fr], centres[q_idx[pr], fr]  # (n, S, 3)
        origin = a.mean(dim=1, keepdim=True)  # near the spheres: no cancellation in the matrix-product distances
        overlap = torch.cdist(a - origin, b - origin) < reach  # (n, S, S)
        n, i, j = torch.nonzero(overlap, as_tuple=True)
        found.append(torch.stack([n + start, i, j]))
    n, i, j = torch.cat(found, dim=1) if found else centres.new_zeros(3, 0, dtype=torch.long)
    return p_idx[pair[n]], q_idx[pair[n]], frame[n], i, j


def measure_segment_radii(vertices_m: np.ndarray, keypoints_m: np.ndarray) -> dict[str, float]:
    """Measure :data:`SEGMENT_RADII_M` on one body mesh (module docstring).

    Every vertex goes to the nearest element of the sphere skeleton of ``keypoints_m``: a point (the head), a
    line segment (the neck's axis from the shoulders' to the ears' midpoint, each chain from its first to its last
    sphere centre) or the torso quad (the bilinear patch of the torso grid, approximated by its two triangles); a
    segment's radius is the mean distance of its vertices to its element, except the hands': the mean distance of a
    hand's vertices to the hand's own plane (a flat hand is no tube: its half-thickness, so that the hands' spheres
    stay inside the hand rather than reaching past the palm, which made real hands next to each other overlap).

    Args:
        vertices_m: (V, 3) vertices of one body's skin, metres (anny's mesh without the eyes and the mouth,
            which sit inside the head: ``evaluation.contact_metrics.skin_vertices``).
        keypoints_m: (23, 3) its canonical keypoints, metres.

    Returns:
        Radius per segment name, metres.
    """
    vertices = np.asarray(vertices_m, dtype=np.float64)
    centres = np.asarray(_SPHERE_WEIGHTS, dtype=np.float64) @ np.asarray(keypoints_m, dtype=np.float64)
    segments = np.array(SPHERE_SEGMENTS)
    distances: list[np.ndarray] = []
    names: list[str] = []
    for segment in SEGMENT_RADII_M:
        rows = np.flatnonzero(segments == segment)
        if segment == "torso":
            grid = centres[rows].reshape(len(_TORSO_ROWS), len(_TORSO_COLUMNS), 3)
            corners = grid[0, 0], grid[0, -1], grid[-1, 0], grid[-1, -1]
            d = np.minimum(_triangle_distance(vertices, corners[0], corners[1], corners[2]),
                           _triangle_distance(vertices, corners[1], corners[3], corners[2]))
            distances.append(d)
            names.append(segment)
            continue
        if segment == "neck":  # its axis, from the shoulders' midpoint to the ears' midpoint
            kp = np.asarray(keypoints_m, dtype=np.float64)
            ends = [kp[[_idx("left_shoulder"), _idx("right_shoulder")]].mean(0),
                    kp[[_idx("left_ear"), _idx("right_ear")]].mean(0)]
            distances.append(_segment_distance(vertices, *ends))
            names.append(segment)
            continue
        # the head: one point; the others: the left side's element, then the right's
        per_side = len(rows) // 2 if segment != "head" else 1
        for start in range(0, len(rows), per_side):
            part = centres[rows[start:start + per_side]]
            distances.append(_segment_distance(vertices, part[0], part[-1]))
            names.append(segment)
    stacked = np.stack(distances)
    nearest = np.argmin(stacked, axis=0)
    out: dict[str, float] = {}
    for segment in SEGMENT_RADII_M:
        mine = [i for i, n in enumerate(names) if n == segment]
        if segment == "hand":  # flat: the mean distance to each hand's own plane (its two widest directions)
            out[segment] = float(np.mean(np.concatenate([_plane_distance(vertices[nearest == i]) for i in mine])))
            continue
        picked = np.isin(nearest, mine)
        out[segment] = float(stacked[nearest[picked], np.flatnonzero(picked)].mean())
    return out


def _plane_distance(points: np.ndarray) -> np.ndarray:
    """(N,) distance of (N, 3) points to their least-squares plane (through the centroid, across the direction of
    least spread)."""
    centred = points - points.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    return np.abs(centred @ normal)


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) distance of (N, 3) points to the segment [a, b] (a point when a == b)."""
    ab = b - a
    length2 = float(ab @ ab)
    s = np.zeros(len(points)) if length2 == 0 else np.clip((points - a) @ ab / length2, 0.0, 1.0)
    return np.linalg.norm(points - (a + s[:, None] * ab), axis=-1)


def _triangle_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N,) distance of (N, 3) points to the triangle (a, b, c): the plane inside it, else the nearest edge."""
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    height = (points - a) @ normal
    foot = points - height[:, None] * normal
    inside = np.ones(len(points), bool)
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= np.cross(q - p, foot - p) @ normal >= 0
    edges = np.minimum.reduce([_segment_distance(points, p, q) for p, q in ((a, b), (b, c), (c, a))])
    return np.where(inside, np.abs(height), edges)
