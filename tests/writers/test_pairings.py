"""Corrected timestamp pairings written back out and read again."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.audit import audit_log
from syncaudit.logs import open_log
from syncaudit.rig import load_rig
from syncaudit.writers.pairings import PAIRING_TYPE, pairing_topic, write_pairings

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_short.bag"


@pytest.mark.parametrize("name", ["pairings.mcap", "pairings.bag"])
def test_pairings_round_trip(tmp_path: Path, name: str) -> None:
    result = audit_log(SAMPLE, load_rig(f"{SAMPLE}.rig.yaml"), jobs=1)
    out = tmp_path / name
    written = write_pairings(result, out)
    assert written == sum(c.sync.frames_total for c in result.cameras)
    with open_log(out) as log:
        for cam in result.cameras:
            topic = pairing_topic(cam.sync.camera)
            assert log.topics[topic].msgtype == PAIRING_TYPE
            msgs: list[Any] = [log.deserialize(m) for m in log.messages([topic])]
            frames = cam.sync.frames
            assert len(msgs) == len(frames)
            lidar_ns = np.array(
                [m.lidar_at_camera.sec * 10**9 + m.lidar_at_camera.nanosec for m in msgs]
            )
            assert np.array_equal(lidar_ns, np.rint(frames["t_estimated_ns"]).astype(np.int64))
            err = np.array([m.sync_error for m in msgs])
            assert np.allclose(err, frames["error_signed_ns"].to_numpy() / 1e9, atol=1e-9)
            assert all(m.paired for m in msgs)
    # An existing output is never clobbered silently.
    with pytest.raises(Exception, match="exists"):
        write_pairings(result, out)
