"""The ROS 2 side (rclpy node and tools). Only this package may import rclpy."""


def start_signal_line(name: str) -> str:
    """The one line of a signal during the node's start-up (gyro_sim.ros.start before the
    imports, gyro_sim.ros.node.Shutdown after them): `name` is "SIGINT" or "SIGTERM"."""
    return f"gyro_sim_node: {name} during start-up: not started (nothing recorded)"
