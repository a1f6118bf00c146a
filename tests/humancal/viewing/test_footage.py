"""Footage: rendered for a synthetic scene (the people's silhouettes where their detections are), read back by frame
number from videos and image folders, checked against a view's image size; overlays drawn on it land on the
detections, measured on the written video frames."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from humancal.camera import Camera, cameras_from_table
from humancal.fitting import FittedMotions
from humancal.formats import FormatError
from humancal.keypoints import JOINT_INDEX
from humancal.synthetic import generate_scene, preset
from humancal.viewing import CaptureView
from humancal.viewing.footage import (
    BACKGROUND_BGR,
    FootageReader,
    check_footage,
    footage_for_views,
    open_footage,
    write_footage,
)
from humancal.viewing.mesh import fitted_meshes
from humancal.viewing.overlays import overlay_alignment, write_overlays
from humancal.viewing.reprojection import fitted_keypoints

_TORSO = [JOINT_INDEX[name] for name in ("left_hip", "right_hip", "left_shoulder", "right_shoulder")]


@pytest.fixture(scope="module")
def filmed(body_model, tmp_path_factory):
    """A small synthetic scene, its true bodies' meshes and the footage rendered of them."""
    scene = generate_scene(preset("tiny", num_frames=6, num_people=2, num_views=3, seed=5), body_model, sequence="f")
    motions = FittedMotions.from_table(scene.motions, scene.config.fps)
    meshes, faces = fitted_meshes(body_model, motions)
    keypoints = fitted_keypoints(motions)
    cameras = cameras_from_table(scene.cameras)
    names = [f"cam{v}" for v in range(len(cameras))]
    folder = tmp_path_factory.mktemp("footage")
    paths = write_footage(names, cameras, meshes, faces, list(range(scene.config.num_frames)), scene.config.fps,
                          folder)
    return scene, cameras, names, keypoints, folder, paths


def _covered(image: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Whether each point falls on a silhouette (not the background) of a rendered frame."""
    x, y = np.round(points_px).astype(int).T
    inside = (x >= 0) & (y >= 0) & (x < image.shape[1]) & (y < image.shape[0])
    out = np.zeros(len(points_px), bool)
    pixels = image[y[inside], x[inside]].astype(int)
    out[inside] = np.abs(pixels - BACKGROUND_BGR).sum(1) > 40
    return out


def test_rendered_footage_shows_the_people_where_their_detections_are(filmed):
    scene, cameras, names, _, folder, paths = filmed
    assert [p.name for p in paths] == [f"{n}.mp4" for n in names] and not list(folder.glob(".*partial*"))
    torso = scene.detections[scene.detections["joint"].isin(["left_hip", "right_hip", "left_shoulder",
                                                              "right_shoulder"]) & (scene.detections["score"] > 0)]
    for v, path in enumerate(paths):
        footage = open_footage(path)
        assert footage.kind == "video" and footage.size_px == (cameras[v].width_px, cameras[v].height_px)
        assert footage.num_frames == scene.config.num_frames
        mine = torso[torso["view"] == v]
        covered = []
        with FootageReader(footage) as reader:
            for frame, rows in mine.groupby("frame"):
                covered += _covered(reader.frame(int(frame)), rows[["x_px", "y_px"]].to_numpy()).tolist()
        assert len(covered) > 20 and np.mean(covered) > 0.9  # the torso's detections lie on the silhouettes
        # and the background is most of the image: silhouettes, not a filled frame
        with FootageReader(footage) as reader:
            image = reader.frame(0)
        assert 0.002 < (np.abs(image.astype(int) - BACKGROUND_BGR).sum(2) > 40).mean() < 0.5


def test_overlays_on_the_footage_lie_on_the_detections_within_the_fits_error(filmed, tmp_path):
    """Measured on the written frames: each detected joint is within the fit's reprojection error of the drawn fit
    (plus the line's half width); a camera turned by 2 degrees moves the drawn fit off the detections."""
    scene, cameras, names, keypoints, folder, _ = filmed
    footage = footage_for_views([str(folder)], names)
    assert all(f is not None for f in footage)

    def measured(final_cameras) -> tuple[float, float]:
        view = CaptureView("f", names, {"final": final_cameras}, scene.config.fps, detections=scene.detections,
                           associations=scene.associations, keypoints_world_m=keypoints, footage=footage)
        out = tmp_path / f"overlays{len(list(tmp_path.iterdir()))}"
        result = write_overlays(view, out, show_detections=False, max_width_px=10_000)
        for v, path in enumerate(result.videos):  # the overlays are drawn at the cameras' full size
            capture = cv2.VideoCapture(str(path))
            assert (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT)) == \
                (cameras[v].width_px, cameras[v].height_px)
            capture.release()
        table = overlay_alignment(view, result)
        assert (table["joints"] > 20).all()
        return float(np.median(table["distance_px"])), float(np.median(table["fit_error_px"]))

    distance, error = measured(cameras)
    assert 0.0 < error < 10.0 and distance <= error + 3.0
    turn = cv2.Rodrigues(np.array([0.0, np.radians(2.0), 0.0]))[0]  # about the camera's own centre
    turned = [Camera.from_center(c.K, turn @ c.R_cam_from_world, c.center_world_m, c.width_px, c.height_px)
              for c in cameras]
    distance_off, error_off = measured(turned)
    assert error_off > 3 * error and distance_off > 3 * distance


def test_image_folders_are_read_by_the_frame_number_in_their_names(tmp_path):
    folder = tmp_path / "cam1"
    folder.mkdir()
    for frame in (4, 5, 7):
        cv2.imwrite(str(folder / f"cam1_{frame:06d}.png"), np.full((30, 40, 3), frame * 10, np.uint8))
    footage = open_footage(folder)
    assert footage.kind == "images" and footage.size_px == (40, 30) and footage.last_frame == 7
    with FootageReader(footage) as reader:
        assert reader.frame(5)[0, 0, 0] == 50 and reader.frame(6) is None and reader.frame(7)[0, 0, 0] == 70
    with FootageReader(dataclasses.replace(footage, frame_scale=2.0, frame_offset=1.0)) as reader:
        assert reader.frame(2)[0, 0, 0] == 50  # a view on another clock: the capture's frame 2 is its frame 5
    assert check_footage(footage, "cam1", (400, 300), 7) == []
    assert "ends at frame 7" in check_footage(footage, "cam1", (400, 300), 9)[0]
    with pytest.raises(ValueError, match=r"--videos: view cam1: .* 40x30 frames, but the view's image size is 300x400"):
        check_footage(footage, "cam1", (300, 400), 7, "--videos")


def test_footage_that_cannot_be_read_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such video file or image folder"):
        open_footage(tmp_path / "missing.mp4")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FormatError, match="a folder of images"):
        open_footage(tmp_path / "empty")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(FormatError, match="a video file"):
        open_footage(tmp_path / "notes.txt")
    (tmp_path / "broken.mp4").write_bytes(b"not a video")
    with pytest.raises(FormatError, match="a video OpenCV can decode"):
        open_footage(tmp_path / "broken.mp4")
    with pytest.raises(ValueError, match="--videos: expected one video file or image folder per view"):
        footage_for_views([tmp_path / "a.mp4", tmp_path / "b.mp4"], ["c1", "c2", "c3"], "--videos")
    with pytest.raises(ValueError, match="holds no footage named after the views"):
        footage_for_views([tmp_path / "empty"], ["c1", "c2"], "--videos")


def test_a_captures_footage_is_read_on_the_captures_clock(tmp_path):
    """``humancal add --videos`` with per-view frame rates and time offsets: each view's footage is read at its own
    frame for the capture's frame n (n / fps_0 + offset_0 = m / fps_v + offset_v); dropped views have none."""
    from humancal.datasets.inputs import capture_footage
    from humancal.datasets.sequences import SequenceSpec

    folders = []
    for name in ("cam1", "cam2", "cam3"):
        (tmp_path / "op" / name).mkdir(parents=True)
        folder = tmp_path / "video" / name
        folder.mkdir(parents=True)
        for frame in range(4):
            cv2.imwrite(str(folder / f"{frame:06d}.png"), np.zeros((30, 40, 3), np.uint8))
        folders.append(str(folder))
    options = {"format": "openpose", "views": [str(tmp_path / "op" / n) for n in ("cam1", "cam2", "cam3")],
               "image_size": [40, 30], "fps": 30, "view_fps": {"cam2": 60}, "time_offsets": {"cam2": 0.5},
               "videos": folders}
    spec = SequenceSpec("lab", "take", "capture", options, str(tmp_path / "datasets.yaml"))
    footage = capture_footage(spec, ["cam1", "cam2"])  # cam3 dropped
    assert [f.path.name for f in footage] == ["cam1", "cam2"]
    assert (footage[0].frame_scale, footage[0].frame_offset) == (1.0, 0.0)
    # cam2 at 60 fps started 0.5 s late: the capture's frame 30 (1 s) is its frame (1 - 0.5) * 60 = 30
    assert footage[1].frame_scale == 2.0 and footage[1].frame_offset == -30.0
    assert capture_footage(dataclasses.replace(spec, options={**options, "videos": None}), ["cam1"]) is None
    assert capture_footage(SequenceSpec("synthetic", "demo", "synthetic", {}), ["view_0"]) is None


def test_a_writer_that_fails_leaves_nothing_half_written(filmed, tmp_path, monkeypatch):
    import humancal.viewing.overlays as overlays

    scene, cameras, names, keypoints, _, _ = filmed
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("disk gone")
        return np.zeros((cameras[0].height_px, cameras[0].width_px, 3), np.uint8)

    monkeypatch.setattr(overlays, "draw_frame", failing)
    view = CaptureView("f", names, {"final": cameras}, scene.config.fps, detections=scene.detections,
                       associations=scene.associations, keypoints_world_m=keypoints)
    with pytest.raises(RuntimeError, match="disk gone"):
        write_overlays(view, tmp_path / "overlays")
    assert list((tmp_path / "overlays").iterdir()) == []
    import humancal.viewing.footage as footage_module

    def frames_then_failure(*args):
        yield np.zeros((cameras[0].height_px, cameras[0].width_px, 3), np.uint8)
        raise RuntimeError("disk gone")

    monkeypatch.setattr(footage_module, "_rendered", frames_then_failure)
    meshes = {0: (np.arange(2), np.zeros((2, 3, 3)))}
    with pytest.raises(RuntimeError, match="disk gone"):
        write_footage(names[:1], cameras[:1], meshes, np.array([[0, 1, 2]]), [0, 1], 30.0, tmp_path / "footage")
    assert list((tmp_path / "footage").iterdir()) == []
