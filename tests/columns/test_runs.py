"""run_starts: the first index of each run equals np.unique's on nondecreasing columns."""

from __future__ import annotations

import numpy as np
import pytest

from syncaudit.columns.runs import run_starts


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.intp])
def test_equals_np_unique_on_nondecreasing(dtype: type[np.integer]) -> None:
    rng = np.random.default_rng(2)
    for size in [1, 2, 3, 10, 1_000]:
        for _ in range(20):
            values = np.sort(rng.integers(0, min(200, max(2, size // 3)), size)).astype(dtype)
            starts = run_starts(values)
            assert starts is not None
            unique, first = np.unique(values, return_index=True)
            np.testing.assert_array_equal(starts, first)
            np.testing.assert_array_equal(values[starts], unique)


def test_general_path_where_not_nondecreasing() -> None:
    assert run_starts(np.array([0, 0, 1, 0], dtype=np.int64)) is None
    assert run_starts(np.array([], dtype=np.int64)) is None
    assert run_starts(np.array([0.0, 1.0])) is None  # floats: NaN breaks runs
    assert run_starts(np.zeros((2, 2), dtype=np.int64)) is None
    # Neighbours are compared, not subtracted: no wrap-round hides a step back.
    extreme = np.iinfo(np.int64)
    assert run_starts(np.array([extreme.max, extreme.min], dtype=np.int64)) is None
    assert run_starts(np.array([200, 3], dtype=np.uint8)) is None
    np.testing.assert_array_equal(
        run_starts(np.array([extreme.min, extreme.max], dtype=np.int64)), [0, 1]
    )
    np.testing.assert_array_equal(run_starts(np.array([7, 7, 7], dtype=np.int64)), [0])
