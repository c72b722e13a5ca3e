"""Exact Coulomb friction of hinges and torque rotors: stick and slip by time-stepping (driver.py;
kernels.py, its compiled part)."""
