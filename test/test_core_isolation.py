"""The core never imports ROS: it runs where rclpy is not installed."""
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_core_does_not_import_rclpy():
    code = (
        "import sys, gyro_sim\n"
        "from gyro_sim import Simulator, load_scene\n"
        "import gyro_sim.dynamics.reference, gyro_sim.simulator, gyro_sim.integrators, gyro_sim.cli\n"
        "sim = Simulator(load_scene('config/chain_4.yaml'))\n"
        "sim.advance(0.01)\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rosidl_runtime_py', 'std_msgs')]\n"
        "assert not bad, bad\n"
    )
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, "-c", code], check=True, cwd=root)
