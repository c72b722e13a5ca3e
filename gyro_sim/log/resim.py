"""Re-simulation of a log: rebuild the Simulator from the embedded scene and parameters, feed it
the recorded commands at their recorded times, and compare with the logged joint states and
IMU messages (sensor_msgs/Imu: the IMUs' noise depends only on their seeds and the time).

The log must keep the contract of :mod:`gyro_sim.log.record` (fixed ``advance_dt``, log time =
offset + simulated time, outputs before commands at a boundary, messages in causal order).
Then, with the same integrator, the same code and the same machine, every logged joint state
is reproduced bit for bit: deviation 0. What can make it non-zero is reported with the numbers:
another integrator or tolerance (``--integrator``), other versions of gyro_sim / numpy / Python
or another machine than the ones recorded in the parameters (different rounding in BLAS and
libm), or a log whose joint states are not at step boundaries.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from gyro_sim.progress import plural
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import LogError, iter_messages, read_info
from gyro_sim.log.record import machine_params

REQUIRED = ("integrator", "rtol", "atol", "step", "advance_dt")
#: most steps a re-simulation may take, of `advance_dt` and (fixed-step integrators) of `step`:
#: a crafted log with a tiny advance_dt or step, or a message stamped far in the future, would
#: otherwise run for days. Checked from the log's own parameters and span before anything runs,
#: and against each message's time as it is read.
MAX_RESIM_STEPS = 10**8
#: the message type each topic re-simulation reads must carry (the commands topic is named by
#: the parameter ``commands_topic``, default /gyro_sim/axis_moments)
TOPIC_TYPES = {M.JOINT_STATES: "sensor_msgs/msg/JointState", M.EVENTS: "std_msgs/msg/String"}
COMMANDS_TYPE = "std_msgs/msg/Float64MultiArray"
#: the node's event when command_timeout passes without a good command: moments back to zero
COMMAND_TIMEOUT_EVENT = "command timeout"
#: the node's event when its dynamics switch backend at a step boundary ("dynamics: numba from
#: here ..."): a start on a cold cache steps on numpy while the kernels compile in the
#: background (gyro_sim.warmup.start_deferred); re-simulation switches at the same boundary
DYNAMICS_EVENT = "dynamics: "
#: the backends a DYNAMICS_EVENT may name
DYNAMICS_BACKENDS = ("numba", "numpy")


@dataclass
class Resimulation:
    """The outcome: the largest deviation of re-simulated from logged joint states."""

    max_deviation: float = 0.0  # over position, velocity and effort of every joint
    by_field: dict = field(default_factory=lambda: {"position": 0.0, "velocity": 0.0, "effort": 0.0})
    worst: tuple | None = None  # (time s, joint, field)
    compared: int = 0  # joint-state messages compared
    imu_compared: int = 0  # IMU messages compared (their fields in by_field as imu_...)
    off_boundary: int = 0  # joint states not at a step boundary (not compared)
    commands: int = 0
    rejected: int = 0  # logged commands the simulator refuses (wrong length, non-finite)
    resets: int = 0
    switches: int = 0  # backend switches repeated (DYNAMICS_EVENT)
    steps: int = 0
    sim_time: float = 0.0
    integrator: str = ""
    notes: list = field(default_factory=list)  # why the deviation may not be 0

    def report(self) -> str:
        lines = [
            f"re-simulated {self.sim_time:.6g} s ({plural(self.steps, 'step')} of the recorded size, "
            f"{plural(self.commands, 'command')}, {plural(self.resets, 'reset')}"
            + (f", the dynamics' backend switched {self.switches} time{'s' if self.switches != 1 else ''} as recorded"
               if self.switches else "") + f") with {self.integrator}",
            f"compared {plural(self.compared, 'joint-state message')}"
            + (f" and {plural(self.imu_compared, 'IMU message')}" if self.imu_compared else "")
            + (f" ({self.off_boundary} off the step boundaries, skipped)" if self.off_boundary else ""),
            f"largest deviation: {self.max_deviation:.3e}"
            + (f" ({self.worst[2]} of {self.worst[1]} at t = {self.worst[0]:.6g} s)"
               if self.worst and self.max_deviation else ""),
            "  by field: " + ", ".join(f"{k} {v:.3e}" for k, v in self.by_field.items()),
        ]
        if self.max_deviation == 0.0 and self.compared:
            lines.append("bit-for-bit identical to the log")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def resimulate(path: str | os.PathLike, *, integrator: str | None = None, rtol: float | None = None,
               atol: float | None = None, progress=None) -> Resimulation:
    """Re-run the log at `path` (see the module docstring); optionally with another integrator."""
    from gyro_sim.simulator import Simulator

    info = prepare(path, integrator=integrator)
    p = info.params
    scene = info.scene()
    name = integrator or p["integrator"]
    # the backend the run started on ("dynamics": numpy when it started before its kernels were
    # compiled; a DYNAMICS_EVENT then says where it switched); a log without it: as any run
    sim = Simulator(scene, integrator=name, rtol=p["rtol"] if rtol is None else rtol,
                    atol=p["atol"] if atol is None else atol, step=p["step"],
                    backend="numpy" if p.get("dynamics") == "numpy" else "auto")
    dt = float(p["advance_dt"])
    names = info.topic_names(path)
    cmd_topic = p.get("commands_topic", names.axis_moments)
    out = Resimulation(integrator=name)
    if name != p["integrator"] or rtol is not None or atol is not None:
        out.notes.append(f"integrator {name} (rtol {sim.integrator.rtol:g}) differs from the recorded "
                         f"{p['integrator']} (rtol {p['rtol']:g}): the deviation is the difference of the two "
                         "solutions' errors, not 0")
    here = machine_params()
    for key in ("gyro_sim_version", "numpy", "python", "machine"):
        if key in p and p[key] != here[key]:
            out.notes.append(f"recorded with {key} {p[key]}, re-simulated with {here[key]}: rounding may differ")

    end = info.end_ns or 0
    topics = [names.joint_states, cmd_topic, names.events]
    if sim.control_names:  # the servos' joint commands, on their own topic
        topics.append(names.joint_commands)
    if sim.imu_names:  # the IMUs sampled as the log's publications did
        sim.set_imu_default_rate(float(p.get("publish_rate", 100.0)))
        topics += [topic for topic, msgtype in info.topics.items() if msgtype == M.IMU_TYPE]
    # file order is causal order (record.py); log_time_order=False keeps it
    _replay(path, sim, out, dt, cmd_topic, topics, end, progress, names)
    if out.compared == 0:
        out.notes.append("no joint states were compared")
    return out


def prepare(path: str | os.PathLike, *, integrator: str | None = None):
    """The log's LogInfo, once everything re-simulation takes from it is checked: the
    parameters (:func:`_check_params`), the types of the topics it reads, and the work its span
    takes (at most MAX_RESIM_STEPS). LogError naming the first problem; nothing is simulated."""
    from gyro_sim.integrators import INTEGRATORS, FixedStepIntegrator

    info = read_info(path)
    p = info.params
    missing = [k for k in REQUIRED if k not in p]
    if missing:
        raise LogError(f"{path}: the parameters lack {', '.join(missing)}: not a re-simulable gyro_sim log")
    _check_params(path, p)
    names = info.topic_names(path)
    cmd_topic = p.get("commands_topic", names.axis_moments)
    types = {names.joint_states: TOPIC_TYPES[M.JOINT_STATES], names.events: TOPIC_TYPES[M.EVENTS]}
    if cmd_topic in types:
        raise LogError(f"{path}: parameter commands_topic: {cmd_topic} is the topic of "
                       f"{types[cmd_topic]}, not of the commands")
    wanted_types = {**types, cmd_topic: COMMANDS_TYPE, names.joint_commands: TOPIC_TYPES[M.JOINT_STATES]}
    for topic, wanted in wanted_types.items():
        have = info.topics.get(topic)
        if have is not None and have != wanted:
            what = "parameter commands_topic: " if topic == cmd_topic else ""
            raise LogError(f"{path}: {what}topic {topic[:80]} carries {have[:80]}, not {wanted}: "
                           "not a re-simulable gyro_sim log")
    span = (info.end_ns or 0) / 1e9
    dt = float(p["advance_dt"])
    name = integrator or p["integrator"]
    work = [(span / dt, f"advance_dt = {dt:g} s")]
    cls = INTEGRATORS.get(name)
    if cls is not None and issubclass(cls, FixedStepIntegrator):
        work.append((span / float(p["step"]), f"{name} steps of step = {float(p['step']):g} s"))
    for steps, what in work:
        if steps > MAX_RESIM_STEPS:
            raise LogError(f"{path}: the log's {span:.6g} s at {what} would take {steps:.3g} steps; the limit "
                           f"is {MAX_RESIM_STEPS:.0e}: refused")
    return info


def _replay(path, sim, out: Resimulation, dt: float, cmd_topic: str, topics, end: int, progress,
            names: M.TopicNames = M.ROOT_TOPICS) -> None:
    """Feed the log's commands, resets and timeouts to `sim`, comparing its joint states."""
    offset = 0
    imus = None  # (log time, {name: reading}) of the IMU messages at one time
    for topic, msgtype, t, msg in iter_messages(path, topics, log_time_order=False):
        needed = (t - offset - M.time_ns(sim.time)) / (dt * 1e9)
        if out.steps + needed > MAX_RESIM_STEPS:
            raise LogError(f"{path}: a message at log time {t / 1e9:.9g} s would take the re-simulation to "
                           f"{out.steps + needed:.3g} steps of advance_dt = {dt:g} s; the limit is "
                           f"{MAX_RESIM_STEPS:.0e}: refused")
        while offset + M.time_ns(sim.time) < t:
            sim.advance(dt)
            out.steps += 1
            if progress is not None:
                progress((offset + M.time_ns(sim.time)) / 1e9, end / 1e9)
        here_ns = offset + M.time_ns(sim.time)
        if topic == names.joint_states:
            if here_ns != t:
                out.off_boundary += 1
                continue
            try:
                _compare(out, sim.joint_states(), _fields(path, msg, topic, t, JOINT_STATE_FIELDS), t)
            except TypeError as exc:  # fields of the wrong kind (a crafted schema)
                raise LogError(f"{path}: {topic} at log time {t / 1e9:.9g} s: {exc}") from None
        elif msgtype == M.IMU_TYPE and topic not in (cmd_topic, names.events):
            if here_ns != t:
                out.off_boundary += 1
                continue
            if imus is None or imus[0] != t:
                imus = (t, {r.name: r for r in sim.imus()})
            _compare_imu(path, out, imus[1], msg, topic, t)
        elif topic == cmd_topic:
            if here_ns != t:
                out.notes.append(f"command at t = {t / 1e9:.9g} s is not at a step boundary: applied at the next one")
            try:
                sim.set_axis_moments(list(_fields(path, msg, topic, t, ("data",)).data))
            except (TypeError, ValueError):  # the node logs rejected commands too, and refused them the same way
                out.rejected += 1
                continue
            out.commands += 1
        elif topic == names.joint_commands and sim.control_names:
            fields = _fields(path, msg, topic, t, JOINT_STATE_FIELDS)
            try:
                sim.set_controls(sim.joint_command_controls(list(fields.name), list(fields.position),
                                                            list(fields.velocity), list(fields.effort)))
            except (TypeError, ValueError):  # refused as the node refuses it
                out.rejected += 1
                continue
            out.commands += 1
        elif topic == names.events:
            event = _fields(path, msg, topic, t, ("data",)).data
            if not isinstance(event, str):
                raise LogError(f"{path}: {topic} at log time {t / 1e9:.9g} s: data is not a string")
            if event == "reset":
                sim.reset()
                offset = t
                out.resets += 1
            elif event.startswith(COMMAND_TIMEOUT_EVENT):
                sim.set_axis_moments([0.0] * len(sim.axis_names))
            elif event.startswith(DYNAMICS_EVENT):
                backend = event[len(DYNAMICS_EVENT):].split(" ", 1)[0]
                if backend not in DYNAMICS_BACKENDS:
                    raise LogError(f"{path}: {topic} at log time {t / 1e9:.9g} s: a switch to an unknown backend "
                                   f"{backend[:40]!r}")
                if here_ns != t:
                    raise LogError(f"{path}: {topic} at log time {t / 1e9:.9g} s: a backend switch off the step "
                                   "boundaries")
                sim.switch_backend(backend)
                out.switches += 1
    out.sim_time = (offset + M.time_ns(sim.time)) / 1e9


def _check_params(path, p: dict) -> None:
    """The recorded parameters re-simulation uses, checked (LogError naming the first bad one)."""
    from gyro_sim.integrators import INTEGRATORS

    if not isinstance(p["integrator"], str) or p["integrator"] not in INTEGRATORS:
        raise LogError(f"{path}: parameter integrator: {str(p['integrator'])[:40]!r} is not one of "
                       f"{', '.join(INTEGRATORS)}")
    for key in ("rtol", "atol", "step", "advance_dt"):
        v = p[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 \
                or (v == 0 and key != "atol"):
            raise LogError(f"{path}: parameter {key}: must be a positive finite number, got {str(v)[:40]!r}")
    if not isinstance(p.get("commands_topic", M.AXIS_MOMENTS), str):
        raise LogError(f"{path}: parameter commands_topic: must be a string")


#: the fields of a joint state re-simulation compares
JOINT_STATE_FIELDS = ("name", "position", "velocity", "effort")


def _fields(path, msg, topic: str, t_ns: int, names):
    """`msg`, once it is checked to have each of `names` (a crafted schema may lack them)."""
    for name in names:
        if not hasattr(msg, name):
            raise LogError(f"{path}: {topic} at log time {t_ns / 1e9:.9g} s has no field {name}: its schema "
                           "is not that of its type")
    return msg


def _compare(out: Resimulation, js, logged, t_ns: int) -> None:
    out.compared += 1
    if list(js.name) != list(logged.name):
        raise LogError(f"joint names differ at t = {t_ns / 1e9:g} s: log {list(logged.name)}, "
                       f"re-simulation {list(js.name)}")
    for fld in ("position", "velocity", "effort"):
        mine, theirs = getattr(js, fld), getattr(logged, fld)
        if len(theirs) != len(mine):
            raise LogError(f"joint {fld} lengths differ at t = {t_ns / 1e9:g} s")
        for name, a, b in zip(js.name, mine, theirs):
            d = abs(a - b) if math.isfinite(a) else math.inf
            if d > out.by_field[fld]:
                out.by_field[fld] = d
            if d > out.max_deviation:
                out.max_deviation = d
                out.worst = (t_ns / 1e9, name, fld)


def _compare_imu(path, out: Resimulation, readings: dict, logged, topic: str, t_ns: int) -> None:
    """One logged sensor_msgs/Imu against the re-simulated reading of the IMU it names."""
    try:
        name = logged.header.frame_id
        fields = {"imu_orientation": ([logged.orientation.x, logged.orientation.y, logged.orientation.z,
                                       logged.orientation.w], "orientation"),
                  "imu_angular_velocity": ([getattr(logged.angular_velocity, a) for a in "xyz"], "angular_velocity"),
                  "imu_linear_acceleration": ([getattr(logged.linear_acceleration, a) for a in "xyz"],
                                              "linear_acceleration")}
    except AttributeError as exc:
        raise LogError(f"{path}: {topic} at log time {t_ns / 1e9:.9g} s: {exc}: its schema is not that of "
                       f"{M.IMU_TYPE}") from None
    reading = readings.get(name)
    if reading is None:
        raise LogError(f"{path}: {topic} at log time {t_ns / 1e9:.9g} s: the scene has no IMU {str(name)[:64]!r}")
    out.imu_compared += 1
    for key, (theirs, attr) in fields.items():
        mine = getattr(reading, attr)
        if attr == "orientation":
            mine = [mine[1], mine[2], mine[3], mine[0]]
        out.by_field.setdefault(key, 0.0)
        for a, b in zip(mine, theirs):
            d = abs(a - b) if math.isfinite(a) and math.isfinite(b) else math.inf
            if d > out.by_field[key]:
                out.by_field[key] = d
            if d > out.max_deviation:
                out.max_deviation = d
                out.worst = (t_ns / 1e9, name, key)
