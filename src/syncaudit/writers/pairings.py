"""Write each audited frame's corrected timing back out as a log of FramePairing messages."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from syncaudit.columns.audit_result import AuditedLog
from syncaudit.writers.log_writer import open_writer
from syncaudit.writers.outputs import OutputSet

PAIRING_TYPE = "syncaudit_msgs/msg/FramePairing"


def pairing_topic(camera: str) -> str:
    """Topic the pairings of one camera go to."""
    return f"/syncaudit/{camera}/pairing"


def _ns(value: Any) -> int:
    """An Int64 value as an exact int (0 where missing: builtin Time has no null)."""
    return 0 if value is None or value is pd.NA else int(value)


def write_pairings(
    result: AuditedLog, out: Path, *, overwrite: bool = False, outputs: OutputSet | None = None
) -> int:
    """Write one FramePairing per frame (MCAP, .db3 or .bag by the suffix); return the count.

    With `outputs` the log goes into that OutputSet (committed by its owner).

    Raises:
        OutputError: `out` exists without `overwrite`, or cannot be written.
    """
    count = 0
    with open_writer(out, None, overwrite=overwrite, outputs=outputs) as writer:
        for cam in result.cameras:
            topic = pairing_topic(cam.sync.camera)
            writer.add_topic(topic, PAIRING_TYPE)
            frames = cam.sync.frames
            # Stamps stay exact int64 (object Ints, <NA> for missing), never float64.
            rows: Any = frames.astype(
                {c: "object" for c in frames.columns if str(frames[c].dtype) == "Int64"}
            ).itertuples(index=False)  # pandas rows are untyped
            for row in rows:
                t_l = _ns(row.t_l_ns)
                stamp = t_l or _ns(row.header_stamp_ns)
                msg = writer.new_msg(
                    PAIRING_TYPE,
                    header=writer.header(stamp, str(cam.sync.camera)),
                    camera=str(cam.sync.camera),
                    frame_sequence=_ns(row.frame_sequence),
                    image_stamp=writer.time(_ns(row.header_stamp_ns)),
                    exposure_middle=writer.time(t_l),
                    lidar_at_camera=writer.time(_ns(row.t_estimated_ns)),
                    revolution_start=writer.time(_ns(row.revolution_start_ns)),
                    sync_error=float(row.error_signed_ns) / 1e9 if row.paired else math.nan,
                    paired=bool(row.paired),
                )
                writer.write_msg(topic, stamp, msg)
                count += 1
    return count
