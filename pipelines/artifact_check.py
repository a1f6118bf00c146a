"""Does a stored artifact still hold what its latest materialization recorded? The files are the truth.

A fresh asset partition whose file is missing, unreadable, or whose content hash
(:func:`resources.io_managers.stored_content_version`, the function the assets' data versions come from) differs
from the recorded data version is recomputed. Hashing every artifact costs time (about 0.5 s for the 16.6 MB of
``synthetic__demo``), so the IO managers record the file's size and modification time beside the data version
(``resources.io_managers.STORED_FILE_KEY``) and a file that still has them is not read again. A file that was
deleted, truncated or rewritten has another size or time and is hashed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import dagster as dg
from upath import UPath

from pipelines.staleness import StalenessView, io_manager_key
from pipelines.update_graph import UpdateGraph
from resources.io_managers import (
    TABLE_METADATA_KEY,
    ArtifactError,
    CheckpointIOManagerFactory,
    ParquetIOManagerFactory,
    file_signature,
    partition_path,
    stored_content_version,
)

__all__ = ["ArtifactCheck"]

AssetPartition = tuple[dg.AssetKey, str | None]


@dataclass
class ArtifactCheck:
    """Checks that a fresh asset partition's stored file still holds what its materialization recorded."""

    defs: dg.Definitions
    graph: UpdateGraph
    checked: dict[AssetPartition, str | None] = field(default_factory=dict)
    hashed: int = 0
    """How many files were read and hashed (the others still had their recorded size and time)."""

    def problem(self, view: StalenessView, key: dg.AssetKey, pk: str | None) -> str | None:
        """Why the stored artifact cannot be trusted (``None``: it can, or it is not ours to check). Cached."""
        if (key, pk) not in self.checked:
            self.checked[(key, pk)] = self._problem(view, key, pk)
        return self.checked[(key, pk)]

    def forget(self, key: dg.AssetKey, pk: str | None) -> None:
        self.checked.pop((key, pk), None)

    def _problem(self, view: StalenessView, key: dg.AssetKey, pk: str | None) -> str | None:
        where = self.location(key, pk)
        if where is None:
            return None
        recorded = view.recorded(key, pk)
        # Only content-hash data versions can be checked against the file; an asset without a stored value
        # (e.g. a registry that reports metadata only) has no artifact.
        if recorded is None or not recorded.user_provided:
            return None
        path, kind, table = where
        if recorded.file_signature is not None and file_signature(path) == recorded.file_signature:
            return None  # the file written by that materialization, untouched since
        self.hashed += 1
        try:
            version = stored_content_version(path, kind, table)
        except FileNotFoundError:
            return f"its stored artifact is missing ({path})"
        except ArtifactError as err:
            return f"its stored artifact is unreadable: {err}"
        if version != recorded.data_version:
            return f"its stored artifact ({path}) differs from its recorded data version"
        return None

    def location(self, key: dg.AssetKey, pk: str | None) -> tuple[UPath, str, str | None] | None:
        manager = self.defs.resources.get(io_manager_key(self.defs, key))
        if isinstance(manager, ParquetIOManagerFactory):
            kind, extension = "table", ".parquet"
        elif isinstance(manager, CheckpointIOManagerFactory):
            kind, extension = "checkpoint", ".pt"
        else:
            return None
        table = (self.graph.specs[key].metadata or {}).get(TABLE_METADATA_KEY)
        if kind == "table" and table is None:
            return None
        path = partition_path(manager.base_path, "/".join(key.path), pk, extension)
        return path, kind, table
