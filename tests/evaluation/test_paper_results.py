"""The paper's numbers as read from evaluation/paper_results.csv (anchors checked against the paper's text)."""

import pandas as pd
import pytest

from evaluation.paper_results import PAPER_COLUMNS, PAPER_FILE, paper_results, peer_results


def _value(table, dataset, method, metric):
    rows = table[(table["dataset"] == dataset) & (table["method"] == method) & (table["metric"] == metric)]
    assert len(rows), (dataset, method, metric)
    assert rows["value"].nunique() == 1
    return float(rows["value"].iloc[0])


def test_the_anchors_are_in_the_file():
    paper = paper_results()
    assert list(paper.columns) == list(PAPER_COLUMNS)
    # Table V, Shelf, "Ours +int +ext." (fully self-calibrated)
    assert _value(paper, "shelf", "int_ext", "focal_error_pct") == 6.14
    assert _value(paper, "shelf", "int_ext", "position_error_mm") == 26.45
    assert _value(paper, "shelf", "int_ext", "angle_error_deg") == 1.32
    assert _value(paper, "shelf", "int_ext", "reprojection_error_px") == 11.33
    # Shelf PCP average (derived from the three actors): ground-truth cameras / fully self-calibrated
    assert round(_value(paper, "shelf", "gt_cameras", "pcp_avg"), 1) == 98.1
    assert round(_value(paper, "shelf", "int_ext", "pcp_avg"), 1) == 93.8
    assert (paper.loc[paper["metric"] == "pcp_avg", "note"].str.contains("derived")).all()


def test_every_table_and_regime_is_there():
    paper = paper_results()
    assert {f"Table {n}" for n in ("I", "II", "III", "IV", "V", "VI", "VII", "VIII")} <= set(paper["table"])
    shelf_cameras = paper[(paper["table"] == "Table V") & (paper["dataset"] == "shelf")]
    assert {"init", "separate", "ext", "int_ext", "per_frame_prior", "gt_cameras", "dmmr_int_ext"} <= set(shelf_cameras["method"])
    assert {"no_local_linear", "basic_gru", "no_skip"} <= set(paper.loc[paper["table"] == "Table VII", "method"])
    assert {"campus", "shelf", "panoptic", "mhhi"} <= set(paper["dataset"])
    assert paper["value"].notna().all()


def test_the_loader_rejects_a_damaged_file(tmp_path):
    raw = pd.read_csv(PAPER_FILE, comment="#", dtype=str, keep_default_na=False)
    bad = tmp_path / "paper.csv"
    raw.drop(columns="note").to_csv(bad, index=False)
    with pytest.raises(ValueError, match="columns must be"):
        paper_results(bad)
    raw.assign(value=raw["value"].where(raw.index != 3, "n/a")).to_csv(bad, index=False)
    with pytest.raises(ValueError, match="finite number"):
        paper_results(bad)
    # Table I and Table VI both give DMMR's Shelf PCP: a typo in one of them is caught
    typo = (raw["table"] == "Table VI") & (raw["method"] == "dmmr") & (raw["dataset"] == "shelf")
    raw.assign(value=raw["value"].where(~typo, "1.0")).to_csv(bad, index=False)
    with pytest.raises(ValueError, match="dmmr shelf pcp_actor\\d differs between tables"):
        paper_results(bad)


def test_peer_results_name_their_tool():
    peers = peer_results()
    pose2sim = peers[peers["source"] == "pose2sim"]
    assert _value(pose2sim, "shelf", "pose2sim_gt_cameras", "pcp_avg") == 94.45
