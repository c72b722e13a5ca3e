"""Logs: MCAP files of ROS 2 messages written and read without ROS (SPEC.md, "Logs").

- :mod:`.msgdefs`: message definitions as MCAP schemas (installed or shipped copies)
- :mod:`.messages`: a Simulator's outputs as messages (plain dicts, no rclpy)
- :mod:`.mcap_log`: :class:`~.mcap_log.LogWriter` (the node's recorder and offline runs), reading
- :mod:`.urdf`: the chain's shapes, and its URDF on /robot_description
- :mod:`.record`: recording offline runs; the contract that makes logs re-simulable
- :mod:`.resim`: re-simulation of a log against its joint states
- :mod:`.replay`: publishing a log again on ROS 2 (rclpy, imported only there)
- :mod:`.recover`: recovering a file cut short (SIGKILL, power loss)
- :mod:`.commands`: the ``gyro-sim`` subcommands view, replay, recover
"""
