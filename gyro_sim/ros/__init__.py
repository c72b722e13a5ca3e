"""The ROS 2 side (rclpy node and tools). Only this package may import rclpy."""
