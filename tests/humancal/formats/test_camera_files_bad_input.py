"""Every camera reader on broken files: one-line FormatError naming the file, the field and the expectation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from humancal.formats import FormatError, read_cameras, write_cameras

NOT_A_ROTATION = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def _raises(path: Path, field: str | None, expected: str, fmt: str | None = None, **options) -> str:
    with pytest.raises(FormatError) as excinfo:
        read_cameras(path, fmt, **options)
    message = str(excinfo.value)
    assert "\n" not in message
    assert path.name in message, message
    if field is not None:
        assert f"field '{field}'" in message, message
    assert expected in message, message
    return message


# --- Shelf calibration.json ----------------------------------------------------------------------------------------


def _shelf(tmp_path: Path, edit) -> Path:
    cam = {
        "K": [1000.0, 0, 500, 0, 1000, 400, 0, 0, 1],
        "RT": [1.0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3],
        "imgSize": [1032, 776],
    }
    data = {"0": dict(cam), "1": dict(cam)}
    edit(data)
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "edit, field, expected",
    [
        (lambda d: d["1"].pop("RT"), "1.RT", "the field is required"),
        (lambda d: d["1"].update(RT=[1.0] * 9), "1.RT", "12 numbers"),
        (lambda d: d["0"].update(K=[1000.0, 0, 500, 0, float("nan"), 400, 0, 0, 1]), "0.K", "finite numbers"),
        (lambda d: d["0"].update(RT=[1.0, 0.1, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3]), "0.RT", "a rotation matrix"),
        (lambda d: d["0"].update(imgSize=[1032]), "0.imgSize", "[width, height]"),
        (lambda d: d["0"].update(K=[1000.0, 0, 500, 0, 1000, 400, 0, 0, 2]), "0.K", "[0, 0, 1]"),
        (lambda d: d.update({"5": d.pop("1")}), None, "camera keys ['0', '1']"),
    ],
)
def test_shelf(tmp_path, edit, field, expected):
    _raises(_shelf(tmp_path, edit), field, expected, "shelf")


def test_shelf_truncated(tmp_path):
    path = _shelf(tmp_path, lambda d: None)
    path.write_text(path.read_text()[:40])
    _raises(path, None, "valid JSON", "shelf")


# --- humancal JSON -------------------------------------------------------------------------------------------------


def _humancal(tmp_path: Path, cameras, edit) -> Path:
    path = write_cameras(cameras, tmp_path / "cams.json", "humancal")
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "edit, field, expected",
    [
        (lambda d: d.update(format="other"), "format", "'humancal.cameras'"),
        (lambda d: d.update(version=2), "version", "1 (files of other versions"),
        (lambda d: d["convention"].update(world="Y up"), "convention", "the version-1 convention"),
        (lambda d: d["cameras"][1].pop("K"), "cameras[1].K", "the field is required"),
        (lambda d: d["cameras"][0].update(R_cam_from_world=NOT_A_ROTATION), "cameras[0].R_cam_from_world", "orthonorm"),
        (lambda d: d["cameras"][0].update(t_cam_from_world_m=[0.0, 1.0]), "cameras[0].t_cam_from_world_m", "3 numbers"),
        (lambda d: d["cameras"][0].update(distortion=[0.0] * 4), "cameras[0].distortion", "5 distortion numbers"),
        (lambda d: d["cameras"][0].update(width_px=-5), "cameras[0].width_px/height_px", "positive integers"),
        (lambda d: d["cameras"][2].update(name="cam_00"), "cameras[].name", "distinct camera names"),
        (lambda d: d.update(cameras=[]), "cameras", "non-empty list"),
    ],
)
def test_humancal_json(tmp_path, cameras, edit, field, expected):
    _raises(_humancal(tmp_path, cameras, edit), field, expected, "humancal")


def test_humancal_json_truncated(tmp_path, cameras):
    path = write_cameras(cameras, tmp_path / "cams.json", "humancal")
    path.write_text(path.read_text()[:-30])
    _raises(path, None, "valid JSON", "humancal")


# --- Pose2Sim / anipose TOML ---------------------------------------------------------------------------------------


def _toml(tmp_path: Path, cameras, old: str, new: str) -> Path:
    path = write_cameras(cameras, tmp_path / "calib.toml", "pose2sim")
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    "old, new, field, expected",
    [
        ("fisheye = false", 'fisheye = false\nsize = [1, 2]', None, "valid TOML"),  # duplicate key
        ("name = \"cam_01\"\nsize", "name = \"cam_01\"\nsizes", "cam_01.size", "the field is required"),
        ("rotation = [", "rotation = [ 1.0,", "cam_00.rotation", "3 numbers"),
        ("translation = [", "translation = [ nan, 1.0, 2.0] #", "cam_00.translation", "finite numbers"),
        ("distortions = [", "distortions = [ 0.0, 0.0, 0.0, ", "cam_00.distortions", "4 or 5 distortion numbers"),
        ("matrix = [", "matrix = [ [ 1.0, 2.0], ", "cam_00.matrix", "3x3 intrinsic matrix"),
        ("size = [", 'size = [ "wide", ', "cam_00.size", "[width, height]"),
    ],
)
def test_toml(tmp_path, cameras, old, new, field, expected):
    _raises(_toml(tmp_path, cameras, old, new), field, expected)


def test_toml_truncated_and_empty(tmp_path, cameras):
    path = write_cameras(cameras, tmp_path / "calib.toml", "pose2sim")
    text = path.read_text()
    path.write_text(text[: text.index("matrix") + 12])
    _raises(path, None, "valid TOML")
    path.write_text("[metadata]\nadjusted = false\n")
    _raises(path, None, "at least one camera table")


# --- EasyMocap YAML ------------------------------------------------------------------------------------------------


def _easymocap(tmp_path: Path, cameras, which: str, old: str, new: str) -> Path:
    folder = write_cameras(cameras, tmp_path / "calib", "easymocap", names=["a", "b", "c"])
    path = folder / which
    text = path.read_text()
    assert old in text, text
    path.write_text(text.replace(old, new, 1))
    return path


SIZE = {"image_size": (1920, 1080)}


@pytest.mark.parametrize(
    "which, old, new, field, expected",
    [
        ("intri.yml", "K_b: !!opencv-matrix", "Kb: !!opencv-matrix", "K_b", "an !!opencv-matrix node"),
        ("intri.yml", "dist_a: !!opencv-matrix\n   rows: 1\n   cols: 5",
         "dist_a: !!opencv-matrix\n   rows: 1\n   cols: 3", "dist_a", "rows x cols"),  # fmt: skip
        ("extri.yml", "T_c: !!opencv-matrix", "T_c: 3.0\nX_c: !!opencv-matrix", "T_c", "an !!opencv-matrix node"),
        ("extri.yml", "names:", "nomes:", "names", "a non-empty list of camera names"),
        ("extri.yml", "Rot_a: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ ",
         "Rot_a: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 0.5, ",
         "Rot_a", "rows x cols"),  # fmt: skip
    ],
)
def test_easymocap(tmp_path, cameras, which, old, new, field, expected):
    path = _easymocap(tmp_path, cameras, which, old, new)
    _raises(path, field, expected, "easymocap", **SIZE)


def test_easymocap_rotation_checks(tmp_path, cameras):
    folder = write_cameras(cameras, tmp_path / "calib", "easymocap", names=["a", "b", "c"])
    extri = folder / "extri.yml"
    text = extri.read_text()
    start = text.index("Rot_a:")
    data_at = text.index("data: [", start) + len("data: [")
    end = text.index("]", data_at)
    extri.write_text(text[:data_at] + " 1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0 " + text[end:])
    _raises(extri, "Rot_a", "a rotation matrix", "easymocap", **SIZE)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # a rotation, but not the one of R_a
    extri.write_text(text[:data_at] + " " + ", ".join(map(str, R.ravel())) + " " + text[end:])
    _raises(extri, "Rot_a", "the rotation of R_a", "easymocap", **SIZE)


def test_easymocap_truncated_and_missing(tmp_path, cameras):
    folder = write_cameras(cameras, tmp_path / "calib", "easymocap")
    intri = folder / "intri.yml"
    text = intri.read_text()
    intri.write_text(text[: text.index("data: [") + 12])
    _raises(intri, None, "an OpenCV YAML file", "easymocap", **SIZE)
    intri.write_text("")
    _raises(intri, None, "an OpenCV YAML file", "easymocap", **SIZE)
    intri.unlink()
    with pytest.raises(FileNotFoundError):
        read_cameras(folder, "easymocap", **SIZE)


# --- COLMAP --------------------------------------------------------------------------------------------------------


def _colmap(tmp_path: Path, cameras, which: str, old: str, new: str) -> Path:
    folder = write_cameras(cameras, tmp_path / "sparse", "colmap")
    path = folder / which
    text = path.read_text()
    assert old in text, text
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    "which, old, new, field, expected",
    [
        ("cameras.txt", "1 OPENCV", "1 THIN_PRISM_FISHEYE", "line 4 MODEL", "one of ['SIMPLE_PINHOLE'"),
        ("cameras.txt", "2 OPENCV 1910 1080 ", "2 OPENCV 1910 1080 1.0 ", "line 5 PARAMS", "8 numbers for OPENCV"),
        ("cameras.txt", "3 FULL_OPENCV 1900 1080", "3 FULL_OPENCV 1900 x", "line 6 HEIGHT", "an integer"),
        ("images.txt", "1 cam_00", "9 cam_00", "line 5 CAMERA_ID", "one of the ids of cameras.txt"),
        ("images.txt", "\n2 ", "\n2 nan ", "line 7 QW", "a finite number"),
        ("images.txt", "\n3 ", "\n3 0.5 ", "line 9 CAMERA_ID", "an integer"),
        ("images.txt", " 3 cam_02", " cam_02", "line 9", "'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME'"),
    ],
)
def test_colmap(tmp_path, cameras, which, old, new, field, expected):
    path = _colmap(tmp_path, cameras, which, old, new)
    _raises(path, field, expected, "colmap")


def test_colmap_non_unit_quaternion_and_missing_points_line(tmp_path, cameras):
    folder = write_cameras(cameras, tmp_path / "sparse", "colmap")
    images = folder / "images.txt"
    lines = images.read_text().splitlines()
    header = lines[4].split()
    header[1] = str(float(header[1]) * 1.1)
    images.write_text("\n".join([*lines[:4], " ".join(header), *lines[5:]]) + "\n")
    _raises(images, "line 5 QW QX QY QZ", "a unit quaternion", "colmap")
    images.write_text("\n".join([*lines[:4], lines[4], lines[6]]) + "\n")  # points line of image 1 left out
    _raises(images, "line 6", "the 2D points line of the image on line 5", "colmap")


def test_colmap_truncated(tmp_path, cameras):
    folder = write_cameras(cameras, tmp_path / "sparse", "colmap")
    path = folder / "cameras.txt"
    text = path.read_text()
    path.write_text(text[: text.index("1 OPENCV") + 12])
    _raises(path, "line 4", "'CAMERA_ID MODEL WIDTH HEIGHT PARAMS...'", "colmap")
