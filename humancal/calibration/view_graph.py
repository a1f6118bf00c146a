"""The view graph of the extrinsics step: views linked by pairs of consistently matched detections; views outside
its largest connected part cannot be placed in one solve and are named."""

from __future__ import annotations

from humancal.calibration.types import CalibrationError

__all__ = ["view_components", "check_view_graph"]


def view_components(pairs, num_views: int, min_support: int) -> list[list[int]]:
    """Connected components of the view graph (an edge: a view pair with ``min_support`` consistently matched
    detections), largest first (ties: the one holding the lowest view first)."""
    parent = list(range(num_views))

    def root(v):
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for p in pairs:
        if p.support >= min_support:
            a, b = root(p.view_a), root(p.view_b)
            parent[max(a, b)] = min(a, b)
    components: dict[int, list[int]] = {}
    for v in range(num_views):
        components.setdefault(root(v), []).append(v)
    return sorted(components.values(), key=lambda c: (-len(c), c[0]))


def check_view_graph(pairs, num_views, min_support, view_names) -> None:
    """Raise :class:`CalibrationError` naming the views outside the largest connected part of the view graph.

    One solve cannot place views that share no matched people with the others (no relative rotation, translation
    or scale ties them to the rest): they are named, with whether they match nobody at all or form a group of
    their own, so that the user can remove them or calibrate that group separately.
    """
    components = view_components(pairs, num_views, min_support)
    if len(components) == 1:
        return
    names = view_names or [f"view {v}" for v in range(num_views)]

    def label(v):
        return names[v] if view_names is None else f"{names[v]!r} (view {v})"

    alone = [v for c in components[1:] for v in c if len(c) == 1]
    apart = [c for c in components[1:] if len(c) > 1]
    parts = []
    if alone:
        parts.append(f"{', '.join(label(v) for v in alone)} match no person seen by the other views")
    for c in apart:
        parts.append(f"{', '.join(label(v) for v in c)} share people only among themselves")
    raise CalibrationError(
        f"extrinsics, rotations: {'; '.join(parts)} (at least {min_support} consistent detection pairs link two "
        f"views; the connected views are {', '.join(label(v) for v in components[0])}): views that share no people "
        "with the others cannot be placed in one solve; remove them or calibrate them separately"
    )
