"""Atomic writes of the shared files: a temporary renamed over the target on a file system, the object written
directly on an object store (the S3 protocol itself: tests/pipelines/test_state_on_object_storage.py)."""

import uuid

import pytest
from upath import UPath

import humancal.storage as storage
from humancal.storage import is_local, is_object_store, write_atomic


def test_protocols():
    assert is_local("/a/b") and is_local("file:///a/b") and not is_local("s3://bucket/a")
    assert is_object_store("s3://bucket/a") and is_object_store("gs://bucket/a") and is_object_store("memory://a")
    assert not is_object_store("/a/b") and not is_object_store("sftp://host/a")


def test_a_file_system_write_goes_through_a_hidden_temporary(tmp_path, monkeypatch):
    target = tmp_path / "table.parquet"
    write_atomic(target, b"old")

    def dies_half_way(f, payload):
        f.write(payload[: len(payload) // 2])
        raise OSError("disk full")

    monkeypatch.setattr(storage, "_write_chunks", dies_half_way)
    with pytest.raises(OSError, match="disk full"):
        write_atomic(target, b"new bytes")
    assert target.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["table.parquet"]


def test_an_object_store_write_puts_the_object_without_a_temporary(monkeypatch):
    root = UPath(f"memory://humancal-test-{uuid.uuid4().hex[:8]}")
    renames = []
    monkeypatch.setattr(type(root.fs), "mv", lambda *args, **kwargs: renames.append(args))
    write_atomic(root / "datasets.yaml", b"datasets: {}\n")
    assert (root / "datasets.yaml").read_bytes() == b"datasets: {}\n"
    assert [p.name for p in root.iterdir()] == ["datasets.yaml"] and renames == []
    root.fs.rm(root.path, recursive=True)
