"""Qualisys calibration ``.qca.txt`` (XML written by Qualisys Track Manager; the calibration Pose2Sim's demos ship).

Read only. The file, as this reader understands it::

    <calibration ...>
      <cameras>
        <camera serial="cam01" model="Miqus Video" viewrotation="0" [video_resolution="720p"] ...>
          <fov_marker left=".." top=".." right=".." bottom=".."/>        (ignored: the marker mode's region)
          <fov_video left="0" top="0" right="1087" bottom="1919"/>      sensor pixels, bounds included
          <transform x=".." y=".." z=".." r11=".." r12=".." ... r33=".."/>
          <intrinsic focalLengthU=".." focalLengthV=".." centerPointU=".." centerPointV=".." skew="0"
                     radialDistortion1=".." radialDistortion2=".." radialDistortion3=".."
                     tangentalDistortion1=".." tangentalDistortion2=".." focallength="9.3" sensorMinU=".." .../>
        </camera> ...

(also inside ``<QTM_Parameters_Ver_...>``, as QTM's real-time protocol sends it). What is assumed, following
Pose2Sim's own converter (``calib_qca_to_toml``):

* **Which cameras.** The video cameras: a ``model`` containing "video" (``Miqus Video``, ``Miqus Video
  UnderWater``) or ``none`` (files written by Pose2Sim); marker-only cameras are skipped. They are put in natural
  order of their ``serial`` (``cam2`` before ``cam10``), which is the view order; the names are the serials.
* **Image size.** ``fov_video`` is the recorded region of the sensor, in sensor pixels with both bounds included:
  ``width = right - left + 1`` (1088 for ``0..1087``; Pose2Sim's older converter wrote ``right - left``). A
  ``video_resolution="<N>p"`` attribute scales everything by ``N / 1080`` (the sensor's pixels are those of the
  1080p mode, as Pose2Sim assumes); sizes are rounded to whole pixels.
* **Intrinsics.** ``focalLength*`` and ``centerPoint*`` are in 1/64 sensor pixels: ``f = focalLengthU / 64``;
  the principal point is taken relative to the recorded region, ``cx = centerPointU / 64 - left``. With a scale
  ``s`` (above), ``f * s`` and ``(cx + 0.5) * s - 0.5`` (pixel centres at integers in both images; Pose2Sim
  scales ``cx`` without the half pixel, 0.17 px apart at 720p). A non-zero ``skew`` is refused.
* **Distortion.** ``(k1, k2, p1, p2, k3) = (radialDistortion1, radialDistortion2, tangentalDistortion1,
  tangentalDistortion2, radialDistortion3) / 64``, Pose2Sim's reading (which drops k3). Qualisys does not publish
  the model; the coefficients only matter for evaluation (known cameras never reach the method).
* **Extrinsics.** ``x, y, z`` is the camera centre in the world, millimetres. The matrix ``Q`` with rows
  ``(r11, r12, r13)``, ``(r21, r22, r23)``, ``(r31, r32, r33)`` maps world directions to Qualisys's camera axes
  (x right, y up, z out of the back of the camera); OpenCV's camera has y down and z forward, so
  ``R_cam_from_world = diag(1, -1, -1) Q`` and ``t_cam_from_world_m = -R_cam_from_world C_mm / 1000``.
  Equivalently, the file holds the camera's orientation (camera -> world, ``Q^T``) column by column. This is
  Pose2Sim's conversion (its ``world_to_camera_persp`` then a half turn about x); with it the cameras of Pose2Sim's
  demo calibration look at the capture volume with the world's up at the top of the image. QTM's world is Z up by
  default, as humancal's.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from humancal.camera import Camera, CameraRig, intrinsic_matrix
from humancal.formats.cameras._checks import make_camera
from humancal.formats.errors import FormatError, missing_field

__all__ = ["SUBPIXELS_PER_PIXEL", "read_qualisys_calibration"]

SUBPIXELS_PER_PIXEL = 64.0
"""Qualisys's intrinsics are in 1/64 sensor pixels."""

OPENCV_FROM_QUALISYS_CAMERA = np.diag([1.0, -1.0, -1.0])
"""Qualisys camera axes (x right, y up, z backwards) to OpenCV's (x right, y down, z forwards)."""

_INTRINSIC = ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV")
_DISTORTION = ("radialDistortion1", "radialDistortion2", "tangentalDistortion1", "tangentalDistortion2",
               "radialDistortion3")
_TRANSFORM = ("x", "y", "z", "r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33")
_FOV = ("left", "top", "right", "bottom")


def read_qualisys_calibration(path: str | Path) -> tuple[CameraRig, list[str]]:
    """Read the video cameras of a Qualisys ``.qca.txt`` calibration (module docstring: what is assumed).

    Args:
        path: the ``.qca.txt`` file.

    Returns:
        cameras: the rig (world -> camera, metres, OpenCV pixels), views in natural order of their serials.
        names: the serials.

    Raises:
        FileNotFoundError: no such file.
        FormatError: not XML; no ``cameras/camera``; no video camera; a missing or non-numeric attribute
            (``camera[cam01].intrinsic.focalLengthU``); a non-zero skew; a ``transform`` that is not a rotation;
            duplicate serials.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        root = ET.fromstring(path.read_bytes())
    except ET.ParseError as err:
        raise FormatError(path, None, "valid XML (a Qualisys calibration)", str(err)) from None
    calibration = root if root.tag == "calibration" else root.find(".//calibration")
    found = [] if calibration is None else calibration.findall("cameras/camera")
    if not found:
        raise FormatError(path, "calibration.cameras", "<camera> elements inside <calibration><cameras>", "none")
    video = [c for c in found if _is_video(c.get("model"))]
    if not video:
        models = sorted({str(c.get("model")) for c in found})
        raise FormatError(path, "camera.model", "video cameras (a model with 'Video' in its name, or 'none')", models)
    serials = [c.get("serial") or f"#{i}" for i, c in enumerate(video)]
    if len(set(serials)) != len(serials):
        raise FormatError(path, "camera.serial", "distinct serials", serials)
    order = sorted(range(len(video)), key=lambda i: _natural_key(serials[i]))
    cameras = [_camera(video[i], serials[i], path) for i in order]
    return CameraRig.from_cameras(cameras), [serials[i] for i in order]


def _is_video(model: str | None) -> bool:
    return model is None or model.strip().lower() == "none" or "video" in model.lower()


def _natural_key(text: str) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", text)]


def _numbers(element: ET.Element | None, names: tuple[str, ...], path: Path, field: str,
             default: float | None = None) -> dict[str, float]:
    """The named attributes of ``element`` as finite floats (``default`` for missing ones when given)."""
    if element is None:
        raise missing_field(path, field)
    out = {}
    for name in names:
        text = element.get(name)
        if text is None and default is not None:
            out[name] = default
            continue
        if text is None:
            raise missing_field(path, f"{field}.{name}")
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not np.isfinite(value):
            raise FormatError(path, f"{field}.{name}", "a finite number", text)
        out[name] = value
    return out


def _scale(camera: ET.Element, path: Path, field: str) -> float:
    """The video's size over the sensor's 1080p mode, from ``video_resolution="<N>p"`` (1 when absent)."""
    text = camera.get("video_resolution")
    if text is None:
        return 1.0
    match = re.fullmatch(r"\s*(\d+)\s*[pP]\s*", text)
    if not match or int(match.group(1)) == 0:
        raise FormatError(path, f"{field}.video_resolution", "a video height such as '1080p' or '720p'", text)
    return int(match.group(1)) / 1080.0


def _camera(camera: ET.Element, serial: str, path: Path) -> Camera:
    field = f"camera[{serial}]"
    fov = _numbers(camera.find("fov_video"), _FOV, path, f"{field}.fov_video")
    intrinsic = _numbers(camera.find("intrinsic"), _INTRINSIC, path, f"{field}.intrinsic")
    distortion = _numbers(camera.find("intrinsic"), _DISTORTION, path, f"{field}.intrinsic", default=0.0)
    skew = _numbers(camera.find("intrinsic"), ("skew",), path, f"{field}.intrinsic", default=0.0)["skew"]
    transform = _numbers(camera.find("transform"), _TRANSFORM, path, f"{field}.transform")
    if skew != 0.0:
        raise FormatError(path, f"{field}.intrinsic.skew", "0 (skewed pixels are not supported)", skew)
    width, height = fov["right"] - fov["left"] + 1, fov["bottom"] - fov["top"] + 1
    if not (width > 0 and height > 0):
        raise FormatError(path, f"{field}.fov_video", "right >= left and bottom >= top (sensor pixels)", fov)
    s = _scale(camera, path, field)
    fx, fy = (intrinsic[k] / SUBPIXELS_PER_PIXEL * s for k in ("focalLengthU", "focalLengthV"))
    cx = (intrinsic["centerPointU"] / SUBPIXELS_PER_PIXEL - fov["left"] + 0.5) * s - 0.5
    cy = (intrinsic["centerPointV"] / SUBPIXELS_PER_PIXEL - fov["top"] + 0.5) * s - 0.5
    if not (fx > 0 and fy > 0):
        raise FormatError(path, f"{field}.intrinsic.focalLengthU", "positive focal lengths", (fx, fy))
    K = intrinsic_matrix(fx, fy, cx, cy)
    dist = np.array([distortion[k] for k in _DISTORTION]) / SUBPIXELS_PER_PIXEL
    Q = np.array([[transform[f"r{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    R = OPENCV_FROM_QUALISYS_CAMERA @ Q
    centre_m = np.array([transform["x"], transform["y"], transform["z"]]) / 1000.0
    size = (int(round(width * s)), int(round(height * s)))
    return make_camera(K, R, -R @ centre_m, size, dist, path, f"{field}.transform")
