"""The benchmark table and its markdown, on small hand-made metric tables."""

import numpy as np
import pandas as pd

from evaluation.benchmark import (
    SECTIONS,
    Section,
    benchmark_markdown,
    benchmark_table,
    stage_timings_markdown,
)
from humancal.tables.schemas import SCHEMAS


def _rows(dataset, sequence, method, figures, failed=None, view=None):
    return pd.DataFrame({"dataset": dataset, "sequence": sequence, "method": method, "metric": list(figures),
                         "view": pd.array([view] * len(figures), dtype="Int32"), "value": list(figures.values()),
                         "unit": "u", "failed_checks": failed})


PAPER = pd.DataFrame({
    "table": ["Table V", "Table V", "Table VI", "Table I", "Table VI"],
    "label": "x", "row": ["Ours +int +ext.", "Initial ours", "Ours +int +ext.", "DMMR", "DMMR"],
    "method": ["int_ext", "init", "int_ext", "dmmr", "dmmr"],
    "dataset": ["shelf", "shelf", "shelf", "shelf", "shelf"],
    "metric": ["focal_error_pct", "focal_error_pct", "pcp_avg", "pcp_avg", "pcp_avg"],
    "value": [6.14, 8.15, 93.83, 97.97, 97.97], "unit": ["%"] * 5, "note": "",
})
PEERS = pd.DataFrame({"dataset": ["shelf"], "sequence": ["test"], "method": ["pose2sim_gt_cameras"],
                      "metric": ["pcp_avg"], "value": [94.45], "unit": ["%"], "source": ["pose2sim"], "note": [""]})


def _metrics():
    return pd.concat([
        _rows("shelf", "test", "init", {"focal_error_pct": 9.0, "position_error_mm": 300.0}, "focal_constrained"),
        _rows("shelf", "test", "init", {"focal_error_pct": 12.0}, "", view=0),  # per view: not in the benchmark
        _rows("shelf", "test", "int_ext", {"focal_error_pct": 5.0, "pcp_avg": 94.0}, ""),
        _rows("shelf", "test", "epipolar_only", {"pcp_avg": 92.8}),
        _rows("synthetic", "demo", "int_ext", {"mpjpe_mm": 30.0, "seconds": 12.0}),
        _rows("synthetic", "demo", "no_skip", {"mpjpe_mm": 33.0}),
    ], ignore_index=True)


def test_table_has_ours_the_paper_and_the_peers_with_their_source():
    table = benchmark_table(_metrics(), PAPER, PEERS)
    assert list(table.columns) == SCHEMAS["benchmark"].names
    by = {(r.dataset, r.sequence if isinstance(r.sequence, str) else None, r.method, r.metric, r.source): r.value
          for r in table.itertuples()}
    assert by[("shelf", "test", "init", "focal_error_pct", "humancal")] == 9.0  # the headline, not the view's
    assert by[("shelf", "test", "epipolar_only", "pcp_avg", "epipolar")] == 92.8
    assert by[("shelf", "test", "pose2sim_gt_cameras", "pcp_avg", "pose2sim")] == 94.45
    assert by[("shelf", None, "int_ext", "focal_error_pct", "paper")] == 6.14
    assert (table["source"] == "paper").sum() == 4  # DMMR given by two tables: once
    paper_rows = table[table["source"] == "paper"]
    assert paper_rows["sequence"].isna().all() and paper_rows["paper_table"].notna().all()


def test_a_figure_given_twice_keeps_the_later_one():
    later = _rows("shelf", "test", "int_ext", {"pcp_avg": 95.5}, "")
    table = benchmark_table(pd.concat([_metrics(), later], ignore_index=True), PAPER, None)
    ours = table[(table["method"] == "int_ext") & (table["metric"] == "pcp_avg") & (table["source"] == "humancal")]
    assert ours["value"].tolist() == [95.5]


def test_markdown_puts_ours_beside_the_paper_and_leaves_missing_figures_blank():
    text = benchmark_markdown(benchmark_table(_metrics(), PAPER, PEERS))
    cameras = text.split("### Cameras: shelf / test")[1].split("###")[0]
    init = next(line for line in cameras.splitlines() if line.startswith("| init"))
    cells = [c.strip() for c in init.strip("|").split("|")]
    header = [c.strip() for c in cameras.splitlines()[2].strip("|").split("|")]
    assert cells[header.index("focal % here")] == "9.00*" and cells[header.index("focal % paper")] == "8.15"
    assert cells[header.index("pos. mm here")] == "300.00*"
    assert "failed checks: focal_constrained" in cameras
    int_ext = next(line for line in cameras.splitlines() if line.startswith("| int_ext"))
    assert [c.strip() for c in int_ext.strip("|").split("|")][header.index("pos. mm here")] == ""  # not measured
    pcp = text.split("### PCP: shelf / test")[1].split("###")[0]
    assert "| epipolar_only" in pcp and "epipolar" in pcp and "pose2sim" in pcp and "| dmmr" in pcp
    synthetic = text.split("\n## Synthetic scenes\n")[1]
    assert "| no_skip" in synthetic and " paper" not in synthetic  # ours only
    assert "Ablations: synthetic / demo" in text  # the prior ablation that ran


def test_sections_are_declared_and_an_empty_table_renders():
    assert all(isinstance(s, Section) for s in SECTIONS)
    assert [s.title for s in SECTIONS] == ["Cameras", "PCP", "Ablations", "Synthetic scenes"]
    empty = benchmark_table(_metrics().iloc[:0], PAPER.iloc[:0], None)
    assert len(empty) == 0 and "no figure" in benchmark_markdown(empty)


def test_stage_timings_markdown_lists_assets_per_sequence_and_the_total():
    timings = pd.DataFrame({"sequence": ["a__b", "a__b", "a__b"], "asset": ["detections", "metric_tables", "total"],
                            "step": ["detections", "metric_tables", ""], "seconds": [1.25, 2.0, 3.25],
                            "run_id": ["r", "r", None], "materialized_at": pd.NaT})
    paper = pd.DataFrame({"table": "Sec. IV-B", "label": "", "row": ["Ours, whole fit"], "method": ["int_ext"],
                          "dataset": ["reference_workload"], "metric": ["seconds"], "value": [330.0], "unit": ["s"],
                          "note": ["30 s 5-view video; about"]})
    text = stage_timings_markdown(timings, paper)
    lines = text.splitlines()
    assert "a__b" in lines[0] and lines[-1].startswith("The paper (30 s 5-view video): Ours, whole fit: 330 s")
    assert any(line.startswith("| total") and "3.2" in line for line in lines)
    assert np.isfinite(timings["seconds"]).all()
