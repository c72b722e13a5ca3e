"""Every message gyro_sim publishes or logs, from one Snapshot, as CDR bytes (no rclpy here).

This module owns every topic name, type name, frame name and diagnostics key. The node
(:mod:`gyro_sim.ros.outputs`) publishes the bytes built here and records the same bytes; the
offline recorder (:mod:`gyro_sim.log.record`) writes them to its log. Nothing else builds
message content.

Topics and frames (docs/ros-interface.md), all stamped with the log time (simulated time
since the start, resets included). The names below are those of a node in the root namespace
and of offline logs; a node in a namespace (:class:`TopicNames`) has ``joint_states`` and
``robot_description`` under its namespace and ``/gyro_sim/...`` under its fully qualified
name (``/robot1/joint_states``, ``/robot1/gyro_sim/poses``), /tf, /clock and /diagnostics
global:

==================================  ===============================  ==========================
topic                               type                             frame_id
==================================  ===============================  ==========================
/joint_states                       sensor_msgs/msg/JointState       "" (joint states have none)
/gyro_sim/wrench/<joint>            geometry_msgs/msg/WrenchStamped  <joint> = the body's name
/gyro_sim/poses                     geometry_msgs/msg/PoseArray      world (one pose per body)
/tf                                 tf2_msgs/msg/TFMessage           world -> <body>, every body
/clock                              rosgraph_msgs/msg/Clock
/diagnostics                        diagnostic_msgs/msg/DiagnosticArray
/gyro_sim/axis_moments              std_msgs/msg/Float64MultiArray   (the commands)
/gyro_sim/events                    std_msgs/msg/String              (markers: "reset", ...)
/robot_description                  std_msgs/msg/String              (the URDF; transient local)
==================================  ===============================  ==========================

A wrench is R^k (eq 40) and L^k (eq 48) at O^k in body k's own frame. A pose or transform is
O^k and world_R_body of body k.

Diagnostics: one DiagnosticArray with the status ``gyro_sim: dynamics`` (from the snapshot:
the same keys from the node and from offline runs) and, when the caller has run figures, the
status ``gyro_sim: run`` (real-time factor, step times, commands ...). Every number is its own
key with its unit in the name (vectors as ``_x_``/``_y_``/``_z_`` before the unit) and its
value written exactly (``repr``); strings only for states and reasons (:data:`STRING_KEYS`).
A value that does not apply (no data yet) is left out, never written as NaN.

Non-finite numbers never leave here: every builder raises :class:`NonFiniteError`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Iterable, Mapping, Sequence

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.msgs.cdr import NS_PER_S, CdrWriter, Refill
from gyro_sim.scene.names import topic_token

# --- names ---------------------------------------------------------------------------------------
WORLD_FRAME = "world"
NAMESPACE = "/gyro_sim"  # the node's fully qualified name: ~/x is NAMESPACE/x
JOINT_STATES = "/joint_states"
WRENCH_PREFIX = NAMESPACE + "/wrench/"
POSES = NAMESPACE + "/poses"
TF = "/tf"
CLOCK = "/clock"
DIAGNOSTICS = "/diagnostics"
AXIS_MOMENTS = NAMESPACE + "/axis_moments"
JOINT_COMMANDS = NAMESPACE + "/joint_commands"  # the servos' controls, by joint (sensor_msgs/JointState)
EVENTS = NAMESPACE + "/events"
ROBOT_DESCRIPTION = "/robot_description"  # the URDF, written once by every log (io.urdf)

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
POSE_ARRAY_TYPE = "geometry_msgs/msg/PoseArray"
TF_TYPE = "tf2_msgs/msg/TFMessage"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
COMMAND_TYPE = "std_msgs/msg/Float64MultiArray"
STRING_TYPE = "std_msgs/msg/String"

#: names of the two DiagnosticStatus entries
DYNAMICS_STATUS = "gyro_sim: dynamics"
RUN_STATUS = "gyro_sim: run"
#: diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: keys whose values are text (states and reasons); every other value is a number
STRING_KEYS = frozenset({"integrator", "integrator_now", "integrator_reason", "state", "reason", "backend",
                         "last_reject_reason", "record"})
#: the invariants (gyro_sim.dynamics.invariants) as diagnostics: key stem and unit
INVARIANT_KEYS = {
    "energy": ("energy", "J"),
    "kinetic": ("kinetic_energy", "J"),
    "potential": ("potential_energy", "J"),
    "jacobi": ("jacobi_integral", "J"),
    "vertical_momentum": ("vertical_momentum", "Nms"),
    "angular_momentum_O1": ("angular_momentum_O1", "Nms"),
    "linear_momentum": ("linear_momentum", "Ns"),
    "angular_momentum": ("angular_momentum_com", "Nms"),
    "lagrange_82": ("lagrange_82", "Nms"),
    "lagrange_85": ("lagrange_85", "J"),
}
#: work of the commands and the energy balance E - E(0) - W (gyro_sim.snapshot)
WORK_KEY = "work_by_commands_J"
#: "fixed" over its real-time budget (docs/integrators.md): the calls kept beyond the energy
#: watchdog's limit since the reset, and the sum of their energy errors relative to the kinetic energy
BUDGET_CALLS_KEY = "integrator_over_budget_calls"
BUDGET_ERROR_KEY = "integrator_over_budget_energy_error"
#: scenes with actuator limits: the work of friction (<= 0, counted apart in the balance) and
#: the commanded moments clipped to their max_torque since the reset
FRICTION_WORK_KEY = "work_by_friction_J"
SATURATED_KEY = "saturated_commands"
BALANCE_KEY = "energy_balance_J"
BALANCE_REL_KEY = "energy_balance_rel"
DRIFT_SUFFIX = "_drift_rel"
ERROR_ESTIMATE_KEY = "error_estimate_rel"
SIM_TIME_KEY = "sim_time_s"
#: simulated seconds between two /diagnostics (node and offline logs alike)
DIAGNOSTICS_PERIOD = 0.1


def vector_key(stem: str, axis: str, unit: str) -> str:
    return f"{stem}_{axis}_{unit}"


def drift_key(invariant: str) -> str:
    """Relative drift of a conserved invariant since the reset (gyro_sim.dynamics.invariants)."""
    return INVARIANT_KEYS.get(invariant, (invariant, ""))[0] + DRIFT_SUFFIX


def axis_moment_key(axis: str) -> str:
    return f"axis_moment_{axis}_Nm"


class NonFiniteError(GyroSimError, ValueError):
    """A NaN or infinity in an output: refused, it must never reach a topic or a log."""


def wrench_topic(joint: str, namespace: str = NAMESPACE) -> str:
    return f"{namespace}/wrench/{topic_token(joint)}"


class NamespaceError(GyroSimError, ValueError):
    """A log whose channels are not those of one node (two robots' topics mixed in one file)."""


#: node name of gyro_sim_node (its private topics ``~/x`` are ``<namespace>/gyro_sim/x``)
NODE_NAME = "gyro_sim"


@dataclass(frozen=True)
class TopicNames:
    """The fully qualified topic names of one gyro_sim node (docs/ros-interface.md).

    ``joint_states`` and ``robot_description`` are relative to the node's namespace (as
    robot_state_publisher's), ``~/x`` topics are under the node's fully qualified name,
    /tf, /clock and /diagnostics are global (tf2 listeners, simulated time and diagnostic
    aggregators read them there; a status names its node).

    Parameters
    ----------
    namespace : the node's namespace, "/" (root) or "/robot1"
    node : the node's fully qualified name ("/gyro_sim", "/robot1/gyro_sim")
    frame_prefix : put before every body's frame name (the /tf child frames and the wrenches'
        frame_id; "world" stays as it is), as robot_state_publisher's parameter of that name:
        two robots on one /tf then have frames of their own ("robot1/arm1")
    """

    namespace: str = "/"
    node: str = NAMESPACE
    frame_prefix: str = ""

    def _relative(self, name: str) -> str:
        return f"{self.namespace.rstrip('/')}/{name}"

    @property
    def joint_states(self) -> str:
        return self._relative("joint_states")

    @property
    def robot_description(self) -> str:
        return self._relative("robot_description")

    @property
    def axis_moments(self) -> str:
        return f"{self.node}/axis_moments"

    @property
    def joint_commands(self) -> str:
        return f"{self.node}/joint_commands"

    @property
    def events(self) -> str:
        return f"{self.node}/events"

    @property
    def poses(self) -> str:
        return f"{self.node}/poses"

    @property
    def wrench_prefix(self) -> str:
        return f"{self.node}/wrench/"

    def wrench(self, joint: str) -> str:
        return wrench_topic(joint, self.node)

    def status_name(self, root_name: str) -> str:
        """A DiagnosticStatus name (DYNAMICS_STATUS, RUN_STATUS) for this node: as it is in the
        root namespace, else with the node's namespace before it ("robot1/gyro_sim: run"), so
        that the statuses of two robots on the global /diagnostics are told apart."""
        if self.node == NAMESPACE:
            return root_name
        return self.node.lstrip("/") + root_name[len(NODE_NAME):]

    tf: ClassVar[str] = TF
    clock: ClassVar[str] = CLOCK
    diagnostics: ClassVar[str] = DIAGNOSTICS


#: the topics of a node in the root namespace (and of offline logs)
ROOT_TOPICS = TopicNames()


def log_topic_names(topics: Iterable[str], where: str = "log", frame_prefix: str = "") -> TopicNames:
    """The TopicNames of the node that wrote a log with these channels: its namespace is the one
    of its ``.../joint_states`` channel, its node name that of ``.../events`` or
    ``.../axis_moments`` under it (else ``<namespace>/gyro_sim``). A log with no joint states is
    read as root. NamespaceError when joint states of more than one namespace are in it."""
    topics = list(topics)
    spaces = sorted({t[:-len("/joint_states")] or "/" for t in topics if t.endswith("/joint_states")})
    if len(spaces) > 1:
        raise NamespaceError(f"{where}: joint states of {len(spaces)} namespaces ({', '.join(spaces[:4])}): "
                             "a log of one robot is read, not a mix; record each robot to its own file")
    ns = spaces[0] if spaces else "/"
    base = ns.rstrip("/")
    nodes = sorted({t.rsplit("/", 1)[0] for t in topics
                    if t.endswith(("/events", "/axis_moments")) and t.startswith(base + "/")
                    and t.count("/") == base.count("/") + 2})
    node = nodes[0] if len(nodes) == 1 else f"{base}/{NODE_NAME}"
    return TopicNames(namespace=ns, node=node, frame_prefix=frame_prefix)


# --- quality of service ---------------------------------------------------------------------------
#: depth of the node's publishers (keep last)
PUBLISHER_DEPTH = 10
#: an infinite duration as the ROS graph reports it for a publisher without deadline, lifespan or
#: liveliness lease (RMW_DURATION_INFINITE: what rosbag2 records for them)
INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}
#: metadata key of an MCAP channel holding its publisher's QoS (rosbag2_storage_mcap)
QOS_METADATA_KEY = "offered_qos_profiles"


@dataclass(frozen=True)
class Qos:
    """The QoS a gyro_sim publisher offers (keep last `depth`; policy names as rmw spells them)."""

    reliability: str = "reliable"
    durability: str = "volatile"
    depth: int = PUBLISHER_DEPTH

    def as_dict(self) -> dict:
        """The profile as rosbag2 serialises it (metadata version 9: policy names, not numbers)."""
        return {"history": "keep_last", "depth": self.depth, "reliability": self.reliability,
                "durability": self.durability, "deadline": dict(INFINITE_DURATION),
                "lifespan": dict(INFINITE_DURATION), "liveliness": "automatic",
                "liveliness_lease_duration": dict(INFINITE_DURATION), "avoid_ros_namespace_conventions": False}

    def yaml(self) -> str:
        """``offered_qos_profiles`` of a channel: a YAML list with this one profile."""
        import yaml

        return yaml.safe_dump([self.as_dict()], sort_keys=False)


#: every topic of the node but the robot description
PUBLISHER_QOS = Qos()
#: /robot_description: reliable, transient local, depth 1 (robot_state_publisher's): a late
#: subscriber asking for transient local gets the last one
LATCHED_QOS = Qos(durability="transient_local", depth=1)


def topic_qos(topic: str) -> Qos:
    """The QoS the node publishes `topic` with (and a log records for it)."""
    return LATCHED_QOS if topic.rsplit("/", 1)[-1] == "robot_description" else PUBLISHER_QOS


def topic_types(joints: Iterable[str], namespace: str = NAMESPACE) -> dict[str, str]:
    """topic -> message type of everything a simulation publishes (commands and events included)."""
    out = {JOINT_STATES: JOINT_STATE_TYPE}
    out.update({wrench_topic(j, namespace): WRENCH_TYPE for j in joints})
    out.update({f"{namespace}/poses": POSE_ARRAY_TYPE, TF: TF_TYPE, CLOCK: CLOCK_TYPE,
                DIAGNOSTICS: DIAGNOSTICS_TYPE, f"{namespace}/axis_moments": COMMAND_TYPE,
                f"{namespace}/events": STRING_TYPE})
    return out


# --- time ----------------------------------------------------------------------------------------
def time_ns(t: float) -> int:
    """Simulated time (s) as integer nanoseconds: the log time and the stamps of a message."""
    if not math.isfinite(t) or t < 0:
        raise NonFiniteError(f"simulated time must be finite and >= 0, got {t!r}")
    return int(round(t * NS_PER_S))


class NodeTime:
    """The time of the stamps and log times of a run, in integer ns: the node time of the last
    reset (`offset_ns`) plus the simulator's time since (which a reset takes back to zero)."""

    def __init__(self, sim):
        self.sim = sim
        self.offset_ns = 0

    @property
    def ns(self) -> int:
        return self.offset_ns + time_ns(self.sim.time)


def stamp_ns(st) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time (dict or object)."""
    if isinstance(st, Mapping):
        return int(st["sec"]) * NS_PER_S + int(st["nanosec"])
    return int(st.sec) * NS_PER_S + int(st.nanosec)


def _finite(a, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if not np.all(np.isfinite(a)):
        raise NonFiniteError(f"{what}: non-finite value in {a.tolist()}")
    return a


# --- one message each ------------------------------------------------------------------------------
def joint_state(snap, t_ns: int) -> bytes:
    """sensor_msgs/JointState: header, name[], position[], velocity[], effort[]."""
    return bytes(_joint_state(CdrWriter(), snap.joint_names, _finite(snap.position, "joint_states.position"),
                              _finite(snap.velocity, "joint_states.velocity"),
                              _finite(snap.effort, "joint_states.effort"), t_ns))


def _joint_state(w: CdrWriter, names, position, velocity, effort, t_ns: int) -> CdrWriter:
    w.header(t_ns, "")
    w.strings(names)
    w.f64_seq(position)
    w.f64_seq(velocity)
    w.f64_seq(effort)
    return w


def wrench_stamped(t_ns: int, frame: str, force, moment) -> bytes:
    """geometry_msgs/WrenchStamped: header, wrench (force, torque)."""
    return bytes(_wrench_stamped(CdrWriter(), t_ns, frame, np.concatenate(
        [_finite(force, f"wrench {frame}.force"), _finite(moment, f"wrench {frame}.torque")])))


def _wrench_stamped(w: CdrWriter, t_ns: int, frame: str, wrench) -> CdrWriter:
    w.header(t_ns, frame)
    w.f64_block(wrench)
    return w


def _poses_xyzw(snap, what: str) -> np.ndarray:
    """(n, 7) position and quaternion x, y, z, w of every body (the geometry_msgs order)."""
    return _xyzw(snap.body_position, snap.body_quaternion, f"{what}.position", f"{what}.orientation")


def _xyzw(positions, quaternions, p_what: str, q_what: str) -> np.ndarray:
    """(n, 7) positions (n, 3) and quaternions (n, 4; w, x, y, z) as geometry_msgs orders them
    (x, y, z, w), each refused if not finite (named `p_what`, `q_what`)."""
    p = _finite(positions, p_what)
    q = _finite(quaternions, q_what)
    return np.concatenate([p, q[:, 1:], q[:, :1]], axis=1)


def pose_array(snap, t_ns: int) -> bytes:
    """geometry_msgs/PoseArray of every body, frame "world"."""
    return bytes(_pose_array(CdrWriter(), _poses_xyzw(snap, "poses"), t_ns))


def _pose_array(w: CdrWriter, poses, t_ns: int) -> CdrWriter:
    w.header(t_ns, WORLD_FRAME)
    w.u32(len(poses))
    w.f64_block(poses)  # Pose = 7 float64, no padding between poses
    return w


def tf_message(snap, t_ns: int) -> bytes:
    """tf2_msgs/TFMessage: world -> each body frame, named after the body."""
    return bytes(_tf_message(CdrWriter(), snap.body_names, _poses_xyzw(snap, "tf"), t_ns))


def frames_tf_message(names: Sequence[str], positions, quaternions, t_ns: int) -> bytes:
    """tf2_msgs/TFMessage: world -> each named frame at its position (n, 3) and quaternion (n, 4;
    w, x, y, z): a URDF robot's link frames (gyro_sim.scene.robot). Refuses a non-finite number."""
    return bytes(_tf_message(CdrWriter(), names, _xyzw(positions, quaternions, "tf.translation", "tf.rotation"),
                             t_ns))


def _tf_message(w: CdrWriter, body_names, poses, t_ns: int) -> CdrWriter:
    w.u32(len(poses))
    for name, pose in zip(body_names, poses):
        w.header(t_ns, WORLD_FRAME)
        w.string(name)  # child_frame_id
        w.f64_block(pose)  # Transform: translation, rotation
    return w


def clock(t_ns: int) -> bytes:
    """rosgraph_msgs/Clock."""
    w = CdrWriter()
    w.time(t_ns)
    return bytes(w)


def axis_moments(values: Sequence[float]) -> bytes:
    """std_msgs/Float64MultiArray of a command (one value per actuated axis, no layout: the
    forward-command convention of ros2_controllers)."""
    w = CdrWriter()
    w.u32(0)  # layout.dim: empty
    w.u32(0)  # layout.data_offset
    w.f64_seq(_finite(values, "axis_moments"))
    return bytes(w)


class _CdrReader:
    """Reads little-endian CDR (the node's command inputs), without rclpy: each primitive
    aligned to its size counted after the 4-byte encapsulation header. ValueError on bytes that
    do not hold what is read."""

    def __init__(self, data: bytes, least: int):
        self.b = memoryview(data)
        if len(self.b) < least or bytes(self.b[:2]) != b"\x00\x01":
            raise ValueError("not little-endian CDR")
        self.pos = 4

    def u32(self) -> int:
        import struct

        self.pos += -(self.pos - 4) % 4
        if self.pos + 4 > len(self.b):
            raise ValueError("truncated")
        (v,) = struct.unpack_from("<I", self.b, self.pos)
        self.pos += 4
        return v

    def skip_string(self) -> int:
        n = self.u32()
        if n > len(self.b):
            raise ValueError("bad string length")
        self.pos += n
        return n

    def text(self) -> str:
        start = self.pos + 4 + -(self.pos - 4) % 4
        n = self.skip_string()
        if n < 1 or self.pos > len(self.b):
            raise ValueError("bad string length")
        return bytes(self.b[start:start + n - 1]).decode("utf-8")

    def doubles(self, last: bool = False) -> np.ndarray:
        """sequence<float64>; `last`: the message's end, which serializers may pad (to 4 or 8)."""
        n = self.u32()
        if n:
            self.pos += -(self.pos - 4) % 8
        spare = len(self.b) - (self.pos + 8 * n)
        if spare < 0 or (last and spare >= 8):
            raise ValueError(f"{n} values do not fit the {len(self.b)} bytes")
        out = np.frombuffer(self.b, dtype="<f8", count=n, offset=self.pos).astype(float)
        self.pos += 8 * n
        return out


def decode_axis_moments(data: bytes) -> np.ndarray:
    """The values of a std_msgs/Float64MultiArray in CDR (the node's command input), without
    rclpy; the layout is skipped. Raises ValueError on bytes that are not such a message."""
    r = _CdrReader(data, 16)
    for _ in range(r.u32()):  # layout.dim: label, size, stride
        r.skip_string()
        r.u32()
        r.u32()
    r.u32()  # layout.data_offset
    return r.doubles(last=True)


def joint_command(names: Sequence[str], position=(), velocity=(), effort=()) -> bytes:
    """sensor_msgs/JointState of a joint command (`~/joint_commands`, stamp zero): each array
    empty or one value per name."""
    return bytes(_joint_state(CdrWriter(), list(names), _finite(position, "joint_commands.position"),
                              _finite(velocity, "joint_commands.velocity"), _finite(effort, "joint_commands.effort"),
                              0))


def decode_joint_command(data: bytes) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(name, position, velocity, effort) of a sensor_msgs/JointState in CDR (the node's joint
    command input), without rclpy; the header is skipped. Raises ValueError on bytes that are
    not such a message."""
    r = _CdrReader(data, 8)
    r.u32(), r.u32()  # stamp
    r.skip_string()  # frame_id
    count = r.u32()
    if count > len(r.b):
        raise ValueError("bad name count")
    names = [r.text() for _ in range(count)]
    return names, r.doubles(), r.doubles(), r.doubles(last=True)


def string(text: str) -> bytes:
    """std_msgs/String."""
    w = CdrWriter()
    w.string(str(text))
    return bytes(w)


# --- IMUs ------------------------------------------------------------------------------------------
#: sensor_msgs/Imu of each IMU of a scene (gyro_sim.dynamics.imu), frame_id the IMU's name
IMU_TYPE = "sensor_msgs/msg/Imu"
IMU_PREFIX = NAMESPACE + "/imu/"


def imu_topic(name: str, namespace: str = NAMESPACE) -> str:
    """The topic ``~/imu/<name>`` of an IMU."""
    return f"{namespace}/imu/{topic_token(name)}"


def imu(reading, t_ns: int) -> bytes:
    """sensor_msgs/Imu of one IMU reading (gyro_sim.dynamics.imu.ImuReading), frame_id its name:
    orientation (x, y, z, w) of the IMU frame in the world, covariance 0 (exact: no noise model);
    angular velocity and linear acceleration (specific force) in the IMU frame, covariances
    diagonal with the white noise's per-sample variance (0 for a noise-free IMU)."""
    q = np.asarray(reading.orientation, dtype=float)
    gyro, accel = reading.angular_velocity, reading.linear_acceleration
    block = np.concatenate((q[1:], q[:1], _ZEROS9, gyro, _EYE9 * reading.angular_velocity_variance, accel,
                            _EYE9 * reading.linear_acceleration_variance))
    if not np.all(np.isfinite(block)):  # one check of the whole block; the field named when one fails
        _finite(q, f"imu {reading.name}.orientation")
        _finite(gyro, f"imu {reading.name}.angular_velocity")
        _finite(accel, f"imu {reading.name}.linear_acceleration")
        _finite([reading.angular_velocity_variance, reading.linear_acceleration_variance],
                f"imu {reading.name}.covariance")
    w = CdrWriter()
    w.header(t_ns, reading.name)
    w.f64_block(block)
    return bytes(w)


#: the constant parts of an Imu message's block: the orientation's covariance (zero: exact), and
#: the identity the other covariances are a variance times
_ZEROS9 = np.zeros(9)
_EYE9 = np.eye(3).ravel()


def imu_messages(readings, t_ns: int, namespace: str = NAMESPACE) -> list[tuple[str, str, bytes]]:
    """[(topic, type, bytes)] of IMU readings."""
    return [(imu_topic(r.name, namespace), IMU_TYPE, imu(r, t_ns)) for r in readings]


# --- diagnostics -------------------------------------------------------------------------------------
def dynamics_values(snap) -> dict[str, float | str]:
    """The key-values of the ``gyro_sim: dynamics`` status of a snapshot."""
    out: dict[str, float | str] = {SIM_TIME_KEY: snap.time, "integrator": snap.integrator}
    if snap.method:  # an integrator that chooses ("fixed"): which method steps now, and why
        out["integrator_now"] = snap.method
        out["integrator_reason"] = snap.method_reason or ""
        if snap.substeps is not None:
            out["integrator_substeps"] = float(snap.substeps)
        if snap.h_lambda is not None:
            out["stiffness_h_lambda"] = snap.h_lambda
        if snap.budget_calls is not None:  # "fixed" over its real-time budget: the drift it let through
            out[BUDGET_CALLS_KEY] = float(snap.budget_calls)
            out[BUDGET_ERROR_KEY] = snap.budget_energy_error
    for name, value in (snap.invariants or {}).items():
        stem, unit = INVARIANT_KEYS[name]
        v = np.asarray(value, dtype=float)
        if v.ndim == 0:
            out[f"{stem}_{unit}"] = float(v)
        else:
            for axis, c in zip("xyz", v):
                out[vector_key(stem, axis, unit)] = float(c)
    for name, d in (snap.drift or {}).items():
        out[drift_key(name)] = d
    if snap.work is not None:
        out[WORK_KEY] = snap.work
    if snap.friction_work is not None:
        out[FRICTION_WORK_KEY] = snap.friction_work
    if snap.saturated_commands is not None:
        out[SATURATED_KEY] = float(snap.saturated_commands)
    if snap.energy_balance is not None:
        out[BALANCE_KEY] = snap.energy_balance
        out[BALANCE_REL_KEY] = snap.energy_balance / snap.energy_scale
    if snap.error_estimate is not None:
        out[ERROR_ESTIMATE_KEY] = snap.error_estimate
    for axis, m in zip(snap.axis_names, snap.axis_moments):
        out[axis_moment_key(axis)] = float(m)
    return out


@dataclass(frozen=True)
class Status:
    """One diagnostic_msgs/DiagnosticStatus."""

    name: str
    values: Mapping[str, float | int | str]
    level: int = OK
    message: str = ""
    hardware_id: str = ""


def diagnostic_array(t_ns: int, statuses: Sequence[Status]) -> bytes:
    """diagnostic_msgs/DiagnosticArray; numbers written with repr (exact), refused if not finite."""
    w = CdrWriter()
    w.header(t_ns, "")
    w.u32(len(statuses))
    for st in statuses:
        w.u8(int(st.level))
        w.string(st.name)
        w.string(st.message)
        w.string(st.hardware_id)
        w.u32(len(st.values))
        texts = []
        for k, v in st.values.items():
            if k in STRING_KEYS:
                text = str(v)
            elif type(v) is float:  # most values: repr(float(v)) is repr(v)
                if not math.isfinite(v):
                    raise NonFiniteError(f"diagnostics {k}: expected a finite number, got {v!r}")
                text = repr(v)
            else:
                if isinstance(v, str) or not math.isfinite(v):
                    raise NonFiniteError(f"diagnostics {k}: expected a finite number, got {v!r}")
                text = repr(int(v)) if isinstance(v, (int, np.integer)) else repr(float(v))
            texts += (k, text)
        w.string_run(texts)
    return bytes(w)


def diagnostics(snap, t_ns: int, hardware_id: str, run: Status | None = None, name: str = DYNAMICS_STATUS) -> bytes:
    """The /diagnostics message of a snapshot (and the run's figures, when given); `name`: the
    dynamics status's name (TopicNames.status_name)."""
    statuses = [Status(name, dynamics_values(snap), hardware_id=hardware_id)]
    if run is not None:
        statuses.append(run)
    return diagnostic_array(t_ns, statuses)


def diagnostic_numbers(msg) -> dict[str, float]:
    """The numeric key-values of a decoded DiagnosticArray (every gyro_sim status), by key."""
    status = msg["status"] if isinstance(msg, Mapping) else msg.status
    out = {}
    for st in status:
        for kv in (st["values"] if isinstance(st, Mapping) else st.values):
            key, value = (kv["key"], kv["value"]) if isinstance(kv, Mapping) else (kv.key, kv.value)
            if key not in STRING_KEYS:
                out[key] = float(value)
    return out


# --- a publication ------------------------------------------------------------------------------------
class Publication:
    """The messages of one snapshot: [(topic, type, bytes)] in publication order.

    Parameters
    ----------
    body_names : the scene's bodies (the wrench topics)
    namespace : the node's fully qualified name (topics ``~/x``), when `topics` is not given
    hardware_id : the scene's name (diagnostics)
    topics : the node's topic names (default: those of a node named `namespace` in the root namespace)
    """

    def __init__(self, body_names: Sequence[str], *, namespace: str = NAMESPACE, hardware_id: str = "",
                 topics: TopicNames | None = None):
        self.body_names = tuple(body_names)
        self.topics = topics = topics or TopicNames(node=namespace)
        #: the bodies' frame names in /tf and the wrenches (frame_prefix + body name)
        self.frame_names = tuple(topics.frame_prefix + b for b in self.body_names)
        self.joint_states_topic = topics.joint_states
        self.wrench_topics = tuple(topics.wrench(b) for b in self.body_names)
        self.poses_topic = topics.poses
        self.hardware_id = hardware_id
        self.dynamics_status = topics.status_name(DYNAMICS_STATUS)
        # the messages of fixed layout, written once and refilled (same bytes as the builders)
        n = len(self.body_names)
        zeros = np.zeros((n, 7))
        self._wrenches = Refill([_wrench_stamped(CdrWriter(record=True), 0, b, zeros[0, :6]) for b in self.frame_names])
        self._poses = Refill([_pose_array(CdrWriter(record=True), zeros, 0)])
        self._tf = Refill([_tf_message(CdrWriter(record=True), self.frame_names, zeros, 0)])
        self._joints: tuple[tuple[str, ...], Refill] | None = None

    def frame(self, joint_names: Sequence[str], *, wrenches: bool, poses: bool, tf: bool) -> "Frame":
        """The messages of fixed layout of a publication (joint states, /clock, and the wrenches,
        poses and /tf asked for) in one buffer that `Simulator.snapshot(into=frame.scatter)` fills."""
        return Frame(self, tuple(joint_names), wrenches=wrenches, poses=poses, tf=tf)

    def _joint_refill(self, names: tuple[str, ...]) -> Refill:
        if self._joints is None or (self._joints[0] is not names and self._joints[0] != names):
            z = np.zeros(len(names))
            self._joints = (names, Refill([_joint_state(CdrWriter(record=True), names, z, z, z, 0)]))
        return self._joints[1]

    def messages(self, snap, t_ns: int, *, poses: bool = True, tf: bool = True,
                 diagnostics_run: Status | None | bool = False) -> list[tuple[str, str, bytes]]:
        """The snapshot's messages. Wrenches when the snapshot has them; poses and /tf when asked
        and the snapshot has bodies; diagnostics when `diagnostics_run` is not False (None: the
        dynamics status only; a Status: that too). The same bytes as the builders above."""
        js = np.concatenate((snap.position, snap.velocity, snap.effort))
        if not np.all(np.isfinite(js)):
            joint_state(snap, t_ns)  # raises, naming the field
        (data,) = self._joint_refill(tuple(snap.joint_names)).fill(t_ns, js)
        out = [(self.joint_states_topic, JOINT_STATE_TYPE, data), (CLOCK, CLOCK_TYPE, clock(t_ns))]
        if snap.wrench_force is not None:
            wr = np.concatenate((snap.wrench_force, snap.wrench_moment), axis=1)
            if not np.all(np.isfinite(wr)):
                for frame, f, m in zip(self.body_names, snap.wrench_force, snap.wrench_moment):
                    wrench_stamped(t_ns, frame, f, m)  # raises, naming the body and field
            out += zip(self.wrench_topics, (WRENCH_TYPE,) * len(self.wrench_topics), self._wrenches.fill(t_ns, wr))
        if snap.body_position is not None and (poses or tf):
            xyzw = _poses_xyzw(snap, "poses" if poses else "tf")
            if poses:
                out.append((self.poses_topic, POSE_ARRAY_TYPE, self._poses.fill(t_ns, xyzw)[0]))
            if tf:
                out.append((TF, TF_TYPE, self._tf.fill(t_ns, xyzw)[0]))
        if diagnostics_run is not False:
            out.append((DIAGNOSTICS, DIAGNOSTICS_TYPE,
                        diagnostics(snap, t_ns, self.hardware_id, diagnostics_run or None, self.dynamics_status)))
        return out


class Frame:
    """Every message of fixed layout of one publication, written once into one buffer: the
    compiled outputs put their numbers straight into its float64 slots (`scatter`, a
    gyro_sim.snapshot.Scatter), `messages` puts the stamps in and cuts the bytes. The same
    bytes as the builders above (test/msgs/test_publication_frame.py).

    Each message starts 8-aligned in the buffer, whose start is 4 bytes past an 8-byte
    boundary: every float64 of every message (8-aligned after its 4-byte CDR header) is then an
    aligned slot of one float64 view, and every stamp an aligned pair of a uint32 view.
    """

    def __init__(self, publication: Publication, joint_names: tuple[str, ...], *, wrenches: bool, poses: bool,
                 tf: bool) -> None:
        from gyro_sim.snapshot import Scatter

        self.joint_names = joint_names
        body_names = publication.body_names
        n, J = len(body_names), len(joint_names)
        z, z7 = np.zeros(J), np.zeros((n, 7))
        msgs = [(publication.joint_states_topic, JOINT_STATE_TYPE,
                 _joint_state(CdrWriter(record=True), joint_names, z, z, z, 0))]
        w = CdrWriter(record=True)
        w.time(0)
        msgs.append((CLOCK, CLOCK_TYPE, w))
        if wrenches:
            msgs += [(topic, WRENCH_TYPE, _wrench_stamped(CdrWriter(record=True), 0, b, z7[0, :6]))
                     for topic, b in zip(publication.wrench_topics, publication.frame_names)]
        if poses:
            msgs.append((publication.poses_topic, POSE_ARRAY_TYPE, _pose_array(CdrWriter(record=True), z7, 0)))
        if tf:
            msgs.append((TF, TF_TYPE, _tf_message(CdrWriter(record=True), publication.frame_names, z7, 0)))
        starts, at = [], 0
        for _, _, m in msgs:
            starts.append(at)
            at += -(-len(m.buf) // 8) * 8
        size = at + 8
        raw = np.zeros(size + 8, dtype=np.uint8)
        off = (4 - raw.ctypes.data) % 8  # the buffer starts 4 past an 8-byte boundary
        self._raw = raw
        self.buffer = raw[off:off + size]
        for (_, _, m), a in zip(msgs, starts):
            self.buffer[a:a + len(m.buf)] = np.frombuffer(bytes(m.buf), dtype=np.uint8)
        self._f64 = raw[off + 4:off + 4 + 8 * ((size - 4) // 8)].view("<f8")
        self._u32 = raw[off:off + 4 * (size // 4)].view("<u4")
        stamps = [a + o for (_, _, m), a in zip(msgs, starts) for o in m.stamps]
        self._sec = np.array(stamps, dtype=np.intp) // 4
        self._nsec = self._sec + 1

        def slots(i: int) -> np.ndarray:  # the float64 slots of message i, in writing order
            m, a = msgs[i][2], starts[i]
            return np.concatenate([(a + o - 4) // 8 + np.arange(c) for o, c in m.floats]).astype(np.int64)

        joint = slots(0).reshape(1, 3, J) if J else np.zeros((1, 3, 0), dtype=np.int64)
        i = 2
        wrench = np.zeros((0, n, 6), dtype=np.int64)
        if wrenches:
            wrench = np.stack([slots(i + k) for k in range(n)])[None]
            i += n
        pose_slots = []
        for on in (poses, tf):
            if on:
                pose_slots.append(slots(i).reshape(n, 7))
                i += 1
        ps = np.array(pose_slots, dtype=np.int64).reshape(len(pose_slots), n, 7)
        self.scatter = Scatter(self._f64, joint, np.ascontiguousarray(ps[:, :, :3]),
                               np.ascontiguousarray(ps[:, :, [6, 3, 4, 5]]),  # w, x, y, z <- x, y, z, w
                               np.ascontiguousarray(wrench))
        self.topics = tuple(t for t, _, _ in msgs)
        self.types = tuple(ty for _, ty, _ in msgs)
        self._slices = tuple(slice(a, a + len(m.buf)) for (_, _, m), a in zip(msgs, starts))
        #: ((topic, type, start, stop), ...): where each message lies in the block (one object
        #: per frame: a recorder sends it once and then only blocks)
        self.layout = tuple((t, ty, s.start, s.stop) for t, ty, s in zip(self.topics, self.types, self._slices))

    def messages(self, t_ns: int) -> FrameBatch:
        """[(topic, type, bytes)] with the numbers the last `snapshot(into=self.scatter)` wrote
        and every stamp t_ns, in one block (`block`, with the `layout`) from which each message
        is cut when asked."""
        sec, nsec = divmod(int(t_ns), NS_PER_S)
        self._u32[self._sec] = sec & 0xFFFFFFFF  # int32 seconds, two's complement
        self._u32[self._nsec] = nsec
        return FrameBatch(self.buffer.tobytes(), self.layout)


class FrameBatch:
    """A publication's [(topic, type, bytes)] from a :class:`Frame`, as a sequence: its first
    len(layout) items are `block[start:stop]` for each (topic, type, start, stop) of `layout`,
    cut when read (a message only recorded goes as part of the block, never cut: ~70 ns a
    message, 100 wrench topics at n = 100); items appended after them (`extra`: the diagnostics)
    are not in the block."""

    __slots__ = ("block", "layout", "extra")

    def __init__(self, block: bytes, layout: tuple) -> None:
        self.block, self.layout = block, layout
        self.extra: list[tuple[str, str, bytes]] = []

    def append(self, item: tuple[str, str, bytes]) -> None:
        self.extra.append(item)

    def __len__(self) -> int:
        return len(self.layout) + len(self.extra)

    def __iter__(self):
        block = self.block
        for topic, msgtype, a, b in self.layout:
            yield topic, msgtype, block[a:b]
        yield from self.extra

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        n = len(self.layout)
        j = i + len(self) if i < 0 else i
        if 0 <= j < n:
            topic, msgtype, a, b = self.layout[j]
            return topic, msgtype, self.block[a:b]
        if j < 0:
            raise IndexError(i)
        return self.extra[j - n]

    def __eq__(self, other) -> bool:
        try:
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        except TypeError:
            return NotImplemented

    __hash__ = None

    def __repr__(self) -> str:
        return f"FrameBatch({list(self)!r})"
