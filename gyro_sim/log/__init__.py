"""Logs: MCAP files of ROS 2 messages, written and read without ROS.

- :mod:`.mcap_log`: :class:`~.mcap_log.LogWriter` (the node's recorder and offline runs), reading
  and verifying
- :mod:`.record`: recording offline runs; the contract that makes logs re-simulable
- :mod:`.resim`: re-simulation of a log against its joint states
- :mod:`.recover`: recovering a file cut short (SIGKILL, power loss, full disk)
- :mod:`.commands`: the ``gyro-sim`` subcommands view, replay, recover

Publishing a log again on ROS 2 is :mod:`gyro_sim.ros.replay`.
"""
