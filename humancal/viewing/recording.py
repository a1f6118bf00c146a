"""A capture's result as a Rerun recording: cameras, people, meshes and the 2D evidence on one timeline.

Entities (world metres, Z up, ``docs/conventions.md``):

* ``world/floor``: a grid on z = 0 (static);
* ``world/cameras/<kind>/<view>``: each camera as a frustum (``Transform3D`` world-from-camera and ``Pinhole``),
  kinds ``final``, ``calibrated``, ``refined``, ``reference`` in distinct colours (static);
* ``world/people/<id>/skeleton``: the triangulated 3D skeleton per frame (bones and joints), one colour per
  person id, the same in every entity; ``world/people/<id>/path``: the person's hip-centre path (static);
* ``world/people/<id>/body``: the fitted anny mesh per frame (decimated, :mod:`.mesh`, unless ``full_mesh``);
* ``world/cameras/final/<view>/detections``: the 2D detections of each frame in that camera's image (grey where
  the association rejected them); ``.../fit``: the fitted keypoints reprojected; ``errors/<view>``: the view's mean
  reprojection error of the fit per frame (a scalar plot);
* ``world/cameras/final/<view>/image``: the view's footage per frame (JPEG), when the capture has it.

Timelines: ``frame`` (the sequence's frame numbers) and ``time`` (seconds at the capture's frame rate).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import rerun as rr

from humancal.camera import Camera, CameraRig
from humancal.keypoints import JOINT_INDEX, LIMB_INDEX, NUM_JOINTS
from humancal.viewing.footage import Footage, FootageReader
from humancal.viewing.mesh import decimation
from humancal.viewing.reprojection import detection_people, joint_index, reprojected_fit


__all__ = ["CaptureView", "RecordingSummary", "record_capture", "person_colour", "CAMERA_COLOURS", "blueprint"]

CAMERA_COLOURS = {"final": (255, 160, 0), "calibrated": (200, 120, 255), "refined": (40, 140, 255),
                  "reference": (40, 200, 80)}
"""Frustum colour (RGB) per camera kind."""

_PALETTE = np.array([(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
                     (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)], dtype=np.uint8)
_REJECTED = (150, 150, 150)
_HIPS = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]


def person_colour(person_id: int) -> tuple[int, int, int]:
    """The stable RGB colour of a person id (the same in every entity and every recording)."""
    return tuple(int(c) for c in _PALETTE[int(person_id) % len(_PALETTE)])


@dataclass(frozen=True)
class CaptureView:
    """What a recording shows: the stored tables of one capture (any may be empty or None).

    Attributes:
        name: the capture (partition) name.
        view_names: the views' names, in view order.
        cameras: camera kind (keys of :data:`CAMERA_COLOURS`) -> the rig of that kind (one :class:`Camera` per view).
        fps: frame rate, frames per second (the ``time`` timeline).
        skeletons3d: the ``skeletons3d`` table (triangulated joints per frame and person).
        detections: the ``raw_detections`` table (2D keypoints, long form).
        associations: the ``associations`` table (person id per detection; -1 rejected).
        keypoints_world_m: person id -> ((T,) frames, (T, 23, 3) fitted keypoints), from ``fitted_motions``.
        meshes: person id -> ((T,) frames, (T, V, 3) vertices), and ``faces`` (F, 3): the fitted bodies.
        footage: per view, its footage (None where a view has none), or None: the images under the overlays.
    """

    name: str
    view_names: Sequence[str]
    cameras: dict[str, CameraRig]
    fps: float
    skeletons3d: pd.DataFrame | None = None
    detections: pd.DataFrame | None = None
    associations: pd.DataFrame | None = None
    keypoints_world_m: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    meshes: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    faces: np.ndarray | None = None
    footage: Sequence[Footage | None] | None = None


@dataclass(frozen=True)
class RecordingSummary:
    """What :func:`record_capture` logged: entity path -> number of log calls (frames for the per-frame ones)."""

    entities: dict[str, int]

    @property
    def frames(self) -> int:
        return max(self.entities.values(), default=0)


def record_capture(view: CaptureView, recording: rr.RecordingStream, *, full_mesh: bool = False,
                   mesh_cell_m: float = 0.03, image_every: int = 1, jpeg_quality: int = 75,
                   progress: Callable[[str], None] = lambda message: None) -> RecordingSummary:
    """Log ``view`` into ``recording`` (module docstring for the entities).

    Args:
        view: the capture's tables.
        recording: an open Rerun recording stream (e.g. ``rr.RecordingStream("humancal")`` with ``.save(path)``).
        full_mesh: log anny's full mesh (about 14k vertices) instead of a decimated one.
        mesh_cell_m: the decimation's cell size, metres.
        image_every: log every n-th frame of the footage (a lighter file).
        jpeg_quality: the footage's JPEG quality (0-100).
        progress: called with one line per stage.
    """
    counts: dict[str, int] = {}

    def log(path: str, *archetypes, static: bool = False) -> None:
        recording.log(path, *archetypes, static=static)
        counts[path] = counts.get(path, 0) + 1

    log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    log("world/floor", _floor(view), static=True)
    for kind, cameras in view.cameras.items():
        for name, camera in zip(view.view_names, cameras):
            _log_camera(log, f"world/cameras/{kind}/{name}", camera, CAMERA_COLOURS[kind])
    progress(f"cameras: {', '.join(f'{k} ({len(v)})' for k, v in view.cameras.items())}")

    def at(frame: int) -> None:
        recording.set_time("frame", sequence=int(frame))
        recording.set_time("time", duration=float(frame) / view.fps)

    if view.skeletons3d is not None and len(view.skeletons3d):
        _log_skeletons(log, at, view.skeletons3d)
        progress(f"skeletons: {view.skeletons3d['person_id'].nunique()} people")
    if view.meshes and view.faces is not None:
        _log_meshes(log, at, view, full_mesh, mesh_cell_m)
        progress(f"meshes: {len(view.meshes)} people ({'full' if full_mesh else 'decimated'})")
    if view.detections is not None and len(view.detections) and "final" in view.cameras:
        _log_views(log, at, view)
        progress(f"2D: {len(view.view_names)} views")
    if view.footage and "final" in view.cameras and view.detections is not None and len(view.detections):
        logged = _log_footage(log, at, view, image_every, jpeg_quality)
        progress(f"footage: {logged} images")
    return RecordingSummary(counts)


def blueprint(view_names: Sequence[str]):
    """The layout the recording opens with: the 3D world large on the left; the views' images (detections and the
    reprojected fit) as tabs and the per-view reprojection errors over time on the right."""
    import rerun.blueprint as rrb

    images = [rrb.Spatial2DView(origin=f"world/cameras/final/{name}", name=name) for name in view_names]
    right = [rrb.Tabs(*images)] if images else []
    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin="world", name="world"),
        rrb.Vertical(*right, rrb.TimeSeriesView(origin="errors", name="reprojection error (px)")),
        column_shares=[3, 2]), collapse_panels=False)


def _floor(view: CaptureView, step_m: float = 0.5) -> rr.LineStrips3D:
    """Grid lines on z = 0 covering the cameras and the people, ``step_m`` apart."""
    points = [camera.center_world_m for cameras in view.cameras.values() for camera in cameras]
    if view.skeletons3d is not None and len(view.skeletons3d):
        points.append(view.skeletons3d[["x_m", "y_m", "z_m"]].to_numpy().min(0))
        points.append(view.skeletons3d[["x_m", "y_m", "z_m"]].to_numpy().max(0))
    extent = np.array(points)[:, :2] if points else np.zeros((1, 2))
    lo = np.floor(np.nanmin(extent, 0) / step_m) * step_m - step_m
    hi = np.ceil(np.nanmax(extent, 0) / step_m) * step_m + step_m
    xs, ys = np.arange(lo[0], hi[0] + 1e-9, step_m), np.arange(lo[1], hi[1] + 1e-9, step_m)
    strips = [[[x, lo[1], 0.0], [x, hi[1], 0.0]] for x in xs] + [[[lo[0], y, 0.0], [hi[0], y, 0.0]] for y in ys]
    return rr.LineStrips3D(strips, colors=[(90, 90, 90)], radii=0.003)


def _log_camera(log, path: str, camera: Camera, colour) -> None:
    R = camera.R_cam_from_world
    log(path, rr.Transform3D(translation=camera.center_world_m, mat3x3=R.T), static=True)
    log(path, rr.Pinhole(image_from_camera=camera.K, resolution=[camera.width_px, camera.height_px],
                         camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.4, color=colour), static=True)


def _log_skeletons(log, at, skeletons: pd.DataFrame) -> None:
    valid = skeletons[skeletons["valid"]]
    for person_id, person in valid.groupby("person_id"):
        colour = person_colour(int(person_id))
        path = f"world/people/{int(person_id)}"
        hips = []
        for frame, rows in person.groupby("frame"):
            joints = np.full((NUM_JOINTS, 3), np.nan)
            joints[joint_index(rows["joint"])] = rows[["x_m", "y_m", "z_m"]].to_numpy()
            at(frame)
            bones = [joints[[a, b]] for a, b in LIMB_INDEX if np.isfinite(joints[[a, b]]).all()]
            seen = np.isfinite(joints).all(1)
            log(f"{path}/skeleton", rr.LineStrips3D(bones, colors=[colour], radii=0.01),
                rr.Points3D(joints[seen], colors=[colour], radii=0.015))
            if np.isfinite(joints[_HIPS]).all():
                hips.append(joints[_HIPS].mean(0))
        if len(hips) > 1:
            log(f"{path}/path", rr.LineStrips3D([np.array(hips) * [1.0, 1.0, 0.0]], colors=[colour], radii=0.006),
                static=True)


def _log_meshes(log, at, view: CaptureView, full_mesh: bool, cell_m: float) -> None:
    for person_id, (frames, vertices) in view.meshes.items():
        keep, faces = (np.arange(vertices.shape[1]), view.faces) if full_mesh else decimation(
            vertices[0], view.faces, cell_m)
        colour = person_colour(person_id)
        for frame, frame_vertices in zip(frames, vertices):
            at(frame)
            log(f"world/people/{person_id}/body", rr.Mesh3D(vertex_positions=frame_vertices[keep],
                                                            triangle_indices=faces, albedo_factor=[*colour, 160]))


def _log_footage(log, at, view: CaptureView, every: int, quality: int) -> int:
    """Each view's footage at the frames with detections (every ``every``-th), as JPEG images in its camera."""
    import cv2

    frames = np.asarray(sorted(view.detections["frame"].unique()))[:: max(1, every)]
    logged = 0
    for name, camera, footage in zip(view.view_names, view.cameras["final"], view.footage):
        if footage is None:
            continue
        with FootageReader(footage) as reader:
            for frame in frames:
                image = reader.frame(int(frame))
                if image is None:
                    continue
                if image.shape[:2] != (camera.height_px, camera.width_px):  # the camera's pixels, for the overlays
                    image = cv2.resize(image, (camera.width_px, camera.height_px), interpolation=cv2.INTER_AREA)
                ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
                at(frame)
                log(f"world/cameras/final/{name}/image", rr.EncodedImage(contents=jpeg.tobytes(),
                                                                         media_type="image/jpeg"))
                logged += 1
    return logged


def _log_views(log, at, view: CaptureView) -> None:
    detections = view.detections
    person = detection_people(view.associations)
    cameras = view.cameras["final"]
    for v, name in enumerate(view.view_names):
        base = f"world/cameras/final/{name}"
        mine = detections[detections["view"] == v]
        for frame, rows in mine.groupby("frame"):
            at(frame)
            points, colours = [], []
            for det_id, det in rows.groupby("det_id"):
                pid = person.get((int(frame), v, int(det_id)), -1)
                ok = det["score"].to_numpy() > 0
                points.append(det[["x_px", "y_px"]].to_numpy()[ok])
                colours += [person_colour(pid) if pid >= 0 else _REJECTED] * int(ok.sum())
            if points:
                log(f"{base}/detections", rr.Points2D(np.concatenate(points), colors=colours, radii=3.0))
        for frame, fit in reprojected_fit(view.keypoints_world_m, v, cameras[v], mine, person).items():
            at(frame)
            points = [px[ok] for px, ok in fit.people.values()]
            colours = [person_colour(pid) for pid, (_, ok) in fit.people.items() for _ in range(int(ok.sum()))]
            log(f"{base}/fit", rr.Points2D(np.concatenate(points) if points else np.zeros((0, 2)), colors=colours,
                                           radii=2.0))
            if np.isfinite(fit.error_px):
                log(f"errors/{name}", rr.Scalars(fit.error_px))
