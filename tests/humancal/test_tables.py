import numpy as np
import pandas as pd
import pytest

from humancal.tables.schemas import SCHEMAS, TableError, empty_table, to_arrow, validate_table


def _detections(**overrides):
    data = {
        "sequence": ["s", "s"], "frame": [0, 1], "view": [0, 0], "det_id": [0, 0],
        "joint": ["nose", "left_eye"], "x_px": [10.0, 11.0], "y_px": [5.0, 6.0], "score": [0.9, 0.5],
    }
    data.update(overrides)
    return pd.DataFrame(data)


def test_every_schema_roundtrips_an_empty_table():
    for name, schema in SCHEMAS.items():
        assert to_arrow(empty_table(name), name).schema.equals(schema)


def test_valid_detections_pass_and_keep_declared_dtypes():
    out = validate_table(_detections(), "detections")
    assert out["frame"].dtype == np.int32 and out["x_px"].dtype == np.float64


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"x_px": [np.nan, 1.0]}, "column 'x_px' has 1 non-finite"),
        ({"score": [1.5, 0.2]}, "'score' must lie in [0, 1]"),
        ({"frame": [-1, 0]}, "column 'frame' must be >= 0"),
        ({"joint": [None, "nose"]}, "column 'joint' has 1 missing"),
        ({"frame": ["a", "b"]}, "column 'frame' cannot be stored as int32"),
    ],
)
def test_bad_values_name_table_and_column(overrides, message):
    with pytest.raises(TableError, match=message.replace("[", r"\[").replace("]", r"\]")):
        validate_table(_detections(**overrides), "detections", source="unit-test")


def test_missing_and_extra_columns_are_errors():
    with pytest.raises(TableError, match=r"missing column\(s\) \['score'\]"):
        validate_table(_detections().drop(columns="score"), "detections")
    with pytest.raises(TableError, match=r"unexpected column\(s\) \['extra'\]"):
        validate_table(_detections().assign(extra=1), "detections")
    with pytest.raises(TableError, match="unknown table"):
        validate_table(_detections(), "detectionz")


def test_metrics_view_and_failed_checks_are_the_nullable_columns():
    rows = pd.DataFrame({"dataset": "d", "sequence": "s", "method": "m", "metric": ["a", "a"],
                         "view": [None, 2], "value": [1.0, 2.0], "unit": "px", "failed_checks": [None, "rig_geometry"]})
    out = validate_table(rows, "metrics")
    assert str(out["view"].dtype) == "Int32" and out["view"].isna().tolist() == [True, False] and out["view"][1] == 2
    assert out["failed_checks"].isna().tolist() == [True, False] and out["failed_checks"][1] == "rig_geometry"
    with pytest.raises(TableError, match="column 'view' must be >= 0"):
        validate_table(rows.assign(view=[None, -1]), "metrics")
    with pytest.raises(TableError, match="column 'metric' has 1 missing"):
        validate_table(rows.assign(metric=[None, "a"]), "metrics")
    with pytest.raises(TableError, match="column 'view' has 1 missing"):
        validate_table(_detections(view=[None, 0]), "detections")
