"""`humancal report --benchmark`: from the stored benchmark_table, or built from the stored per-partition tables."""

import os
import time

import pandas as pd
import pyarrow.parquet as pq

from evaluation.benchmark import benchmark_table
from evaluation.paper_results import paper_results
from humancal.tables.schemas import to_arrow
from pipelines.cli import build_parser, main


def _metrics(sequence, value):
    return pd.DataFrame({"dataset": "shelf", "sequence": sequence, "method": "int_ext",
                         "metric": ["focal_error_pct", "pcp_avg"], "view": pd.array([None, None], dtype="Int32"),
                         "value": [value, 90.0], "unit": ["%", "%"], "failed_checks": ""})


def _state(tmp_path, monkeypatch):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "dagster_home"))  # restored after the test
    folder = tmp_path / "artifacts" / "metric_tables"
    folder.mkdir(parents=True)
    pq.write_table(to_arrow(_metrics("test", 7.5), "metrics"), str(folder / "shelf__test.parquet"))
    return tmp_path / "artifacts"


def test_parser_knows_report_benchmark():
    args = build_parser().parse_args(["report", "--benchmark", "--partition", "shelf__test"])
    assert args.benchmark and args.partition == ["shelf__test"]
    assert not build_parser().parse_args(["report"]).benchmark


def test_report_benchmark_builds_from_the_stored_tables_when_not_materialized(tmp_path, monkeypatch, capsys):
    _state(tmp_path, monkeypatch)
    assert main(["report", "--benchmark"]) == 0
    captured = capsys.readouterr()
    assert "benchmark_table is not materialized: built here from the stored per-partition tables" in captured.err
    assert "metric_tables: shelf__test" in captured.err
    cameras = captured.out.split("### Cameras: shelf / test")[1].split("###")[0]
    int_ext = next(line for line in cameras.splitlines() if line.startswith("| int_ext"))
    assert "7.50" in int_ext and "6.14" in int_ext  # ours beside the paper's
    assert "## Per-stage seconds" in captured.out and "no sequence with a materialized metric_tables" in captured.out
    assert main(["report", "--benchmark", "--format", "csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "dataset,sequence,method,metric,source,value,unit,paper_table,failed_checks"
    assert "shelf,test,int_ext,focal_error_pct,humancal,7.5,%,," in lines


def test_report_benchmark_prefers_the_stored_table_and_says_when_it_is_older(tmp_path, monkeypatch, capsys):
    artifacts = _state(tmp_path, monkeypatch)
    stored = artifacts / "benchmark_table.parquet"
    pq.write_table(to_arrow(benchmark_table(_metrics("test", 3.25), paper_results()), "benchmark"), str(stored))
    old = time.time() - 60
    os.utime(stored, (old, old))
    assert main(["report", "--benchmark", "--format", "csv"]) == 0
    captured = capsys.readouterr()
    assert "benchmark_table as stored" in captured.err and "written before metric_tables[shelf__test]" in captured.err
    assert "shelf,test,int_ext,focal_error_pct,humancal,3.25,%,," in captured.out.splitlines()
    assert main(["report", "--benchmark", "--format", "csv", "--partition", "shelf__other"]) == 0
    rows = pd.read_csv(__import__("io").StringIO(capsys.readouterr().out))
    assert (rows["source"] == "paper").all()  # ours restricted to the partition asked for; the paper's stay
