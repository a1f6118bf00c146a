"""A `humancal update` killed with SIGKILL in the middle resumes where it stopped: the next update computes only
what the killed one had not finished, leaves no partial artifact behind, and a third update has nothing to do."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PARTITION = "synthetic__tiny"

pytestmark = pytest.mark.slow


def _update(env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipelines.cli", "update", "--partition", PARTITION], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=600)


def _materialized(out: str) -> int:
    line = next(line for line in out.splitlines() if line.startswith("materialized "))
    return int(line.split()[1])


def test_killed_update_resumes(tmp_path):
    env = dict(os.environ, HUMANCAL_STATE_DIR=str(tmp_path / "state"), HUMANCAL_DATA_DIR=str(tmp_path / "no_data"))
    log = tmp_path / "killed.log"
    with log.open("w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "pipelines.cli", "update", "--partition", PARTITION], cwd=REPO,
                                env=env, stdout=out, stderr=subprocess.STDOUT)
    artifacts = tmp_path / "state" / "artifacts"
    lifted = artifacts / "detections" / f"{PARTITION}.parquet"
    deadline = time.time() + 300
    while not lifted.exists():  # the inputs and the lifter are done, and the run of the rest has begun
        assert proc.poll() is None and time.time() < deadline, f"update ended early:\n{log.read_text()[-2000:]}"
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)

    done_before = {p.relative_to(artifacts) for p in artifacts.rglob("*") if p.is_file()}
    assert Path("metric_tables") / f"{PARTITION}.parquet" not in done_before
    resumed = _update(env)
    assert resumed.returncode == 0, resumed.stdout[-2000:] + resumed.stderr[-2000:]
    assert "detections[" not in resumed.stdout and "lifter_checkpoint" not in resumed.stdout  # not redone
    assert "extrinsics[" in resumed.stdout and "metric_tables[" in resumed.stdout and _materialized(resumed.stdout) >= 2
    assert not [p for p in artifacts.rglob(".*.tmp-*")], "a partial artifact was left behind"
    again = _update(env)
    assert again.returncode == 0 and _materialized(again.stdout) == 0
