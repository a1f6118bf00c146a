"""Associations: validation, table round trip, the vectorized detection-to-person lookup."""

import numpy as np
import pandas as pd
import pytest

from humancal.tables.associations import Associations


def _table():
    return pd.DataFrame({"sequence": "s__x", "frame": [0, 0, 0, 1, 1, 7], "view": [0, 1, 1, 0, 2, 1],
                         "det_id": [0, 0, 1, 3, 0, 2], "person_id": [4, 4, -1, 5, 4, 9]})


def test_lookup_agrees_with_a_pandas_reindex():
    table = _table()
    assoc = Associations.from_table(table)
    rng = np.random.default_rng(0)
    frame, view, det = rng.integers(0, 9, 500), rng.integers(0, 4, 500), rng.integers(0, 5, 500)
    frame[:6], view[:6], det[:6] = table["frame"], table["view"], table["det_id"]
    expected = (table.set_index(["frame", "view", "det_id"])["person_id"]
                .reindex(pd.MultiIndex.from_arrays([frame, view, det])).fillna(-1).to_numpy(np.int64))
    got = assoc.person_of(frame, view, det)
    np.testing.assert_array_equal(got, expected)
    assert got[:6].tolist() == [4, 4, -1, 5, 4, 9] and (got[6:] >= 0).any() and (got[6:] == -1).any()
    assert assoc.person_of([100], [0], [0]).tolist() == [-1]  # beyond the table: not listed
    assert Associations.from_table(table.iloc[:0]).person_of([0], [0], [0]).tolist() == [-1]


def test_round_trip_and_validation():
    assoc = Associations.from_table(_table())
    back = Associations.from_table(assoc.to_table("s__x"))
    np.testing.assert_array_equal(back.person_id, assoc.person_id)
    assert len(back) == 6 and assoc.to_table("s__x")["person_id"].dtype == np.int32
    with pytest.raises(ValueError, match=r"frame 0, view 1, det_id 1\) is listed more than once"):
        Associations.from_table(pd.concat([_table(), _table().iloc[[2]]]))
    with pytest.raises(ValueError, match="person_id must be >= -1"):
        Associations.from_table(_table().assign(person_id=-2))
    with pytest.raises(ValueError, match=r"lacks columns \['det_id'\]"):
        Associations.from_table(_table().drop(columns="det_id"))


def test_row_of_finds_rows_in_any_order():
    table = _table().sample(frac=1.0, random_state=1)
    assoc = Associations.from_table(table)
    rows = assoc.row_of(table["frame"].to_numpy()[::-1], table["view"].to_numpy()[::-1], table["det_id"].to_numpy()[::-1])
    assert rows.tolist() == list(range(len(table)))[::-1]
    assert assoc.row_of([0], [2], [0]).tolist() == [-1]
