import pytest

from humancal.settings import DataRootError, data_root, dataset_dir


def test_explicit_data_root(tmp_path, monkeypatch):
    (tmp_path / "shelf_4dassoc").mkdir()
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path))
    assert data_root() == tmp_path
    assert dataset_dir("shelf_4dassoc") == tmp_path / "shelf_4dassoc"


def test_missing_root_names_the_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path / "nowhere"))
    assert data_root() is None
    with pytest.raises(DataRootError, match="HUMANCAL_DATA_DIR=.*is not a directory; dataset 'shelf' needs it"):
        data_root(required_for="dataset 'shelf'")


def test_missing_dataset_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path))
    with pytest.raises(DataRootError, match="cmu_mocap does not exist"):
        dataset_dir("cmu_mocap")
