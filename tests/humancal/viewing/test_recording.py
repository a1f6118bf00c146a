"""The Rerun recording of a synthetic capture, read back with Rerun's own tool (``rerun rrd print``): every camera,
person, mesh and view is there, and the fit's reprojection error is the detections' noise when the fit is the
truth."""

from __future__ import annotations

import re
import subprocess
import sys
from collections import Counter

import numpy as np
import pytest
import rerun as rr

from humancal.camera import cameras_from_table
from humancal.fitting import FittedMotions
from humancal.synthetic import generate_scene, preset
from humancal.viewing import CaptureView, decimation, record_capture
from humancal.viewing.mesh import fitted_meshes
from humancal.viewing.reprojection import fitted_keypoints

_CHUNK = re.compile(r"^Chunk\(\S+\) with (\d+) rows .* - (\S+) - data columns: \[(.*)\]$")


def _entities(path) -> dict[str, tuple[int, set[str]]]:
    """entity path -> (rows, archetype:field columns) of an .rrd file, as ``rerun rrd print`` lists its chunks."""
    printed = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(path)], capture_output=True,
                             text=True, timeout=120, check=True).stdout
    rows, columns = Counter(), {}
    for line in printed.splitlines():
        match = _CHUNK.match(line.strip())
        if match:
            count, entity, fields = match.groups()
            rows[entity] += int(count)
            columns.setdefault(entity, set()).update(fields.split())
    return {entity: (rows[entity], columns[entity]) for entity in rows}


@pytest.fixture(scope="module")
def recorded(body_model, tmp_path_factory):
    scene = generate_scene(preset("tiny", num_frames=12, num_people=2, num_views=3, seed=3), body_model, sequence="v")
    cameras = cameras_from_table(scene.cameras)
    motions = FittedMotions.from_table(scene.motions, scene.config.fps)
    meshes, faces = fitted_meshes(body_model, motions)
    names = [f"cam{v}" for v in range(len(cameras))]
    view = CaptureView("synthetic__v", names, {"final": cameras, "reference": cameras}, scene.config.fps,
                       scene.poses3d, scene.detections, scene.associations, fitted_keypoints(motions), meshes, faces)
    path = tmp_path_factory.mktemp("rrd") / "capture.rrd"
    recording = rr.RecordingStream("humancal_test", recording_id="synthetic__v")
    recording.save(str(path))
    summary = record_capture(view, recording)
    recording.flush()
    recording.disconnect()
    return scene, names, summary, path, view


def test_every_camera_person_mesh_and_view_is_in_the_file(recorded):
    scene, names, summary, path, _ = recorded
    entities = _entities(path)
    people = sorted(scene.poses3d["person_id"].unique())
    frames = scene.poses3d["frame"].nunique()
    for kind in ("final", "reference"):
        for name in names:
            assert {"Pinhole:image_from_camera", "Pinhole:resolution"} <= entities[f"/world/cameras/{kind}/{name}"][1]
    for person_id in people:
        rows, columns = entities[f"/world/people/{person_id}/skeleton"]
        assert rows == frames and {"LineStrips3D:strips", "Points3D:positions"} <= columns
        rows, columns = entities[f"/world/people/{person_id}/body"]
        assert rows == frames and "Mesh3D:vertex_positions" in columns
        assert f"/world/people/{person_id}/path" in entities
    for name in names:
        assert entities[f"/world/cameras/final/{name}/detections"][0] == frames
        assert entities[f"/world/cameras/final/{name}/fit"][0] == frames
        assert "Scalars:scalars" in entities[f"/errors/{name}"][1]
    assert summary.entities["world/floor"] == 1 and summary.frames == frames


def test_the_fit_of_the_truth_sits_on_the_detections(recorded):
    """The error plot's figure: the true keypoints reprojected are the detections' noise away (a few px)."""
    scene, names, summary, path, _ = recorded
    from humancal.viewing.reprojection import detection_people, reprojected_fit

    motions = FittedMotions.from_table(scene.motions, scene.config.fps)
    keypoints = {int(p): (motions.frames[motions.present[i]], motions.keypoints_world_m[i, motions.present[i]])
                 for i, p in enumerate(motions.person_ids)}
    cameras = cameras_from_table(scene.cameras)
    fits = reprojected_fit(keypoints, 0, cameras[0], scene.detections[scene.detections["view"] == 0],
                           detection_people(scene.associations))
    errors = [fit.error_px for fit in fits.values()]
    assert np.isfinite(errors).all() and 0.0 < np.median(errors) < 10.0


def test_decimation_keeps_a_closed_lighter_mesh():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    keep, faces = decimation(sphere.vertices, sphere.faces, cell_m=0.05)
    assert len(keep) < 0.5 * len(sphere.vertices) and faces.max() < len(keep) and len(faces) > 100
    light = trimesh.Trimesh(sphere.vertices[keep], faces, process=False)
    assert abs(light.volume - sphere.volume) / sphere.volume < 0.1  # the same body, fewer triangles, outward
    with pytest.raises(ValueError, match="cell_m"):
        decimation(sphere.vertices, sphere.faces, cell_m=0.0)


def test_overlays_draw_every_frame_of_every_view_in_the_people_colours(recorded, tmp_path):
    import cv2

    from humancal.viewing import person_colour
    from humancal.viewing.overlays import write_overlays

    scene, names, _, _, _ = recorded
    motions = FittedMotions.from_table(scene.motions, scene.config.fps)
    keypoints = {int(p): (motions.frames[motions.present[i]], motions.keypoints_world_m[i, motions.present[i]])
                 for i, p in enumerate(motions.person_ids)}
    view = CaptureView("v", names, {"final": cameras_from_table(scene.cameras)}, scene.config.fps,
                       detections=scene.detections, associations=scene.associations, keypoints_world_m=keypoints)
    result = write_overlays(view, tmp_path / "overlays", sheet_frames=3)
    frames = scene.detections["frame"].nunique()
    assert [p.name for p in result.videos] == [f"{name}.mp4" for name in names] and len(result.frames) == frames
    capture = cv2.VideoCapture(str(result.videos[0]))
    count, colours = 0, set()
    while True:
        ok, image = capture.read()
        if not ok:
            break
        count += 1
        pixels = image.reshape(-1, 3).astype(int)
        for person_id in keypoints:  # the person's colour is drawn (MP4 compression: within a tolerance)
            b, g, r = person_colour(person_id)[::-1]
            if (np.abs(pixels - [b, g, r]).sum(1) < 40).sum() > 20:
                colours.add(person_id)
    assert count == frames and colours == set(keypoints)
    sheet = cv2.imread(str(result.contact_sheet))
    assert sheet.shape[1] == 3 * 320 and sheet.shape[0] >= len(names) * 100
    assert all(0.0 < error < 10.0 for error in result.median_error_px)
    assert not list((tmp_path / "overlays").glob(".*partial*"))
    with pytest.raises(ValueError, match="no final cameras"):
        write_overlays(CaptureView("v", names, {}, 30.0), tmp_path / "none")


def test_the_footage_is_in_each_camera_of_the_recording(recorded, tmp_path):
    import dataclasses

    from humancal.viewing.footage import open_footage, write_footage

    scene, names, _, _, view = recorded
    frames = sorted(scene.detections["frame"].unique())
    paths = write_footage(names, view.cameras["final"], view.meshes, view.faces, frames, view.fps, tmp_path / "footage")
    with_footage = dataclasses.replace(view, meshes={}, footage=[open_footage(paths[0]), None, open_footage(paths[2])])
    path = tmp_path / "footage.rrd"
    recording = rr.RecordingStream("humancal_test", recording_id="footage")
    recording.save(str(path))
    summary = record_capture(with_footage, recording, image_every=2)
    recording.flush()
    recording.disconnect()
    entities = _entities(path)
    for name in (names[0], names[2]):
        rows, columns = entities[f"/world/cameras/final/{name}/image"]
        assert rows == len(frames[::2]) and "EncodedImage:blob" in columns
    assert f"/world/cameras/final/{names[1]}/image" not in entities  # a view without footage has no images
    assert summary.entities[f"world/cameras/final/{names[0]}/image"] == len(frames[::2])
