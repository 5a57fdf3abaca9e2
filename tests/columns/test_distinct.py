"""`distinct` gives np.unique's values for integer columns without importing numpy.ma."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from syncaudit.columns.distinct import distinct

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "pandar40p_adaptive.mcap"


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.intp, np.bool_])
def test_same_values_and_dtype_as_np_unique(dtype: type[np.generic]) -> None:
    rng = np.random.default_rng(7)
    for size in (0, 1, 2, 5, 1000):
        values = rng.integers(0, 4 if dtype is np.bool_ else 50, size=size).astype(dtype)
        got, want = distinct(values), np.unique(values)
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)


def test_flattens_like_np_unique() -> None:
    values = np.array([[3, 1, 3], [-2, 1, 7]], dtype=np.int64)
    np.testing.assert_array_equal(distinct(values), [-2, 1, 3, 7])


def test_refuses_floats() -> None:
    """NaN != NaN: a float column would keep every NaN, where np.unique keeps one."""
    with pytest.raises(TypeError, match="float64"):
        distinct(np.array([np.nan, np.nan]))


SCRIPT = """
import sys
from syncaudit.logs import open_log
from syncaudit.lidar.stream import decode_scan

with open_log(sys.argv[1]) as log:
    n = 0
    for msg in log.messages(["/pandar_packets"]):
        n += decode_scan("hesai", msg, 0) is not None
print(n, "numpy.ma" in sys.modules)
"""


def test_hesai_decoding_does_not_import_numpy_ma() -> None:
    """A reader worker decoding Hesai scans (model detection per message) never imports
    numpy.ma (~8 ms per worker)."""
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(SAMPLE)], capture_output=True, text=True, check=True
    )
    decoded, imported = done.stdout.split()
    assert int(decoded) == 100 and imported == "False"
