"""`humancal remove NAME`: a capture added by the user leaves the user datasets file, the instance's partitions and
the artifacts; packaged datasets are refused; an interrupted removal can be finished."""

from pathlib import Path

import dagster as dg
import pytest
import yaml

from humancal.datasets.sequences import add_user_sequence, remove_user_sequences
from pipelines.cli import main
from pipelines.partitions import SEQUENCES


@pytest.fixture
def state(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "state"
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(folder))
    monkeypatch.setenv("DAGSTER_HOME", str(folder / "dagster_home"))  # restored after the test (the CLI sets it)
    monkeypatch.setenv("HUMANCAL_INBOX", str(tmp_path / "inbox"))
    return folder


def _capture(state: Path, dataset: str, sequences: tuple[str, ...]) -> list[str]:
    """Register a capture as `humancal add` would, with a stored artifact per partition, and its partitions."""
    from pipelines import cli

    keys = []
    for sequence in sequences:
        keys.append(add_user_sequence(dataset, sequence, "capture", {"format": "openpose", "views": ["a/", "b/"]}).key)
        for asset in ("raw_detections", "metric_tables"):
            path = state / "artifacts" / asset / f"{keys[-1]}.parquet"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(b"table")
    cli._instance().add_dynamic_partitions(SEQUENCES.name, keys)
    return keys


def _registered() -> set[str]:
    return set(dg.DagsterInstance.get().get_dynamic_partitions(SEQUENCES.name))


def test_remove_a_capture_everywhere(state, capsys):
    keys = _capture(state, "myrig", ("capture", "take2"))
    _capture(state, "other", ("capture",))
    (state / "artifacts" / "benchmark_table.parquet").write_bytes(b"summary")  # it holds myrig's rows
    assert main(["remove", "myrig", "--sequence", "take2"]) == 0
    assert "myrig__take2" not in _registered() and "myrig__capture" in _registered()
    assert not (state / "artifacts" / "metric_tables" / "myrig__take2.parquet").exists()
    assert (state / "artifacts" / "metric_tables" / "myrig__capture.parquet").exists()
    assert main(["remove", "myrig"]) == 0
    out = capsys.readouterr().out
    assert f"removed {keys[0]} from {state / 'datasets.yaml'}" in out and "deleted 2 artifact file(s)" in out
    assert set(yaml.safe_load((state / "datasets.yaml").read_text())["datasets"]) == {"other"}
    assert _registered() == {"other__capture"}
    assert sorted(p.name for p in (state / "artifacts").rglob("*.parquet")) == ["other__capture.parquet"] * 2
    assert "benchmark_table" in out  # deleted: the next update computes it again without myrig


def test_packaged_and_unknown_datasets_are_refused(state):
    with pytest.raises(SystemExit, match=r"dataset 'synthetic' comes with humancal .*only the captures you added"):
        main(["remove", "synthetic"])
    _capture(state, "myrig", ("capture",))
    with pytest.raises(SystemExit, match=r"no dataset 'nope'; your datasets: myrig"):
        main(["remove", "nope"])
    with pytest.raises(SystemExit, match=r"has no sequence 'take9'; its sequences: capture"):
        main(["remove", "myrig", "--sequence", "take9"])
    assert "myrig__capture" in _registered()


def test_an_interrupted_removal_is_finished(state, capsys):
    [key] = _capture(state, "myrig", ("capture",))
    remove_user_sequences("myrig")  # the config entry went, then the removal was interrupted
    assert main(["remove", "myrig"]) == 0
    assert "removing what is left of it: myrig__capture" in capsys.readouterr().out
    assert key not in _registered() and not list((state / "artifacts").rglob(f"{key}.*"))
