from glob import glob

from setuptools import find_packages, setup

package_name = "gyro_sim"

ROS = ["ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"]
# pin: Pinocchio, the independent engine the tests compare against (test-only)
TEST = ["pytest>=7", "pin>=3"]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["numpy>=1.24", "scipy>=1.10", "PyYAML>=6"],
    extras_require={"ros": ROS, "test": TEST},
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="gyro_sim developers",
    maintainer_email="gyro-sim@example.org",
    description="Real-time simulation of chains of gyrostats (rigid bodies with rotors) for ROS 2",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "gyro-sim = gyro_sim.cli:main",
            "gyro_sim_node = gyro_sim.ros.node:main",
        ],
    },
)
