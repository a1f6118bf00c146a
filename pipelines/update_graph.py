"""The asset graph as ``humancal update`` walks it: parents, children, partitioning, on-request assets and the
steps that compute several assets at once, from Dagster's public asset specs and definitions."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from graphlib import TopologicalSorter

import dagster as dg

from assets.benchmark import FAN_IN_CONFIG_KEY
from assets.common import ON_REQUEST_KEY

__all__ = ["UpdateGraph", "closure"]


class UpdateGraph:
    """Parents, children and partitioning of the assets of ``defs``."""

    def __init__(self, defs: dg.Definitions):
        self.defs = defs
        self.specs = {spec.key: spec for spec in defs.resolve_all_asset_specs()}
        # A fan-in reads the partitions of an input computed on request only (method_tables for benchmark_table)
        # as stored: the update never waits for it; its new data still makes the fan-in stale (Dagster's lineage).
        self.parents = {key: [d.asset_key for d in spec.deps if d.asset_key in self.specs
                              and not (self._fan_in(spec) and self.on_request(d.asset_key))]
                        for key, spec in self.specs.items()}
        self.children: dict[dg.AssetKey, list[dg.AssetKey]] = defaultdict(list)
        graph = defs.resolve_asset_graph()
        self.blocking_checked = {
            spec.asset_key for assets_def in graph.assets_defs for spec in assets_def.check_specs if spec.blocking
        } | {spec.asset_key for checks_def in (getattr(defs, "asset_checks", None) or [])
             for spec in checks_def.check_specs if spec.blocking}
        for key, parents in self.parents.items():
            for parent in parents:
                self.children[parent].append(key)
        self._steps: dict[dg.AssetKey, tuple[dg.AssetKey, ...]] = {}
        self._upstream_first: list[dg.AssetKey] | None = None

    @staticmethod
    def _fan_in(spec: dg.AssetSpec) -> bool:
        return bool((spec.metadata or {}).get(FAN_IN_CONFIG_KEY))

    def partitioned(self, key: dg.AssetKey) -> bool:
        return self.specs[key].partitions_def is not None

    def on_request(self, key: dg.AssetKey) -> str | None:
        return (self.specs[key].metadata or {}).get(ON_REQUEST_KEY)

    def takes_left_out(self, key: dg.AssetKey) -> bool:
        """Whether the fan-in asset ``key`` takes the partitions to leave out as run config."""
        return self._fan_in(self.specs[key])

    def code_version(self, key: dg.AssetKey) -> str | None:
        return self.specs[key].code_version

    def step(self, key: dg.AssetKey) -> tuple[dg.AssetKey, ...]:
        """The assets computed with ``key`` in one step that cannot be run apart (a multi-asset that cannot be
        subset, e.g. ``body_fit``: ``fitted_motions`` and ``refined_cameras``); ``(key,)`` for the others."""
        if key not in self._steps:
            assets_def = self.defs.resolve_assets_def(key)
            keys = tuple(sorted(assets_def.keys, key=lambda k: k.to_user_string()))
            self._steps[key] = (key,) if assets_def.can_subset or len(keys) == 1 else keys
        return self._steps[key]

    def with_descendants(self, keys: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
        return closure(keys, self.children)

    def with_ancestors(self, keys: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
        return closure(keys, self.parents)

    def sorted_keys(self) -> list[dg.AssetKey]:
        return sorted(self.specs, key=lambda k: k.to_user_string())

    def upstream_first(self) -> list[dg.AssetKey]:
        """Every asset, each after all of its parents."""
        if self._upstream_first is None:
            order = TopologicalSorter({key: self.parents[key] for key in self.sorted_keys()})
            self._upstream_first = list(order.static_order())
        return self._upstream_first


def closure(keys: Iterable[dg.AssetKey], edges: dict) -> set[dg.AssetKey]:
    """``keys`` and every asset reachable from them along ``edges`` (key -> neighbours)."""
    out, todo = set(), list(keys)
    while todo:
        key = todo.pop()
        if key not in out:
            out.add(key)
            todo.extend(edges[key])
    return out
