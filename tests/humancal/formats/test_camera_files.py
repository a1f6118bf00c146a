"""Camera readers and writers: round trips, fixtures mimicking each tool's files, dispatch, atomic writes."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from humancal.camera import Camera
from humancal.formats import (
    CAMERA_FORMATS,
    FormatError,
    infer_camera_format,
    read_cameras,
    read_cameras_with_names,
    write_cameras,
)
from humancal.formats.cameras import read_colmap_text, read_easymocap, read_toml_calibration

TARGETS = {
    "humancal": "cams.json",
    "shelf": "calibration.json",
    "pose2sim": "Calib.toml",
    "anipose": "calibration.toml",
    "easymocap": "easymocap",
    "colmap": "sparse",
}
READ_OPTIONS = {"easymocap": {"image_size": [(1920, 1080), (1910, 1080), (1900, 1080)]}}


def _without_distortion(cameras: list[Camera]) -> list[Camera]:
    return [Camera(c.K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px) for c in cameras]


@pytest.mark.parametrize("fmt", CAMERA_FORMATS)
def test_round_trip(tmp_path, fmt, cameras, cameras_close):
    cams = _without_distortion(cameras) if fmt == "shelf" else cameras
    written = write_cameras(cams, tmp_path / TARGETS[fmt], fmt)
    back = read_cameras(written, fmt, **READ_OPTIONS.get(fmt, {}))
    cameras_close(cams, back, atol=1e-9)
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.parametrize("fmt", ["humancal", "pose2sim", "anipose", "easymocap", "colmap"])
def test_names_round_trip_and_format_is_inferred(tmp_path, fmt, cameras):
    names = ["left", "mid-1", "right_2"]
    written = write_cameras(cameras, tmp_path / TARGETS[fmt], fmt, names=names)
    inferred = infer_camera_format(written)
    assert inferred == ("pose2sim" if fmt == "anipose" else fmt)
    _, got = read_cameras_with_names(written, **READ_OPTIONS.get(fmt, {}))
    assert got == names


def test_length_unit_scales_translations(tmp_path, cameras, cameras_close):
    path = write_cameras(cameras, tmp_path / "a.toml", "anipose", length_unit_m=0.001)
    text = path.read_text()
    assert "[cam_0]" in text and "[cam_2]" in text
    back = read_cameras(path, "anipose", length_unit_m=0.001)
    cameras_close(cameras, back, atol=1e-9)
    raw = read_cameras(path, "anipose")
    np.testing.assert_allclose(raw[0].t_cam_from_world_m, 1000 * cameras[0].t_cam_from_world_m)


# --- fixtures written the way each tool writes them ----------------------------------------------------------------

SHELF_TEXT = """{
\t"0":
\t{
\t\t"K" : [ 1.0635121e+03, 0.0, 5.1173825e+02, 0.0, 1.0718636e+03, 3.5008829e+02, 0.0, 0.0, 1.0 ],
\t\t"RT" : [ 0.65097713, -0.7587173, 0.02402735, -0.5942785,
\t\t\t-0.01886197, -0.04781039, -0.99867845, 0.9719739,
\t\t\t0.758863, 0.649664, -0.045434, 2.624511 ],
\t\t"imgSize" : [ 1032, 776 ]
\t},
\t"1":
\t{
\t\t"K" : [ 1000.0, 0.0, 500.0, 0.0, 1000.0, 400.0, 0.0, 0.0, 1.0 ],
\t\t"RT" : [ 1.0, 0.0, 0.0, 0.1, 0.0, 1.0, 0.0, 0.2, 0.0, 0.0, 1.0, 3.0 ],
\t\t"imgSize" : [ 1032, 776 ]
\t}
}
"""


def test_shelf_fixture(tmp_path):
    path = tmp_path / "calibration.json"
    path.write_text(SHELF_TEXT)
    cams, names = read_cameras_with_names(path)
    assert names == ["0", "1"]
    np.testing.assert_allclose(cams[0].K[0], [1063.5121, 0.0, 511.73825])
    np.testing.assert_allclose(cams[0].R_cam_from_world[1], [-0.01886197, -0.04781039, -0.99867845])
    np.testing.assert_allclose(cams[0].t_cam_from_world_m, [-0.5942785, 0.9719739, 2.624511])
    assert (cams[0].width_px, cams[0].height_px) == (1032, 776)
    np.testing.assert_allclose(cams[1].center_world_m, [-0.1, -0.2, -3.0])
    assert not cams[0].distortion.any()


POSE2SIM_TEXT = """[int_cam01_img]
name = "int_cam01_img"
size = [ 1088.0, 1920.0]
matrix = [ [ 1677.1, 0.0, 543.8], [ 0.0, 1678.9, 962.5], [ 0.0, 0.0, 1.0]]
distortions = [ -0.0015, 0.0234, -0.0016, 0.0003]
rotation = [ 1.4587, -1.3281, 0.8516]
translation = [ 0.1157, 0.8543, 3.6617]
fisheye = false

[int_cam02_img]
name = "int_cam02_img"
size = [ 1088.0, 1920.0]
matrix = [ [ 1681.5, 0.0, 540.4], [ 0.0, 1680.2, 960.8], [ 0.0, 0.0, 1.0]]
distortions = [ 0.0, 0.0, 0.0, 0.0]
rotation = [ 0.0, 0.0, 0.0]
translation = [ 0.0, 0.0, 2.0]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""


def test_pose2sim_fixture(tmp_path):
    path = tmp_path / "Calib_board.toml"
    path.write_text(POSE2SIM_TEXT)
    cams, names = read_cameras_with_names(path)
    assert names == ["int_cam01_img", "int_cam02_img"]
    assert (cams[0].width_px, cams[0].height_px) == (1088, 1920)
    np.testing.assert_allclose(cams[0].distortion, [-0.0015, 0.0234, -0.0016, 0.0003, 0.0])
    angle = np.linalg.norm([1.4587, -1.3281, 0.8516])
    assert np.degrees(np.arccos((np.trace(cams[0].R_cam_from_world) - 1) / 2)) == pytest.approx(np.degrees(angle))
    np.testing.assert_allclose(cams[1].R_cam_from_world, np.eye(3))
    np.testing.assert_allclose(cams[1].t_cam_from_world_m, [0.0, 0.0, 2.0])


ANIPOSE_TEXT = """[cam_0]
name = "A"
size = [ 1280, 1024,]
matrix = [ [ 1400.0, 0.0, 640.0,], [ 0.0, 1400.0, 512.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.2, 0.1, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 10.0, -20.0, 1500.0,]

[metadata]
"""


def test_anipose_fixture_in_millimetres(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TEXT)
    cams, names = read_cameras_with_names(path, "anipose", length_unit_m=0.001)
    assert names == ["A"]
    np.testing.assert_allclose(cams[0].t_cam_from_world_m, [0.01, -0.02, 1.5])
    np.testing.assert_allclose(cams[0].distortion, [-0.2, 0.1, 0.0, 0.0, 0.0])


INTRI_TEXT = """%YAML:1.0
---
names:
   - "01"
   - "02"
K_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.1251203466308606e+03, 0., 5.1187579174810379e+02, 0.,
       1.1262440195315155e+03, 3.8493431838768848e+02, 0., 0., 1. ]
dist_01: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -2.4e-01, 1.9e-01, 1.0e-03, -2.0e-03, 0. ]
K_02: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1000., 0., 500., 0., 1000., 400., 0., 0., 1. ]
dist_02: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
"""

EXTRI_TEXT = """%YAML:1.0
---
names:
   - "01"
   - "02"
R_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 0., 1.5707963267948966 ]
Rot_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0., -1., 0., 1., 0., 0., 0., 0., 1. ]
T_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 1.0, 2.0, 3.0 ]
R_02: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 0., 0. ]
T_02: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 0., 4. ]
"""


def _easymocap_fixture(folder: Path, intri: str = INTRI_TEXT, extri: str = EXTRI_TEXT) -> Path:
    folder.mkdir(exist_ok=True)
    (folder / "intri.yml").write_text(intri)
    (folder / "extri.yml").write_text(extri)
    return folder


def test_easymocap_fixture(tmp_path):
    folder = _easymocap_fixture(tmp_path / "calib")
    cams, names = read_cameras_with_names(folder / "extri.yml", image_size={"01": (1024, 768), "02": (1000, 800)})
    assert names == ["01", "02"]
    np.testing.assert_allclose(cams[0].K[0, 0], 1125.1203466308606)
    np.testing.assert_allclose(cams[0].distortion, [-0.24, 0.19, 0.001, -0.002, 0.0])
    np.testing.assert_allclose(cams[0].R_cam_from_world, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(cams[1].R_cam_from_world, np.eye(3))  # R_ only, no Rot_
    np.testing.assert_allclose(cams[1].t_cam_from_world_m, [0, 0, 4])
    assert (cams[1].width_px, cams[1].height_px) == (1000, 800)
    written = write_cameras(cams, tmp_path / "out", "easymocap", names=names)
    assert (written / "intri.yml").read_text().startswith("%YAML:1.0\n---\nnames:\n   - \"01\"\n")
    assert "Rot_02: !!opencv-matrix" in (written / "extri.yml").read_text()


COLMAP_CAMERAS = """# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
1 SIMPLE_RADIAL 3072 2304 2559.81 1536 1152 -0.0204
2 PINHOLE 1920 1080 1500.5 1501.5 960.5 540.5
"""

COLMAP_IMAGES = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 2, mean observations per image: 1
7 1 0 0 0 0.5 0.25 4 2 cam_b.jpg
2362.39 248.498 58396
3 0.7071067811865476 0 0 0.7071067811865476 -1 2 3 1 cam_a.jpg

"""


def _colmap_fixture(folder: Path, cameras: str = COLMAP_CAMERAS, images: str = COLMAP_IMAGES) -> Path:
    folder.mkdir(exist_ok=True)
    (folder / "cameras.txt").write_text(cameras)
    (folder / "images.txt").write_text(images)
    (folder / "points3D.txt").write_text("")
    return folder


def test_colmap_fixture(tmp_path):
    cams, names = read_cameras_with_names(_colmap_fixture(tmp_path / "sparse"))
    assert names == ["cam_a.jpg", "cam_b.jpg"]  # IMAGE_ID order
    np.testing.assert_allclose(cams[0].K, [[2559.81, 0, 1535.5], [0, 2559.81, 1151.5], [0, 0, 1]])  # half-pixel shift
    np.testing.assert_allclose(cams[0].distortion, [-0.0204, 0, 0, 0, 0])
    np.testing.assert_allclose(cams[0].R_cam_from_world, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(cams[1].K, [[1500.5, 0, 960], [0, 1501.5, 540], [0, 0, 1]])
    np.testing.assert_allclose(cams[1].t_cam_from_world_m, [0.5, 0.25, 4])
    unshifted = read_colmap_text(tmp_path / "sparse" / "cameras.txt", half_pixel_shift=False)[0]
    assert unshifted[1].K[0, 2] == 960.5


# --- dispatch and atomic writes ------------------------------------------------------------------------------------


def test_unknown_format_lists_known_ones(tmp_path, cameras):
    known = r"field 'format': expected one of \['humancal', 'shelf', .*'colmap'\], got 'opencv'"
    with pytest.raises(FormatError, match=known):
        write_cameras(cameras, tmp_path / "x.yml", "opencv")
    with pytest.raises(FormatError, match="one of"):
        read_cameras(tmp_path, "bundler")
    (tmp_path / "cams.xml").write_text("<x/>")
    with pytest.raises(FormatError, match=r"cams.xml: expected a camera file whose format can be told from its name, "
                                          r"or its format named \(one of \[.*'qualisys'\]\)"):
        read_cameras(tmp_path / "cams.xml")
    (tmp_path / "other.json").write_text('{"cameras": []}')
    with pytest.raises(FormatError, match="other.json"):
        read_cameras(tmp_path / "other.json")
    with pytest.raises(FileNotFoundError):
        read_cameras(tmp_path / "missing.json")


def test_failed_write_leaves_the_previous_file_and_no_temporary(tmp_path, cameras, monkeypatch):
    path = write_cameras(cameras, tmp_path / "cams.json", "humancal")
    before = path.read_text()

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        write_cameras(cameras[:1], path, "humancal")
    monkeypatch.undo()
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cams.json"]


def test_invalid_cameras_are_refused_before_any_file_is_written(tmp_path, cameras):
    with pytest.raises(FormatError, match="zero distortion"):
        write_cameras(cameras, tmp_path / "calibration.json", "shelf")
    skewed = [Camera(np.array([[1000.0, 2.0, 500], [0, 1000, 400], [0, 0, 1]]), np.eye(3), np.zeros(3), 1000, 800)]
    with pytest.raises(FormatError, match="zero skew"):
        write_cameras(skewed, tmp_path / "sparse", "colmap")
    with pytest.raises(FormatError, match="distinct camera names"):
        write_cameras(cameras, tmp_path / "c.toml", "pose2sim", names=["a", "a", "b"])
    with pytest.raises(FormatError, match="names matching"):
        write_cameras(cameras, tmp_path / "em", "easymocap", names=["a b", "c", "d"])
    with pytest.raises(FormatError, match="Shelf calibration keys cameras by index"):
        write_cameras(_without_distortion(cameras), tmp_path / "calibration.json", "shelf", names=["a", "b", "c"])
    assert list(tmp_path.iterdir()) == []


def test_toml_writer_keeps_k3_and_reader_refuses_fisheye(tmp_path, cameras):
    text = write_cameras(cameras, tmp_path / "c.toml", "pose2sim").read_text()
    lines = [line for line in text.splitlines() if line.startswith("distortions")]
    assert [len(line.split(",")) for line in lines] == [4, 4, 5]  # 4 numbers unless k3 != 0
    (tmp_path / "f.toml").write_text(text.replace("fisheye = false", "fisheye = true", 1))
    expected = r"f.toml: field 'cam_00.fisheye': expected false \(fisheye distortion is not supported\)"
    with pytest.raises(FormatError, match=expected):
        read_toml_calibration(tmp_path / "f.toml")


def test_easymocap_needs_image_size(tmp_path):
    folder = _easymocap_fixture(tmp_path / "calib")
    with pytest.raises(FormatError, match="image_size=.*not in this file"):
        read_easymocap(folder)
    with pytest.raises(FormatError, match="none for \\['02'\\]"):
        read_easymocap(folder, image_size={"01": (10, 10)})


def test_json_numbers_are_exact(tmp_path, cameras):
    path = write_cameras(cameras, tmp_path / "cams.json", "humancal")
    data = json.loads(path.read_text())
    assert data["format"] == "humancal.cameras" and data["version"] == 1
    assert data["cameras"][0]["K"][0][0] == cameras[0].K[0, 0]
    assert set(data["convention"]) == {"world", "camera", "extrinsics", "intrinsics", "distortion"}
