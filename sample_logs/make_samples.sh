#!/usr/bin/env bash
# Regenerate the bundled sample logs (deterministic: same seed, same bytes of truth).
set -euo pipefail
cd "$(dirname "$0")"
rm -rf vlp16_three_cameras.mcap* pandar40p_adaptive.mcap* vlp16_short_ros2* vlp16_short.bag*
# The README's first command: VLP-16, three cameras triggered 1.5 ms late, a tunnel.
syncaudit simulate sync vlp16_three_cameras.mcap --lidar VLP-16 --duration 10 --seed 1 --delay-error-us 1500
# Pandar40P whose clock is 2.5 s off the host, controller running live, 2 ms initial delay error.
syncaudit simulate sync pandar40p_adaptive.mcap --lidar Pandar40P --duration 10 --seed 2 \
  --delay-error-us 2000 --clock-offset-s 2.5 --controller
# The same short drive as a ROS 2 sqlite3 bag (a folder) and a ROS 1 bag (identical content).
syncaudit simulate sync vlp16_short_ros2 --lidar VLP-16 --duration 3 --seed 3 --delay-error-us -800 --no-tunnel
syncaudit simulate sync vlp16_short.bag --lidar VLP-16 --duration 3 --seed 3 --delay-error-us -800 --no-tunnel
