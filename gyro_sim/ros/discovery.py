"""How soon other ROS 2 processes find gyro_sim's: Fast DDS's participant announcements.

A Fast DDS participant announces itself to the others every 3 s by default, and a process that
starts after another is often discovered only at the running one's next announcement: a viewer
opened after the node may wait up to 3 s for its first message, and the node started after a
viewer as long (docs/performance.md measures it). gyro_sim's ROS processes (the node,
`gyro-sim cmd`, `replay` and `view --live`) therefore announce themselves every
`ANNOUNCE_PERIOD` s, through the Fast DDS profile `discovery.xml` beside this module, unless
the user configures Fast DDS (a profiles file of their own, a discovery server) or uses
another middleware: then nothing is changed. Nothing here imports rclpy; `announce_often` must
run before rclpy creates the process's first node.
"""
from __future__ import annotations

import os
from pathlib import Path

#: how often (s) a Fast DDS participant announces itself by default
FAST_DDS_ANNOUNCE_PERIOD = 3.0
#: how often (s) gyro_sim's ROS processes announce themselves
ANNOUNCE_PERIOD = 0.5
#: the profile that says so, shipped with the package (`profile_xml(ANNOUNCE_PERIOD)`)
PROFILE = Path(__file__).with_name("discovery.xml")
#: the environment variables through which Fast DDS reads a user's profiles
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
#: the profiles Fast DDS reads from the working directory when present
WORKING_DIRECTORY_PROFILES = ("DEFAULT_FASTRTPS_PROFILES.xml", "DEFAULT_FASTDDS_PROFILES.xml")
#: the middlewares that are Fast DDS (RMW_IMPLEMENTATION; unset is Jazzy's default, Fast DDS)
FAST_DDS = ("", "rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")
#: the variables that configure Fast DDS's discovery otherwise
OTHER_DISCOVERY = ("ROS_DISCOVERY_SERVER", "FASTDDS_ENVIRONMENT_FILE")


def profile_xml(period: float, name: str = "gyro_sim") -> str:
    """A Fast DDS profile whose default participant announces itself every `period` s."""
    sec, nanosec = divmod(round(period * 1e9), 1_000_000_000)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="{name}" is_default_profile="true">
    <rtps>
      <builtin>
        <discovery_config>
          <leaseAnnouncement><sec>{sec}</sec><nanosec>{nanosec}</nanosec></leaseAnnouncement>
        </discovery_config>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


def announce_often(environ=None, cwd: str | os.PathLike | None = None) -> bool:
    """Have this process's Fast DDS participant announce itself every ANNOUNCE_PERIOD s (set
    FASTRTPS_DEFAULT_PROFILES_FILE in `environ`, default os.environ), unless the environment or
    the working directory `cwd` configures Fast DDS, or the middleware is another. True if set."""
    environ = os.environ if environ is None else environ
    where = Path(cwd) if cwd is not None else Path.cwd()
    if environ.get("RMW_IMPLEMENTATION", "") not in FAST_DDS:
        return False
    if any(environ.get(v) for v in PROFILE_VARIABLES + OTHER_DISCOVERY):
        return False
    if any((where / name).exists() for name in WORKING_DIRECTORY_PROFILES):
        return False
    environ[PROFILE_VARIABLES[0]] = str(PROFILE)
    return True
