"""The association picture: a valid PNG of the expected size, the timeline on top and one panel per view below,
with every person's colour drawn in the view panels."""

import numpy as np
import pytest

from humancal.association import AffinityConfig, TrackingConfig, associate
from humancal.association.plot import association_frame, plot_association
from humancal.camera import CameraRig
from humancal.plotting import pyplot
from humancal.synthetic import generate_scene, preset
from humancal.tables.detections import detections_to_dense


@pytest.fixture(scope="module")
def associated(body_model):
    scene = generate_scene(preset("tiny", num_frames=30), body_model, sequence="plot")
    dense = detections_to_dense(scene.detections)
    rig = CameraRig.from_cameras(scene.rig)
    result = associate(dense, None, rig, TrackingConfig(affinity=AffinityConfig.epipolar_only()))
    return result, dense, rig


def _tab10_pixels(image: np.ndarray, person: int) -> int:
    colour = np.array(pyplot().get_cmap("tab10")(person)[:3])
    return int((np.abs(image[..., :3] - colour).max(axis=-1) < 0.02).sum())


def test_picture_has_timeline_and_one_panel_per_view(associated, tmp_path):
    result, dense, rig = associated
    assert result.num_people == 2
    path = plot_association(result, dense, rig, tmp_path / "association.png")
    image = pyplot().imread(path)
    # 4 columns of 3.2 in at 80 dpi; timeline 2.6 in + one row of 16:9 panels (3 views) 3.2 * 9 / 16 + 0.4 in
    assert image.shape[1] == round(3.2 * 4 * 80)
    assert image.shape[0] == round((2.6 + 3.2 * 1080 / 1920 + 0.4) * 80)
    split = round(2.6 * 80)
    timeline, panels = image[:split], image[split:]
    for person in range(result.num_people):
        assert _tab10_pixels(timeline, person) > 50, f"person {person} missing from the timeline"
        assert _tab10_pixels(panels, person) > 50, f"person {person} missing from the view panels"
    # three panels side by side: the blank canvases are framed by axes lines, the fourth column stays empty
    column_dark = (panels[..., :3].max(axis=-1) < 0.3).sum(axis=0)
    quarter = image.shape[1] // 4
    assert column_dark[: 3 * quarter].sum() > 0 and column_dark[3 * quarter + 10:].sum() == 0


def test_frame_with_most_people_and_bad_input(associated, tmp_path):
    result, dense, rig = associated
    frame = association_frame(result)
    people = [np.unique(result.skeleton_person[result.skeleton_frame == f]).size for f in np.unique(result.frame)]
    assert np.unique(result.skeleton_person[result.skeleton_frame == frame]).size == max(people)
    with pytest.raises(ValueError, match="max_views"):
        plot_association(result, dense, rig, tmp_path / "x.png", max_views=0)
    with pytest.raises(ValueError, match="row-aligned"):
        plot_association(result, detections_to_dense_subset(dense), rig, tmp_path / "x.png")


def detections_to_dense_subset(dense):
    from dataclasses import replace

    return replace(dense, frame=dense.frame[1:], view=dense.view[1:], det_id=dense.det_id[1:],
                   keypoints_px=dense.keypoints_px[1:], scores=dense.scores[1:])
