"""Names of a scene's bodies, rotors and IMUs, and the topic tokens made of them.

A name is a joint-state name and a frame name (``sensor_msgs/JointState`` names and tf frame
ids are free strings; robot_state_publisher uses a URDF's joint names as they are), so it is
kept as the scene or the model file gives it: any printable characters but whitespace and
``/``, at most ``MAX_NAME_LENGTH``. Only a topic name has to be a ROS name: where a name
becomes part of one (``~/wrench/<body>``, ``~/imu/<imu>``) it is made a ROS name token by
:func:`topic_token`, and two names whose tokens collide are refused (docs/scene-format.md,
"Names").
"""
from __future__ import annotations

import re

__all__ = ["MAX_NAME_LENGTH", "name_problem", "topic_token"]

#: longest body, rotor or IMU name: names become topic names ``/<node>/wrench/<name>``, and
#: ROS refuses a topic name longer than 247 characters (rmw: 255 - 8; measured with rclpy: a
#: name of 230 characters under ``/gyro_sim/wrench/``); 64 leaves room for namespaces
MAX_NAME_LENGTH = 64
_NOT_TOKEN = re.compile(r"[^A-Za-z0-9_]+")
_UNDERSCORES = re.compile(r"__+")


def topic_token(name: str) -> str:
    """`name` as a ROS topic token: every run of characters other than ASCII letters, digits
    and underscores becomes one underscore, repeated underscores (reserved by ROS) become one,
    and an underscore goes before a leading digit (``flying_arm_2__j1`` -> ``flying_arm_2_j1``,
    ``wrist-1`` -> ``wrist_1``, ``1st`` -> ``_1st``)."""
    token = _UNDERSCORES.sub("_", _NOT_TOKEN.sub("_", name))
    return token if token and not token[0].isdigit() else f"_{token}"


def name_problem(value: str) -> str | None:
    """Why string `value` cannot be a name (None when it can)."""
    if not value:
        return "must not be empty"
    if len(value) > MAX_NAME_LENGTH:
        return (f"at most {MAX_NAME_LENGTH} characters (got {len(value)}): names become topic "
                "names ~/wrench/<name>, which ROS limits")
    bad = sorted({c for c in value if c.isspace() or c == "/" or not c.isprintable()})
    if bad:
        shown = value if len(value) <= 40 else value[:37] + "..."
        return (f"must not contain whitespace, '/' or control characters (a joint-state and "
                f"frame name; got {shown!r})")
    return None
