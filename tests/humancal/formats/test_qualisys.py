"""Qualisys ``.qca.txt`` calibrations: hand-made files of known cameras read back, the axis convention on a camera
placed by hand, and bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humancal.camera import Camera
from humancal.camera.projection import project_points_np
from humancal.formats import FormatError, infer_camera_format, read_cameras, read_cameras_with_names, write_cameras

FLIP = np.diag([1.0, -1.0, -1.0])  # OpenCV camera axes <-> Qualisys camera axes (y up, z backwards)


def _n(x: float) -> str:
    return repr(float(x))


def _camera_xml(camera: Camera, serial: str, *, left: int = 0, top: int = 0, scale: float = 1.0,
                model: str = "Miqus Video") -> str:
    """One <camera> element holding ``camera`` as QTM writes it, by hand: the inverse of what the reader assumes.

    ``scale`` < 1: the video is the sensor's 1080p region shrunk to ``1080 * scale`` lines (``video_resolution``).
    """
    K, d = camera.K, camera.distortion
    width, height = round(camera.width_px / scale), round(camera.height_px / scale)
    fu, fv = K[0, 0] / scale * 64, K[1, 1] / scale * 64
    cu = ((K[0, 2] + 0.5) / scale - 0.5 + left) * 64
    cv = ((K[1, 2] + 0.5) / scale - 0.5 + top) * 64
    Q = FLIP @ camera.R_cam_from_world  # world -> Qualisys camera axes
    centre_mm = camera.center_world_m * 1000
    r = " ".join(f'r{i + 1}{j + 1}="{_n(Q[i, j])}"' for i in range(3) for j in range(3))
    resolution = f' video_resolution="{round(1080 * scale)}p"' if scale != 1 else ""
    return (
        f'<camera active="1" avg-residual="0.4" model="{model}" serial="{serial}" viewrotation="0"{resolution}>'
        f'<fov_marker left="0" top="0" right="4095" bottom="3071"/>'
        f'<fov_video left="{left}" top="{top}" right="{left + width - 1}" bottom="{top + height - 1}"/>'
        f'<transform x="{_n(centre_mm[0])}" y="{_n(centre_mm[1])}" z="{_n(centre_mm[2])}" {r}/>'
        f'<intrinsic focalLengthU="{_n(fu)}" focalLengthV="{_n(fv)}" centerPointU="{_n(cu)}" '
        f'centerPointV="{_n(cv)}" focallength="9.3" sensorMinU="0" sensorMaxU="{(width - 1) * 64}" sensorMinV="0" '
        f'sensorMaxV="{(height - 1) * 64}" skew="0" radialDistortion1="{_n(d[0] * 64)}" '
        f'radialDistortion2="{_n(d[1] * 64)}" radialDistortion3="{_n(d[4] * 64)}" '
        f'tangentalDistortion1="{_n(d[2] * 64)}" tangentalDistortion2="{_n(d[3] * 64)}"/></camera>'
    )


def _qca(path: Path, cameras_xml: list[str]) -> Path:
    path.write_text("<?xml version='1.0' encoding='ASCII'?>\n<calibration type=\"regular\"><results/><cameras>"
                    + "".join(cameras_xml) + "</cameras></calibration>\n")
    return path


def _camera(seed: int, width: int = 1920, height: int = 1080) -> Camera:
    rng = np.random.default_rng(seed)
    K = np.array([[1500.0 + 100 * rng.random(), 0.0, width / 2 + 10 * rng.normal()],
                  [0.0, 1500.0 + 100 * rng.random(), height / 2 + 10 * rng.normal()], [0.0, 0.0, 1.0]])
    R = Rotation.random(random_state=seed).as_matrix()
    d = np.array([-0.05, 0.1, 0.001, -0.0005, 0.002]) * rng.random()
    return Camera(K, R, rng.normal(size=3) * 2.0, width, height, d)


def test_known_cameras_read_back_with_crop_resolution_order_and_marker_cameras(tmp_path, cameras_close):
    a, b, c = _camera(0), _camera(1, 1088, 1920), _camera(2, 1280, 720)
    path = _qca(tmp_path / "Calib.qca.txt", [
        _camera_xml(c, "cam10", scale=720 / 1080),             # a 720p video of the 1080p region
        _camera_xml(a, "cam2"),
        _camera_xml(_camera(3), "28600", model="Oqus 700+"),   # a marker camera: not a view
        _camera_xml(b, "cam3", left=416, top=8),                # a portrait region of a larger sensor
    ])
    assert infer_camera_format(path) == "qualisys"
    cameras, names = read_cameras_with_names(path)
    assert names == ["cam2", "cam3", "cam10"]  # natural order of the serials
    cameras_close([a, b, c], cameras, atol=1e-9)


def test_axes_of_a_camera_placed_by_hand(tmp_path):
    # 4 m behind the origin along -y, 1.5 m up, looking along +y: its x axis is the world's x, its (Qualisys) y axis
    # the world's up, its z axis points back out of the lens (-y).
    xml = ('<camera serial="1" model="Miqus Video"><fov_video left="0" top="0" right="1919" bottom="1079"/>'
           '<transform x="0" y="-4000" z="1500" r11="1" r12="0" r13="0" r21="0" r22="0" r23="1" r31="0" r32="-1" '
           'r33="0"/><intrinsic focalLengthU="96000" focalLengthV="96000" centerPointU="61408" centerPointV="34528"/>'
           '</camera>')
    (camera,) = read_cameras(_qca(tmp_path / "one.qca.txt", [xml]))
    assert camera.K[0, 0] == 1500.0 and (camera.K[0, 2], camera.K[1, 2]) == (959.5, 539.5)
    np.testing.assert_allclose(camera.center_world_m, [0.0, -4.0, 1.5], atol=1e-12)
    points = np.array([[0.0, 0.0, 1.5], [0.0, 0.0, 2.5], [1.0, 0.0, 1.5]])  # ahead, 1 m higher, 1 m to the right
    uv, _ = project_points_np(points, camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m)
    np.testing.assert_allclose(uv, [[959.5, 539.5], [959.5, 539.5 - 375.0], [959.5 + 375.0, 539.5]], atol=1e-9)


@pytest.mark.parametrize(
    "text, needles",
    [
        ("<calibration><cameras>", ["valid XML"]),
        ("<calibration><cameras/></calibration>", ["field 'calibration.cameras'", "<camera> elements"]),
        ('<calibration><cameras><camera serial="1" model="Oqus 7+"/></cameras></calibration>',
         ["field 'camera.model'", "video cameras", "['Oqus 7+']"]),
        ('<calibration><cameras><camera serial="c1" model="none"><fov_video left="0" top="0" right="9" bottom="9"/>'
         '<intrinsic focalLengthU="6400" focalLengthV="6400" centerPointU="x" centerPointV="0"/></camera>'
         "</cameras></calibration>", ["field 'camera[c1].intrinsic.centerPointU'", "a finite number", "got x"]),
        ('<calibration><cameras><camera serial="c1" model="none"><fov_video left="0" top="0" right="9" bottom="9"/>'
         '<intrinsic focalLengthU="6400" focalLengthV="6400" centerPointU="0" centerPointV="0"/></camera>'
         "</cameras></calibration>", ["field 'camera[c1].transform'", "the field is required"]),
        ('<calibration><cameras><camera serial="c1" model="none"><fov_video left="0" top="0" right="9" bottom="9"/>'
         '<intrinsic focalLengthU="6400" focalLengthV="6400" centerPointU="0" centerPointV="0" skew="2"/>'
         '<transform x="0" y="0" z="0" r11="1" r12="0" r13="0" r21="0" r22="1" r23="0" r31="0" r32="0" r33="1"/>'
         "</camera></cameras></calibration>", ["field 'camera[c1].intrinsic.skew'", "skewed pixels"]),
        ('<calibration><cameras><camera serial="c1" model="none"><fov_video left="0" top="0" right="9" bottom="9"/>'
         '<intrinsic focalLengthU="6400" focalLengthV="6400" centerPointU="0" centerPointV="0"/>'
         '<transform x="0" y="0" z="0" r11="1" r12="0" r13="0" r21="0" r22="1" r23="0" r31="0" r32="0" r33="2"/>'
         "</camera></cameras></calibration>", ["field 'camera[c1].transform'", "a rotation matrix"]),
    ],
)
def test_bad_files_name_the_camera_and_field(tmp_path, text, needles):
    path = tmp_path / "bad.qca.txt"
    path.write_text(text)
    with pytest.raises(FormatError) as err:
        read_cameras(path)
    for needle in needles:
        assert needle in str(err.value)


def test_qualisys_is_read_only(tmp_path):
    with pytest.raises(FormatError, match=r"one of \[.*'colmap'\] \(qualisys: read only\)"):
        write_cameras([_camera(0)], tmp_path / "out.qca.txt", "qualisys")
