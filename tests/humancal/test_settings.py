import pytest

from humancal.settings import DataRootError, anny_cache_dir, data_root, dataset_dir, local_dir, state_dir, state_url


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


@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A stand-in for the checkout (its ``.humancal`` is the default of both folders), and no folder settings."""
    from humancal import settings

    monkeypatch.setattr(settings, "REPO_ROOT", tmp_path / "checkout")
    for name in ("HUMANCAL_STATE_DIR", "HUMANCAL_LOCAL_DIR", "ANNY_CACHE_DIR"):
        monkeypatch.delenv(name, raising=False)
    return tmp_path / "checkout"


def test_a_local_state_dir_holds_everything_as_before(checkout, tmp_path, monkeypatch):
    default = checkout / ".humancal"
    assert state_dir() == default and local_dir() == default and anny_cache_dir() == default / "cache" / "anny"
    assert state_url() is None and default.is_dir()
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path / "shared"))
    assert state_dir() == local_dir() == tmp_path / "shared"
    assert anny_cache_dir() == tmp_path / "shared" / "cache" / "anny"
    monkeypatch.setenv("HUMANCAL_STATE_DIR", f"file://{tmp_path / 'as_url'}")
    assert state_url() is None and state_dir() == local_dir() == tmp_path / "as_url"


def test_a_state_dir_on_a_store_keeps_what_is_per_machine_in_the_local_dir(checkout, tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", "s3://bucket/prefix/")
    assert state_url() == "s3://bucket/prefix" and str(state_dir()) == "s3://bucket/prefix"
    assert state_dir().protocol == "s3"
    assert local_dir() == checkout / ".humancal" and anny_cache_dir() == checkout / ".humancal" / "cache" / "anny"
    monkeypatch.setenv("HUMANCAL_LOCAL_DIR", str(tmp_path / "node"))
    assert local_dir() == tmp_path / "node" and anny_cache_dir() == tmp_path / "node" / "cache" / "anny"
    monkeypatch.setenv("ANNY_CACHE_DIR", str(tmp_path / "anny"))
    assert anny_cache_dir() == tmp_path / "anny"


def test_the_local_dir_must_be_a_folder_of_this_machine(checkout, monkeypatch):
    monkeypatch.setenv("HUMANCAL_LOCAL_DIR", "s3://bucket/node")
    with pytest.raises(ValueError, match=r"HUMANCAL_LOCAL_DIR='s3://bucket/node': expected a folder of this machine"):
        local_dir()
