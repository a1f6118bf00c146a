"""`humancal export motions`: reads the stored fitted_motions table and writes BVH / glTF / npz / OBJ files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humancal.fitting import FittedMotions
from humancal.mocap.bvh import parse_bvh
from pipelines.cli import build_parser, main

PARTITION = "synthetic__tiny"


def _store_motions(state_dir, fps=30.0) -> FittedMotions:
    rng = np.random.default_rng(1)
    P, T = 2, 6
    rot = Rotation.from_rotvec(rng.normal(scale=0.2, size=(P * T * 22, 3))).as_matrix().reshape(P, T, 22, 3, 3)
    present = np.ones((P, T), bool)
    present[1, :2] = False
    motions = FittedMotions(np.array([0, 4]), np.arange(10, 10 + T), present, np.full((P, 6), 0.5), rot,
                            rng.normal(size=(P, T, 3)), rng.normal(size=(P, T, 23, 3)), fps)
    folder = state_dir / "artifacts" / "fitted_motions"
    folder.mkdir(parents=True)
    motions.to_table(PARTITION).to_parquet(folder / f"{PARTITION}.parquet")
    return motions


def test_parser_knows_the_motions_export():
    args = build_parser().parse_args(["export", "motions", "--partition", PARTITION, "--format", "obj", "--out", "o",
                                      "--frames", "0:100:5", "--fps", "25"])
    assert (args.what, args.format, args.frames, args.fps) == ("motions", "obj", "0:100:5", 25.0)


def test_export_motions_bvh_and_obj(tmp_path, monkeypatch, capsys, body_model):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path / "state"))
    monkeypatch.setattr("humancal.body.BodyModel", lambda: body_model)  # the session's model (construction ~1 s)
    _store_motions(tmp_path / "state")
    out = tmp_path / "bvh"
    assert main(["export", "motions", "--partition", PARTITION, "--format", "bvh", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "2 people, frames 10-15 at 30 fps (synthetic preset 'tiny')" in printed
    assert f"person 4: frames 12-15 -> {out / 'person_4.bvh'}" in printed
    assert parse_bvh(out / "person_4.bvh").values.shape[0] == 4
    with pytest.raises(SystemExit, match=f"{out} is a folder that is not empty; pass --overwrite"):
        main(["export", "motions", "--partition", PARTITION, "--format", "bvh", "--out", str(out), "--fps", "50"])
    assert main(["export", "motions", "--partition", PARTITION, "--format", "bvh", "--out", str(out), "--fps", "50",
                 "--overwrite"]) == 0
    assert "at 50 fps (--fps)" in capsys.readouterr().out
    assert parse_bvh(out / "person_4.bvh").fps == pytest.approx(50.0)
    meshes = tmp_path / "obj"
    assert main(["export", "motions", "--partition", PARTITION, "--format", "obj", "--out", str(meshes),
                 "--frames", "12:16:3"]) == 0
    assert sorted(p.relative_to(meshes).as_posix() for p in meshes.rglob("*.obj")) == [
        "person_0/frame_000012.obj", "person_0/frame_000015.obj", "person_4/frame_000012.obj",
        "person_4/frame_000015.obj"]


def test_export_motions_errors(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    out = str(tmp_path / "out")
    with pytest.raises(SystemExit, match=r"fitted_motions of synthetic__tiny is not stored .*run `humancal update --partition synthetic__tiny`"):
        main(["export", "motions", "--partition", PARTITION, "--format", "bvh", "--out", out])
    with pytest.raises(SystemExit, match="supports --format bvh, gltf, npz, obj; got fbx"):
        main(["export", "motions", "--partition", PARTITION, "--format", "fbx", "--out", out])
    with pytest.raises(SystemExit, match="--frames applies to --format obj only"):
        main(["export", "motions", "--partition", PARTITION, "--format", "bvh", "--out", out, "--frames", "0:5"])
    with pytest.raises(SystemExit, match=r"--frames expects START:STOP\[:STEP\]"):
        main(["export", "motions", "--partition", PARTITION, "--format", "obj", "--out", out, "--frames", "x"])
