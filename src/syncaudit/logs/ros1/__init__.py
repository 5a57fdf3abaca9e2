"""logs.ros1."""
