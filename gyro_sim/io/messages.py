"""A Simulator's outputs as ROS 2 messages in plain Python (dicts in the messages' field layout).

The node publishes them (after filling its rclpy message classes) and the recorders encode
them as CDR (:class:`gyro_sim.io.mcap_log.LogWriter`); nothing here imports rclpy.

Topics and frames (SPEC.md, "ROS interface"), all stamped with the simulated time:

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
/robot_description                  std_msgs/msg/String              (logs only: the URDF, t = 0)
==================================  ===============================  ==========================

A wrench is R^k (eq 40) and L^k (eq 48) at O^k in body k's own frame. A pose or transform is
O^k and world_R_body of body k. Diagnostics carry the invariants, their drift since the
reference (the start of the run, or the last reset) and the total angular momentum about O^1.

Non-finite numbers never leave here: every builder raises :class:`NonFiniteError`.
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Sequence

import numpy as np

WORLD_FRAME = "world"
JOINT_STATES = "/joint_states"
WRENCH_PREFIX = "/gyro_sim/wrench/"
POSES = "/gyro_sim/poses"
TF = "/tf"
CLOCK = "/clock"
DIAGNOSTICS = "/diagnostics"
AXIS_MOMENTS = "/gyro_sim/axis_moments"
EVENTS = "/gyro_sim/events"
ROBOT_DESCRIPTION = "/robot_description"  # the URDF, written once by every log (io.urdf)

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
POSE_ARRAY_TYPE = "geometry_msgs/msg/PoseArray"
TF_TYPE = "tf2_msgs/msg/TFMessage"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
COMMAND_TYPE = "std_msgs/msg/Float64MultiArray"
STRING_TYPE = "std_msgs/msg/String"

#: name of the DiagnosticStatus of the dynamics
DIAGNOSTIC_NAME = "gyro_sim: dynamics"
#: diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: relative drift is measured against max(|reference|, DRIFT_FLOOR) (an integral near zero)
DRIFT_FLOOR = 1e-12
#: the invariants whose drift is reported (the first integrals; not kinetic / potential)
DRIFT_KEYS = ("energy", "vertical_momentum", "jacobi", "lagrange_82", "lagrange_85")

NS_PER_S = 1_000_000_000


class NonFiniteError(ValueError):
    """A NaN or infinity in an output: refused, it must never reach a topic or a log."""


def wrench_topic(joint: str) -> str:
    return WRENCH_PREFIX + joint


def topic_types(joints: Iterable[str]) -> dict[str, str]:
    """topic -> message type of everything a simulation publishes (commands and events included)."""
    out = {JOINT_STATES: JOINT_STATE_TYPE}
    out.update({wrench_topic(j): WRENCH_TYPE for j in joints})
    out.update({POSES: POSE_ARRAY_TYPE, TF: TF_TYPE, CLOCK: CLOCK_TYPE, DIAGNOSTICS: DIAGNOSTICS_TYPE,
                AXIS_MOMENTS: COMMAND_TYPE, EVENTS: STRING_TYPE})
    return out


# --- time ----------------------------------------------------------------------------------------
def time_ns(t: float) -> int:
    """Simulated time (s) as integer nanoseconds: the log time and the stamps of a message."""
    if not math.isfinite(t) or t < 0:
        raise NonFiniteError(f"simulated time must be finite and >= 0, got {t!r}")
    return int(round(t * NS_PER_S))


def stamp(t_ns: int) -> dict:
    """builtin_interfaces/Time of integer nanoseconds."""
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return {"sec": sec, "nanosec": nanosec}


def stamp_ns(st) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time (dict or object)."""
    if isinstance(st, Mapping):
        return int(st["sec"]) * NS_PER_S + int(st["nanosec"])
    return int(st.sec) * NS_PER_S + int(st.nanosec)


def header(t_ns: int, frame_id: str = "") -> dict:
    return {"stamp": stamp(t_ns), "frame_id": frame_id}


def _floats(values, what: str) -> list[float]:
    out = [float(v) for v in np.asarray(values, dtype=float).ravel()]
    if not all(math.isfinite(v) for v in out):
        raise NonFiniteError(f"{what}: non-finite value in {out}")
    return out


def _vec(v, what: str) -> dict:
    x, y, z = _floats(v, what)
    return {"x": x, "y": y, "z": z}


def _quat(q_wxyz, what: str) -> dict:
    w, x, y, z = _floats(q_wxyz, what)
    return {"x": x, "y": y, "z": z, "w": w}


# --- builders --------------------------------------------------------------------------------------
def joint_state(js, t_ns: int) -> dict:
    """sensor_msgs/JointState of `Simulator.joint_states()` (name, position, velocity, effort)."""
    return {
        "header": header(t_ns),
        "name": [str(n) for n in js.name],
        "position": _floats(js.position, "joint_states.position"),
        "velocity": _floats(js.velocity, "joint_states.velocity"),
        "effort": _floats(js.effort, "joint_states.effort"),
    }


def wrench_stamped(w, t_ns: int) -> dict:
    """geometry_msgs/WrenchStamped of one `Simulator.wrenches()` entry (frame: the body)."""
    return {
        "header": header(t_ns, w.frame),
        "wrench": {"force": _vec(w.force, f"wrench {w.joint}.force"),
                   "torque": _vec(w.moment, f"wrench {w.joint}.torque")},
    }


def pose_array(bodies, t_ns: int) -> dict:
    """geometry_msgs/PoseArray of every body (`Simulator.body_states()`), frame "world"."""
    return {
        "header": header(t_ns, WORLD_FRAME),
        "poses": [{"position": _vec(b.position, f"pose {b.name}.position"),
                   "orientation": _quat(b.quaternion, f"pose {b.name}.orientation")} for b in bodies],
    }


def tf_message(bodies, t_ns: int) -> dict:
    """tf2_msgs/TFMessage: world -> each body frame, named after the body."""
    return {
        "transforms": [
            {"header": header(t_ns, WORLD_FRAME), "child_frame_id": b.name,
             "transform": {"translation": _vec(b.position, f"tf {b.name}.translation"),
                           "rotation": _quat(b.quaternion, f"tf {b.name}.rotation")}}
            for b in bodies
        ]
    }


def clock(t_ns: int) -> dict:
    """rosgraph_msgs/Clock."""
    return {"clock": stamp(t_ns)}


def axis_moments(values: Sequence[float], names: Sequence[str] | None = None) -> dict:
    """std_msgs/Float64MultiArray of a command (one value per actuated axis, no layout:
    the forward-command convention of ros2_controllers)."""
    data = _floats(values, "axis_moments")
    if names is not None and len(names) != len(data):
        raise ValueError(f"{len(data)} axis moments for {len(names)} axes {list(names)}")
    return {"layout": {"dim": [], "data_offset": 0}, "data": data}


def string(text: str) -> dict:
    return {"data": str(text)}


def _drift(value: float, ref: float) -> float:
    """Signed relative drift (value - ref) / max(|ref|, DRIFT_FLOOR)."""
    return (value - ref) / max(abs(ref), DRIFT_FLOOR)


def diagnostic_values(invariants: Mapping, reference: Mapping | None = None,
                      momentum_O1=None, error_estimate: float | None = None) -> dict[str, float]:
    """The numbers of the dynamics' DiagnosticStatus, by key.

    Scalars of `invariants` as they are, vectors by component (``<name>_x`` ...), the first
    integrals (DRIFT_KEYS) that have a reference also as ``<name>_drift`` (signed, relative:
    not every one is conserved in every scene, see gyro_sim.core.invariants.conserved); `momentum_O1` (3,) as
    ``angular_momentum_O1_x`` ...; `error_estimate` when not None.
    """
    out: dict[str, float] = {}
    for name, value in invariants.items():
        v = np.asarray(value, dtype=float)
        if v.ndim == 0:
            out[name] = float(v)
            if reference is not None and name in reference and name in DRIFT_KEYS:
                out[f"{name}_drift"] = _drift(float(v), float(reference[name]))
        else:
            for axis, c in zip("xyz", v.ravel()):
                out[f"{name}_{axis}"] = float(c)
    if momentum_O1 is not None:
        for axis, c in zip("xyz", np.asarray(momentum_O1, dtype=float).ravel()):
            out[f"angular_momentum_O1_{axis}"] = float(c)
    if error_estimate is not None:
        out["error_estimate"] = float(error_estimate)
    return out


def diagnostic_array(t_ns: int, values: Mapping[str, float | str], *, level: int = OK, message: str = "",
                     name: str = DIAGNOSTIC_NAME, hardware_id: str = "") -> dict:
    """diagnostic_msgs/DiagnosticArray with one status; numbers written with repr (exact)."""
    kv = []
    for k, v in values.items():
        if isinstance(v, str):
            kv.append({"key": str(k), "value": v})
        else:
            f = float(v)
            if not math.isfinite(f):
                raise NonFiniteError(f"diagnostics {k}: non-finite value {f!r}")
            kv.append({"key": str(k), "value": repr(f)})
    status = {"level": int(level), "name": name, "message": message, "hardware_id": hardware_id, "values": kv}
    return {"header": header(t_ns), "status": [status]}


def diagnostic_numbers(msg) -> dict[str, float]:
    """The numeric key-values of a decoded DiagnosticArray (first status), by key."""
    status = msg["status"] if isinstance(msg, Mapping) else msg.status
    out = {}
    for st in status:
        for kv in (st["values"] if isinstance(st, Mapping) else st.values):
            key, value = (kv["key"], kv["value"]) if isinstance(kv, Mapping) else (kv.key, kv.value)
            try:
                out[key] = float(value)
            except ValueError:
                pass
    return out


def angular_momentum_O1(sim) -> np.ndarray:
    """Total angular momentum of the chain about O^1, world frame (3,), rotors included.

    The vector whose vertical component is `invariants()["vertical_momentum"]` (eq 79).
    """
    return np.asarray(sim.invariants()["angular_momentum_O1"], dtype=float)


class Snapshot:
    """Every output of a Simulator at its current time, as messages (topic -> dict).

    Parameters
    ----------
    sim : the Simulator
    reference : invariants the drifts are measured against (None: no drifts)
    extra : more diagnostic values (the node: step time, real-time factor, misses ...)
    """

    def __init__(self, sim, t_ns: int | None = None, reference: Mapping | None = None,
                 extra: Mapping[str, float | str] | None = None):
        self.t_ns = time_ns(sim.time) if t_ns is None else int(t_ns)
        t = self.t_ns
        bodies = sim.body_states()
        self.messages: dict[str, dict] = {JOINT_STATES: joint_state(sim.joint_states(), t)}
        for w in sim.wrenches():
            self.messages[wrench_topic(w.joint)] = wrench_stamped(w, t)
        self.messages[POSES] = pose_array(bodies, t)
        self.messages[TF] = tf_message(bodies, t)
        self.messages[CLOCK] = clock(t)
        values = diagnostic_values(sim.invariants(), reference, None, sim.error_estimate)
        values["time"] = sim.time
        if extra:
            values.update(extra)
        self.messages[DIAGNOSTICS] = diagnostic_array(t, values, hardware_id=sim.scene.name)

    def items(self):
        return self.messages.items()
