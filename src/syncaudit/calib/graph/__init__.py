"""Stage 3, graph: per-LiDAR pose graphs and the joint graph over every LiDAR's stops and the extrinsics."""
