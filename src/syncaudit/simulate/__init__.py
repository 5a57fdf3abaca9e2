"""Simulated logs with known truth, for tests, benchmarks and demos."""
