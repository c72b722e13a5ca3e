"""Start the gyro_sim node with its parameters file, and optionally a demo command publisher.

    ros2 launch gyro_sim gyro_sim.launch.py
    ros2 launch gyro_sim gyro_sim.launch.py namespace:=robot1 scene:=heavy_top record:=run.mcap
    ros2 launch gyro_sim gyro_sim.launch.py demo:=true      # the hinges driven by `gyro-sim cmd`

Arguments: `params_file` (default: the installed config/params.yaml), `namespace` (default
none), `scene` and `record` (override the parameters file when not empty), `demo` (true:
also run `gyro-sim cmd` with a sine on every axis of the hinge chain, on this node's
~/axis_moments).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

#: the demo's command profile: a sine on each of the hinge chain's three axes (N m, Hz)
DEMO_PROFILE = ["sine", "--amplitude", "0.002", "0.05", "0.03", "--frequency", "0.5"]


def _node_and_demo(context):
    namespace = LaunchConfiguration("namespace").perform(context).strip("/")
    overrides = {}
    for name in ("scene", "record"):
        value = LaunchConfiguration(name).perform(context)
        if value:
            overrides[name] = value
    node = Node(package="gyro_sim", executable="gyro_sim_node", name="gyro_sim", namespace=namespace or None,
                parameters=[LaunchConfiguration("params_file"), overrides], output="screen")
    topic = "/".join(["", *([namespace] if namespace else []), "gyro_sim", "axis_moments"])
    demo = ExecuteProcess(cmd=["gyro-sim", "cmd", "--topic", topic, *DEMO_PROFILE], output="screen",
                          condition=IfCondition(LaunchConfiguration("demo")))
    return [node, demo]


def generate_launch_description():
    share = get_package_share_directory("gyro_sim")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=os.path.join(share, "config", "params.yaml"),
                              description="the node's parameters file"),
        DeclareLaunchArgument("namespace", default_value="", description="the node's namespace"),
        DeclareLaunchArgument("scene", default_value="", description="a scene file or a shipped scene's name"),
        DeclareLaunchArgument("record", default_value="", description="an MCAP log to record"),
        DeclareLaunchArgument("demo", default_value="false", description="true: drive the hinges with gyro-sim cmd"),
        OpaqueFunction(function=_node_and_demo),
    ])
