"""The pictures on the Dagster UI's asset pages, seen the way a user sees them: a small synthetic capture computed with
`humancal update`, the real UI started with `humancal ui`, and each page shot with headless Chromium after opening
its picture (``scripts/ui_screenshot.py``), which must show the image.

Slow (about 4 minutes: the capture, the UI's start and one browser per page); needs ``chromium`` on PATH.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PARTITION = "synthetic__tiny"
PAGES = [("raw_detections", "picture"), ("extrinsics", "rig"), ("associations", "picture"),
         ("fitted_motions", "errors_per_view"), ("fitted_motions", "scene"), ("metric_tables", "rigs")]
"""(asset, metadata key of its picture) of the pages shot."""

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(shutil.which("chromium") is None, reason="needs chromium (apt-get install chromium)")]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _humancal(*args: str, env: dict, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([str(Path(sys.executable).parent / "humancal"), *args], env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def ui(tmp_path_factory):
    state = tmp_path_factory.mktemp("state")
    env = dict(os.environ, HUMANCAL_STATE_DIR=str(state))
    done = _humancal("update", "--partition", PARTITION, env=env, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    port = _free_port()
    log = (state / "ui.log").open("w")
    server = subprocess.Popen([str(Path(sys.executable).parent / "humancal"), "ui", "--port", str(port)], env=env,
                              stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.time() + 180
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/server_info", timeout=3):
                    break
            except OSError:
                if time.time() > deadline or server.poll() is not None:
                    raise AssertionError(f"the UI did not come up: {(state / 'ui.log').read_text()[-2000:]}")
                time.sleep(1.0)
        yield f"http://127.0.0.1:{port}"
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
        log.close()


@pytest.mark.parametrize("asset,key", PAGES, ids=[f"{a}-{k}" for a, k in PAGES])
def test_each_asset_page_shows_its_picture(ui, asset, key, tmp_path):
    out = tmp_path / f"{asset}_{key}.png"
    shot = subprocess.run([sys.executable, str(REPO / "scripts" / "ui_screenshot.py"),
                           f"{ui}/assets/{asset}?partition={PARTITION}", str(out), "--size", "1400x1000",
                           "--wait", "12", "--show-markdown", key, "--expect-images", "1", "--port", str(_free_port())],
                          capture_output=True, text=True, timeout=180)
    assert shot.returncode == 0, shot.stdout + shot.stderr
    assert "pictures: 1" in shot.stdout or "pictures: 2" in shot.stdout
    assert 20_000 < out.stat().st_size < 600_000  # a page with a picture on it, small enough to keep
