"""Simulated logs with known truth, for tests, benchmarks and demos."""

from typing import Literal

LidarModel = Literal[
    "VLP-16",
    "VLP-32C",
    "VLS-128",
    "Pandar40P",
    "PandarXT32",
    "PandarXT32M",
    "Pandar128E4X",
    "OS-1-64",
]
"""LiDAR models the sync simulator writes real-format packets for."""
SceneKind = Literal[
    "yard", "ground_and_wall", "corridor", "parking_lot", "parking_lot_open", "parking_lot_facing"
]
"""The calibration scenes `simulate.calib_config.SceneConfig.kind` accepts (here, where the
CLI reads them without importing the simulator)."""
