"""The extrinsics asset hands the views' names to the calibration, for its messages."""

import pandas as pd

from assets.calibration import _view_names


def test_view_names_in_view_order():
    views = pd.DataFrame({"view": [1, 0, 2], "name": ["east", "north", 3]})
    assert _view_names(views, 3) == ["north", "east", "3"]


def test_no_names_when_the_table_cannot_name_every_view():
    assert _view_names(pd.DataFrame({"view": [0, 1]}), 2) is None
    assert _view_names(pd.DataFrame({"view": [0, 1], "name": ["a", "b"]}), 3) is None
