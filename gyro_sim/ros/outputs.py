"""The node's outputs: Simulator state -> ROS messages -> CDR bytes -> DDS (and the recorder).

A state is prepared (computed and serialised) as soon as it is computed, ahead of its wall
deadline, and sent at the deadline. Each message is serialised once; the same bytes are
published (`Publisher.publish(bytes)`) and handed to the recorder, so the log holds exactly
the wire bytes. Wrenches and poses are
computed only when the parameters ask for them and someone listens (or the node records).
"""
from __future__ import annotations

import math
import re
import time

import numpy as np

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, WrenchStamped
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ..core.simulator import SimulationError
from .loop import OutputsClosed

WORLD_FRAME = "world"
#: wall seconds between two checks whether an optional output has subscribers
WANT_PERIOD = 0.5
JOINT_STATES = ("/joint_states", "sensor_msgs/msg/JointState")
CLOCK = ("/clock", "rosgraph_msgs/msg/Clock")
DIAGNOSTICS = ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
POSES_TYPE = "geometry_msgs/msg/PoseArray"
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
COMMAND_TYPE = "std_msgs/msg/Float64MultiArray"


def stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def topic_token(name: str) -> str:
    """A body name as a ROS topic token (letters, digits, underscores; not starting with a digit)."""
    tok = re.sub(r"\W", "_", name)
    return tok if tok and not tok[0].isdigit() else f"_{tok}"


class Outputs:
    """Publishers of the node, and what turns the Simulator's state into their messages.

    Parameters
    ----------
    node : rclpy Node
    sim : Simulator (for names)
    config : NodeConfig
    recorder : Recorder or None
    qos : depth of the publishers' queues
    """

    def __init__(self, node, sim, config, recorder=None, qos: int = 10):
        self.node, self.recorder = node, recorder
        self.names = list(sim.model.names)
        self.js_pub = node.create_publisher(JointState, JOINT_STATES[0], qos)
        self.clock_pub = node.create_publisher(Clock, CLOCK[0], qos)
        self.diag_pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS[0], qos)
        ns = node.get_fully_qualified_name()
        self.poses_topic = f"{ns}/poses"
        self.command_topic = f"{ns}/axis_moments"
        self.poses_pub = node.create_publisher(PoseArray, "~/poses", qos) if config.publish_poses else None
        self.wrench_pubs = []
        if config.publish_wrenches:
            for name in self.names:
                topic = f"~/wrench/{topic_token(name)}"
                self.wrench_pubs.append((node.create_publisher(WrenchStamped, topic, qos),
                                         f"{ns}/wrench/{topic_token(name)}"))
        self.hardware_id = sim.scene.name
        self._want: dict[int, tuple[float, bool]] = {}
        self._js = JointState()
        self._js.header.frame_id = ""

    def _send(self, pub, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        try:
            pub.publish(data)
        except Exception as exc:  # the context went away (shutdown under way)
            raise OutputsClosed(str(exc)) from exc
        if self.recorder is not None:
            self.recorder.raw(topic, msgtype, t_ns, data)

    def _wanted(self, pub) -> bool:
        """Recording, or someone subscribes (the count is asked at most every WANT_PERIOD s)."""
        if self.recorder is not None:
            return True
        now = time.monotonic()
        hit = self._want.get(id(pub))
        if hit is None or now - hit[0] > WANT_PERIOD:
            hit = self._want[id(pub)] = (now, pub.get_subscription_count() > 0)
        return hit[1]

    # --- called by the physics loop -------------------------------------------------------------
    def prepare_state(self, t_ns: int, sim) -> list:
        """The state's messages, serialised: [(publisher, topic, type, bytes)] plus ("tf", transforms)
        for the recorder. Raises SimulationError rather than let a non-finite value out."""
        st = stamp(t_ns)
        js = sim.joint_states()
        if not all(map(math.isfinite, js.position + js.velocity + js.effort)):
            raise SimulationError(f"t = {t_ns * 1e-9:.6g} s: non-finite joint states (not published)")
        m = self._js
        m.header.stamp = st
        m.name = js.name
        m.position = js.position
        m.velocity = js.velocity
        m.effort = js.effort
        batch = [(self.js_pub, JOINT_STATES[0], JOINT_STATES[1], serialize_message(m)),
                 (self.clock_pub, CLOCK[0], CLOCK[1], serialize_message(Clock(clock=st)))]
        if self.wrench_pubs and any(self._wanted(p) for p, _ in self.wrench_pubs):
            wrenches = sim.wrenches()
            if not all(np.isfinite(w.force).all() and np.isfinite(w.moment).all() for w in wrenches):
                raise SimulationError(f"t = {t_ns * 1e-9:.6g} s: non-finite joint wrenches (not published)")
            for (pub, topic), w in zip(self.wrench_pubs, wrenches):
                msg = WrenchStamped()
                msg.header.stamp = st
                msg.header.frame_id = w.frame
                f, l = w.force, w.moment
                msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = float(f[0]), float(f[1]), float(f[2])
                msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = float(l[0]), float(l[1]), float(l[2])
                batch.append((pub, topic, WRENCH_TYPE, serialize_message(msg)))
        want_poses = self.poses_pub is not None and self._wanted(self.poses_pub)
        if want_poses or self.recorder is not None:
            bodies = sim.body_states()
            if want_poses:
                msg = PoseArray()
                msg.header.stamp = st
                msg.header.frame_id = WORLD_FRAME
                msg.poses = [_pose(b) for b in bodies]
                batch.append((self.poses_pub, self.poses_topic, POSES_TYPE, serialize_message(msg)))
            if self.recorder is not None:
                batch.append(("tf", [_transform(b) for b in bodies]))
        return batch

    def send(self, t_ns: int, batch: list) -> None:
        """Publish a prepared state (and hand the same bytes to the recorder)."""
        for item in batch:
            if item[0] == "tf":
                self.recorder.tf(t_ns, item[1])
            else:
                self._send(item[0], item[1], item[2], t_ns, item[3])

    def publish_diagnostics(self, t_ns: int, level: int, message: str, values: dict) -> None:
        status = DiagnosticStatus(
            level=bytes([level]), name="gyro_sim: simulation", message=message, hardware_id=self.hardware_id,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = stamp(t_ns)
        self._send(self.diag_pub, DIAGNOSTICS[0], DIAGNOSTICS[1], t_ns, serialize_message(msg))

    def record_command(self, t_ns: int, raw: bytes) -> None:
        if self.recorder is not None:
            self.recorder.raw(self.command_topic, COMMAND_TYPE, t_ns, raw)

    def event(self, t_ns: int, text: str) -> None:
        self.node.get_logger().info(f"t = {t_ns * 1e-9:.6f} s: {text}")
        if self.recorder is not None:
            self.recorder.event(t_ns, text)


def _pose(b) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in b.position)
    w, x, y, z = (float(v) for v in b.quaternion)
    p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z = w, x, y, z
    return p


def _transform(b) -> tuple:
    """(child frame, position, quaternion x y z w) of a body in the world frame (for /tf)."""
    w, x, y, z = (float(v) for v in b.quaternion)
    return b.name, tuple(float(v) for v in b.position), (x, y, z, w)
