"""Checks of a capture's inputs: image sizes against where the joints lie, the skeleton against the people's
anatomy (synthetic and Shelf's real OpenPose detections), the views; messages name the capture's options."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from humancal.captures import CaptureConfig, load_capture
from humancal.formats.detections.checks import InputCheckError, check_image_sizes, check_views
from humancal.formats.detections.skeleton_fit import (
    SkeletonMismatch,
    check_skeleton_fit,
    neighbour_spread,
    reinterpret,
)
from humancal.keypoints import JOINT_INDEX

COLUMNS = ["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"]


def _table(points_by_view: dict[int, np.ndarray], frames=None) -> pd.DataFrame:
    """One detection per point: (frame = index or ``frames[i]``, view, det 0, nose, x, y, 0.9)."""
    rows = []
    for view, points in points_by_view.items():
        for i, (x, y) in enumerate(points):
            rows.append(("s", i if frames is None else frames[view][i], view, 0, "nose", float(x), float(y), 0.9))
    return pd.DataFrame(rows, columns=COLUMNS)


def _uniform(rng, n, width, height) -> np.ndarray:
    return np.c_[rng.uniform(0, width - 1, n), rng.uniform(0, height - 1, n)]


# --- image size --------------------------------------------------------------------------------------------------


def test_image_size_errors_propose_the_size_that_holds_the_joints():
    rng = np.random.default_rng(0)
    portrait = _uniform(rng, 500, 1088, 1920)
    with pytest.raises(InputCheckError, match=r"^view 0 \(a\): \d+ % of the joints lie outside the declared 1920x1088 "
                                              r"image; .*: is the image 1088x1920 \(image_size\)\?$"):
        check_image_sizes(_table({0: portrait}), {0: (1920, 1088)}, ["a"])
    big = _uniform(rng, 500, 2560, 1440)
    with pytest.raises(InputCheckError, match=r"is the image 2560x1440 \(--image-size\)\?$"):
        check_image_sizes(_table({0: big}), {0: (1920, 1080)}, ["a"], "--image-size")
    huge = _uniform(rng, 500, 9000, 5000)
    with pytest.raises(InputCheckError, match=r"is the image at least 89\d\dx49\d\d \(image_size\)\?$"):
        check_image_sizes(_table({0: huge}), {0: (1920, 1080)}, ["a"])
    shifted = _uniform(rng, 500, 1920, 1080) - 600
    with pytest.raises(InputCheckError, match=r"are they pixels of this view's video, and is the image size right"):
        check_image_sizes(_table({0: shifted}), {0: (1920, 1080)}, ["a"])


def test_a_few_off_image_joints_pass_and_coverage_warnings():
    rng = np.random.default_rng(1)
    inside = _uniform(rng, 950, 1920, 1080)
    spill = np.c_[rng.uniform(1925, 2100, 50), rng.uniform(0, 1079, 50)]  # 5 %: trackers' extrapolations
    assert check_image_sizes(_table({0: np.r_[inside, spill]}), {0: (1920, 1080)}, ["a"]) == []
    landscape_in_portrait = _uniform(rng, 400, 1000, 1000)  # a landscape camera's people, left of x = 1000
    (warning,) = check_image_sizes(_table({0: landscape_in_portrait}), {0: (1088, 1920)}, ["a"])
    assert "% of the declared 1088x1920 image: is the image 1920x1088 (image_size)?" in warning
    quarter = _uniform(rng, 400, 900, 500)  # a half-size video declared at full size
    (warning,) = check_image_sizes(_table({0: quarter}), {0: (1920, 1080)}, ["a"])
    assert "within the top-left quarter of the declared 1920x1080 image: were the detections made on a smaller " \
           "video (image_size)?" in warning
    assert check_image_sizes(_table({0: quarter[:100]}), {0: (1920, 1080)}, ["a"]) == []  # too few to tell


# --- skeleton ----------------------------------------------------------------------------------------------------


def test_reinterpret_puts_body25b_joints_where_body25_reads_them():
    kp = np.full((1, 23, 2), np.nan)
    kp[0, JOINT_INDEX["left_eye"]] = (1.0, 2.0)  # BODY_25 index 16 read as left eye; BODY_25B's 16 is right ankle
    out = reinterpret(kp, "body25", "body25b")
    np.testing.assert_array_equal(out[0, JOINT_INDEX["right_ankle"]], (1.0, 2.0))
    assert np.isnan(out[0, JOINT_INDEX["left_eye"]]).all()


def _shelf_detections():
    from humancal.datasets.shelf import load_shelf
    from humancal.settings import DataRootError, dataset_dir

    try:
        root = dataset_dir("shelf_4dassoc")
    except DataRootError as err:
        pytest.skip(f"Shelf data not available: {err}")
    return load_shelf(root).detections


def test_shelf_openpose_detections_fit_body25_and_not_body25b(tmp_path):
    from humancal.formats import read_detections, write_openpose

    shelf = _shelf_detections()
    check_skeleton_fit(shelf, "body25", ["body25b"])  # real BODY_25: accepted
    spread, pairs = neighbour_spread(_dense(shelf), "body25")
    assert spread < 0.06 and pairs > 10_000
    folders = write_openpose(shelf, tmp_path / "op", skeleton="body25")  # the same people as OpenPose writes them
    as_b = read_detections(list(folders.values()), "openpose", sequence="s", image_size=(1032, 776),
                           skeleton="body25b")
    with pytest.raises(SkeletonMismatch, match=r"do not look like body25b: .* a median \d+ % of the person's size "
                                               r"apart, \d % when read as body25: is the skeleton body25 \(skeleton\)"):
        check_skeleton_fit(as_b, "body25b", ["body25"])


def _dense(table: pd.DataFrame) -> np.ndarray:
    from humancal.tables.detections import detections_to_dense

    return detections_to_dense(table).keypoints_px


def test_too_few_neighbour_pairs_decide_nothing():
    rng = np.random.default_rng(2)
    rows = [("s", f, 0, 0, joint, *rng.uniform(0, 500, 2), 0.9) for f in range(3) for joint in JOINT_INDEX]
    check_skeleton_fit(pd.DataFrame(rows, columns=COLUMNS), "body25")  # random joints, 24 pairs: no verdict


# --- views -------------------------------------------------------------------------------------------------------


def test_views_identical_empty_or_without_shared_frames():
    rng = np.random.default_rng(3)
    a = _uniform(rng, 30, 1920, 1080)
    with pytest.raises(InputCheckError, match=r"view 0 \(a\) and view 2 \(c\) hold identical detections"):
        check_views(_table({0: a, 1: a + 1, 2: a}), ["a", "b", "c"])
    with pytest.raises(InputCheckError, match=r"view 2 \(c\): no detection in any of its files"):
        check_views(_table({0: a, 1: a + 1}), ["a", "b", "c"])
    frames = {0: list(range(30)), 1: list(range(100, 130))}
    with pytest.raises(InputCheckError, match=r"view 0 \(a\): none of its frames \(0-29\) has detections in another "
                                              r"view \(frames 100-129\)"):
        check_views(_table({0: a, 1: a + 1}, frames), ["a", "b"])
    frames = {0: list(range(30)), 1: list(range(25, 55))}
    warnings = check_views(_table({0: a, 1: a + 1}, frames), ["a", "b"])
    assert warnings == [f"view {v} ({n}) shares only 5 frame(s) with the other views (25-29): the calibration needs "
                        "people seen by several views at once" for v, n in enumerate("ab")]


# --- the capture: option names, known cameras --------------------------------------------------------------------


def _write_views(root, sizes_and_offsets):
    import json

    from humancal.formats.skeletons import SKELETONS

    body25 = SKELETONS["body25"]
    folders = []
    for v, (dx, dy) in enumerate(sizes_and_offsets):
        folder = root / f"cam{v}"
        folder.mkdir(parents=True)
        for f in range(12):
            flat = np.zeros((25, 3))
            flat[body25.index("nose")] = (100.0 + dx + 3 * f, 50.0 + dy, 0.9)
            flat[body25.index("left_ankle")] = (100.0 + dx + 3 * f, 250.0 + dy, 0.9)
            (folder / f"cam{v}_{f:012d}_keypoints.json").write_text(json.dumps({"people": [
                {"pose_keypoints_2d": flat.ravel().tolist()}]}))
        folders.append(folder)
    return folders


def test_capture_messages_name_the_datasets_file_options_unless_told_otherwise(tmp_path):
    folders = _write_views(tmp_path, [(0, 1500), (10, 1500)])  # joints at y 1550-1750 in a "1920x1080" image
    config = CaptureConfig("openpose", tuple(folders), ((1920, 1080),) * 2, "body25")
    with pytest.raises(InputCheckError, match=r"is the image 1080x1920 \(image_size\)\?$"):
        load_capture(config, "s")
    with pytest.raises(InputCheckError, match=r"\(--image-size\)\?$"):
        load_capture(config, "s", option_names={"image_size": "--image-size"})
    single = CaptureConfig("openpose", (folders[0],), ((1920, 1080),), "body25")
    with pytest.raises(InputCheckError, match=r"^views: expected two views or more"):
        load_capture(single, "s")


def test_easymocap_known_cameras_take_the_views_image_size(tmp_path):
    from humancal.camera import Camera
    from humancal.formats import write_cameras

    folders = _write_views(tmp_path, [(0, 0), (10, 0)])
    cam = Camera(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.eye(3), np.array([0.0, 0.0, 3.0]), 640, 480)
    calib = write_cameras([cam, cam], tmp_path / "calib", "easymocap")
    config = CaptureConfig("openpose", tuple(folders), ((640, 480),) * 2, "body25", cameras=calib)
    capture = load_capture(config, "s")
    assert capture.known_cameras[["width_px", "height_px"]].values.tolist() == [[640, 480]] * 2
