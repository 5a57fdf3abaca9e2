"""Per-point times of PointCloud2 scans (calib.io.decode_xyz_times), the input of deskewing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from syncaudit.calib.io import iter_scans
from syncaudit.simulate.calib_config import calib_scene_config
from syncaudit.simulate.calib_session import simulate_calib_session


def test_velodyne_and_ouster_point_times_span_one_sweep(tmp_path: Path) -> None:
    """The simulator writes the front LiDAR as Velodyne XYZIRT (`time`, float s) and the
    rear as ouster-ros (`t`, uint32 ns): both decode to ns from the scan stamp, within
    one 0.1 s sweep, every point with its own time."""
    out = tmp_path / "s.mcap"
    config = calib_scene_config(motion="drive", beams=16, n_stops=2, organized="second")
    simulate_calib_session(out, config)
    seen = set()
    for scan in iter_scans(out, ["/lidar/front/points", "/lidar/rear/points"]):
        assert scan.times_ns is not None
        assert scan.times_ns.shape[0] == scan.points_m.shape[0]
        assert scan.times_ns.dtype == np.int64
        assert int(scan.times_ns.min()) >= -1_000_000 and int(scan.times_ns.max()) <= 100_000_000
        assert int(scan.times_ns.max()) - int(scan.times_ns.min()) > 10_000_000
        seen.add(scan.topic)
    assert seen == {"/lidar/front/points", "/lidar/rear/points"}
