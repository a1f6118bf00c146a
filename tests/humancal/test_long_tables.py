"""The pivot helpers agree with numpy's and pandas' general (slower) forms."""

import numpy as np
import pandas as pd
import pytest

from humancal.tables.pivot import name_codes, unique_rows


@pytest.mark.parametrize("low, high", [(0, 5), (-3, 4), (0, 2**40)])
def test_unique_rows_is_numpys_unique_over_rows(low, high):
    rng = np.random.default_rng(0)
    keys = rng.integers(low, high, size=(500, 3))
    keys = np.concatenate([keys, keys[:100]])  # repeated rows
    unique, inverse = unique_rows(keys)
    expected, expected_inverse = np.unique(keys, axis=0, return_inverse=True)
    np.testing.assert_array_equal(unique, expected)
    np.testing.assert_array_equal(inverse, expected_inverse.reshape(-1))
    np.testing.assert_array_equal(unique[inverse], keys)
    assert unique.dtype == np.int64 and inverse.dtype == np.int64


def test_unique_rows_of_nothing_and_bad_shapes():
    unique, inverse = unique_rows(np.zeros((0, 2), dtype=np.int64))
    assert unique.shape == (0, 2) and inverse.shape == (0,)
    with pytest.raises(ValueError, match="2-D"):
        unique_rows(np.arange(4))


def test_name_codes_marks_unknown_and_missing_names():
    names = pd.Series(["b", "a", "z", None, "c", "a"], dtype="string")
    np.testing.assert_array_equal(name_codes(names, ("a", "b", "c")), [1, 0, -1, -1, 2, 0])


def test_has_repeats():
    from humancal.tables.pivot import has_repeats

    assert not has_repeats(np.array([0, 3, 1]), 4)
    assert has_repeats(np.array([0, 3, 3]), 4)
    assert not has_repeats(np.zeros(0, dtype=np.int64), 0)
