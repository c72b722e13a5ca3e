"""Benchmarks and reports (`gyro-sim bench ...`)."""
