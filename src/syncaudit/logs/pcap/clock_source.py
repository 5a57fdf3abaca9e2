"""What a capture's packets say about the sensor's time source, for `info`'s warnings.

Velodyne position packets (512 bytes): byte 202 is the PPS status (0 absent,
1 synchronising, 2 locked, 3 error) and a NMEA $GPRMC sentence starts at byte 206 (its
status field A = valid fix, V = void), as the VLP-16 / HDL-32E manuals lay them out. Ouster
lidar packets carry no clock state; the metadata's `timestamp_mode` says what the sensor
was set to.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

PPS_OFFSET = 202
NMEA_OFFSET = 206
PPS_STATES = {0: "absent", 1: "synchronising", 2: "locked", 3: "error"}


@dataclass(slots=True)
class PositionClock:
    """PPS states and GPRMC fix statuses seen in one stream's position packets."""

    pps: dict[int, int] = field(default_factory=dict)
    fixes: dict[str, int] = field(default_factory=dict)

    def add(self, payload: bytes) -> None:
        """Count one position packet's PPS status and NMEA fix status."""
        if len(payload) <= PPS_OFFSET:
            return
        state = payload[PPS_OFFSET]
        self.pps[state] = self.pps.get(state, 0) + 1
        sentence = payload[NMEA_OFFSET:].split(b"\x00", 1)[0].split(b"\r", 1)[0]
        parts = sentence.split(b",")
        fix = (
            parts[2].decode("ascii", "replace")
            if sentence.startswith(b"$GPRMC") and len(parts) > 2
            else "none"
        )
        self.fixes[fix] = self.fixes.get(fix, 0) + 1

    def describe(self) -> str:
        """One line: the PPS states and NMEA fixes with their packet counts."""
        pps = ", ".join(
            f"{PPS_STATES.get(k, f'0x{k:02X}')} x{n}" for k, n in sorted(self.pps.items())
        )
        fixes = ", ".join(
            f"{'no $GPRMC' if k == 'none' else 'valid' if k == 'A' else 'void' if k == 'V' else k} x{n}"
            for k, n in sorted(self.fixes.items())
        )
        return f"PPS {pps or 'none'}; NMEA fix {fixes or 'none'}"


def ouster_timestamp_mode(metadata_text: str | None) -> str | None:
    """The metadata's timestamp_mode (flat or nested format), None where absent."""
    if not metadata_text:
        return None
    try:
        root = json.loads(metadata_text)
    except ValueError:
        return None
    if not isinstance(root, dict):
        return None
    for place in (root, root.get("config_params")):
        mode = place.get("timestamp_mode") if isinstance(place, dict) else None
        if isinstance(mode, str):
            return mode
    return None
