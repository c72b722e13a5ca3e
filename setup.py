from glob import glob

from setuptools import find_packages, setup

package_name = "gyro_sim"

# ROS 2 Jazzy from PyPI; a user with an apt-installed ROS skips this extra
ROS = ["ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"]
# rerun-sdk (~500 MB): the 3D view of logs; kept out of the core's imports
VIZ = ["rerun-sdk>=0.41"]
# report plots, and the peer engines the reports compare against
BENCH = ["matplotlib>=3.6", "mujoco>=3", "pin>=3"]
# MJCF and URDF models read as scenes (MjSpec.from_file; checked with MuJoCo 4.0)
MODELS = ["mujoco>=3.3"]
# pin (Pinocchio): the independent engine of the cross-check tests; rosbags: an independent
# MCAP reader for the log tests
# gyro-sim sweep: dask[distributed] runs the points on a local or remote cluster; pyarrow writes
# the Parquet table (without pandas); matplotlib draws the map
SWEEP = ["dask[distributed]>=2024.1", "pyarrow>=14", "matplotlib>=3.6"]
# ruff: the linter .ci/run runs before the tests (ruff.toml)
TEST = ["pytest>=7", "rosbags>=0.9", "ruff>=0.5"] + ROS + VIZ + BENCH + SWEEP + MODELS
# Basilisk (bsk): the peer engine of the reaction-wheel cross-check; it caps numpy, matplotlib and
# protobuf below what the test extra installs, so CI gives it a venv of its own (.ci/run)
PEERS = ["bsk>=2.12"]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={"gyro_sim": ["msgs/msg/*/*.msg", "ros/discovery.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config/sweeps", glob("config/sweeps/*.yaml")),
        ("share/" + package_name + "/config/models", glob("config/models/*.xml") + glob("config/models/*.urdf")
         + glob("config/models/LICENSE-*")),  # *.xml: package.xml too (the meshes' package)
        ("share/" + package_name + "/config/models/meshes/ur5", glob("config/models/meshes/ur5/*.stl")),
    ],
    # mcap + mcap-ros2-support: logs are written and read without ROS installed;
    # numba: the compiled dynamics (35x faster than numpy at n = 10: real time at 1 kHz)
    install_requires=[
        "numpy>=1.24",
        "scipy>=1.10",
        "PyYAML>=6",
        "numba>=0.59",
        "mcap>=1.6",
        "mcap-ros2-support>=0.5",
    ],
    extras_require={"ros": ROS, "viz": VIZ, "bench": BENCH, "sweep": SWEEP, "models": MODELS, "test": TEST,
                    "peers": PEERS},
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="gyro_sim developers",
    maintainer_email="gyro-sim@example.org",
    description="Real-time simulation of chains of gyrostats (rigid bodies with rotors) for ROS 2",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "gyro-sim = gyro_sim.cli:main",
            "gyro_sim_node = gyro_sim.ros.start:main",
        ],
    },
)
