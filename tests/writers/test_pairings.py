"""Corrected timestamp pairings written back out and read again."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.audit.run import audit_log
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
            assert np.array_equal(lidar_ns, frames["t_estimated_ns"].to_numpy(np.int64))
            err = np.array([m.sync_error for m in msgs])
            assert np.allclose(err, frames["error_signed_ns"].to_numpy() / 1e9, atol=1e-9)
            assert all(m.paired for m in msgs)
    # An existing output is never clobbered silently.
    with pytest.raises(Exception, match="exists"):
        write_pairings(result, out)


def _ns(t: Any) -> int:
    return int(t.sec) * 10**9 + int(t.nanosec)


def test_pairing_stamps_are_the_exact_image_stamps(tmp_path: Path) -> None:
    """Every pairing joins its image by stamp: no float64 epoch ns (256 ns steps) on the way."""
    result = audit_log(SAMPLE, load_rig(f"{SAMPLE}.rig.yaml"), jobs=1)
    out = tmp_path / "pairings.mcap"
    write_pairings(result, out)
    with open_log(SAMPLE) as log:
        image_topics = {t for t in log.topics if t.endswith("image_raw")}
        image_stamps = {
            _ns(log.deserialize(m).header.stamp) for m in log.messages(sorted(image_topics))
        }
    assert len(image_stamps) > 50
    with open_log(out) as log:
        pairings: list[Any] = [log.deserialize(m) for m in log.messages(sorted(log.topics))]
    assert len(pairings) == sum(c.sync.frames_total for c in result.cameras)
    assert {_ns(m.image_stamp) for m in pairings} <= image_stamps
    # The exposure middles are exact too: t_l is stored as int64 end to end.
    t_l = np.concatenate([c.sync.frames["t_l_ns"].to_numpy(np.int64) for c in result.cameras])
    assert sorted(_ns(m.exposure_middle) for m in pairings) == sorted(t_l.tolist())
    assert np.any(t_l % 256 != 0)
