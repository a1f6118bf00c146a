"""Everyday commands: a light parser, one overwrite rule for every export, one line for a read-only state dir or
output folder, and the no-op shortcut of ``humancal update`` (what it depends on, and that it is taken)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pipelines.update_stamp as update_stamp
from pipelines.cli import build_parser, main

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("numpy", "pandas", "dagster", "torch")


def test_the_parser_imports_nothing_heavy():
    code = ("import sys; from pipelines.cli import build_parser; p = build_parser(); p.parse_args(['update', '-v']); "
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_no_op_shortcut_imports_nothing_heavy(tmp_path):
    """The shortcut reads the datasets config and stats files: it answers in well under a second only while it
    imports none of numpy, pandas, dagster or torch (a package ``__init__`` re-exporting a reader once made it
    2.6 s)."""
    code = ("import sys; from pipelines.update_stamp import fingerprint, replay; fingerprint('update'); "
            f"replay('update', False); print([m for m in {HEAVY!r} if m in sys.modules])")
    env = {**os.environ, "HUMANCAL_STATE_DIR": str(tmp_path)}
    (tmp_path / "dagster_home").mkdir()
    (tmp_path / "dagster_home" / "dagster.yaml").write_text(update_stamp.DEFAULT_DAGSTER_YAML)
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True,
                         env=env).stdout
    assert out.strip() == "[]"


def test_the_parsers_format_names_are_the_formats_modules():
    from humancal.formats import CAMERA_FORMATS
    from humancal.formats.cameras import CAMERA_READ_FORMATS
    from humancal.formats.detections import COCO_SKELETONS, OPENPOSE_SKELETONS
    from humancal.formats.motions import MOTION_FORMATS
    from pipelines.cli import format_names

    assert format_names.CAMERA_FORMATS == CAMERA_FORMATS and format_names.MOTION_FORMATS == MOTION_FORMATS
    assert format_names.CAMERA_READ_FORMATS == CAMERA_READ_FORMATS
    assert format_names.OPENPOSE_SKELETONS == OPENPOSE_SKELETONS and format_names.COCO_SKELETONS == COCO_SKELETONS


def test_verbose_before_or_after_the_command():
    parser = build_parser()
    assert parser.parse_args(["-v", "update"]).verbose and parser.parse_args(["update", "--verbose"]).verbose
    assert not parser.parse_args(["update"]).verbose


def _store_cameras(state: Path, partition: str = "d__s") -> None:
    from humancal.camera import Camera, cameras_to_table

    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    folder = state / "artifacts" / "final_cameras"
    folder.mkdir(parents=True)
    cameras_to_table([Camera(K, np.eye(3), np.zeros(3) + [0, 0, 3], 1280, 720)], "s").to_parquet(
        folder / f"{partition}.parquet")


def test_every_export_refuses_an_existing_target_without_overwrite(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    _store_cameras(tmp_path)
    calib = tmp_path / "calib.toml"
    export = ["export", "cameras", "--partition", "d__s", "--format", "pose2sim", "--out", str(calib)]
    assert main(export) == 0
    with pytest.raises(SystemExit, match=f"{calib} exists; pass --overwrite"):
        main(export)
    assert main([*export, "--overwrite"]) == 0
    busy = tmp_path / "bvh"
    busy.mkdir()
    (busy / "person_0.bvh").write_text("HIERARCHY")
    with pytest.raises(SystemExit, match=f"{busy} is a folder that is not empty; pass --overwrite"):
        main(["export", "motions", "--partition", "d__s", "--format", "bvh", "--out", str(busy)])
    with pytest.raises(SystemExit, match=f"{busy} is a folder that is not empty; pass --overwrite"):
        main(["export", "detections", "--partition", "d__s", "--format", "openpose", "--out", str(busy)])


def _unprivileged() -> list[str] | None:
    """A command prefix under which permission bits apply (root keeps its uid but loses DAC override)."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    return [setpriv, "--bounding-set=-dac_override,-dac_read_search"] if setpriv else None


@pytest.mark.parametrize("argv", [["update", "--partition", "synthetic__tiny"], ["add", "x", "--openpose", "a/",
                                                                                "--image-size", "10x10"]])
def test_a_read_only_state_dir_is_one_line(tmp_path, argv):
    prefix = _unprivileged()
    if prefix is None:
        pytest.skip("running as root without setpriv: permission bits do not apply")
    state = tmp_path / "state"
    (state / "dagster_home").mkdir(parents=True)
    for folder in (state / "dagster_home", state):
        folder.chmod(0o555)
    try:
        run = subprocess.run([*prefix, sys.executable, "-m", "pipelines.cli", *argv], cwd=REPO, text=True,
                             capture_output=True, env=dict(os.environ, HUMANCAL_STATE_DIR=str(state)), timeout=120)
    finally:
        for folder in (state, state / "dagster_home"):
            folder.chmod(0o755)
    assert run.returncode == 1 and "Traceback" not in run.stderr
    assert run.stderr.strip().splitlines() == [
        f"humancal: the state dir is read-only: cannot write {state}; make it writable (e.g. chmod -R u+w {state}) "
        "or set HUMANCAL_STATE_DIR to a writable folder"]


def test_a_read_only_export_folder_is_one_line(tmp_path):
    prefix = _unprivileged()
    if prefix is None:
        pytest.skip("running as root without setpriv: permission bits do not apply")
    _store_cameras(tmp_path)
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        run = subprocess.run([*prefix, sys.executable, "-m", "pipelines.cli", "export", "cameras", "--partition",
                              "d__s", "--format", "pose2sim", "--out", str(out / "calib.toml")], cwd=REPO, text=True,
                             capture_output=True, env=dict(os.environ, HUMANCAL_STATE_DIR=str(tmp_path)), timeout=120)
    finally:
        out.chmod(0o755)
    assert run.returncode == 1 and "Traceback" not in run.stderr
    assert run.stderr.strip() == (f"humancal: cannot write {out}: permission denied (or a read-only file system); "
                                  "choose another --out or make it writable")


def test_the_fingerprint_follows_sources_instance_and_artifacts(tmp_path, monkeypatch):
    import humancal.settings

    state, source = tmp_path / "state", tmp_path / "src"
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(state))
    monkeypatch.setattr(humancal.settings, "REPO_ROOT", source)
    monkeypatch.setattr(update_stamp, "PACKAGES", ("humancal",))
    (source / "humancal").mkdir(parents=True)
    (source / "humancal" / "code.py").write_text("CODE_VERSION = '1'\n")
    (state / "dagster_home" / "history").mkdir(parents=True)
    (state / "dagster_home" / "dagster.yaml").write_text(update_stamp.DEFAULT_DAGSTER_YAML)
    (state / "artifacts" / "views").mkdir(parents=True)
    seen = [update_stamp.fingerprint("update")]
    changes = [
        lambda: (source / "humancal" / "code.py").write_text("CODE_VERSION = '2'\n"),
        lambda: (state / "dagster_home" / "history" / "runs.db").write_bytes(b"a run"),
        lambda: (state / "artifacts" / "views" / "a__b.parquet").write_bytes(b"table"),
        lambda: (state / "artifacts" / "views" / "a__b.parquet").unlink(),
        lambda: (state / "datasets.yaml").write_text("datasets: {}\n"),
    ]
    for change in changes:
        change()
        seen.append(update_stamp.fingerprint("update"))
    assert all(before != after for before, after in zip(seen, seen[1:]))
    assert seen[4] == seen[2]  # the artifact added, then deleted: the same state
    assert update_stamp.fingerprint("update") != update_stamp.fingerprint("demo")
    (state / "dagster_home" / "dagster.yaml").write_text("storage:\n  postgres: {}\n")
    assert update_stamp.fingerprint("update") is None  # its changes would leave no trace here


def test_a_no_op_update_takes_the_shortcut_until_something_changes(tmp_path, monkeypatch, capsys):
    import pipelines.definitions
    import pipelines.update

    state = tmp_path / "state"
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(state))
    monkeypatch.setenv("DAGSTER_HOME", str(state / "dagster_home"))  # restored after the test (the CLI sets it)
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path / "no_data"))
    (tmp_path / "datasets.yaml").write_text("datasets: {}\n")  # no partition: the shared assets only
    monkeypatch.setenv("HUMANCAL_DATASETS", str(tmp_path / "datasets.yaml"))
    monkeypatch.setattr(pipelines.definitions, "defs", pipelines.definitions.build_definitions())
    assert main(["update"]) == 0
    first = capsys.readouterr().out
    assert "lifter_checkpoint" in first and (state / update_stamp.FILE_NAME).exists()

    real_update = pipelines.update.update
    monkeypatch.setattr(pipelines.update, "update", lambda *a, **k: pytest.fail("the shortcut was not taken"))
    assert main(["update"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "materialized 0 asset partitions"

    (state / "artifacts" / "lifter_checkpoint.pt").unlink()  # a deleted artifact: the full path, which restores it
    calls = []
    monkeypatch.setattr(pipelines.update, "update", lambda *a, **k: calls.append(1) or real_update(*a, **k))
    assert main(["update"]) == 0
    assert calls and "materialized 1 asset partitions" in capsys.readouterr().out
    assert (state / "artifacts" / "lifter_checkpoint.pt").exists()


def test_warp_initialises_without_its_banner_or_cuda_driver_warning():
    code = ("from pipelines.quiet_warp import init_warp_quietly; init_warp_quietly(); "
            "import warp; warp.init(); import anny.skinning.warp_skinning")  # anny's own wp.init() comes after
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "CUDA driver" not in run.stderr and "initialized" not in run.stdout + run.stderr
