"""logs.ros2."""
