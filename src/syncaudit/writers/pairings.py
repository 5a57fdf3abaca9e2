"""Write each audited frame's corrected timing back out as a log of FramePairing messages."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from syncaudit.audit import AuditResult
from syncaudit.writers.log_writer import infer_format, open_writer

PAIRING_TYPE = "syncaudit_msgs/msg/FramePairing"


def pairing_topic(camera: str) -> str:
    """Topic the pairings of one camera go to."""
    return f"/syncaudit/{camera}/pairing"


def _ns(value: Any) -> int:
    """A whole number from a table cell; 0 for None, NaN and pandas' NA (TypeError on float)."""
    try:
        number = float(value)
    except TypeError:
        return 0
    return round(number) if math.isfinite(number) else 0


def write_pairings(result: AuditResult, out: Path, overwrite: bool = False) -> int:
    """Write one FramePairing per frame (MCAP, .db3 or .bag by the suffix); returns the count."""
    count = 0
    with open_writer(out, infer_format(out), overwrite=overwrite) as writer:
        for cam in result.cameras:
            topic = pairing_topic(cam.sync.camera)
            writer.add_topic(topic, PAIRING_TYPE)
            rows: Any = cam.sync.frames.itertuples(index=False)  # pandas rows are untyped
            for row in rows:
                t_l = _ns(row.t_l_ns)
                stamp = t_l or _ns(row.header_stamp_ns)
                msg = writer.new_msg(
                    PAIRING_TYPE,
                    header=writer.header(stamp, str(cam.sync.camera)),
                    camera=str(cam.sync.camera),
                    frame_sequence=_ns(row.frame_sequence) or 0,
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
