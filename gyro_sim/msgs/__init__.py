"""ROS 2 messages without rclpy: the exact CDR bytes DDS carries, and their definitions.

- :mod:`.cdr`: a small CDR (XCDR1, little endian) writer and reader
- :mod:`.msgdefs`: message definitions as MCAP schemas (installed or shipped copies in ``msg/``)
- :mod:`.messages`: every message gyro_sim publishes or logs, built from one Snapshot
"""
