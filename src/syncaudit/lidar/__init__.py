"""LiDAR packet decoding: vendor packet bytes -> per-packet timing columns."""
