"""Views of gyro_sim logs (rerun-sdk, imported only by :mod:`.rerun_view`)."""
