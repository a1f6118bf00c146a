"""A capture's footage: per view a video file or a folder of images, read frame by frame; and plain footage rendered
for synthetic scenes (the people's mesh silhouettes on a grey background), so that overlays and the viewer can be
shown and tested without real videos.

Frame numbers are those of the detections (``docs/conventions.md``): frame ``n`` of a view is the video's ``n``-th
frame (from 0), or, in an image folder, the image whose file name carries the number ``n`` (names such as
``cam1_000012.jpg``; without distinct numbers in the names, the ``n``-th image in sorted order). That is how OpenPose
numbers the JSON files it writes for a video or a folder of images.
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from humancal.camera import Camera, CameraRig, project_points
from humancal.formats import FormatError
from humancal.formats.detections.openpose import frame_numbers_in_names
from humancal.viewing.mesh import decimation

__all__ = ["VIDEO_SUFFIXES", "IMAGE_SUFFIXES", "Footage", "FootageReader", "open_footage", "check_footage",
           "footage_for_views", "render_silhouettes", "write_footage"]

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
BACKGROUND_BGR = (64, 64, 64)
"""The rendered footage's background."""
_SHADES = (200, 160, 225, 180, 145)
"""Grey level of each person's silhouette in rendered footage (by person index, cycled)."""


@dataclass(frozen=True)
class Footage:
    """One view's footage.

    Attributes:
        path: the video file or image folder.
        kind: ``"video"`` or ``"images"``.
        size_px: (width, height) of its frames, pixels.
        num_frames: how many frames it holds.
        images: for an image folder, frame number -> image file.
        frame_scale, frame_offset: the capture's frame ``n`` is the footage's frame ``round(frame_scale * n +
            frame_offset)`` (a view on another clock than the capture's first view; default: the same frame).
    """

    path: Path
    kind: str
    size_px: tuple[int, int]
    num_frames: int
    images: Mapping[int, Path] = field(default_factory=dict)
    frame_scale: float = 1.0
    frame_offset: float = 0.0

    @property
    def last_frame(self) -> int:
        """The highest frame number it holds."""
        return max(self.images) if self.images else self.num_frames - 1


def open_footage(path: str | Path) -> Footage:
    """Probe one view's footage: a video file OpenCV reads, or a folder of images.

    Raises:
        FileNotFoundError: no such file or folder.
        FormatError: not a readable video, an empty folder, or an image that cannot be read (names the file).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such video file or image folder")
    if path.is_dir():
        files = sorted(p for p in path.iterdir()
                       if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))
        if not files:
            raise FormatError(path, None, f"a folder of images ({', '.join(IMAGE_SUFFIXES)})", "none")
        numbers = frame_numbers_in_names([p.name for p in files])
        images = dict(zip(numbers if numbers is not None else range(len(files)), files))
        first = cv2.imread(str(files[0]), cv2.IMREAD_COLOR)
        if first is None:
            raise FormatError(files[0], None, "an image OpenCV can read", "an unreadable file")
        return Footage(path, "images", (first.shape[1], first.shape[0]), len(files), images)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise FormatError(path, None, f"a video file ({', '.join(VIDEO_SUFFIXES)}) or a folder of images",
                          f"a {path.suffix or 'suffix-less'} file")
    capture = cv2.VideoCapture(str(path))
    try:
        ok, first = capture.read() if capture.isOpened() else (False, None)
        if not ok:
            raise FormatError(path, None, "a video OpenCV can decode", "no readable frame")
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        capture.release()
    return Footage(path, "video", (first.shape[1], first.shape[0]), max(count, 1))


def footage_for_views(paths: Sequence[str | Path], view_names: Sequence[str],
                      option: str = "videos") -> list[Footage | None]:
    """Each view's footage from what a user gives: one video file or image folder per view in view order, or one
    folder holding ``<view name>.<video suffix>`` or ``<view name>/`` (an image folder) per view (views without one
    get None; what :func:`write_footage` writes).

    Raises:
        ValueError: neither form (the message names ``option`` and the views), or no view found in the folder.
        FileNotFoundError, FormatError: a path that :func:`open_footage` cannot read.
    """
    paths = [Path(p) for p in paths]
    if len(paths) == 1 and paths[0].is_dir():
        found = [_named_in(paths[0], name) for name in view_names]
        if any(f is not None for f in found):  # a folder of footage named after the views
            return [None if f is None else open_footage(f) for f in found]
        if len(view_names) != 1:
            raise ValueError(f"{option}: {paths[0]} holds no footage named after the views "
                             f"({', '.join(view_names)}: <view>.mp4 or an image folder <view>/)")
    if len(paths) == len(view_names):  # one per view, in view order
        return [open_footage(p) for p in paths]
    raise ValueError(f"{option}: expected one video file or image folder per view ({len(view_names)}: "
                     f"{', '.join(view_names)}), or one folder holding <view>.mp4 per view; got {len(paths)} paths")


def _named_in(folder: Path, name: str) -> Path | None:
    """The footage of view ``name`` in ``folder``: ``<name><video suffix>`` or the image folder ``<name>/``."""
    for suffix in VIDEO_SUFFIXES:
        if (folder / f"{name}{suffix}").is_file():
            return folder / f"{name}{suffix}"
    return folder / name if (folder / name).is_dir() else None


def check_footage(footage: Footage, view: str, image_size_px: tuple[int, int], last_frame: int,
                  option: str = "videos") -> list[str]:
    """Check one view's footage against what its detections declare.

    Args:
        footage: the probed footage.
        view: the view's name (for messages).
        image_size_px: the view's declared image size (width, height).
        last_frame: the highest frame number with detections in this view.
        option: how messages name the option (the command line passes ``--videos``).

    Returns:
        Warnings, one line each (footage shorter than the detections).

    Raises:
        ValueError: frames of another aspect ratio than the image size (a rotated or cropped video, or a wrong
            image size): the message names the view, both sizes and the option.
    """
    (fw, fh), (w, h) = footage.size_px, image_size_px
    if abs(fw / fh - w / h) > 0.01 * (w / h):
        raise ValueError(f"{option}: view {view}: {footage.path} has {fw}x{fh} frames, but the view's image size is "
                         f"{w}x{h}: a rotated or cropped video, or the wrong image size")
    if footage.last_frame < last_frame:
        return [f"view {view}: {footage.path} ends at frame {footage.last_frame}, its detections run to frame "
                f"{last_frame}: later frames are drawn without an image"]
    return []


class FootageReader:
    """Frames of one view's footage by frame number; reading in increasing order is sequential (no seek).

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, footage: Footage) -> None:
        self.footage = footage
        self._capture = cv2.VideoCapture(str(footage.path)) if footage.kind == "video" else None
        self._next = 0

    def frame(self, number: int) -> np.ndarray | None:
        """The BGR image of the capture's frame ``number`` (H, W, 3) uint8, or None where the footage has none."""
        number = int(round(self.footage.frame_scale * number + self.footage.frame_offset))
        if self._capture is None:
            path = self.footage.images.get(int(number))
            return None if path is None else cv2.imread(str(path), cv2.IMREAD_COLOR)
        if number < 0 or number >= self.footage.num_frames:
            return None
        if number != self._next:
            self._capture.set(cv2.CAP_PROP_POS_FRAMES, int(number))
        ok, image = self._capture.read()
        self._next = int(number) + 1
        return image if ok else None

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()

    def __enter__(self) -> FootageReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_silhouettes(camera: Camera, people_vertices_m: Sequence[np.ndarray], faces: Sequence[np.ndarray],
                       shades: Sequence[int] | None = None) -> np.ndarray:
    """One frame of plain footage: the people's meshes filled in grey, far to near, on :data:`BACKGROUND_BGR`.

    Args:
        camera: the view's camera (its lens distortion applied to the vertices).
        people_vertices_m: per person, (V_p, 3) world vertices, metres.
        faces: per person, (F_p, 3) triangles into its vertices.
        shades: per person, its grey level (default :data:`_SHADES`, cycled).

    Returns:
        (height_px, width_px, 3) BGR uint8.
    """
    image = np.empty((camera.height_px, camera.width_px, 3), np.uint8)
    image[:] = BACKGROUND_BGR
    drawn = []
    for index, (vertices, triangles) in enumerate(zip(people_vertices_m, faces)):
        pixels, depth = project_points(camera, np.asarray(vertices, dtype=np.float64))
        in_front = (depth[triangles] > 0.05).all(1) & np.isfinite(pixels[triangles]).all((1, 2))
        if in_front.any():
            drawn.append((float(np.median(depth)), index, pixels, triangles[in_front]))
    palette = shades or _SHADES
    for _, index, pixels, triangles in sorted(drawn, reverse=True):  # far to near: nearer people cover farther ones
        shade = palette[index % len(palette)]
        corners = np.clip(np.round(pixels[triangles] * 4), -2**20, 2**20).astype(np.int32)  # 2 bits of sub-pixel
        cv2.fillPoly(image, list(corners), (shade, shade, shade), cv2.LINE_AA, shift=2)
    return image


def write_footage(view_names: Sequence[str], cameras: CameraRig,
                  meshes: Mapping[int, tuple[np.ndarray, np.ndarray]], faces: np.ndarray, frames: Sequence[int],
                  fps: float, out_dir: str | Path, *, cell_m: float = 0.02,
                  progress: Callable[[str], None] = lambda message: None) -> list[Path]:
    """Render plain footage of known bodies: one MP4 per view (``<view>.mp4``, frames ``frames`` in order, so that
    video frame ``i`` is ``frames[i]`` when ``frames`` is ``0, 1, 2, ...``).

    Args:
        view_names: (V,) the views' names.
        cameras: the rig of the V cameras that filmed them.
        meshes: person id -> ((T,) frames, (T, N, 3) vertices, world metres): the bodies.
        faces: (F, 3) the bodies' triangles.
        frames: the frame numbers to render.
        fps: the videos' frame rate.
        out_dir: the folder (created); each video is written under a temporary name and renamed when complete.
        cell_m: the meshes are decimated to this cell size first (silhouettes need no detail).
        progress: called with one line per view.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    light = {}
    for person_id, (person_frames, vertices) in meshes.items():
        keep, triangles = decimation(vertices[0], faces, cell_m)
        light[person_id] = ({int(f): i for i, f in enumerate(person_frames)}, vertices[:, keep], triangles)
    paths = []
    for name, camera in zip(view_names, cameras):
        path, partial = out / f"{name}.mp4", out / f".{name}.partial.mp4"
        writer = cv2.VideoWriter(str(partial), cv2.VideoWriter_fourcc(*"mp4v"), float(fps),
                                 (camera.width_px, camera.height_px))
        if not writer.isOpened():
            raise OSError(errno.EIO, "OpenCV cannot write an MP4 video here", str(partial))
        try:
            for image in _rendered(camera, light, frames):
                writer.write(image)
        except BaseException:
            writer.release()
            partial.unlink(missing_ok=True)  # nothing half-written is left behind
            raise
        writer.release()
        partial.replace(path)
        paths.append(path)
        progress(f"{name}: {len(frames)} frames -> {path}")
    return paths


def _rendered(camera: Camera, light: Mapping[int, tuple[dict, np.ndarray, np.ndarray]],
              frames: Sequence[int]) -> Iterator[np.ndarray]:
    order = sorted(light)
    for frame in frames:
        present = [pid for pid in order if int(frame) in light[pid][0]]
        yield render_silhouettes(camera, [light[pid][1][light[pid][0][int(frame)]] for pid in present],
                                 [light[pid][2] for pid in present],
                                 [_SHADES[order.index(pid) % len(_SHADES)] for pid in present])
