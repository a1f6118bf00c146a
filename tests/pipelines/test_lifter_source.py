"""Which lifter the graph uses: the shipped weights until `humancal train lifter` stores a trained checkpoint,
then that one (a new code version of `lifter_checkpoint`, so what depends on it is recomputed); `--discard`
returns to the shipped weights. None of it needs the data root."""

from __future__ import annotations

import dagster as dg
import pytest
import torch

from humancal.lifter import CHECKPOINT_FORMAT, LifterConfig, LifterNet, LifterWeightsError, shipped_info
from pipelines.cli import main
from pipelines.definitions import build_definitions
from resources.lifter_source import active_lifter, trained_lifter_path


@pytest.fixture(scope="module")
def tiny_lifter_checkpoint():
    """An untrained tiny network in the checkpoint format (what is stored matters here, not how well it lifts)."""
    config = LifterConfig.tiny()
    torch.manual_seed(0)
    net = LifterNet(config.width, config.num_blocks, config.dropout)
    return {"format": CHECKPOINT_FORMAT, "state_dict": net.state_dict(), "config": config.to_dict(),
            "train_subjects": ["01"], "val_subjects": ["02"], "val_metrics": {"pa_mpjpe_mm": 99.0},
            "training_time_s": 0.0}


def _code_version(defs) -> str:
    return defs.get_assets_def("lifter_checkpoint").code_versions_by_key[dg.AssetKey("lifter_checkpoint")]


def test_shipped_weights_are_in_force_until_a_lifter_is_trained(tmp_path, tiny_lifter_checkpoint):
    shipped = active_lifter(tmp_path)
    assert shipped.source == "shipped" and shipped.digest == shipped_info()["digest"]
    assert "shipped with humancal" in shipped.describe()
    before = _code_version(build_definitions(storage_root=str(tmp_path)))

    trained = trained_lifter_path(tmp_path)
    trained.parent.mkdir(parents=True, exist_ok=True)
    torch.save(tiny_lifter_checkpoint, str(trained))
    active = active_lifter(tmp_path)
    assert active.source == "trained" and active.digest != shipped.digest
    assert "trained here" in active.describe()
    after = _code_version(build_definitions(storage_root=str(tmp_path)))
    assert before.startswith("2-shipped-") and after.startswith("2-trained-") and before != after


def test_a_damaged_trained_lifter_is_an_error_naming_the_file_and_the_way_back(tmp_path):
    trained = trained_lifter_path(tmp_path)
    trained.parent.mkdir(parents=True, exist_ok=True)
    trained.write_bytes(b"\x00not a checkpoint")
    with pytest.raises(LifterWeightsError, match=r"lifter_trained\.pt.*--discard"):
        active_lifter(tmp_path)


def test_lifter_checkpoint_materializes_the_shipped_weights_without_data(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path / "no_data"))
    defs = build_definitions(storage_root=str(tmp_path / "artifacts"))
    (tmp_path / "home").mkdir()
    with dg.instance_for_test(temp_dir=str(tmp_path / "home")) as instance:
        result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                                selection=dg.AssetSelection.assets("lifter_checkpoint"), instance=instance)
        event = instance.get_latest_materialization_event(dg.AssetKey("lifter_checkpoint"))
    assert result.success
    metadata = event.asset_materialization.metadata
    assert metadata["source"].value == "shipped"
    assert event.asset_materialization.tags["dagster/data_version"] == shipped_info()["digest"][:16]


def test_train_discard_returns_to_the_shipped_weights(tmp_path, monkeypatch, capsys, tiny_lifter_checkpoint):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    trained = trained_lifter_path(tmp_path / "artifacts")
    trained.parent.mkdir(parents=True, exist_ok=True)
    torch.save(tiny_lifter_checkpoint, str(trained))
    assert main(["train", "lifter", "--discard"]) == 0
    out = capsys.readouterr().out
    assert not trained.exists() and "shipped lifter is in force again" in out and "shipped with humancal" in out


def test_train_without_mocap_says_what_it_needs(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    monkeypatch.setenv("HUMANCAL_DATA_DIR", str(tmp_path))  # a data root without cmu_mocap/
    with pytest.raises(SystemExit, match="training the lifter needs cmu_mocap/ under the data root"):
        main(["train", "lifter"])
