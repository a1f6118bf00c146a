import pytest

from humancal.datasets.sequences import (
    DatasetsConfigError,
    available_sequences,
    load_datasets_config,
    parse_partition_key,
)


def _write(tmp_path, text):
    path = tmp_path / "datasets.yaml"
    path.write_text(text)
    return path


def test_packaged_config_has_the_demo_sequence():
    specs = load_datasets_config()
    assert specs["synthetic__demo"].kind == "synthetic"
    assert specs["synthetic__demo"].options["preset"] == "demo"


def test_available_sequences_need_their_data_folder(tmp_path):
    specs = load_datasets_config(user_path=tmp_path / "no_user_datasets.yaml")  # not the captures added here
    assert {s.key for s in available_sequences(specs, None)} == {"synthetic__demo", "synthetic__tiny", "synthetic__benchmark"}
    (tmp_path / "shelf_4dassoc").mkdir()
    assert "shelf__test" in {s.key for s in available_sequences(specs, tmp_path)}


@pytest.mark.parametrize(
    "text, message",
    [
        ("datasets: [1, 2]", "expected a mapping with a 'datasets' mapping"),
        ("datasets:\n  a: {kind: video, sequences: {x: {}}}", r"datasets.a.kind: expected one of \['synthetic', 'shelf', 'capture'\]"),
        ("datasets:\n  a: {kind: synthetic, sequences: {}}", "datasets.a.sequences: expected a non-empty mapping"),
        ("datasets:\n  a__b: {kind: synthetic, sequences: {x: {}}}", "dataset names may not contain '__'"),
        ("datasets: {a: [", "not valid YAML"),
    ],
)
def test_malformed_config_names_file_and_field(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(DatasetsConfigError, match=message) as excinfo:
        load_datasets_config(path)
    assert str(path) in str(excinfo.value)


def test_missing_config_file(tmp_path):
    with pytest.raises(DatasetsConfigError, match="datasets config not found"):
        load_datasets_config(tmp_path / "nope.yaml")


def test_partition_keys():
    specs = load_datasets_config()
    assert parse_partition_key("synthetic__tiny", specs).sequence == "tiny"
    with pytest.raises(DatasetsConfigError, match="unknown dataset 'mars'"):
        parse_partition_key("mars__x", specs)
    with pytest.raises(DatasetsConfigError, match="unknown sequence"):
        parse_partition_key("synthetic__nope", specs)
    with pytest.raises(DatasetsConfigError, match="expected '<dataset>__<sequence>'"):
        parse_partition_key("synthetic-demo", specs)
