"""`info`'s view of the trigger design: which one each camera's records look like, and why.

Cheap: the record type decides for TriggerEvents (the chain) and for cameras with no trigger
records (free-running); bare trigger times (`builtin_interfaces/Time`, `TimeReference`) are
read, at most `MAX_TRIGGERS`, and tested against PTP time and the LiDAR's revolutions
(`analysis.designs.guess_design`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from syncaudit.analysis.designs import guess_design
from syncaudit.errors import SyncauditError

if TYPE_CHECKING:
    from syncaudit.columns.lidar import LidarScan
    from syncaudit.logs import LogReader
    from syncaudit.rig import CameraConfig, Rig

MAX_TRIGGERS = 600
"""Bare trigger times read per camera (a minute at 10 Hz)."""
BARE_TRIGGERS = {"builtin_interfaces/msg/Time", "sensor_msgs/msg/TimeReference"}


def _bare_times_ns(log: LogReader, topic: str) -> np.ndarray:
    times: list[int] = []
    for raw in log.messages(topic):
        msg = log.deserialize(raw)
        t = getattr(msg, "time_ref", msg)
        times.append(int(t.sec) * 1_000_000_000 + int(t.nanosec))  # type: ignore[attr-defined]
        if len(times) >= MAX_TRIGGERS:
            break
    return np.asarray(times, dtype=np.int64)


def camera_design(
    log: LogReader, camera: CameraConfig, rig: Rig | None, scan: LidarScan | None
) -> tuple[str, str]:
    """(design, why) of one camera as `info` sees it."""
    stated = rig.trigger.design if rig is not None else None
    if stated is not None:
        return stated, "stated by the rig (trigger.design)"
    topic = log.topics.get(camera.trigger_topic) if camera.trigger_topic else None
    if topic is None:
        return "free_running", "no trigger records: image stamps and exposure metadata only"
    if topic.msgtype not in BARE_TRIGGERS:
        return "lidar_packet", f"{topic.msgtype} records the trigger chain's checkpoints"
    try:
        times = _bare_times_ns(log, topic.name)
    except Exception as exc:
        return "ptp_phase", f"bare trigger times ({topic.msgtype}) that could not be read: {exc}"
    offset = scan.clock.offset_ns if scan is not None and scan.clock is not None else 0
    zero = (
        scan.revolutions.zero_crossing_sensor_ns + offset
        if scan is not None
        else np.empty(0, dtype=np.int64)
    )
    guess = guess_design(trigger_ns=times, has_checkpoints=False, frame_ns=times, zero_host_ns=zero)
    return guess.design, guess.why


def image_rows(log: LogReader, camera: CameraConfig) -> int | None:
    """The camera's image height from its first CameraInfo (else its first raw Image): the
    rows of a rolling shutter whose rig gives the readout but not the rows."""
    for topic in (camera.info_topic, camera.image_topic):
        info = log.topics.get(topic) if topic else None
        if info is None or info.msgtype not in {
            "sensor_msgs/msg/CameraInfo",
            "sensor_msgs/msg/Image",
        }:
            continue
        try:
            for raw in log.messages(info.name):
                height = int(log.deserialize(raw).height)  # type: ignore[attr-defined]
                return height if height > 0 else None
        except (SyncauditError, ValueError, AttributeError, TypeError):
            continue  # no rows: the rig must give them (the audit warns)
    return None
