"""Partitions of the graph; defined with the assets in :mod:`assets.partitions` (assets never import pipelines)."""

from assets.partitions import SEQUENCES

__all__ = ["SEQUENCES"]
