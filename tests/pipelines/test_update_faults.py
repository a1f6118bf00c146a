"""`humancal update` faults, on toy assets (no external data):

* one output of a step that cannot be subset (a multi-asset like ``body_fit``) deleted: the whole step reruns
  (it used to fail every later update with ``DagsterInvalidSubsetError``);
* a partition that keeps failing: the fan-in is computed without it (and told why), the failure is reported once
  and then reminded, not retried while nothing changed, retried under ``--partition`` or after a change;
* an unchanged artifact is not hashed again (its size and time are recorded beside the data version).
"""

import dagster as dg
import pandas as pd
import pytest

from assets.benchmark import FAN_IN_CONFIG_KEY
from assets.common import UPDATE_CONDITION, table_metadata, table_output
from pipelines.failure_record import FailureRecord
from pipelines.partitions import SEQUENCES
from pipelines.update import stale_asset_partitions, update
from resources.io_managers import ParquetIOManagerFactory, partition_path

GOOD, BAD = "toy__good", "toy__bad"


def _views(sequence: str, width_px: int) -> pd.DataFrame:
    return pd.DataFrame({"sequence": [sequence], "view": [0], "name": ["cam0"], "width_px": [width_px], "height_px": [480]})


class LeftOut(dg.Config):
    left_out: dict[str, str] = {}


def toy_defs(storage, fail: str | None = None, code: str = "1") -> dg.Definitions:
    """raw -> (left, right: one step that cannot be subset) -> metric_tables -> summary (fan-in, every partition).
    ``metric_tables`` of partition ``fail`` raises."""

    @dg.asset(partitions_def=SEQUENCES, metadata=table_metadata("views"), code_version="1",
              automation_condition=UPDATE_CONDITION)
    def raw(context: dg.AssetExecutionContext) -> dg.Output:
        return table_output(_views(context.partition_key, 640), "views")

    @dg.multi_asset(outs={name: dg.AssetOut(metadata=table_metadata("views"), code_version="1",
                                            automation_condition=UPDATE_CONDITION) for name in ("left", "right")},
                    partitions_def=SEQUENCES, can_subset=False)
    def pair(raw: pd.DataFrame):
        yield table_output(raw, "views", output_name="left")
        yield table_output(raw.assign(width_px=raw["width_px"] + 1), "views", output_name="right")

    @dg.asset(partitions_def=SEQUENCES, metadata=table_metadata("views"), code_version=code,
              automation_condition=UPDATE_CONDITION)
    def metric_tables(context: dg.AssetExecutionContext, left: pd.DataFrame, right: pd.DataFrame) -> dg.Output:
        if context.partition_key == fail:
            raise ValueError(f"{fail} cannot be calibrated")
        return table_output(right, "views")

    @dg.asset(deps=["metric_tables"], metadata={**table_metadata("views"), FAN_IN_CONFIG_KEY: True},
              code_version="1", automation_condition=UPDATE_CONDITION)
    def summary(context: dg.AssetExecutionContext, config: LeftOut) -> dg.Output:
        read = [p for p in sorted(context.instance.get_dynamic_partitions(SEQUENCES.name)) if p not in config.left_out]
        rows = pd.concat([pd.read_parquet(str(partition_path(str(storage), "metric_tables", p))) for p in read])
        return table_output(rows.assign(view=range(len(rows))), "views")

    return dg.Definitions(assets=[raw, pair, metric_tables, summary],
                          resources={"io_manager": ParquetIOManagerFactory(base_path=str(storage))})


@pytest.fixture
def instance():
    inst = dg.DagsterInstance.ephemeral()
    inst.add_dynamic_partitions(SEQUENCES.name, [BAD, GOOD])
    return inst


def _summary_sequences(storage) -> list[str]:
    return sorted(pd.read_parquet(str(partition_path(str(storage), "summary", None)))["sequence"])


def test_a_deleted_output_of_a_step_that_cannot_be_subset_reruns_the_whole_step(instance, tmp_path):
    storage = tmp_path / "artifacts"
    defs = toy_defs(storage)
    assert update(defs, instance).failed == ()
    partition_path(str(storage), "right", GOOD).unlink()
    assert [(k.to_user_string(), p) for k, p, _ in stale_asset_partitions(defs, instance)] == [("right", GOOD)]
    result = update(defs, instance)  # used to raise DagsterInvalidSubsetError
    assert sorted(result.materialized) == [("left", GOOD), ("right", GOOD)] and result.failed == ()
    assert update(defs, instance).count == 0


def test_a_failing_partition_is_left_out_of_the_fan_in_reported_once_then_reminded(instance, tmp_path):
    storage, record = tmp_path / "artifacts", tmp_path / "update_failures.json"
    defs = toy_defs(storage, fail=BAD)
    first = update(defs, instance, failures=FailureRecord(record))
    assert [(a, p) for a, p, _ in first.failed] == [("metric_tables", BAD)]
    assert ("summary", None) in first.materialized and _summary_sequences(storage) == [GOOD]
    [(asset, partition, reason)] = first.left_out
    assert (asset, partition) == ("summary", BAD) and "ValueError: toy__bad cannot be calibrated" in reason
    assert first.waiting == () and first.exit_status == 1

    again = update(defs, instance, failures=FailureRecord(record))  # nothing changed: not retried
    assert again.count == 0 and again.failed == () and again.waiting == ()
    [reminder] = again.earlier_failed
    assert (reminder.asset, reminder.partition) == ("metric_tables", BAD) and "cannot be calibrated" in reminder.message
    assert again.exit_status == 0  # nothing new went wrong

    named = update(defs, instance, partitions=[BAD], failures=FailureRecord(record))  # asked for by name: retried
    assert [(a, p) for a, p, _ in named.failed] == [("metric_tables", BAD)] and named.exit_status == 1

    bumped = toy_defs(storage, fail=BAD, code="2")  # a new code version: retried everywhere, fails again
    retried = update(bumped, instance, failures=FailureRecord(record))
    assert ("metric_tables", GOOD) in retried.materialized and [(a, p) for a, p, _ in retried.failed] == [
        ("metric_tables", BAD)]

    fixed = toy_defs(storage, code="3")
    done = update(fixed, instance, failures=FailureRecord(record))
    assert ("metric_tables", BAD) in done.materialized and ("summary", None) in done.materialized
    assert _summary_sequences(storage) == [BAD, GOOD] and done.left_out == () and done.exit_status == 0
    assert not record.exists()  # nothing failing is remembered
    assert update(fixed, instance, failures=FailureRecord(record)).count == 0


def test_the_fan_in_waits_when_every_partition_fails(instance, tmp_path):
    storage = tmp_path / "artifacts"
    defs = toy_defs(storage, fail=BAD)
    instance.delete_dynamic_partition(SEQUENCES.name, GOOD)
    result = update(defs, instance)
    [(name, _, reason)] = result.waiting
    assert name == "summary" and "metric_tables[toy__bad] failed" in reason
    assert ("summary", None) not in result.materialized


def test_an_unchanged_artifact_is_not_hashed_again(instance, tmp_path, monkeypatch):
    import pipelines.artifact_check as artifact_check

    storage = tmp_path / "artifacts"
    defs = toy_defs(storage)
    update(defs, instance)
    hashed = []
    original = artifact_check.stored_content_version
    monkeypatch.setattr(artifact_check, "stored_content_version", lambda *a: hashed.append(a[0]) or original(*a))
    assert stale_asset_partitions(defs, instance) == [] and hashed == []
    path = partition_path(str(storage), "left", GOOD)
    path.write_bytes(path.read_bytes())  # same content, a new modification time: hashed, and still fresh
    assert stale_asset_partitions(defs, instance) == [] and [str(p) for p in hashed] == [str(path)]


@pytest.fixture
def cli_on(instance, tmp_path, monkeypatch):
    """``humancal`` on the toy graph whose partition toy__bad fails, a user's capture (dataset ``toy``)."""
    import pipelines.cli as cli
    import pipelines.definitions
    from humancal.datasets.sequences import add_user_sequence

    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path / "state"))
    add_user_sequence("toy", "bad", "capture", {"format": "openpose", "views": ["a/"]})
    monkeypatch.setattr(pipelines.definitions, "defs", toy_defs(tmp_path / "artifacts", fail=BAD))
    monkeypatch.setattr(cli, "_instance", lambda: instance)
    monkeypatch.setattr(cli, "register_partitions", lambda instance, defs: [BAD, GOOD])
    monkeypatch.setattr(cli, "_check_partitions", lambda requested, defs: None)
    monkeypatch.setattr(cli, "_report_missing_data", lambda defs, emit=print: {})
    monkeypatch.setattr(cli, "_print_active_lifter", lambda emit=print: None)
    return lambda *argv: cli.main(list(argv))


def test_the_cli_says_it_once_then_reminds_and_keeps_the_exit_status_honest(cli_on, capsys):
    way_out = "(fix the capture, then `humancal update --partition toy__bad` retries it; or `humancal remove toy`)"
    assert cli_on("update", "-v") == 1
    out, err = capsys.readouterr()
    assert f"FAILED toy__bad: metric_tables: ValueError: toy__bad cannot be calibrated {way_out}" in err.splitlines()
    assert "summary computed without toy__bad (metric_tables[toy__bad] failed: " in out  # -v
    assert cli_on("update") == 0
    out, err = capsys.readouterr()
    assert "materialized 0 asset partitions" in out and "summary" not in out
    [reminder] = err.splitlines()
    assert reminder.startswith("reminder: toy__bad failed in an earlier update (") and reminder.endswith(
        f"not retried: metric_tables: ValueError: toy__bad cannot be calibrated {way_out}")
    assert cli_on("update", "--partition", BAD) == 1  # asked for by name: retried, and it fails
    assert "FAILED toy__bad" in capsys.readouterr().err
