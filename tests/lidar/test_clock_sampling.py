"""ClockEstimator keeps every stride-th difference across chunks, as the index mask did.

The estimator decimates its quantile sample by doubling a stride once the sample exceeds
SAMPLE_CAP. Picking the kept differences by slicing must keep exactly those the mask
`(arange(n) + phase) % stride == 0` kept (main afb8a17), whatever the chunk sizes.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.lidar import clock
from syncaudit.lidar.clock import ClockEstimator


def _reference_sample(chunks: list[NDArray[np.int64]], cap: int) -> NDArray[np.int64]:
    """The kept differences by the index mask and the same doubling rule."""
    stride, phase, sample, size = 1, 0, [], 0
    for raw in chunks:
        kept = raw[(np.arange(raw.size) + phase) % stride == 0]
        phase = (phase + raw.size) % stride
        sample.append(kept)
        size += kept.size
        if size > cap:
            merged = np.concatenate(sample)[::2]
            sample, size, stride = [merged], merged.size, stride * 2
    return np.concatenate(sample)


@pytest.mark.parametrize("seed", range(5))
def test_sample_as_the_mask_kept(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    cap = 50
    monkeypatch.setattr(clock, "SAMPLE_CAP", cap)
    rng = np.random.default_rng(seed)
    sensor = [np.cumsum(rng.integers(1, 10**6, int(rng.integers(1, 40)))) for _ in range(60)]
    driver = [s + rng.integers(150_000, 900_000, s.size) for s in sensor]
    estimator = ClockEstimator()
    for d, s in zip(driver, sensor, strict=True):
        estimator.feed(d, s)
    want = _reference_sample([d - s for d, s in zip(driver, sensor, strict=True)], cap)
    assert estimator._stride >= 8  # decimated several times, phases carried across chunks
    np.testing.assert_array_equal(np.concatenate(estimator._sample), want)
    report = estimator.finish()
    assert report is not None
    assert report.raw_median_ns == int(np.median(want))
    assert report.t1_p99_ns == float(np.percentile(want.astype(np.float64), 99))
