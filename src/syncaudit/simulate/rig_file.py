"""The rig file that goes with a simulated log, derived from its truth."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from syncaudit.rig import Rig


def rig_path(out: Path) -> Path:
    """Where the rig of a simulated log goes: `<out>.rig.yaml` (`x.mcap` -> `x.mcap.rig.yaml`).

    The log's whole name is kept, as for `<out>.truth.json`, so that logs differing only in
    their container (`x.bag`, `x.db3`) get rigs of their own.
    """
    return out.with_name(out.name + ".rig.yaml")


def rig_from_truth(truth: dict[str, Any]) -> Rig:
    """A rig naming the simulated topics and camera azimuths exactly as simulated."""
    lidar = truth["lidar"]
    cameras = []
    for name, cam in truth["cameras"].items():
        topics = cam["topics"]
        cameras.append(
            {
                "name": name,
                "image_topic": topics.get("image"),
                "exposure_topic": topics.get("exposure") or topics.get("meta"),
                "trigger_topic": topics.get("trigger"),
                "azimuth_deg": cam["azimuth_deg"] % 360.0,
                "frame_id": cam.get("frame_id"),
                "hfov_deg": cam["hfov_deg"],
                "stamp": cam["stamp_semantics"],
                **_rolling_shutter(cam),
            }
        )
    return Rig.model_validate(
        {
            "lidar": {
                "topic": lidar["topic"],
                "zero_azimuth_deg": lidar["zero_azimuth_deg"],
                "azimuth_increases": lidar["azimuth_increases"],
                "azimuth_of_x_axis_deg": lidar.get("azimuth_of_x_axis_deg"),
            },
            "cameras": cameras,
        }
    )


def _rolling_shutter(cam: dict[str, Any]) -> dict[str, Any]:
    """readout_us and rows of a simulated rolling-shutter camera (none for a global one)."""
    design = cam.get("trigger_design") or {}
    if not design.get("row_time_ns"):
        return {}
    return {"readout_us": design["row_time_ns"] * design["rows"] / 1e3, "rows": design["rows"]}
