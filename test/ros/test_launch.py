"""launch/gyro_sim.launch.py: installed with the package, and building the node it should.

`launch` and `launch_ros` are not on PyPI: where they are importable (an apt or colcon ROS),
the file is loaded by them; everywhere, it is run against small stand-ins of their classes
that record what it builds, so the node and its parameters are checked.
"""
from __future__ import annotations

import importlib.util
import re
import runpy
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAUNCH_FILE = ROOT / "launch" / "gyro_sim.launch.py"


class _Recorded:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def _stand_ins(share: Path) -> dict[str, types.ModuleType]:
    mods = {name: types.ModuleType(name) for name in (
        "ament_index_python", "ament_index_python.packages", "launch", "launch.actions", "launch.conditions",
        "launch.substitutions", "launch_ros", "launch_ros.actions")}
    mods["ament_index_python.packages"].get_package_share_directory = \
        lambda pkg: str(share) if pkg == "gyro_sim" else (_ for _ in ()).throw(LookupError(pkg))
    mods["launch"].LaunchDescription = lambda actions: list(actions)
    for name in ("DeclareLaunchArgument", "ExecuteProcess", "OpaqueFunction"):
        setattr(mods["launch.actions"], name, type(name, (_Recorded,), {}))
    mods["launch.conditions"].IfCondition = type("IfCondition", (_Recorded,), {})
    mods["launch.substitutions"].LaunchConfiguration = _LaunchConfiguration
    mods["launch_ros.actions"].Node = type("Node", (_Recorded,), {})
    return mods


def _built(monkeypatch, **arguments):
    """(declared defaults, node) of the launch file run with `arguments` over its defaults."""
    for name, mod in _stand_ins(ROOT).items():
        monkeypatch.setitem(sys.modules, name, mod)
    description = runpy.run_path(str(LAUNCH_FILE))["generate_launch_description"]()
    declared = {a.args[0]: a.kwargs["default_value"] for a in description
                if type(a).__name__ == "DeclareLaunchArgument"}
    (opaque,) = [a for a in description if type(a).__name__ == "OpaqueFunction"]
    (node,) = opaque.kwargs["function"]({**declared, **arguments})
    return declared, node


def test_setup_installs_the_launch_file():
    setup = (ROOT / "setup.py").read_text()
    assert re.search(r'"share/" \+ package_name \+ "/launch", glob\("launch/\*\.launch\.py"\)', setup)
    assert LAUNCH_FILE.is_file()


def test_the_node_is_the_console_script_with_the_shipped_parameters(monkeypatch):
    declared, node = _built(monkeypatch)
    assert node.kwargs["package"] == "gyro_sim" and node.kwargs["name"] == "gyro_sim"
    assert "gyro_sim_node = gyro_sim.ros.start:main" in (ROOT / "setup.py").read_text()
    assert node.kwargs["executable"] == "gyro_sim_node"
    assert Path(declared["params_file"]) == ROOT / "config" / "params.yaml"
    params_file, overrides = node.kwargs["parameters"]
    assert params_file.name == "params_file" and overrides == {}  # empty arguments override nothing
    assert node.kwargs["namespace"] is None
    assert declared["demo"] == "false"


def test_namespace_scene_record_and_demo(monkeypatch):
    from gyro_sim.ros.params import PARAMETERS

    _, node = _built(monkeypatch, namespace="/robot1", scene="heavy_top", record="run.mcap", demo="true")
    assert node.kwargs["namespace"] == "robot1"
    overrides = node.kwargs["parameters"][1]
    assert overrides == {"scene": "heavy_top", "record": "run.mcap", "demo": True}
    kinds = {p.name: p.kind for p in PARAMETERS}
    assert all(isinstance(v, kinds[k]) for k, v in overrides.items())  # each is a node parameter of its type


@pytest.mark.skipif(importlib.util.find_spec("launch_ros") is None,
                    reason="launch_ros is not installed (it is not on PyPI; an apt or colcon ROS has it)")
def test_launch_ros_loads_it():
    from launch import LaunchContext
    from launch.launch_description_sources import PythonLaunchDescriptionSource

    description = PythonLaunchDescriptionSource(str(LAUNCH_FILE)).get_launch_description(LaunchContext())
    names = {a.name for a in description.get_launch_arguments()}
    assert {"params_file", "namespace", "scene", "record", "demo"} <= names
