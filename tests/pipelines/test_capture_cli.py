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


def _shifted(joints: dict[str, tuple[float, float, float]], dx: float) -> dict[str, tuple[float, float, float]]:
    return {name: (x + dx, y, c) for name, (x, y, c) in joints.items()}


def _views(root: Path, frames: int = 3, views: int = 2) -> list[str]:
    """Small OpenPose folders: one standing person per frame (a few pixels apart from view to view: two cameras never
    see the same picture), files named like OpenPose's."""
    for v in range(views):
        for f in range(frames):
            person = _person(_shifted(STANDING, 7.0 * v))
            _frame(root / f"cam{v + 1:02d}", f"cam{v + 1:02d}_{f:012d}_keypoints.json", [person])
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
    assert "2 views, 3 frames, 6 detections, skeleton body25, cameras calibrated from the people" in out
    entry = yaml.safe_load(_user_file(state).read_text())["datasets"]["lab"]
    assert entry["kind"] == "capture"
    assert entry["sequences"]["capture"] == {"format": "openpose", "views": views, "image_size": [640, 480],
                                             "skeleton": "body25", "fps": 30.0}
    from humancal.datasets.sequences import load_datasets_config

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
    from humancal.datasets.inputs import load_sequence_inputs
    from humancal.datasets.sequences import DatasetsConfigError, load_datasets_config

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
    assert "every camera known (used instead of a calibration)" in capsys.readouterr().out


def test_one_known_camera_among_unknown_ones_and_reference_cameras(tmp_path, state, capsys):
    from humancal.camera import Camera
    from humancal.formats import write_cameras

    views = _views(tmp_path / "op")
    cam = Camera(K=np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), R_cam_from_world=np.eye(3),
                 t_cam_from_world_m=np.array([0.0, 0.0, 3.0]), width_px=640, height_px=480)
    one = write_cameras([cam], tmp_path / "one.toml", "pose2sim")
    both = write_cameras([cam, cam], tmp_path / "both.toml", "pose2sim")
    base = ["lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25"]
    assert _add(*base, "--cameras", str(one), "--known-views", "nope") == 2
    _expect_error(capsys, state, "one.toml", "--known-views", "distinct names of the capture's views", "'nope'")
    assert _add(*base, "--known-views", "cam02") == 2
    _expect_error(capsys, state, "--known-views: given without --cameras")
    assert _add(*base, "--cameras", str(one), "--known-views", "cam02", "--reference-cameras", str(both)) == 0
    out = capsys.readouterr().out
    assert "cameras of cam02 known (the others calibrated around them); reference cameras given (evaluation only)" \
        in out
    entry = yaml.safe_load(_user_file(state).read_text())["datasets"]["lab"]["sequences"]["capture"]
    assert entry["cameras"] == {"path": str(one), "views": ["cam02"]}
    assert entry["reference_cameras"] == {"path": str(both)}
    from humancal.datasets.inputs import load_sequence_inputs
    from humancal.datasets.sequences import load_datasets_config

    inputs = load_sequence_inputs(load_datasets_config()["lab__capture"], body_model=lambda: None, data_root=None)
    assert inputs.known_cameras["view"].tolist() == [1] and len(inputs.gt_cameras) == 2


def test_coco_files_with_placeholders(tmp_path, state, capsys):
    coco17 = SKELETONS["coco17"]
    files = []
    for v in range(2):
        entries = [{"image_id": f, "category_id": 1, "score": 0.9,
                    "keypoints": _person(_shifted(STANDING, 7.0 * v), coco17)["pose_keypoints_2d"]} for f in range(5)]
        entries.append({"image_id": 2, "category_id": 1, "score": 0.0, "keypoints": []})
        files.append(tmp_path / f"cam{v}.json")
        files[-1].write_text(json.dumps(entries))
    assert _add("lab", "--coco", *map(str, files), "--image-size", "640x480") == 0
    out = capsys.readouterr().out
    assert "view 1 cam1: 5 frames with detections, 5 detections, 1 placeholder entries skipped" in out
    assert "skeleton coco17 (told from the array length)" in out


# --- inputs checked before anything runs: wrong image size, wrong skeleton, views that cannot be right ------------

# A standing person facing the camera, canonical joints in pixels relative to the point between the feet (y down,
# the person's left at +x), 380 px tall.
BODY = {"nose": (0, -370), "left_eye": (6, -378), "right_eye": (-6, -378), "left_ear": (14, -372),
        "right_ear": (-14, -372), "left_shoulder": (40, -310), "right_shoulder": (-40, -310),
        "left_elbow": (48, -240), "right_elbow": (-48, -240), "left_wrist": (52, -175), "right_wrist": (-52, -175),
        "left_hip": (25, -190), "right_hip": (-25, -190), "left_knee": (27, -100), "right_knee": (-27, -100),
        "left_ankle": (28, -15), "right_ankle": (-28, -15), "left_big_toe": (36, 0), "right_big_toe": (-36, 0),
        "left_small_toe": (42, 0), "right_small_toe": (-42, 0), "left_heel": (26, -4), "right_heel": (-26, -4)}


def _people_views(root: Path, skeleton: str = "body25", views: int = 2, frames=range(12), feet=(500.0, 700.0),
                  step=(25.0, 4.0), scale: float = 1.0) -> list[str]:
    """OpenPose folders of one walking person per frame, written with ``skeleton``'s joint order (BODY_25B files
    are the canonical joints re-ordered by the writer)."""
    import pandas as pd

    from humancal.formats import write_openpose

    rows = []
    for v in range(views):
        for f in frames:
            x0, y0 = feet[0] + step[0] * f + 40.0 * v, feet[1] + step[1] * f
            rows += [("cap", f, v, 0, joint, x0 + scale * dx, y0 + scale * dy, 0.9) for joint, (dx, dy) in BODY.items()]
    table = pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"])
    return [str(folder) for folder in write_openpose(table, root, skeleton=skeleton).values()]


def test_portrait_cameras_declared_landscape_are_an_error_proposing_the_transposed_size(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op", feet=(300.0, 1850.0), step=(20.0, -3.0), scale=4.0)  # 1088x1920 videos
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1088", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "view 0 (view_00): 53 % of the joints lie outside the declared 1920x1088 image; the "
                  "detections span 109-711 x 306-1850 px: is the image 1088x1920 (--image-size)?")
    assert _add("lab", "--openpose", *views, "--image-size", "1088x1920", "--skeleton", "body25") == 0


def test_an_image_size_far_too_small_proposes_a_size_holding_the_joints(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op", feet=(300.0, 900.0), step=(100.0, 0.0))  # joints up to 1480 x 900 px
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 2
    _expect_error(capsys, state, "view 0 (view_00): ", "outside the declared 640x480 image",
                  "is the image 1920x1080 (--image-size)?")


def test_a_few_extrapolated_off_image_joints_stay_accepted_and_counted(tmp_path, state, capsys):
    # the person walks out at the right: in the last frames some joints are past x = 1919 (trackers extrapolate)
    views = _people_views(tmp_path / "op", frames=range(40), feet=(1300.0, 700.0), step=(15.0, 0.0))
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", "body25") == 0
    out = capsys.readouterr().out
    # 35 of view 1's 920 joints (4 %): over the 20-joint minimum, under the 10 % share
    assert "view 1 view_01: 40 frames with detections, 40 detections, 0 placeholder entries skipped, 35 off-image " \
        "joints dropped" in out


def test_landscape_cameras_declared_portrait_warn_when_the_people_stay_in_the_top_part(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op", feet=(300.0, 1000.0), step=(30.0, 0.0))  # within 1080 x 1000 px
    assert _add("lab", "--openpose", *views, "--image-size", "1088x1920", "--skeleton", "body25") == 0
    out = capsys.readouterr().out
    assert "warning: view 0 (view_00): the joints span " in out
    assert "% of the declared 1088x1920 image: is the image 1920x1088 (--image-size)?" in out


def test_detections_within_the_top_left_quarter_warn_of_a_smaller_video(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op", feet=(100.0, 450.0))  # a 960x540 video's detections
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", "body25") == 0
    assert "warning: view 0 (view_00): the joints span 54-421 x 73-494 px, within the top-left quarter of the " \
           "declared 1920x1080 image: were the detections made on a smaller video (--image-size)?" in \
           capsys.readouterr().out


@pytest.mark.parametrize("written, declared", [("body25b", "body25"), ("body25", "body25b")])
def test_a_25_point_skeleton_the_anatomy_contradicts_is_an_error_naming_the_other(tmp_path, state, capsys, written,
                                                                                  declared):
    views = _people_views(tmp_path / "op", skeleton=written)
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", declared) == 2
    _expect_error(capsys, state, f"the 25-point detections do not look like {declared}: joints that are neighbours "
                  "on a body (nose and eyes, eyes and ears, ankles and heels and big toes) lie a median ",
                  f"when read as {written}: is the skeleton {written} (--skeleton)?")
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", written) == 0


def test_views_that_cannot_be_right_are_errors(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op", views=3)
    size = ["--image-size", "1920x1080", "--skeleton", "body25"]
    assert _add("lab", "--openpose", views[0], *size) == 2
    _expect_error(capsys, state, "--openpose: expected two views or more (one camera cannot be calibrated", "got 1")
    assert _add("lab", "--openpose", views[0], views[1], views[0], *size) == 2
    _expect_error(capsys, state, "--openpose: views 0 and 2 are the same path",
                  "give each camera's folder or file once")
    import shutil

    shutil.copytree(views[1], tmp_path / "copy")
    assert _add("lab", "--openpose", views[0], views[1], str(tmp_path / "copy"), *size) == 2
    _expect_error(capsys, state, "view 1 (view_01) and view 2 (copy) hold identical detections: the same camera's "
                  "files given twice (--openpose)?")
    late = _people_views(tmp_path / "late", views=1, frames=range(300, 312), step=(1.0, 0.0))
    assert _add("lab", "--openpose", views[0], views[1], *late, *size) == 2
    _expect_error(capsys, state, "view 2 (view_00): none of its frames (300-311) has detections in another view "
                  "(frames 0-11): are the videos in sync, and do the file names count frames the same way?")
    for f in range(12):
        _frame(tmp_path / "empty", f"empty_{f:012d}_keypoints.json", [])
    assert _add("lab", "--openpose", views[0], views[1], str(tmp_path / "empty"), *size) == 2
    _expect_error(capsys, state, "view 2 (empty): no detection in any of its files: is it the right folder or file "
                  "(--openpose)?")


def test_footage_is_checked_against_the_views_and_stored_with_the_capture(tmp_path, state, capsys):
    import cv2

    views = _views(tmp_path / "op")
    footage = []
    for v, shape in enumerate([(240, 320), (240, 320), (240, 240)]):  # two at half size, one square
        folder = tmp_path / "frames" / f"cam{v + 1:02d}"
        folder.mkdir(parents=True)
        for f in range(2):
            cv2.imwrite(str(folder / f"{f:06d}.jpg"), np.zeros((*shape, 3), np.uint8))
        footage.append(str(folder))
    size = ["--image-size", "640x480", "--skeleton", "body25"]
    assert _add("lab", "--openpose", *views, *size, "--videos", footage[0]) == 2
    _expect_error(capsys, state, "--videos", "one video file or image folder per view (2), got 1")
    assert _add("lab", "--openpose", *views, *size, "--videos", footage[0], footage[2]) == 2
    _expect_error(capsys, state, "--videos: view cam02", "240x240 frames", "image size is 640x480")
    assert _add("lab", "--openpose", *views, *size, "--videos", footage[0], str(tmp_path / "gone.mp4")) == 2
    _expect_error(capsys, state, "--videos: view cam02", "gone.mp4: no such video file or image folder")
    assert _add("lab", "--openpose", *views, *size, "--videos", *footage[:2]) == 0
    out = capsys.readouterr().out
    assert "footage: images 320x240, 2 frames" in out and "ends at frame 1, its detections run to frame 2" in out
    entry = yaml.safe_load(_user_file(state).read_text())["datasets"]["lab"]["sequences"]["capture"]
    assert entry["videos"] == footage[:2]


def test_views_sharing_few_frames_are_registered_with_a_warning(tmp_path, state, capsys):
    first = _people_views(tmp_path / "a", views=1, frames=range(0, 20))
    second = _people_views(tmp_path / "b", views=1, frames=range(17, 40), feet=(520.0, 690.0))
    assert _add("lab", "--openpose", *first, *second, "--image-size", "1920x1080", "--skeleton", "body25") == 0
    out = capsys.readouterr().out
    assert "warning: view 1 (view_00) shares only 3 frame(s) with the other views (17-19): the calibration needs " \
           "people seen by several views at once" in out


def test_camera_files_of_unknown_format_name_the_flag(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    (tmp_path / "calib.yaml").write_text("cameras: []")
    assert _add("lab", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25",
                "--cameras", str(tmp_path / "calib.yaml")) == 2
    _expect_error(capsys, state, "calib.yaml: expected a camera file whose format its name tells (.toml, .json, "
                  ".qca.txt, intri.yml, cameras.txt), or its format given with --cameras-format (one of [")


def test_qualisys_calibration_as_known_cameras(tmp_path, state, capsys):
    views = _people_views(tmp_path / "op")
    cameras = "".join(
        f'<camera serial="{serial}" model="Miqus Video"><fov_video left="0" top="0" right="1919" bottom="1079"/>'
        f'<transform x="{x}" y="-4000" z="1500" r11="1" r12="0" r13="0" r21="0" r22="0" r23="1" r31="0" r32="-1" '
        'r33="0"/><intrinsic focalLengthU="96000" focalLengthV="96000" centerPointU="61440" centerPointV="34560" '
        'skew="0"/></camera>'
        for serial, x in (("28513", -1000), ("28514", 1000))
    )
    path = tmp_path / "session.qca.txt"
    path.write_text(f"<?xml version='1.0'?><calibration><cameras>{cameras}</cameras></calibration>")
    assert _add("lab", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", "body25",
                "--cameras", str(path)) == 0
    assert "every camera known (used instead of a calibration)" in capsys.readouterr().out
    entry = yaml.safe_load(_user_file(state).read_text())["datasets"]["lab"]["sequences"]["capture"]
    assert entry["cameras"] == {"path": str(path)}


# --- end to end: synthetic truth -> files -> add -> update -> export -> compare -------------------------------------


def _write_synthetic_capture(root: Path, body_model, num_frames: int = 80, footage_every: int = 0):
    """A 4-person, 5-view synthetic scene as OpenPose folders, COCO files and a Pose2Sim calibration; with
    ``footage_every``, also footage as image folders (``root/footage/<view>``, every n-th frame: the rest missing)."""
    from humancal.camera import cameras_from_table
    from humancal.formats import write_cameras, write_openpose
    from humancal.formats.detections import detections_to_arrays
    from humancal.formats.joint_mapping import from_canonical
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
    if footage_every:
        _write_footage_images(scene, cameras, body_model, root / "footage", folders, footage_every)
    return folders, coco_files, cameras


def _write_footage_images(scene, cameras, body_model, root: Path, folders: dict, every: int) -> None:
    """The scene's true bodies as silhouettes, one image folder per view named like its detections' folder."""
    import cv2
    import torch

    from humancal.fitting import FittedMotions
    from humancal.viewing.footage import render_silhouettes
    from humancal.viewing.mesh import decimation

    motions = FittedMotions.from_table(scene.motions, scene.config.fps)
    frames = np.arange(0, scene.config.num_frames, every)
    with torch.no_grad():
        vertices = [body_model.reference_forward(
            torch.as_tensor(motions.phenotypes[i : i + 1], dtype=body_model.dtype),
            torch.as_tensor(motions.bone_rotmats_local[i, frames][None], dtype=body_model.dtype),
            torch.as_tensor(motions.root_translation_m[i, frames][None], dtype=body_model.dtype),
        )["vertices"][0].numpy() for i in range(len(motions.person_ids))]
    light = [decimation(v[0], body_model.faces.numpy(), 0.03) for v in vertices]
    for v, folder in folders.items():
        out = root / Path(folder).name
        out.mkdir(parents=True)
        for t, frame in enumerate(frames):
            image = render_silhouettes(cameras[v], [vs[t][keep] for vs, (keep, _) in zip(vertices, light)],
                                       [faces for _, faces in light])
            cv2.imwrite(str(out / f"{Path(folder).name}_{frame:06d}.jpg"), image)


def test_openpose_capture_reads_back_the_synthetic_detections(tmp_path, state, body_model):
    from humancal.datasets.inputs import load_sequence_inputs
    from humancal.datasets.sequences import load_datasets_config
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


@pytest.mark.slow  # about a minute; .ci/run runs it
def test_openpose_capture_end_to_end_matches_the_synthetic_truth(tmp_path, state, monkeypatch, capsys, body_model):
    folders, _, truth = _write_synthetic_capture(tmp_path / "capture", body_model, num_frames=48, footage_every=16)
    # A known principal point half a pixel off the centre (the truth's): small enough not to matter, and it must
    # reach the calibrated cameras, which would otherwise have theirs at the image centre.
    footage = [str(tmp_path / "capture" / "footage" / Path(f).name) for f in folders.values()]
    args = ["--openpose", *map(str, folders.values()), "--image-size", "1920x1080", "--skeleton", "body25",
            "--reference-cameras", str(tmp_path / "capture" / "calib.toml"), "--principal-point", "960.5,539.5",
            "--videos", *footage]
    estimated = _calibrate_and_compare("oplab__capture", args, tmp_path, monkeypatch, capsys)
    _assert_close_to_truth(estimated, truth, "openpose capture", capsys)
    for camera in estimated:
        np.testing.assert_allclose(camera.K[:2, 2], [960.5, 539.5], atol=1e-6)
    assert main(["report", "--partition", "oplab__capture", "--format", "csv"]) == 0
    report = capsys.readouterr().out
    assert "focal_error_pct" in report and "mpjpe" not in report  # known cameras: camera rows; no identities
    # the footage given at `add` is under the overlays and in the recording (frames without an image: none drawn)
    overlays = tmp_path / "overlays"
    assert main(["export", "overlays", "--partition", "oplab__capture", "--format", "mp4", "--out", str(overlays),
                 "--frames", "0:48:16"]) == 0
    assert "on the footage of 5 views" in capsys.readouterr().out and len(list(overlays.glob("*.mp4"))) == 5
    recording = tmp_path / "capture.rrd"
    assert main(["view", "--partition", "oplab__capture", "--no-mesh", "--save", str(recording)]) == 0
    assert "footage: 15 images" in capsys.readouterr().out and recording.stat().st_size > 0
    with pytest.raises(SystemExit, match="no true body motions .* a capture brings its own"):
        main(["export", "footage", "--partition", "oplab__capture", "--format", "mp4", "--out", str(tmp_path / "f")])
    with pytest.raises(SystemExit, match="--videos is an option of `export overlays`"):
        main(["export", "cameras", "--partition", "oplab__capture", "--format", "pose2sim", "--videos", "x",
              "--out", str(tmp_path / "c.toml")])


@pytest.mark.slow
def test_coco_capture_end_to_end_matches_the_synthetic_truth(tmp_path, state, monkeypatch, capsys, body_model):
    _, files, truth = _write_synthetic_capture(tmp_path / "capture", body_model)
    args = ["--coco", *map(str, files), "--image-size", "1920x1080"]
    estimated = _calibrate_and_compare("cocolab__capture", args, tmp_path, monkeypatch, capsys)
    _assert_close_to_truth(estimated, truth, "coco capture", capsys)


# --- unsynchronised videos ---------------------------------------------------------------------------------------


def _write_unsynced_capture(root: Path, body_model, starts=(20, 0, 45, 33, 7, 60, 12), num_frames: int = 291):
    """A synthetic 7-view scene whose cameras were started by hand: view v films ``num_frames`` frames from its
    own start, numbered from 0 (offset ``(starts[v] - starts[0]) / 30`` s)."""
    from humancal.formats import write_openpose
    from humancal.synthetic import generate_scene, preset
    from humancal.synthetic.clocks import started_by_hand

    scene = generate_scene(preset("demo", num_views=7, num_people=4, num_frames=351, seed=109), body_model,
                           sequence="capture")
    folders = write_openpose(started_by_hand(scene.detections, starts, num_frames), root / "op")
    return [str(f) for f in folders.values()], np.asarray(starts) - starts[0]


@pytest.mark.slow
def test_unsynced_offsets_are_checked_and_confirmed_by_the_cameras(tmp_path, state, capsys, body_model):
    """Seven views started by hand, four of whose offsets rest on one pair of views each (refused before the
    cameras checked them, ``tests/humancal/sync/test_with_cameras.py``): `add --unsynced` calibrates the cameras
    from the people on the estimated clock, they confirm those four and agree with the rest, and the offsets stored
    are exact to the frame (the fractions the cameras measure within 0.1 frame)."""
    views, truth = _write_unsynced_capture(tmp_path, body_model)
    assert _add("hand", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", "body25", "--fps", "30",
                "--unsynced") == 0
    out = capsys.readouterr().out
    assert out.count("cameras: agrees") + out.count("cameras: moved") == 7, out
    assert out.count("(confirms an offset one pair of views gave)") >= 1, out
    stored = yaml.safe_load(_user_file(state).read_text())["datasets"]["hand"]["sequences"]["capture"]
    names = [Path(v).name for v in views]
    offsets = np.array([stored["time_offsets"].get(n, 0.0) for n in names]) * 30
    np.testing.assert_allclose(offsets, truth, atol=0.1)  # whole frames exact, fractions of a frame ~0


def test_given_time_offsets_and_per_view_fps_are_stored_and_applied(tmp_path, state, capsys, body_model):
    from humancal.datasets.inputs import load_sequence_inputs, sequence_fps
    from humancal.datasets.sequences import load_datasets_config

    views, truth = _write_unsynced_capture(tmp_path, body_model)
    names = [Path(v).name for v in views]
    given = [f"{n}={t / 30:.6f}" for n, t in zip(names[1:], truth[1:])]
    assert _add("given", "--openpose", *views, "--image-size", "1920x1080", "--skeleton", "body25",
                "--fps", "30", f"{names[3]}=30", "--time-offsets", *given) == 0
    out = capsys.readouterr().out
    assert "time offsets given" in out
    stored = yaml.safe_load(_user_file(state).read_text())["datasets"]["given"]["sequences"]["capture"]
    assert "unsynced" not in stored and stored["view_fps"] == {names[3]: 30.0}
    spec = load_datasets_config()["given__capture"]
    inputs = load_sequence_inputs(spec, body_model=lambda: None, data_root=None)
    assert inputs.detections.groupby("view")["frame"].min().loc[2] == truth[2]
    assert inputs.detections_notes["time_offsets_source"] == "given"
    assert sequence_fps(spec)[0] == 30.0


def test_a_synced_capture_has_no_time_offsets(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    assert _add("synced", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25") == 0
    assert "time offset" not in capsys.readouterr().out


@pytest.mark.parametrize("args, needles", [
    (["--fps", "0"], ["--fps: expected NAME=FPS or FPS (a positive number), got '0'"]),
    (["--fps", "30", "25"], ["--fps: expected NAME=FPS or FPS, got '25' (a second plain number)"]),
    (["--fps", "cam01=abc"], ["--fps: expected NAME=FPS or FPS (a positive number), got 'cam01=abc'"]),
    (["--fps", "cam09=60"], ["--fps: ['cam09'] are not views of the capture"]),
    (["--time-offsets", "1.5"], ["--time-offsets: expected NAME=SECONDS, got '1.5'"]),
    (["--time-offsets", "cam02=x"], ["--time-offsets: expected NAME=SECONDS, got 'cam02=x'"]),
    (["--time-offsets", "cam02=1", "cam02=2"], ["--time-offsets: view 'cam02' given twice"]),
    (["--time-offsets", "camX=1"], ["--time-offsets: ['camX'] are not views of the capture"]),
])
def test_bad_sync_flags_are_errors_naming_the_flag(tmp_path, state, capsys, args, needles):
    views = _views(tmp_path / "op")
    assert _add("bad", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25", *args) == 2
    _expect_error(capsys, state, *needles)


def test_unsynced_and_time_offsets_together_are_refused(tmp_path, state, capsys):
    views = _views(tmp_path / "op")
    with pytest.raises(SystemExit):
        _add("bad", "--openpose", *views, "--image-size", "640x480", "--unsynced", "--time-offsets", "cam02=1")
    assert "not allowed with argument" in capsys.readouterr().err


def test_unsynced_views_whose_people_do_not_move_are_refused_naming_the_view(tmp_path, state, capsys):
    views = _views(tmp_path / "op", frames=90, views=3)
    assert _add("still", "--openpose", *views, "--image-size", "640x480", "--skeleton", "body25", "--unsynced") == 2
    _expect_error(capsys, state, "view 1 (cam02), view 2 (cam03): the time offset is ambiguous",
                  "--time-offsets cam02=SECONDS cam03=SECONDS")
