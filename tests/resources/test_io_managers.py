"""The Parquet and checkpoint IO managers: layout, validation, atomic writes, clear errors."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import dagster as dg
import pandas as pd
import pytest
import torch

from resources.io_managers import CheckpointIOManagerFactory, ParquetIOManagerFactory, TABLE_METADATA_KEY

REPO = Path(__file__).resolve().parents[2]


def _detections(x=1.0):
    return pd.DataFrame({"sequence": ["s"], "frame": [0], "view": [0], "det_id": [0], "joint": ["nose"],
                         "x_px": [x], "y_px": [2.0], "score": [0.5]})


def _assets(x=1.0):
    @dg.asset(metadata={TABLE_METADATA_KEY: "detections"})
    def dets() -> pd.DataFrame:
        return _detections(x)

    @dg.asset
    def n_rows(dets: pd.DataFrame) -> pd.DataFrame:
        return pd.DataFrame({"n": [len(dets)]})

    return [dets, n_rows]


def _error_text(excinfo) -> str:
    parts, err, seen = [], excinfo.value, set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        parts.append(str(err))
        err = err.__cause__ or err.__context__
    return " | ".join(parts)


def test_roundtrip_layout_and_metadata(tmp_path):
    result = dg.materialize(_assets(), resources={"io_manager": ParquetIOManagerFactory(base_path=str(tmp_path))})
    assert result.success
    assert (tmp_path / "dets.parquet").exists() and (tmp_path / "n_rows.parquet").exists()
    assert pd.read_parquet(tmp_path / "n_rows.parquet")["n"].tolist() == [1]
    meta = result.asset_materializations_for_node("dets")[0].metadata
    assert meta["rows"].value == 1 and str(tmp_path / "dets.parquet") in str(meta["path"].value)
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_the_stored_files_size_and_time_are_recorded_beside_the_output(tmp_path):
    from resources.io_managers import STORED_FILE_KEY, file_signature

    result = dg.materialize(_assets(), resources={"io_manager": ParquetIOManagerFactory(base_path=str(tmp_path))})
    meta = result.asset_materializations_for_node("dets")[0].metadata
    assert meta[STORED_FILE_KEY].value == file_signature(tmp_path / "dets.parquet") is not None
    (tmp_path / "dets.parquet").write_bytes((tmp_path / "dets.parquet").read_bytes()[:-1])
    assert file_signature(tmp_path / "dets.parquet") != meta[STORED_FILE_KEY].value
    assert file_signature(tmp_path / "missing.parquet") is None and file_signature("memory://x/y.parquet") is None


def test_schema_violation_fails_and_writes_nothing(tmp_path):
    with pytest.raises(Exception) as excinfo:
        dg.materialize(_assets(x=float("nan")), resources={"io_manager": ParquetIOManagerFactory(base_path=str(tmp_path))})
    assert "column 'x_px' has 1 non-finite" in _error_text(excinfo)
    assert not (tmp_path / "dets.parquet").exists()


def test_corrupt_parquet_is_reported_with_its_path(tmp_path):
    io = {"io_manager": ParquetIOManagerFactory(base_path=str(tmp_path))}
    dg.materialize(_assets(), resources=io)
    (tmp_path / "dets.parquet").write_bytes(b"PAR1 this is not parquet")
    with pytest.raises(Exception) as excinfo:
        dg.materialize(_assets(), resources=io, selection="n_rows")
    text = _error_text(excinfo)
    assert f"{tmp_path / 'dets.parquet'} is not a readable Parquet file" in text
    assert "materialize dets again" in text


def test_unwritable_root_is_a_clear_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(Exception) as excinfo:
        dg.materialize(_assets(), resources={"io_manager": ParquetIOManagerFactory(base_path=str(blocker / "root"))})
    assert f"cannot create {blocker / 'root'}" in _error_text(excinfo)


def test_checkpoint_roundtrip_loads_weights_only(tmp_path):
    @dg.asset(io_manager_key="ckpt")
    def model_state() -> dict:
        return {"weight": torch.arange(6.0).reshape(2, 3), "config": {"hidden": 8}}

    @dg.asset(ins={"model_state": dg.AssetIn(input_manager_key="ckpt")})
    def total(model_state: dict) -> pd.DataFrame:
        return pd.DataFrame({"sum": [float(model_state["weight"].sum())], "hidden": [model_state["config"]["hidden"]]})

    resources = {"io_manager": ParquetIOManagerFactory(base_path=str(tmp_path)),
                 "ckpt": CheckpointIOManagerFactory(base_path=str(tmp_path))}
    assert dg.materialize([model_state, total], resources=resources).success
    assert pd.read_parquet(tmp_path / "total.parquet").to_dict("records") == [{"sum": 15.0, "hidden": 8}]
    (tmp_path / "model_state.pt").write_bytes(b"garbage")
    with pytest.raises(Exception) as excinfo:
        dg.materialize([model_state, total], resources=resources, selection="total")
    assert "is not a readable checkpoint" in _error_text(excinfo)


def test_killed_write_leaves_no_partial_file(tmp_path):
    """SIGKILL in the middle of a write: the target name never holds a partial file."""
    target = tmp_path / "big.parquet"
    script = textwrap.dedent(f"""
        import time
        from upath import UPath
        import humancal.storage
        import resources.io_managers as io

        def slow_chunks(f, payload):
            for i in range(0, len(payload), 1024):
                f.write(payload[i:i + 1024]); f.flush(); time.sleep(0.01)

        humancal.storage._write_chunks = slow_chunks
        io._atomic_write(UPath({str(target)!r}), b"x" * 200_000)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO)
    deadline = time.time() + 60
    while not any(".tmp-" in p.name for p in tmp_path.iterdir()):
        assert time.time() < deadline and proc.poll() is None, "writer never started"
        time.sleep(0.02)
    time.sleep(0.1)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not target.exists()
    leftovers = [p for p in tmp_path.iterdir() if ".tmp-" in p.name]
    assert leftovers and all(p.name.startswith(".") for p in leftovers)  # hidden, never under the real name
    # The next write of the same artifact cleans the leftover and completes.
    from upath import UPath
    import resources.io_managers as io

    io._atomic_write(UPath(str(target)), b"complete")
    assert target.read_bytes() == b"complete"
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]
