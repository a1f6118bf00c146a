"""Atomic writes of humancal's shared files (artifacts, the user datasets file, the failure record), on a local
folder or an object store.

A reader must never find half a file under the real name, whatever happens to the writer. How depends on the
fsspec protocol of the path:

* **Object stores** (:data:`OBJECT_STORE_PROTOCOLS`: S3 and S3-compatible servers, Google Cloud Storage, Azure Blob
  Storage, fsspec's in-memory store): an object becomes visible only once its upload is complete (one PUT, or a
  multipart upload completed at the end and aborted on failure), and replaces the old one whole. The bytes are
  written directly to the object (``fs.pipe_file``). A rename there is a copy and a delete: not atomic, and twice
  the traffic.
* **Everything else** (a local folder, ``file://``, and file systems such as SFTP, SMB, HDFS): the bytes go to a
  hidden temporary sibling (``.<name>.tmp-<random>``), which is renamed over the target once complete. On a local
  file system the rename is atomic (POSIX ``rename``). A leftover temporary of a killed writer is removed by the
  next write of the same file.
"""

from __future__ import annotations

import uuid

from upath import UPath

from humancal.settings import LOCAL_PROTOCOLS

__all__ = ["OBJECT_STORE_PROTOCOLS", "is_local", "is_object_store", "write_atomic"]

OBJECT_STORE_PROTOCOLS = frozenset({"s3", "s3a", "gs", "gcs", "az", "abfs", "abfss", "memory"})
"""fsspec protocols of object stores: an object write is atomic (the object is written directly, without a
temporary), and there are no folders to create."""


def is_local(path: str | UPath) -> bool:
    """Whether ``path`` is on this machine's file system (a plain path or a ``file://`` URL)."""
    return UPath(path).protocol in LOCAL_PROTOCOLS


def is_object_store(path: str | UPath) -> bool:
    """Whether ``path`` is on an object store (:data:`OBJECT_STORE_PROTOCOLS`)."""
    return UPath(path).protocol in OBJECT_STORE_PROTOCOLS


def write_atomic(path: str | UPath, payload: bytes) -> None:
    """Replace the file (or object) ``path`` with ``payload`` so that no reader ever sees part of it.

    On a file system the parent folder must exist (object stores have none).

    Raises:
        OSError: the write failed (the store's own errors too); the target is then as it was before.
    """
    path = UPath(path)
    if is_object_store(path):
        try:
            path.fs.pipe_file(path.path, payload)
        except OSError:
            raise
        except Exception as err:  # a store client raises its own errors too (botocore's connection errors)
            raise OSError(f"{path}: {type(err).__name__}: {err}") from err
        return
    for stale in path.parent.glob(f".{path.name}.tmp-*") if path.parent.exists() else ():
        stale.unlink(missing_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{uuid.uuid4().hex[:8]}")
    try:
        with tmp.open("wb") as f:
            _write_chunks(f, payload)
        tmp.rename(path)
    except BaseException:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        raise


def _write_chunks(f, payload: bytes, chunk_bytes: int = 1 << 22) -> None:
    for start in range(0, len(payload), chunk_bytes):
        f.write(payload[start : start + chunk_bytes])
