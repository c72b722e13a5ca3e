"""gyro_sim: simulation of chains of gyrostats (see README.md).

The package by concept (docs/layout.md has the map with the paper's equations):

- :mod:`gyro_sim.scene`: scene records and loading
- :mod:`gyro_sim.dynamics`: model, the paper's equations (numpy reference and compiled kernels)
- :mod:`gyro_sim.analytic`: the paper's closed forms for chains of Lagrange gyroscopes
- :mod:`gyro_sim.integrators`: time integrators, one folder per method
- :mod:`gyro_sim.simulator`, :mod:`gyro_sim.snapshot`: the Python API and what it shows
- :mod:`gyro_sim.msgs`, :mod:`gyro_sim.log`: ROS 2 messages and MCAP logs without rclpy
- :mod:`gyro_sim.ros`: the rclpy node and its tools (the only package that imports rclpy)
- :mod:`gyro_sim.viz`, :mod:`gyro_sim.sweep`, :mod:`gyro_sim.bench`: views, sweeps, reports
- :mod:`gyro_sim.cli`: the ``gyro-sim`` command
"""
from __future__ import annotations

__all__ = ["load_scene", "Simulator", "__version__"]
__version__ = "0.1.0"


def __getattr__(name):
    # lazy: `import gyro_sim` stays cheap (the node and CLI import what they need)
    if name == "load_scene":
        from gyro_sim.scene.load import load_scene

        return load_scene
    if name == "Simulator":
        from gyro_sim.simulator import Simulator

        return Simulator
    raise AttributeError(name)
