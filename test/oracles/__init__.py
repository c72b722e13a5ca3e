"""Independent engines that tests compare gyro_sim against (not part of the package)."""
