"""The shared state on S3: a real S3 protocol server (moto in server mode, a subprocess on a free localhost port),
reached through s3fs exactly as a cluster reaches AWS or MinIO.

A small part of the real graph is materialized with its artifacts on ``s3://``, and read back by the next step and
by a plain client; an interrupted write leaves the object as it was; the user datasets file and the failure record
live there too; and a state dir on a store without Postgres is refused with the variable to set.
"""

from __future__ import annotations

import io
import os
import select
import signal
import socket
import subprocess
import sys
import textwrap
import time
import urllib.request
import uuid
from pathlib import Path

import dagster as dg
import pandas as pd
import pyarrow.parquet as pq
import pytest

from tests.resources.test_io_managers import _error_text

s3fs = pytest.importorskip("s3fs", reason="s3fs is not installed (pip install -e '.[cluster]')")
pytest.importorskip("moto.server", reason="moto's server is not installed (pip install -e '.[dev]')")

REPO = Path(__file__).resolve().parents[2]
PARTITION = "synthetic__tiny"
QUIET = {"loggers": {"console": {"config": {"log_level": "WARNING"}}}}


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.fixture(scope="module")
def s3_endpoint():
    """``http://127.0.0.1:<port>`` of a moto S3 server running for this module."""
    port = _free_port()
    endpoint = f"http://127.0.0.1:{port}"
    proc = subprocess.Popen([sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                urllib.request.urlopen(f"{endpoint}/moto-api/", timeout=1).close()
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"moto_server did not answer on {endpoint}") from None
                time.sleep(0.1)
        yield endpoint
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _client_env(endpoint: str, tmp_path: Path) -> dict[str, str]:
    """Dummy credentials, and no AWS configuration of this machine that could point elsewhere."""
    return {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1",
            "AWS_CONFIG_FILE": str(tmp_path / "no_aws_config"),
            "AWS_SHARED_CREDENTIALS_FILE": str(tmp_path / "no_aws_credentials")}


@pytest.fixture
def bucket(s3_endpoint, tmp_path, monkeypatch):
    """A fresh bucket; this process reaches the server as a user's would (fsspec's configuration of ``s3``)."""
    import fsspec.config

    for name, value in _client_env(s3_endpoint, tmp_path).items():
        monkeypatch.setenv(name, value)
    for name in ("AWS_PROFILE", "AWS_SESSION_TOKEN", "AWS_ENDPOINT_URL", "AWS_ENDPOINT_URL_S3"):
        monkeypatch.delenv(name, raising=False)
    # what FSSPEC_S3_ENDPOINT_URL sets when a process starts (fsspec reads its variables at import)
    monkeypatch.setitem(fsspec.config.conf, "s3", {"endpoint_url": s3_endpoint})
    s3fs.S3FileSystem.clear_instance_cache()
    name = f"humancal-{uuid.uuid4().hex[:8]}"
    _fs().mkdir(name)
    yield name
    s3fs.S3FileSystem.clear_instance_cache()


def _fs():
    """A client without listing cache: every call asks the server."""
    return s3fs.S3FileSystem(use_listings_cache=False, skip_instance_cache=True)


def _tag(result: dg.ExecuteInJobResult, asset: str) -> str:
    event = next(e for e in result.get_asset_materialization_events() if e.asset_key.to_user_string() == asset)
    return event.materialization.tags["dagster/data_version"]


def test_the_graph_stores_and_reads_its_artifacts_on_s3(bucket, tmp_path):
    from pipelines.definitions import build_definitions
    from pipelines.partitions import SEQUENCES
    from resources.datasets import DatasetsResource
    from resources.io_managers import partition_path, stored_content_version

    root = f"s3://{bucket}/state/artifacts"
    defs = build_definitions(storage_root=root, datasets=DatasetsResource(data_dir=str(tmp_path / "no_data")))
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, [PARTITION])

    def materialize(*assets: str, partition: str | None = None):
        return dg.materialize(list(defs.assets), resources=defs.resources, instance=instance, run_config=QUIET,
                              partition_key=partition, selection=dg.AssetSelection.assets(*assets))

    lifter = materialize("lifter_checkpoint")
    # detections is computed from raw_detections, known_cameras and lifter_checkpoint read back from the bucket
    sequence = materialize("raw_detections", "known_cameras", "detections", partition=PARTITION)
    assert lifter.success and sequence.success

    stored = sorted(_fs().find(f"{bucket}/state"))
    assert stored == [f"{bucket}/state/artifacts/{name}" for name in (
        f"detections/{PARTITION}.parquet", f"known_cameras/{PARTITION}.parquet", "lifter_checkpoint.pt",
        f"raw_detections/{PARTITION}.parquet")]  # no temporaries: objects are written directly

    detections = pq.read_table(io.BytesIO(_fs().cat_file(f"{bucket}/state/artifacts/detections/{PARTITION}.parquet")))
    assert detections.num_rows == len(sequence.output_for_node("detections")) > 0
    assert stored_content_version(partition_path(root, "detections", PARTITION), "table",
                                  "lifted_detections") == _tag(sequence, "detections")
    assert stored_content_version(partition_path(root, "lifter_checkpoint", None, ".pt"),
                                  "checkpoint") == _tag(lifter, "lifter_checkpoint")


def _dets(x: float):
    from resources.io_managers import TABLE_METADATA_KEY

    @dg.asset(metadata={TABLE_METADATA_KEY: "detections"})
    def dets() -> pd.DataFrame:
        return pd.DataFrame({"sequence": ["s"], "frame": [0], "view": [0], "det_id": [0], "joint": ["nose"],
                             "x_px": [x], "y_px": [2.0], "score": [0.5]})

    return dets


def test_an_interrupted_write_leaves_the_object_as_it_was(bucket, monkeypatch):
    import resources.io_managers as io_managers
    from resources.io_managers import ParquetIOManagerFactory

    resources = {"io_manager": ParquetIOManagerFactory(base_path=f"s3://{bucket}/artifacts")}
    assert dg.materialize([_dets(1.0)], resources=resources).success
    key = f"{bucket}/artifacts/dets.parquet"

    def stored_x() -> list[float]:
        return pq.read_table(io.BytesIO(_fs().cat_file(key))).column("x_px").to_pylist()

    real_write_table = io_managers.pq.write_table

    def writer_dies_half_way(table, sink, **kwargs):  # the Parquet writer fails after half its bytes
        whole = io.BytesIO()
        real_write_table(table, whole, **kwargs)
        sink.write(whole.getvalue()[: len(whole.getvalue()) // 2])
        raise OSError("disk full")

    with monkeypatch.context() as patch, pytest.raises(Exception) as excinfo:
        patch.setattr(io_managers.pq, "write_table", writer_dies_half_way)
        dg.materialize([_dets(2.0)], resources=resources)
    assert "disk full" in _error_text(excinfo)
    assert stored_x() == [1.0] and _fs().find(f"{bucket}/artifacts") == [key]

    real_call = s3fs.S3FileSystem._call_s3

    async def upload_dies(self, method, *args, **kwargs):  # the connection drops during the upload
        if method == "put_object":
            raise ConnectionResetError("connection reset by peer")
        return await real_call(self, method, *args, **kwargs)

    with monkeypatch.context() as patch, pytest.raises(Exception) as excinfo:
        patch.setattr(s3fs.S3FileSystem, "_call_s3", upload_dies)
        dg.materialize([_dets(3.0)], resources=resources)
    assert f"cannot write s3://{key}: connection reset by peer" in _error_text(excinfo)
    assert stored_x() == [1.0] and _fs().find(f"{bucket}/artifacts") == [key]


def test_a_writer_killed_after_uploading_every_part_leaves_no_object(bucket, s3_endpoint, tmp_path):
    """A large artifact goes up in parts (a multipart upload); the object appears only when the upload is completed.
    The writer is killed (SIGKILL) with every part on the server, just before it completes the upload."""
    key = f"{bucket}/artifacts/big.pt"
    script = textwrap.dedent(f"""
        import time
        import s3fs
        from humancal.storage import write_atomic

        # parts of 5 MiB (the smallest S3 allows) rather than 50, so that 12 MiB goes up in three
        defaults = list(s3fs.S3FileSystem._pipe_file.__defaults__)
        defaults[0] = 5 * 2**20
        s3fs.S3FileSystem._pipe_file.__defaults__ = tuple(defaults)
        real_call = s3fs.S3FileSystem._call_s3

        async def stall_before_completing(self, method, *args, **kwargs):
            if method == "complete_multipart_upload":
                print("parts uploaded", flush=True)
                time.sleep(600)
            return await real_call(self, method, *args, **kwargs)

        s3fs.S3FileSystem._call_s3 = stall_before_completing
        write_atomic("s3://{key}", b"x" * (12 * 2**20))
    """)
    env = {**os.environ, **_client_env(s3_endpoint, tmp_path), "FSSPEC_S3_ENDPOINT_URL": s3_endpoint}
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, env=env, stdout=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)
        assert ready and proc.stdout.readline().strip() == "parts uploaded", "the writer never finished its parts"
        uploads = _fs().call_s3("list_multipart_uploads", Bucket=bucket).get("Uploads", [])
        parts = _fs().call_s3("list_parts", Bucket=bucket, Key="artifacts/big.pt", UploadId=uploads[0]["UploadId"])
        assert len(parts["Parts"]) == 3
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not _fs().exists(key) and _fs().find(f"{bucket}/artifacts") == []


def test_the_datasets_file_and_the_failure_record_are_shared_on_s3(bucket, monkeypatch, tmp_path):
    from humancal.datasets.sequences import add_user_sequence, load_datasets_config, user_config_path
    from humancal.settings import local_dir, state_dir
    from pipelines.failure_record import FailureRecord

    monkeypatch.setenv("HUMANCAL_STATE_DIR", f"s3://{bucket}/state")
    monkeypatch.setenv("HUMANCAL_LOCAL_DIR", str(tmp_path / "local"))
    assert str(state_dir()) == f"s3://{bucket}/state" and local_dir() == tmp_path / "local"
    views = [str(tmp_path / "cam1"), str(tmp_path / "cam2")]
    spec = add_user_sequence("trials", "t001", "capture", {"format": "openpose", "views": views,
                                                           "image_size": [1920, 1080]})
    assert spec.source == f"s3://{bucket}/state/datasets.yaml" and spec.base_dir is None
    assert str(user_config_path()) == spec.source and _fs().exists(f"{bucket}/state/datasets.yaml")
    assert load_datasets_config()["trials__t001"].options["views"] == views

    record = FailureRecord.in_state_dir(state_dir())
    record.record("intrinsics", "trials__t001", "no upright person", "f0")
    record.save()
    assert [f.name for f in FailureRecord.in_state_dir(state_dir()).all()] == ["intrinsics[trials__t001]"]
    assert sorted(_fs().find(f"{bucket}/state")) == [f"{bucket}/state/datasets.yaml",
                                                      f"{bucket}/state/update_failures.json"]


def test_the_documented_environment_reaches_the_store_from_a_fresh_process(bucket, s3_endpoint, tmp_path):
    """What docs/cluster.md tells a user to set, and nothing else: a worker started with it finds the shared files."""
    script = ("from humancal.datasets.sequences import add_user_sequence, load_datasets_config\n"
              "add_user_sequence('mine', 'a', 'synthetic', {'preset': 'tiny'})\n"
              "print(sorted(load_datasets_config()))\n")
    env = {**os.environ, **_client_env(s3_endpoint, tmp_path), "FSSPEC_S3_ENDPOINT_URL": s3_endpoint,
           "HUMANCAL_STATE_DIR": f"s3://{bucket}/state", "HUMANCAL_LOCAL_DIR": str(tmp_path / "local")}
    run = subprocess.run([sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert "'mine__a'" in run.stdout and _fs().exists(f"{bucket}/state/datasets.yaml")


def test_a_state_dir_on_a_store_needs_postgres(bucket, monkeypatch, capsys, tmp_path):
    from pipelines.cli import main

    monkeypatch.setenv("HUMANCAL_STATE_DIR", f"s3://{bucket}/state")
    monkeypatch.setenv("HUMANCAL_LOCAL_DIR", str(tmp_path / "local"))
    monkeypatch.delenv("HUMANCAL_POSTGRES_URL", raising=False)
    monkeypatch.delenv("HUMANCAL_CELERY_BROKER", raising=False)
    assert main(["update", "--partition", PARTITION]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (f"humancal: error: HUMANCAL_STATE_DIR=s3://{bucket}/state is on a store, so the Dagster "
                       "instance must be shared too: set HUMANCAL_POSTGRES_URL=postgresql://user:password@host:5432/"
                       "database (a SQLite instance is one machine's files and cannot live on a store; "
                       "docs/cluster.md)")
