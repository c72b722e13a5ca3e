"""Console script `gyro_sim_node`: the rclpy node (issue 3, not yet built).

Until it lands, the entry point says so plainly instead of failing on an import.
"""
from __future__ import annotations

import sys


def main(argv=None) -> int:
    print(
        "gyro_sim_node: the ROS 2 node is not implemented yet (next step of the project).\n"
        "Offline simulation works now: gyro-sim run --scene double_gyro_plus --duration 10",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
    sys.exit(main())
