"""Known principal points: the capture option, the CLI's form and the sequence-level reader."""

import pytest

from humancal.captures import CaptureConfig, parse_principal_point, principal_points_option
from humancal.datasets.inputs import sequence_principal_points
from humancal.datasets.sequences import SequenceSpec

SIZES = [(1920, 1080), (1280, 720)]


def test_one_point_for_every_view_or_one_per_view():
    assert principal_points_option([950, 530.5], SIZES) == ((950.0, 530.5), (950.0, 530.5))
    assert principal_points_option([[950, 530], [641.5, 362]], SIZES) == ((950.0, 530.0), (641.5, 362.0))
    assert parse_principal_point(" 963.5, 541.2") == (963.5, 541.2)


@pytest.mark.parametrize("value, needle", [
    ([[950, 530]], "one [cx, cy] per view (2)"),
    ([[950, 530], [1, 2], [3, 4]], "one [cx, cy] per view (2)"),
    ("960,540", "expected [cx, cy]"),
    ([960, float("nan")], "expected [cx, cy]"),
    ([True, 5], "expected [cx, cy]"),
    ([[950, 530], [1300, 360]], "view 1's (1300, 360) is outside its 1280x720 image"),
])
def test_malformed_points_are_named_errors(value, needle):
    with pytest.raises(ValueError, match="principal_point") as error:
        principal_points_option(value, SIZES)
    assert needle in str(error.value)


@pytest.mark.parametrize("text", ["960x540", "960", "a,b", "1,2,3", "inf,2"])
def test_the_cli_form_is_cx_comma_cy(text):
    with pytest.raises(ValueError, match="--principal-point: expected CX,CY"):
        parse_principal_point(text, "--principal-point")


def test_capture_options_round_trip(tmp_path):
    views = [str(tmp_path / "a"), str(tmp_path / "b")]
    options = {"format": "openpose", "views": views, "image_size": [list(s) for s in SIZES],
               "principal_point": [[950.0, 530.0], [641.5, 362.0]]}
    config = CaptureConfig.from_options(options, tmp_path)
    assert config.principal_points_px == ((950.0, 530.0), (641.5, 362.0))
    assert config.to_options()["principal_point"] == options["principal_point"]
    same = CaptureConfig.from_options({**options, "image_size": [640, 480], "principal_point": [320, 240]}, tmp_path)
    assert same.to_options()["principal_point"] == [320.0, 240.0]
    assert "principal_point" not in CaptureConfig.from_options({**options, "principal_point": None}, tmp_path).to_options()
    with pytest.raises(ValueError, match="outside its 640x480 image"):
        CaptureConfig.from_options({**options, "image_size": [640, 480], "principal_point": [700, 240]}, tmp_path)


def test_sequence_reader_names_the_datasets_file_and_partition():
    spec = SequenceSpec("lab", "take1", "capture", {"principal_point": [950, 530]}, "/data/my_datasets.yaml")
    assert sequence_principal_points(spec, SIZES) == [(950.0, 530.0), (950.0, 530.0)]
    assert sequence_principal_points(SequenceSpec("lab", "take1", "capture", {}), SIZES) is None
    bad = SequenceSpec("lab", "take1", "capture", {"principal_point": [[950, 530]]}, "/data/my_datasets.yaml")
    with pytest.raises(ValueError, match=r"/data/my_datasets.yaml: lab__take1: principal_point: expected"):
        sequence_principal_points(bad, SIZES)
