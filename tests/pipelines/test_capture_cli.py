"""`humancal add`: users' own captures registered from OpenPose folders or COCO files, messy files, and the
whole way through the graph to exported cameras."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from humancal.formats.skeletons import SKELETONS
from pipelines.cli import main

BODY25 = SKELETONS["body25"]


@pytest.fixture
def state(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "state"
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(folder))
    return folder


def _person(present: dict[str, tuple[float, float, float]], skeleton=BODY25) -> dict:
    flat = np.zeros((skeleton.num_joints, 3))
    for joint, xyc in present.items():
        flat[skeleton.index(joint)] = xyc
    return {"person_id": [-1], "pose_keypoints_2d": flat.ravel().tolist()}


STANDING = {"nose": (100.0, 50.0, 0.9), "left_shoulder": (110.0, 80.0, 0.9), "right_shoulder": (90.0, 80.0, 0.9),
            "left_hip": (108.0, 140.0, 0.8), "right_hip": (92.0, 140.0, 0.8), "left_ankle": (108.0, 230.0, 0.7),
            "right_ankle": (92.0, 230.0, 0.7)}


def _frame(folder: Path, name: str, people: list[dict]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(json.dumps({"version": 1.3, "people": people}))
    return path


def _views(root: Path, frames: int = 3, views: int = 2) -> list[str]:
    """Small OpenPose folders: one standing person per frame, files named like OpenPose's."""
    for v in range(views):
        for f in range(frames):
            _frame(root / f"cam{v + 1:02d}", f"cam{v + 1:02d}_{f:012d}_keypoints.json", [_person(STANDING)])
    return [str(root / f"cam{v + 1:02d}") for v in range(views)]


def _add(*args: str) -> int:
    return main(["add", *args])


def _user_file(state: Path) -> Path:
    return state / "datasets.yaml"


# --- registering -------------------------------------------------------------------------------------------------


def test_add_writes_the_user_datasets_file_registers_the_partition_and_prints_a_summary(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25", "--fps", "30") == 0
    out = capsys.readouterr().out
    assert "registered lab__capture" in out
    assert "view 0 cam01: 3 frames with detections, 3 detections, 0 placeholder" in out
    assert "2 views, 3 frames, 6 detections, skeleton body25, no known cameras" in out
    entry = yaml.safe_load(_user_file(state).read_text())["datasets"]["lab"]
    assert entry["kind"] == "capture"
    assert entry["sequences"]["capture"] == {"format": "openpose", "views": views, "image_size": [640, 480],
                                             "skeleton": "body25", "fps": 30.0}
    from humancal.sequences import load_datasets_config

    specs = load_datasets_config()
    assert "lab__capture" in specs and "synthetic__demo" in specs  # merged with the packaged config
    import dagster as dg

    instance = dg.DagsterInstance.from_config(str(state / "dagster_home"))
    assert "lab__capture" in instance.get_dynamic_partitions("sequences")
    # a second sequence of the same capture dataset; the same partition again is refused
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25",
                "--sequence", "take2") == 0
    before = _user_file(state).read_text()
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 2
    assert "lab__capture exists" in capsys.readouterr().err
    assert _user_file(state).read_text() == before


def test_user_file_relative_paths_and_name_clash(tmp_path, state):
    from humancal.sequences import DatasetsConfigError, load_datasets_config
    from humancal.inputs import load_sequence_inputs

    _views(tmp_path / "op")
    state.mkdir()
    _user_file(state).write_text(yaml.safe_dump({"datasets": {"mine": {"kind": "capture", "sequences": {"a": {
        "views": ["../op/cam01", "../op/cam02"], "image_size": [640, 480], "skeleton": "body25"}}}}}))
    spec = load_datasets_config()["mine__a"]
    inputs = load_sequence_inputs(spec, body_model=lambda: None, data_root=None)  # no data root needed
    assert len(inputs.views) == 2 and inputs.detections["frame"].nunique() == 3
    assert inputs.gt_cameras.empty and inputs.gt_associations.empty and inputs.gt_poses3d.empty
    _user_file(state).write_text(yaml.safe_dump({"datasets": {"synthetic": {"kind": "capture", "sequences": {"a": {
        "views": ["x"], "image_size": [640, 480]}}}}}))
    with pytest.raises(DatasetsConfigError, match=r"datasets.synthetic: the name is taken by .*datasets.yaml"):
        load_datasets_config()


# --- messy files: a counted skip or a clear error, never half registered ------------------------------------------


def test_messy_but_usable_files_are_read_with_counted_skips(tmp_path, state, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    placeholder = {"person_id": [-1], "pose_keypoints_2d": []}
    off_image = _person({**STANDING, "left_ankle": (-12.0, 230.0, 0.6), "right_ankle": (700.0, 230.0, 0.6)})
    for f in range(4):  # view a: 4 frames named like 'cam01.0000.json' (camera number 01 is not the frame)
        _frame(a, f"cam01.{f:04d}.json", [_person(STANDING), placeholder] if f != 2 else [])  # frame 2 empty
    for f in (1, 2, 3):  # view b starts a frame late
        _frame(b, f"cam02.{f:04d}.json", [off_image])
    assert _add("messy", "--openpose", str(a), str(b), "--image-size", "640x480", "--skeleton", "body25") == 0
    out = capsys.readouterr().out
    assert "view 0 a: 3 frames with detections, 3 detections, 3 placeholder entries skipped, 0 off-image" in out
    assert "view 1 b: 3 frames with detections, 3 detections, 0 placeholder entries skipped, 6 off-image joints" in out
    assert "2 views, 4 frames, 6 detections" in out


def _expect_error(capsys, state: Path, *needles: str) -> None:
    err = capsys.readouterr().err
    for needle in needles:
        assert needle in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert not _user_file(state).exists(), "nothing may be registered after an error"


def test_25_points_without_skeleton_is_an_error_asking_for_it(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480") == 2
    _expect_error(capsys, state, "cam01_000000000000_keypoints.json", "people[0].pose_keypoints_2d",
                  "'body25' and 'body25b'", "--skeleton")


@pytest.mark.parametrize(
    "content, needles",
    [
        ('{"people": [{"pose_keypoints_2d": [1, 2', ["cam02_000000000001_keypoints.json", "valid JSON"]),
        ('{"version": 1.3}', ["cam02_000000000001_keypoints.json", "field 'people'"]),
        (json.dumps({"people": [{"pose_keypoints_2d": [0.0] * 60}]}),
         ["cam02_000000000001_keypoints.json", "people[0].pose_keypoints_2d", "75 numbers"]),
        (json.dumps({"people": [_person({"nose": (float("nan"), 3.0, 0.9)})]}),
         ["cam02_000000000001_keypoints.json", "joint 0 (nose)", "finite x, y"]),
        (json.dumps({"people": [_person({"nose": (1.0, 3.0, -0.2)})]}),
         ["cam02_000000000001_keypoints.json", "joint 0 (nose) confidence", ">= 0"]),
    ],
)
def test_bad_files_name_file_and_field_and_register_nothing(tmp_path, state, capsys, content, needles):
    views = _views(tmp_path / "op")
    (Path(views[1]) / "cam02_000000000001_keypoints.json").write_text(content)
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 2
    _expect_error(capsys, state, *needles)


def test_bad_arguments_are_errors_that_register_nothing(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "1x1", "2x2", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "--image-size", "one size or one per view (2), got 3")
    assert _add("lab", "--openpose", *views, "--image-size", "640by480", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "--image-size", "WIDTHxHEIGHT")
    size = ["--image-size", "640x480", "--skeleton", "body25"]
    assert _add("lab", "--openpose", *views, *size, "--principal-point", "1,2", "3,4", "5,6") == 2
    _expect_error(capsys, state, "--principal-point", "one point or one per view (2), got 3")
    assert _add("lab", "--openpose", *views, *size, "--principal-point", "320x240") == 2
    _expect_error(capsys, state, "--principal-point", "CX,CY")
    assert _add("lab", "--openpose", *views, *size, "--principal-point", "700,240") == 2
    _expect_error(capsys, state, "principal_point", "outside its 640x480 image")
    assert _add("synthetic", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "dataset 'synthetic' is defined in", "datasets.yaml")
    assert _add("a__b", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "dataset name 'a__b'")
    assert _add("lab", "--openpose", *views, str(tmp_path / "nope"), "--image-size", "640x480",
                "--skeleton", "body25") == 2
    _expect_error(capsys, state, "nope: no such folder")


def test_views_without_frame_numbers_and_different_counts_are_an_error(tmp_path, state, capsys):
    for name in ("x.json", "y.json", "z.json"):
        _frame(tmp_path / "a", name, [])
    _frame(tmp_path / "b", "x.json", [])
    assert _add("lab", "--openpose", str(tmp_path / "a"), str(tmp_path / "b"), "--image-size", "640x480") == 2
    _expect_error(capsys, state, str(tmp_path / "b"), "3 files", "1 files", "no frame numbers")


def test_known_cameras_must_match_the_views(tmp_path, state, capsys):
    from humancal.camera import Camera
    from humancal.formats import write_cameras

    views = _views(tmp_path / "op")
    cam = Camera(K=np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), R_cam_from_world=np.eye(3),
                 t_cam_from_world_m=np.array([0.0, 0.0, 3.0]), width_px=640, height_px=480)
    path = write_cameras([cam], tmp_path / "calib.toml", "pose2sim")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25",
                "--cameras", str(path)) == 2
    _expect_error(capsys, state, "calib.toml", "expected 2 cameras (one per view, in view order), got 1 cameras")
    write_cameras([cam, cam], tmp_path / "calib.toml", "pose2sim")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25",
                "--cameras", str(path)) == 0
    assert "known cameras given (evaluation only)" in capsys.readouterr().out


def test_coco_files_with_placeholders(tmp_path, state, capsys):
    coco17 = SKELETONS["coco17"]
    files = []
    for v in range(2):
        entries = [{"image_id": f, "category_id": 1, "score": 0.9,
                    "keypoints": _person(STANDING, coco17)["pose_keypoints_2d"]} for f in range(5)]
        entries.append({"image_id": 2, "category_id": 1, "score": 0.0, "keypoints": []})
        files.append(tmp_path / f"cam{v}.json")
        files[-1].write_text(json.dumps(entries))
    assert _add("lab", "--coco", *map(str, files), "--image-size", "640x480") == 0
    out = capsys.readouterr().out
    assert "view 1 cam1: 5 frames with detections, 5 detections, 1 placeholder entries skipped" in out
    assert "skeleton coco17 (told from the array length)" in out


# --- end to end: synthetic truth -> files -> add -> update -> export -> compare -------------------------------------


def _write_synthetic_capture(root: Path, body_model, num_frames: int = 80):
    """A 4-person, 5-view synthetic scene as OpenPose folders, COCO files and a Pose2Sim calibration."""
    from humancal.camera import cameras_from_table
    from humancal.formats import write_cameras, write_openpose
    from humancal.formats.joint_mapping import from_canonical
    from humancal.formats.detections import detections_to_arrays
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_frames=num_frames, seed=0), body_model, sequence="take1")
    folders = write_openpose(scene.detections, root / "openpose")
    cameras = cameras_from_table(scene.cameras)
    write_cameras(cameras, root / "calib.toml", "pose2sim")
    coco = {v: [] for v in folders}
    for (frame, view), (_, kp, sc) in sorted(detections_to_arrays(scene.detections).items()):
        out_kp, out_sc = from_canonical(kp, sc, "coco17")
        for k, s in zip(out_kp, out_sc):
            flat = np.where(s[:, None] > 0, np.c_[np.nan_to_num(k), s], 0.0)
            coco[view].append({"image_id": int(frame), "category_id": 1, "keypoints": flat.ravel().tolist(),
                               "score": float(s.mean())})
    coco_files = []
    for v, entries in coco.items():
        coco_files.append(root / f"cam{v}.json")
        coco_files[-1].write_text(json.dumps(entries))
    return folders, coco_files, cameras


def test_openpose_capture_reads_back_the_synthetic_detections(tmp_path, state, body_model):
    from humancal.inputs import load_sequence_inputs
    from humancal.sequences import load_datasets_config
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("tiny", seed=1), body_model, sequence="capture")
    from humancal.formats import write_openpose

    folders = write_openpose(scene.detections, tmp_path / "op")
    assert main(["add", "tiny", "--openpose", *map(str, folders.values()), "--image-size", "1920x1080",
                 "--skeleton", "body25"]) == 0
    inputs = load_sequence_inputs(load_datasets_config()["tiny__capture"], body_model=lambda: None, data_root=None)
    import pandas as pd

    pd.testing.assert_frame_equal(inputs.detections, scene.detections.reset_index(drop=True), check_exact=True)
    assert inputs.views[["view", "width_px", "height_px"]].values.tolist() == \
        scene.cameras[["view", "width_px", "height_px"]].values.tolist()


def _calibrate_and_compare(key: str, add_args: list[str], tmp_path: Path, monkeypatch, capsys):
    import pipelines.definitions
    from evaluation.camera_metrics import camera_errors
    from humancal.formats import read_cameras

    # the Definitions' storage root follows the state dir set by the test
    monkeypatch.setattr(pipelines.definitions, "defs", pipelines.definitions.build_definitions())
    dataset, _ = key.split("__")
    assert main(["add", dataset, *add_args]) == 0
    assert main(["update", "--partition", key]) == 0
    out = tmp_path / f"{dataset}.toml"
    assert main(["export", "cameras", "--partition", key, "--cameras-asset", "extrinsics",
                 "--format", "pose2sim", "--out", str(out)]) == 0
    capsys.readouterr()
    return read_cameras(out, "pose2sim")


def _assert_close_to_truth(estimated, truth, label: str, capsys) -> dict:
    from evaluation.camera_metrics import camera_errors

    err = camera_errors(estimated, truth)
    figures = {name: (float(np.mean(err[name])), float(np.max(err[name])))
               for name in ("focal_error_pct", "angle_error_deg", "position_error_mm")}
    with capsys.disabled():  # the figures, for the record (pytest -s)
        print(f"\n{label}: " + ", ".join(f"{k} mean {m:.2f} max {x:.2f}" for k, (m, x) in figures.items()))
    assert len(estimated) == len(truth)
    assert figures["focal_error_pct"][1] < 5.0
    assert figures["angle_error_deg"][1] < 2.0
    return figures


def test_openpose_capture_end_to_end_matches_the_synthetic_truth(tmp_path, state, monkeypatch, capsys, body_model):
    folders, _, truth = _write_synthetic_capture(tmp_path / "capture", body_model)
    # A known principal point half a pixel off the centre (the truth's): small enough not to matter, and it must
    # reach the calibrated cameras, which would otherwise have theirs at the image centre.
    args = ["--openpose", *map(str, folders.values()), "--image-size", "1920x1080", "--skeleton", "body25",
            "--cameras", str(tmp_path / "capture" / "calib.toml"), "--principal-point", "960.5,539.5"]
    estimated = _calibrate_and_compare("oplab__capture", args, tmp_path, monkeypatch, capsys)
    _assert_close_to_truth(estimated, truth, "openpose capture", capsys)
    for camera in estimated:
        np.testing.assert_allclose(camera.K[:2, 2], [960.5, 539.5], atol=1e-6)
    assert main(["report", "--partition", "oplab__capture", "--format", "csv"]) == 0
    report = capsys.readouterr().out
    assert "focal_error_pct" in report and "mpjpe" not in report  # known cameras: camera rows; no identities


@pytest.mark.slow
def test_coco_capture_end_to_end_matches_the_synthetic_truth(tmp_path, state, monkeypatch, capsys, body_model):
    _, files, truth = _write_synthetic_capture(tmp_path / "capture", body_model)
    args = ["--coco", *map(str, files), "--image-size", "1920x1080"]
    estimated = _calibrate_and_compare("cocolab__capture", args, tmp_path, monkeypatch, capsys)
    _assert_close_to_truth(estimated, truth, "coco capture", capsys)
