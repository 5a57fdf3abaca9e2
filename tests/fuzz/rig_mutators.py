"""Rig-file mutators: hostile values, contradicting keys, bytes that are not a rig at all."""

from __future__ import annotations

import random
from typing import Any

import yaml

HOSTILE_VALUES: tuple[Any, ...] = (
    float("nan"),
    float("inf"),
    float("-inf"),
    1e308,
    -1e308,
    -1.0,
    0.0,
    360.0,
    1e-320,
    "x",
    None,
    [],
    {},
    True,
    2**70,
)
NUMERIC_KEYS = (
    ("lidar", "zero_azimuth_deg"),
    ("lidar", "azimuth_of_x_axis_deg"),
    ("cameras", 0, "azimuth_deg"),
    ("cameras", 0, "yaw_deg"),
    ("cameras", 0, "hfov_deg"),
    ("cameras", 0, "assumed_exposure_us"),
    ("thresholds", "error_mean_us"),
    ("thresholds", "error_var_us2"),
    ("thresholds", "min_paired_frames"),
    ("thresholds", "min_paired_fraction"),
    ("analysis", "window_frames"),
    ("analysis", "clock_sync_tolerance_ms"),
)


def _set(doc: dict[str, Any], path: tuple[Any, ...], value: Any) -> None:
    node: Any = doc
    for key in path[:-1]:
        node = node[key] if isinstance(key, int) else node.setdefault(key, {})
    if path[-1] == "yaw_deg" and isinstance(node, dict):
        node.pop("azimuth_deg", None)  # so the yaw is what locates the camera
        node.pop("frame_id", None)
    node[path[-1]] = value


def mutate_rig(text: str, rng: random.Random) -> tuple[bytes, str]:
    """A rig with one hostile change, as bytes (some changes are not even UTF-8)."""
    doc: dict[str, Any] = yaml.safe_load(text)
    kind = rng.choice(("value", "value", "value", "vendor", "topic", "structure", "bytes"))
    if kind == "value":
        path = rng.choice(NUMERIC_KEYS)
        value = rng.choice(HOSTILE_VALUES)
        _set(doc, path, value)
        return _dump(doc), f"rig {'.'.join(map(str, path))} = {value!r}"
    if kind == "vendor":
        vendor = rng.choice(("hesai", "ouster", "velodyne", "bogus", ""))
        doc["lidar"]["vendor"] = vendor
        return _dump(doc), f"rig lidar.vendor = {vendor!r}"
    if kind == "topic":
        cam = doc["cameras"][0]
        choice = rng.choice(("lidar-missing", "lidar-is-image", "image-is-lidar", "camera-missing"))
        if choice == "lidar-missing":
            doc["lidar"]["topic"] = "/no/such/topic"
        elif choice == "lidar-is-image":
            doc["lidar"]["topic"] = cam.get("image_topic", "/x")
        elif choice == "image-is-lidar":
            cam["image_topic"] = doc["lidar"]["topic"]
            cam["exposure_topic"] = doc["lidar"]["topic"]
        else:
            cam["image_topic"] = "/no/such/image"
            cam.pop("exposure_topic", None)
            cam.pop("trigger_topic", None)
        return _dump(doc), f"rig topics: {choice}"
    if kind == "structure":
        choice = rng.choice(
            ("no-cameras", "duplicate-camera", "unknown-key", "cameras-not-list", "not-mapping")
        )
        if choice == "no-cameras":
            doc["cameras"] = []
        elif choice == "duplicate-camera":
            doc["cameras"].append(dict(doc["cameras"][0]))
        elif choice == "unknown-key":
            doc["lidar"]["spin_direction"] = "cw"
        elif choice == "cameras-not-list":
            doc["cameras"] = "front"
        else:
            return b"- just\n- a list\n", "rig is a YAML list"
        return _dump(doc), f"rig structure: {choice}"
    choice = rng.choice(("non-utf8", "utf16-bom", "deep-yaml", "empty", "binary", "cut"))
    raw = _dump(doc)
    if choice == "non-utf8":
        return raw[:20] + b"\xff\xfe\xc3\x28" + raw[20:], "rig with invalid UTF-8 bytes"
    if choice == "utf16-bom":
        return raw.decode().encode("utf-16"), "rig in UTF-16 with a BOM"
    if choice == "deep-yaml":
        depth = rng.choice((1000, 5000))
        return b"lidar: " + b"[" * depth + b"]" * depth + b"\n", f"rig nested {depth} deep"
    if choice == "empty":
        return b"", "empty rig"
    if choice == "binary":
        return bytes(rng.randrange(256) for _ in range(512)), "rig of 512 random bytes"
    cut = rng.randrange(1, len(raw))
    return raw[:cut], f"rig cut at byte {cut}"


def _dump(doc: dict[str, Any]) -> bytes:
    return yaml.safe_dump(doc, sort_keys=False).encode()
