"""Exact Coulomb friction of hinges: stick and slip by time-stepping (driver.py; kernels.py, its compiled part)."""
