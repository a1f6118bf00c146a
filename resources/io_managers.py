"""IO managers: canonical tables to Parquet, torch state to checkpoint files.

Layout under the storage root (local path or any fsspec URL: ``s3://``, ``gs://`` with the matching
fsspec package installed)::

    <root>/<asset key path>/<partition key>.parquet     partitioned tables
    <root>/<asset key path>.parquet                     unpartitioned tables
    <root>/<asset key path>.pt                          checkpoints

Writes are atomic (:mod:`humancal.storage`): on a file system the bytes go to a hidden temporary sibling first,
which is renamed over the target only when complete; on an object store (S3, GCS, Azure, memory) the object is
written directly, since a store shows an object only once its upload is complete. Either way a killed run never
leaves a half-written artifact under the real name.
"""

from __future__ import annotations

import hashlib
import io
import os
from collections.abc import Callable
from typing import Any, Literal

import dagster as dg
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import torch
from upath import UPath

from humancal.lifter import checkpoint_digest
from humancal.storage import is_object_store, write_atomic
from humancal.tables.schemas import SCHEMAS, check_values, table_to_pandas, to_arrow

TABLE_METADATA_KEY = "humancal/table"
"""Asset metadata naming the canonical table an asset holds (validated on every write)."""

STORED_FILE_KEY = "humancal/stored_file"
"""Materialization metadata: the stored file's size and modification time (:func:`file_signature`), recorded beside
the data version so that ``humancal update`` rehashes an artifact only when the file changed since."""


class ArtifactError(RuntimeError):
    """A stored artifact cannot be written or read; the message names the file and what to do."""


class MissingArtifactError(ArtifactError, FileNotFoundError):
    """An artifact that was never written (or was deleted): a ``FileNotFoundError`` too, so that an input declared
    with ``allow_missing_partitions`` (the benchmark's fan-in) skips the partition."""


def read_checkpoint_file(path: str | UPath, unreadable: Callable[[str], Exception]) -> dict:
    """A checkpoint dict written by :class:`CheckpointIOManager` (``torch.load``, ``weights_only``).

    Raises:
        Exception: ``unreadable(why)`` (why: the first line of torch's error) for a missing or damaged file.
    """
    try:
        with UPath(path).open("rb") as f:
            return torch.load(io.BytesIO(f.read()), weights_only=True, map_location="cpu")
    except Exception as err:  # torch raises several unrelated types for a damaged file
        raise unreadable(str(err).splitlines()[0] if str(err) else type(err).__name__) from None


def partition_path(root: str | UPath, asset_key: str, partition_key: str | None, extension: str = ".parquet") -> UPath:
    """Where an asset (partition) lives under ``root``: the one place this layout is defined."""
    base = UPath(root).joinpath(*asset_key.split("/"))
    return UPath(f"{base}/{partition_key}{extension}") if partition_key else UPath(f"{base}{extension}")


ArtifactKind = Literal["table", "checkpoint"]
"""What an IO manager of this module stores: a canonical table (Parquet) or a torch checkpoint."""

CONTENT_VERSION_CHARS = 16
"""Hex characters of the SHA-256 kept as a content data version."""


def table_content_version(df: pd.DataFrame, name: str) -> str:
    """Content hash of canonical table ``name``: SHA-256 of its Arrow IPC stream, as written by :func:`to_arrow`.

    The data version of every table asset, and what :func:`stored_content_version` recomputes from the
    stored file: the one definition both sides share.
    """
    # One record batch whatever the column chunking (a concatenated frame is chunked, the file read back is
    # not), so equal content gives equal bytes.
    table = to_arrow(df, name).combine_chunks()
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return hashlib.sha256(sink.getvalue().to_pybytes()).hexdigest()[:CONTENT_VERSION_CHARS]


def checkpoint_content_version(checkpoint: dict) -> str:
    """Content hash of a checkpoint: :func:`humancal.lifter.checkpoint_digest` (weights, config, subjects)."""
    return checkpoint_digest(checkpoint)[:CONTENT_VERSION_CHARS]


def stored_content_version(path: str | UPath, kind: ArtifactKind, table: str | None = None) -> str:
    """The content version of a stored artifact, computed from the file as the asset computed it from its output.

    Args:
        path: the artifact file (:func:`partition_path`).
        kind: ``"table"`` (Parquet) or ``"checkpoint"``.
        table: canonical table name of a ``"table"`` artifact.

    Raises:
        FileNotFoundError: the file does not exist.
        ArtifactError: the file cannot be read as that kind of artifact (damaged, truncated, other content).
        ValueError: ``kind`` is unknown, or a table artifact without its table name.
    """
    path = UPath(path)
    if kind == "table":
        if table is None:
            raise ValueError("stored_content_version: a table artifact needs its canonical table name (table=...)")
        try:
            with path.open("rb") as f:
                stored = pq.read_table(f)
            return table_content_version(table_to_pandas(stored, table), table)
        except FileNotFoundError:
            raise
        except Exception as err:  # arrow raises several types for bytes that are not Parquet, or another table
            raise ArtifactError(f"{path} is not a readable '{table}' table ({_first_line(err)})") from None
    if kind == "checkpoint":
        try:
            with path.open("rb") as f:
                checkpoint = torch.load(io.BytesIO(f.read()), weights_only=True, map_location="cpu")
            return checkpoint_content_version(checkpoint)
        except FileNotFoundError:
            raise
        except Exception as err:  # torch raises several unrelated types for a damaged file
            raise ArtifactError(f"{path} is not a readable checkpoint ({_first_line(err)})") from None
    raise ValueError(f"stored_content_version: kind must be 'table' or 'checkpoint', got {kind!r}")


def file_signature(path: str | UPath) -> str | None:
    """``"<size>:<mtime_ns>"`` of a local file (``None`` for a remote one or a missing file): what
    :data:`STORED_FILE_KEY` records. A file rewritten since has another signature, unless someone forges both."""
    path = UPath(path)
    if path.protocol not in ("", "file", "local"):
        return None
    try:
        stat = os.stat(path.path)
    except OSError:
        return None
    return f"{stat.st_size}:{stat.st_mtime_ns}"


def _first_line(err: BaseException) -> str:
    return str(err).splitlines()[0] if str(err) else type(err).__name__


def _atomic_write(path: UPath, payload: bytes) -> None:
    """Write ``payload`` to ``path`` atomically (:func:`humancal.storage.write_atomic`: a temporary sibling renamed
    over it on a file system, the object written directly on an object store)."""
    try:
        write_atomic(path, payload)
    except OSError as err:
        raise ArtifactError(f"cannot write {path}: {err.strerror or err} (check the storage root and its "
                            "permissions)") from None


def _make_dir(path: UPath) -> None:
    if is_object_store(path):
        return  # no folders there (and s3fs's mkdir may create a missing bucket)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ArtifactError(
            f"cannot create {path}: {err.strerror or err} (the storage root must be writable; "
            "set HUMANCAL_STATE_DIR or the io manager's base_path)"
        ) from None


def _record_signature(context: dg.OutputContext, path: UPath) -> None:
    signature = file_signature(path)
    if signature is not None:
        context.add_output_metadata({STORED_FILE_KEY: dg.MetadataValue.text(signature)})


class _AtomicUPathIOManager(dg.UPathIOManager):
    def make_directory(self, path: UPath) -> None:
        _make_dir(path)


class ParquetTableIOManager(_AtomicUPathIOManager):
    """Stores pandas DataFrames as Parquet; validates canonical tables against their schema."""

    extension = ".parquet"

    def dump_to_path(self, context: dg.OutputContext, obj: pd.DataFrame, path: UPath) -> None:
        if not isinstance(obj, pd.DataFrame):
            raise TypeError(f"{context.asset_key.to_user_string()}: expected a pandas DataFrame, got {type(obj).__name__}")
        name = (context.definition_metadata or {}).get(TABLE_METADATA_KEY)
        if name is not None:
            table = to_arrow(obj, name, source=context.asset_key.to_user_string())
            check_values(table, name, source=context.asset_key.to_user_string())
        else:
            table = pa.Table.from_pandas(obj, preserve_index=False)
        buffer = io.BytesIO()
        pq.write_table(table, buffer)
        _atomic_write(path, buffer.getvalue())
        _record_signature(context, path)

    def load_from_path(self, context: dg.InputContext, path: UPath) -> pd.DataFrame:
        try:
            with path.open("rb") as f:
                table = pq.read_table(f)
        except FileNotFoundError:
            raise MissingArtifactError(f"{path} does not exist: materialize {context.asset_key.to_user_string()} "
                                       "first") from None
        except (pa.ArrowInvalid, OSError) as err:
            raise ArtifactError(
                f"{path} is not a readable Parquet file ({err}); delete it and materialize "
                f"{context.asset_key.to_user_string()} again"
            ) from None
        name = (context.upstream_output.definition_metadata or {}).get(TABLE_METADATA_KEY) if context.upstream_output else None
        if name is not None and not table.schema.equals(SCHEMAS[name]):
            raise ArtifactError(f"{path}: stored schema differs from the declared '{name}' table; rematerialize it")
        return table.to_pandas() if name is None else table_to_pandas(table, name)

    def get_metadata(self, context: dg.OutputContext, obj: pd.DataFrame) -> dict[str, Any]:
        return {"rows": dg.MetadataValue.int(len(obj)), "columns": dg.MetadataValue.text(", ".join(map(str, obj.columns)))}


class CheckpointIOManager(_AtomicUPathIOManager):
    """Stores torch checkpoints (a dict of tensors and plain values); loads with ``weights_only=True``."""

    extension = ".pt"

    def dump_to_path(self, context: dg.OutputContext, obj: dict, path: UPath) -> None:
        if not isinstance(obj, dict):
            raise TypeError(f"{context.asset_key.to_user_string()}: expected a checkpoint dict, got {type(obj).__name__}")
        buffer = io.BytesIO()
        torch.save(obj, buffer)
        _atomic_write(path, buffer.getvalue())
        _record_signature(context, path)

    def load_from_path(self, context: dg.InputContext, path: UPath) -> dict:
        try:
            with path.open("rb") as f:
                return torch.load(io.BytesIO(f.read()), weights_only=True, map_location="cpu")
        except FileNotFoundError:
            raise MissingArtifactError(f"{path} does not exist: materialize {context.asset_key.to_user_string()} "
                                       "first") from None
        except Exception as err:  # torch raises several unrelated types for a damaged file
            first_line = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise ArtifactError(f"{path} is not a readable checkpoint ({first_line}); delete it and materialize again") from None

    def get_metadata(self, context: dg.OutputContext, obj: dict) -> dict[str, Any]:
        n = sum(v.numel() for v in _tensors(obj))
        return {"parameters": dg.MetadataValue.int(n)}


def _tensors(obj: Any):
    if isinstance(obj, torch.Tensor):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _tensors(v)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from _tensors(v)


class ParquetIOManagerFactory(dg.ConfigurableIOManagerFactory):
    """Parquet tables under ``base_path`` (a local folder or an fsspec URL)."""

    base_path: str

    def create_io_manager(self, context) -> ParquetTableIOManager:
        return ParquetTableIOManager(base_path=UPath(self.base_path))


class CheckpointIOManagerFactory(dg.ConfigurableIOManagerFactory):
    """Torch checkpoints under ``base_path`` (a local folder or an fsspec URL)."""

    base_path: str

    def create_io_manager(self, context) -> CheckpointIOManager:
        return CheckpointIOManager(base_path=UPath(self.base_path))
