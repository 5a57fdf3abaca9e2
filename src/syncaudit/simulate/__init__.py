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
