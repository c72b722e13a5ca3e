"""gyro_sim: simulation of chains of gyrostats (see README.md)."""
from __future__ import annotations

__all__ = ["load_scene", "Simulator", "__version__"]
__version__ = "0.1.0"


def __getattr__(name):
    # lazy: `import gyro_sim` stays cheap (the node and CLI import what they need)
    if name == "load_scene":
        from .core.scene_load import load_scene

        return load_scene
    if name == "Simulator":
        from .core.simulator import Simulator

        return Simulator
    raise AttributeError(name)
