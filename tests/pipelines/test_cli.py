"""The `humancal` CLI: argument handling, reports, and the UI's signal handling."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pandas as pd
import pytest

from pipelines.cli import build_parser, main

REPO = Path(__file__).resolve().parents[2]


def test_parser_knows_the_four_commands():
    parser = build_parser()
    assert parser.parse_args(["update", "--partition", "a__b", "--partition", "c__d"]).partition == ["a__b", "c__d"]
    assert parser.parse_args(["report", "--format", "csv"]).format == "csv"
    with pytest.raises(SystemExit):
        parser.parse_args(["report", "--format", "xml"])


def test_report_prints_stored_tables_as_csv(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    folder = tmp_path / "artifacts" / "metric_tables"
    folder.mkdir(parents=True)
    pd.DataFrame({"dataset": ["d"], "sequence": ["s"], "method": ["m"], "metric": ["mpjpe_mm"], "view": [None],
                  "value": [12.5], "unit": ["mm"]}).to_parquet(folder / "d__s.parquet")
    assert main(["report", "--partition", "d__s", "--format", "csv"]) == 0
    out = capsys.readouterr().out.splitlines()
    # a table stored before the failed_checks column: read with it empty
    assert out[0] == "dataset,sequence,method,metric,view,value,unit,failed_checks" and out[1] == "d,s,m,mpjpe_mm,,12.5,mm,"
    with pytest.raises(SystemExit, match=r"unknown partition\(s\) x__y; known here: .*synthetic__demo"):
        main(["report", "--partition", "x__y"])
    with pytest.raises(SystemExit, match=r"no metric table stored yet .*`humancal update --partition synthetic__tiny`"):
        main(["report", "--partition", "synthetic__tiny"])


def test_report_headline_leaves_out_per_view_and_suffixed_rows(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    folder = tmp_path / "artifacts" / "metric_tables"
    folder.mkdir(parents=True)
    pd.DataFrame({"dataset": "synthetic", "sequence": "demo", "method": "init",
                  "metric": ["focal_error_pct", "focal_error_pct", "focal_error_pct", "pcp_avg/head"],
                  "view": pd.array([None, 0, 1, None], dtype="Int32"), "value": [1.5, 1.0, 2.0, 90.0],
                  "unit": ["%", "%", "%", "%"]}).to_parquet(folder / "synthetic__demo.parquet")
    assert main(["report", "--partition", "synthetic__demo"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if "focal_error_pct" in line or "pcp" in line]
    assert len(lines) == 1 and "1.50" in lines[0]
    assert main(["report", "--partition", "synthetic__demo", "--all"]) == 0
    out = capsys.readouterr().out
    assert "view" in out.splitlines()[0] and out.count("focal_error_pct") == 3 and "pcp_avg/head" in out


def test_report_includes_the_lifters_held_out_table(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    (tmp_path / "artifacts" / "metric_tables").mkdir(parents=True)
    row = {"dataset": ["cmu_mocap"], "sequence": ["held_out_02_14"], "method": ["lifter"], "metric": ["pa_mpjpe_mm"],
           "view": [None], "value": [49.5], "unit": ["mm"]}
    pd.DataFrame(row).to_parquet(tmp_path / "artifacts" / "lifter_heldout_metrics.parquet")
    pd.DataFrame({**row, "dataset": ["d"], "sequence": ["s"]}).to_parquet(tmp_path / "artifacts" / "metric_tables" / "d__s.parquet")
    assert main(["report", "--partition", "cmu_mocap__held_out_02_14", "--format", "csv"]) == 0
    assert capsys.readouterr().out.splitlines()[1] == "cmu_mocap,held_out_02_14,lifter,pa_mpjpe_mm,,49.5,mm,"
    assert main(["report", "--format", "csv"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 3  # header, the held-out row, the sequence row


def test_update_rejects_unknown_partition(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    assert main(["update", "--partition", "mars__base"]) == 2
    assert "unknown dataset 'mars'" in capsys.readouterr().err


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_ui_runs_the_dagster_of_its_own_interpreter(tmp_path, monkeypatch):
    """Without an activated environment `dagster` is not on PATH: the UI must not look it up there."""
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    calls = []
    monkeypatch.setattr(os, "execvpe", lambda file, argv, env: calls.append((file, argv, env)))
    monkeypatch.setattr(os, "chdir", lambda path: None)
    monkeypatch.setattr(signal, "signal", lambda *a: None)
    main(["ui", "--port", "3999"])
    (file, argv, env), = calls
    assert file == sys.executable and argv[:6] == [sys.executable, "-m", "dagster", "dev", "-w", "workspace.yaml"]
    assert argv[-2:] == ["-p", "3999"] and env["DAGSTER_HOME"] == str(tmp_path / "dagster_home")


@pytest.mark.slow
def test_ui_starts_and_stops_on_sigterm(tmp_path):
    port = _free_port()
    # Started the way CI starts background jobs: SIGINT ignored, no terminal; and without the environment on PATH.
    env = dict(os.environ, HUMANCAL_STATE_DIR=str(tmp_path), PATH="/usr/bin:/bin")
    proc = subprocess.Popen([sys.executable, "-m", "pipelines.cli", "ui", "--port", str(port)], cwd=REPO, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        deadline = time.time() + 120
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/server_info", timeout=2) as r:
                    assert r.status == 200
                    break
            except OSError:
                assert proc.poll() is None and time.time() < deadline, "dagster dev did not come up"
                time.sleep(1)
        # the graph it serves, from workspace.yaml: the body fit reads the motion prior through the graph
        query = '{ assetNodeOrError(assetKey: {path: ["fitted_motions"]}) { ... on AssetNode { dependencyKeys { path } } } }'
        request = urllib.request.Request(f"http://127.0.0.1:{port}/graphql", data=json.dumps({"query": query}).encode(),
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=60) as r:
            node = json.load(r)["data"]["assetNodeOrError"]
        parents = {"/".join(key["path"]) for key in node["dependencyKeys"]}
        assert parents == {"detections", "associations", "skeletons3d", "extrinsics", "motion_prior_checkpoint"}
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
        deadline = time.time() + 20
        while True:
            leftovers = subprocess.run(["pgrep", "-g", str(proc.pid)], capture_output=True, text=True).stdout.split()
            if not leftovers or time.time() > deadline:
                break
            time.sleep(0.5)
        assert not leftovers, f"processes still running 20 s after SIGTERM: {leftovers}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_export_cameras_roundtrips_through_a_tool_format(tmp_path, monkeypatch, capsys):
    import numpy as np

    from humancal.camera import Camera, cameras_to_table
    from humancal.formats import read_cameras

    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    stored = {"final_cameras": [0.1, 0.2, 3.0], "gt_cameras": [0.0, 0.0, 4.0]}  # estimated and true cameras differ
    for asset, t in stored.items():
        folder = tmp_path / "artifacts" / asset
        folder.mkdir(parents=True)
        cameras_to_table([Camera(K, np.eye(3), np.array(t), 1280, 720)], "s").to_parquet(folder / "d__s.parquet")
    out = tmp_path / "calib.toml"
    assert main(["export", "cameras", "--partition", "d__s", "--format", "pose2sim", "--out", str(out)]) == 0
    assert "wrote 1 final cameras (asset final_cameras; source not recorded, format pose2sim)" in \
        capsys.readouterr().out
    back = read_cameras(out, format="pose2sim")
    assert np.allclose(back[0].K, K) and np.allclose(back[0].t_cam_from_world_m, stored["final_cameras"])
    for flags in (["--ground-truth"], ["--cameras-asset", "gt_cameras"]):
        assert main(["export", "cameras", "--partition", "d__s", "--format", "pose2sim", "--out", str(out),
                     "--overwrite", *flags]) == 0
        assert "wrote 1 ground-truth cameras (asset gt_cameras, format pose2sim)" in capsys.readouterr().out
        assert np.allclose(read_cameras(out, format="pose2sim")[0].t_cam_from_world_m, stored["gt_cameras"])
    with pytest.raises(SystemExit, match="contradict"):
        main(["export", "cameras", "--partition", "d__s", "--format", "pose2sim", "--out", str(out),
              "--ground-truth", "--cameras-asset", "extrinsics"])
    with pytest.raises(SystemExit, match="is not stored"):
        main(["export", "detections", "--partition", "d__s", "--format", "openpose", "--out", str(tmp_path / "op")])


def test_view_refuses_a_wrong_file_and_a_partition_never_computed(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    with pytest.raises(SystemExit, match=r"a Rerun recording file ends in \.rrd"):
        main(["view", "--partition", "synthetic__demo", "--save", str(tmp_path / "demo.txt")])
    with pytest.raises(SystemExit, match=r"views of synthetic__nothing is not stored .*humancal update --partition"):
        main(["view", "--partition", "synthetic__nothing", "--save", str(tmp_path / "demo.rrd")])
    assert not (tmp_path / "demo.rrd").exists()


def test_export_overlays_takes_mp4_only_and_needs_a_computed_partition(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    with pytest.raises(SystemExit, match="overlays export supports --format mp4"):
        main(["export", "overlays", "--partition", "synthetic__demo", "--format", "avi", "--out", str(tmp_path / "o")])
    with pytest.raises(SystemExit, match=r"views of synthetic__nothing is not stored"):
        main(["export", "overlays", "--partition", "synthetic__nothing", "--format", "mp4", "--out", str(tmp_path / "o")])
