"""Asset check results: a check with nothing to examine is a logged warning, never a green pass."""

from unittest import mock

import dagster as dg
import numpy as np
import pandas as pd

from assets.calibration import _focal_constrained_report, _single_view_focal_report, _upright_report
from assets.checks import check_result
from humancal.tables.plausibility import CheckReport


def _intrinsics(status: list[str], candidates: list[int] | None = None) -> pd.DataFrame:
    n = len(status)
    return pd.DataFrame({
        "view": np.arange(n), "fx_px": 1000.0, "fy_px": 1000.0, "width_px": 1920, "height_px": 1080,
        "status": status, "num_candidates": candidates or [50] * n,
    })


def test_not_checked_is_a_logged_warning():
    context = mock.Mock()
    result = check_result(context, "focal_plausible", CheckReport.nothing_to_check("no view"))
    assert result.passed is False
    assert result.severity == dg.AssetCheckSeverity.WARN
    assert result.description == "not checked: no view"
    assert result.metadata["checked"].value == 0
    context.log.warning.assert_called_once_with("check focal_plausible: not checked: no view")


def test_a_failure_keeps_its_severity_and_a_pass_says_how_much_was_checked():
    context = dg.build_asset_context()
    failed = check_result(context, "x", CheckReport(False, "bad", {"a": 1.0}, checked=3))
    assert failed.passed is False and failed.severity == dg.AssetCheckSeverity.ERROR
    passed = check_result(context, "x", CheckReport(True, "good", checked=3))
    assert passed.passed and passed.metadata["checked"].value == 3


def test_intrinsics_focal_check_when_every_view_is_ill_conditioned():
    report = _single_view_focal_report(_intrinsics(["ill_conditioned", "no_upright", "ill_conditioned"]))
    assert report.not_checked and not report.passed
    assert "every view's single-view focal is flagged (ill_conditioned, no_upright)" in report.description
    assert _single_view_focal_report(_intrinsics([])).not_checked


def test_intrinsics_focal_check_names_the_views_it_skipped():
    report = _single_view_focal_report(_intrinsics(["ok", "ill_conditioned"]))
    assert report.passed and report.checked == 1
    assert "views [1] flagged ['ill_conditioned'] (not checked)" in report.description


def test_upright_and_focal_constrained_checks_on_no_view():
    assert _upright_report(_intrinsics([])).not_checked
    assert not _upright_report(_intrinsics(["ok", "ok"], [50, 3])).passed
    per_view = pd.DataFrame({"view": [0, 1], "focal_status": ["ok", "poorly_constrained"],
                             "focal_px": [900.0, 1200.0], "focal_rel_std": [0.01, 0.2]})
    views = pd.DataFrame({"view": [0, 1], "name": ["left", "right"]})
    assert _focal_constrained_report(per_view.iloc[:0], views).not_checked
    report = _focal_constrained_report(per_view, views)
    assert not report.passed and "view 1 (right): focal 1200 px +- 20 %" in report.description
    assert "--known-views" in report.description and "--drop-view" in report.description
    at_bound = per_view.assign(focal_rel_std=[0.01, np.inf], bundle_status=["ok", "focal_at_bound"])
    assert "view 1 (right): focal 1200 px undetermined (focal at bound)" in _focal_constrained_report(
        at_bound, views).description  # never "+- 0 %"
