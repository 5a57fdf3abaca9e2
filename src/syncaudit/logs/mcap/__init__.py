"""logs.mcap."""
