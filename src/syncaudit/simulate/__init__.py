"""Simulated logs with known truth, for tests, benchmarks and demos."""

from typing import Literal

LidarModel = Literal["VLP-16", "VLP-32C", "VLS-128", "Pandar40P", "PandarXT32"]
"""LiDAR models the sync simulator writes real-format packets for."""
