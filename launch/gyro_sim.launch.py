"""Start the gyro_sim node with its parameters file.

    ros2 launch gyro_sim gyro_sim.launch.py
    ros2 launch gyro_sim gyro_sim.launch.py namespace:=robot1 scene:=heavy_top record:=run.mcap
    ros2 launch gyro_sim gyro_sim.launch.py demo:=true      # the node drives its own axes

Arguments: `params_file` (default: the installed config/params.yaml), `namespace` (default
none: the node's topics then are /joint_states, /robot_description, /gyro_sim/...; with
robot1, /robot1/joint_states, /robot1/robot_description, /robot1/gyro_sim/...), `scene` and
`record` (override the parameters file when not empty), `demo` (true: the node's `demo`
parameter, built-in sines on every axis of any scene until a command arrives).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

#: launch argument values read as true (as launch's IfCondition reads them)
TRUE_VALUES = ("true", "1")


def _node(context):
    namespace = LaunchConfiguration("namespace").perform(context).strip("/")
    overrides = {}
    for name in ("scene", "record"):
        value = LaunchConfiguration(name).perform(context)
        if value:
            overrides[name] = value
    if LaunchConfiguration("demo").perform(context).strip().lower() in TRUE_VALUES:
        overrides["demo"] = True
    return [Node(package="gyro_sim", executable="gyro_sim_node", name="gyro_sim", namespace=namespace or None,
                 parameters=[LaunchConfiguration("params_file"), overrides], output="screen")]


def generate_launch_description():
    share = get_package_share_directory("gyro_sim")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=os.path.join(share, "config", "params.yaml"),
                              description="the node's parameters file"),
        DeclareLaunchArgument("namespace", default_value="", description="the node's namespace"),
        DeclareLaunchArgument("scene", default_value="", description="a scene file or a shipped scene's name"),
        DeclareLaunchArgument("record", default_value="", description="an MCAP log to record"),
        DeclareLaunchArgument("demo", default_value="false",
                              description="true: the node drives its axes with built-in sines until commanded"),
        OpaqueFunction(function=_node),
    ])
