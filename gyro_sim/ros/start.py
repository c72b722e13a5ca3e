"""The console script `gyro_sim_node`'s entry point (also ``python -m gyro_sim.ros.start``).

A signal during the node's start ends it with one line and exit status 0 (docs/ros-interface.md,
"Start, signals and exit codes"). The node's own handling (gyro_sim.ros.node.Shutdown) begins
in its main, after the imports of gyro_sim.ros.node (rclpy, numpy, numba: about a second); a
console script that imported that module first would meet a SIGINT there with Python's
KeyboardInterrupt and its traceback. So this module, which imports nothing heavy, installs
the same outcome first (`gyro_sim.safe_paths.exit_on_signals`) and only then imports the node.
"""
from __future__ import annotations

import sys

from gyro_sim.ros import start_signal_line
from gyro_sim.safe_paths import exit_on_signals


def main(argv=None) -> int:
    """Signals first, then the node's imports, then its main."""
    exit_on_signals(start_signal_line, 0)
    from gyro_sim.ros.node import main as node_main

    return node_main(argv)


if __name__ == "__main__":
    sys.exit(main())
