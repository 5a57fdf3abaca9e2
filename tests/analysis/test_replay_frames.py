"""The controller replay per frame: each corrected error is the recorded one moved by the delay change."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from syncaudit.audit.run import audit_log
from syncaudit.rig import load_rig

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"


def test_replay_per_frame_rows_and_adjustments() -> None:
    result = audit_log(SAMPLE, load_rig(Path(f"{SAMPLE}.rig.yaml")), jobs=1)
    for cam in result.cameras:
        replay = cam.replay
        assert replay is not None
        frames = cam.sync.frames
        errors, delays = replay.per_frame(len(frames))
        rows = replay.frame_rows
        assert np.all(frames["paired"].to_numpy(dtype=bool)[rows])
        recorded = frames["error_signed_ns"].to_numpy(dtype=float)[rows]
        applied = frames["applied_delay_ns"].to_numpy(dtype=float)[rows]
        np.testing.assert_allclose(errors[rows], recorded + (delays[rows] - applied))
        assert np.isnan(np.delete(errors, rows)).all()
        # Before the first adjustment the replay runs the recorded delay.
        first = rows[0] if replay.adjustments == 0 else replay.adjustment_rows[0]
        np.testing.assert_allclose(delays[rows[rows <= first]], applied[rows <= first])
        # After each adjustment the next frame runs the delay it set.
        for row, delay in zip(replay.adjustment_rows, replay.adjustment_delays_ns, strict=True):
            following = rows[rows > row]
            if following.size:
                assert delays[following[0]] == delay
        assert replay.adjustments == replay.adjustment_rows.size > 0
