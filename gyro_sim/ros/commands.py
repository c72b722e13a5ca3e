"""`gyro-sim cmd`: publish commands to the node (there is no `ros2 topic pub` here): axis moments,
or the servos' targets by joint name.

    gyro-sim cmd constant 0.0 0.05 -0.03                  # one value per axis, in sim.axis_names order
    gyro-sim cmd step --before 0 0 0 --after 0 0.05 0 --at 2
    gyro-sim cmd --seconds 10 sine --amplitude 0.002 0.05 0 --frequency 0.5
    gyro-sim cmd sine --amplitude 0.002 0.05 0 --frequency 0.5 --seconds 10   # options go on either side
    gyro-sim cmd --scene hinge_chain constant 0 0.05 0    # checks the count, prints the axis names
    gyro-sim cmd --namespace /robot1 constant 0 0.05 0    # the node started with -r __ns:=/robot1
    gyro-sim cmd --scene arm.xml joints --position shoulder=0.5 elbow=-0.3 --once
    gyro-sim cmd --scene arm.xml joints --velocity wrist=0.2 --seconds 5   # servos by joint name

Values are N m, one per axis (with --scene, a single value stands for every axis). Commands are sent
at --rate Hz (keep it above 1 / command_timeout of the node) from the moment the node's
subscription is seen, the profile's time being wall seconds since then. `joints` sends the
servos' targets as one sensor_msgs/JointState on ~/joint_commands (JOINT=VALUE: a position
servo's position, a velocity servo's velocity, a motor's effort), at --rate Hz or --once; with
--scene each joint is checked against the scene's servos first. Needs rclpy
(pip install 'gyro_sim[ros]') and the node in the same ROS_DOMAIN_ID.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from gyro_sim.errors import GyroSimError

DEFAULT_TOPIC = "/gyro_sim/axis_moments"
DISCOVERY_TIMEOUT = 15.0
#: the entries of a joint command, in sensor_msgs/JointState's order
JOINT_KINDS = ("position", "velocity", "effort")


def command_topic(namespace: str, kind: str = "axis_moments") -> str:
    """~/axis_moments (or ~/joint_commands) of gyro_sim_node started in `namespace` ("/",
    "robot1" or "/robot1")."""
    from gyro_sim.msgs.messages import NODE_NAME, TopicNames

    ns = "/" + namespace.strip("/")
    return getattr(TopicNames(namespace=ns, node=f"{ns.rstrip('/')}/{NODE_NAME}"), kind)


class BadCommand(GyroSimError, ValueError):
    """A command the user wrote that cannot be sent (one line, exit 2)."""


def joint_targets(args) -> dict[str, tuple[str, float]]:
    """joint -> (kind, value) of `joints`'s --position, --velocity and --effort JOINT=VALUE
    items, in the order given. BadCommand naming the item: no "=", no finite number, a joint
    given twice."""
    out: dict[str, tuple[str, float]] = {}
    for kind in JOINT_KINDS:
        for item in getattr(args, kind) or ():
            name, eq, text = item.rpartition("=")
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not eq or not name or not math.isfinite(value):
                raise BadCommand(f"--{kind} {item!r}: expected JOINT=VALUE with a finite number")
            if name in out:
                raise BadCommand(f"joint {name!r}: given twice (--{out[name][0]} and --{kind})")
            out[name] = (kind, value)
    if not out:
        raise BadCommand("joints: give at least one --position, --velocity or --effort JOINT=VALUE")
    return out


def check_joint_targets(targets: dict[str, tuple[str, float]], scene: str) -> list[str]:
    """BadCommand naming the first joint of `targets` that the node of `scene` would refuse: no
    such joint, a joint no servo drives, an entry its servo does not take. Returns the scene's
    servo joints (the numpy backend: nothing compiled)."""
    from gyro_sim.simulator import Simulator

    sim = Simulator(scene, integrator="rk4", backend="numpy")
    model = sim.model
    servos = dict(model.servo_joints)
    for name, (kind, _) in targets.items():
        if name not in sim.joint_names:
            joint = next((j for j, servo in servos.items() if servo.name == name), None)
            raise BadCommand(f"joint {name!r}: no such joint in {scene} (servo joints: {', '.join(servos) or 'none'})"
                             + (f"; {name!r} is the control of joint {joint!r}" if joint else ""))
        if name not in servos:
            raise BadCommand(f"joint {name!r}: no servo drives it (servo joints: {', '.join(servos) or 'none'}"
                             + ("; its axis moment is sent with `gyro-sim cmd constant`)" if name in sim.axis_names
                                else ")"))
        if servos[name].command != kind:
            raise BadCommand(f"joint {name!r}: its servo takes a {servos[name].command}, not a {kind} "
                             f"(--{servos[name].command} {name}=VALUE)")
    return list(servos)


def joint_message(targets: dict[str, tuple[str, float]]) -> dict[str, list]:
    """The JointState's fields of `targets`: every name, and each kind given one value per name
    (the node reads the entry of each servo's kind; the others are 0 and unread: `cmd_joints`
    mixes kinds only with --scene, where each joint's kind is checked)."""
    kinds = {kind for kind, _ in targets.values()}
    fields: dict[str, list] = {"name": list(targets)}
    for kind in JOINT_KINDS:
        fields[kind] = [value if k == kind else 0.0 for k, value in targets.values()] if kind in kinds else []
    return fields


def profile(args):
    """f(t) -> moments (one per axis) for the chosen mode."""
    if args.mode == "constant":
        v = np.asarray(args.values, dtype=float)
        return lambda t: v
    if args.mode == "step":
        before, after = _broadcast(args.before, args.after)
        return lambda t: before if t < args.at else after
    amp, freq, off = _broadcast(args.amplitude, args.frequency, args.offset)
    return lambda t: off + amp * np.sin(2.0 * math.pi * freq * t)


def _broadcast(*lists):
    n = max(len(x) for x in lists)
    out = []
    for x in lists:
        a = np.asarray(x, dtype=float)
        if a.size not in (1, n):
            raise SystemExit(f"gyro-sim cmd: per-axis lists must have one value or {n}, got {list(x)}")
        out.append(np.broadcast_to(a, (n,)).copy())
    return out


def cmd_publish(args) -> int:
    if args.mode == "joints":
        return cmd_joints(args)
    f = profile(args)
    n = len(f(0.0))
    if args.scene:
        from gyro_sim.simulator import Simulator
        from gyro_sim.paths import find_scene

        from gyro_sim.scene.load import SceneError

        try:  # the numpy backend: the axis names without compiling anything
            axes = Simulator(find_scene(args.scene), integrator="rk4", backend="numpy").axis_names
        except (SceneError, FileNotFoundError) as exc:
            print(f"gyro-sim cmd: {exc}", file=sys.stderr)
            return 2
        if n not in (1, len(axes)):
            print(f"gyro-sim cmd: scene {args.scene} has {len(axes)} axes {axes}, got {n} values", file=sys.stderr)
            return 2
        if n == 1:
            f0 = f
            f = lambda t: np.broadcast_to(f0(t), (len(axes),))  # noqa: E731
        print(f"axes: {', '.join(axes)}")
    kinds = _ros_kinds(args, "std_msgs.msg", "Float64MultiArray")
    if kinds is None:
        return 2
    message, shutdown = kinds
    return _publish(args, message, "axis_moments", lambda t: message(data=[float(v) for v in f(t)]), shutdown)


def _ros_kinds(args, module: str, name: str):
    """(the message type `module.name`, rclpy's ExternalShutdownException), or None after one
    line on stderr: a --rate that is not > 0, or no rclpy."""
    if not args.rate > 0:
        print("gyro-sim cmd: --rate must be > 0", file=sys.stderr)
        return None
    try:
        import importlib

        from rclpy.executors import ExternalShutdownException

        return getattr(importlib.import_module(module), name), ExternalShutdownException
    except ImportError as exc:
        print(f"gyro-sim cmd: needs rclpy ({exc}); install it with: pip install 'gyro_sim[ros]'", file=sys.stderr)
        return None


def cmd_joints(args) -> int:
    """`gyro-sim cmd joints`: the servos' targets by joint name on ~/joint_commands."""
    try:
        targets = joint_targets(args)
        if args.scene:
            from gyro_sim.paths import find_scene

            try:
                servos = check_joint_targets(targets, find_scene(args.scene))
            except (GyroSimError, FileNotFoundError) as exc:
                raise BadCommand(str(exc)) from None
            print(f"servo joints: {', '.join(servos)}")
        elif len({kind for kind, _ in targets.values()}) > 1:
            raise BadCommand("joints: --position, --velocity and --effort together need --scene (each "
                             "joint's servo reads one entry; unchecked, another joint's would read a 0)")
        fields = joint_message(targets)
    except BadCommand as exc:
        print(f"gyro-sim cmd: {exc}", file=sys.stderr)
        return 2
    kinds = _ros_kinds(args, "sensor_msgs.msg", "JointState")
    if kinds is None:
        return 2
    message, shutdown = kinds
    return _publish(args, message, "joint_commands", lambda t: message(**fields), shutdown)


def _publish(args, msg_type, kind: str, message, interrupted) -> int:
    """Publish message(t) on ~/`kind` (or --topic) once the node's subscription is seen: at
    --rate Hz for --seconds (0: until Ctrl-C), or once (--once: then wait until the node has
    acknowledged it)."""
    import rclpy
    from rclpy.duration import Duration
    from rclpy.validate_full_topic_name import validate_full_topic_name

    topic = args.topic or command_topic(args.namespace, kind)
    try:
        validate_full_topic_name(topic)
    except Exception as exc:  # noqa: BLE001 - rclpy's InvalidTopicNameException and kin
        print(f"gyro-sim cmd: {topic!r} is not a valid topic name ({str(exc).splitlines()[0]})", file=sys.stderr)
        return 2
    args.topic = topic
    from gyro_sim.ros.discovery import announce_often

    announce_often()
    rclpy.init()
    node = rclpy.create_node("gyro_sim_cmd")
    pub = node.create_publisher(msg_type, args.topic, 10)
    once = getattr(args, "once", False)
    try:
        t0 = time.monotonic()
        if pub.get_subscription_count() == 0:
            print(f"waiting for the gyro_sim node (ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}, "
                  f"up to {DISCOVERY_TIMEOUT:g} s for a subscriber on {args.topic})", flush=True)
        while pub.get_subscription_count() == 0:
            if time.monotonic() - t0 > DISCOVERY_TIMEOUT:
                print(f"gyro-sim cmd: nobody subscribes to {args.topic} (is gyro_sim_node running, "
                      f"same ROS_DOMAIN_ID?)", file=sys.stderr)
                return 1
            time.sleep(0.05)
        if once:
            pub.publish(message(0.0))
            if not pub.wait_for_all_acked(Duration(seconds=DISCOVERY_TIMEOUT)):
                print(f"gyro-sim cmd: the command on {args.topic} was not acknowledged within "
                      f"{DISCOVERY_TIMEOUT:g} s", file=sys.stderr)
                return 1
            print(f"published one {'joint' if kind == 'joint_commands' else args.mode} command to {args.topic}")
            return 0
        print(f"publishing {args.mode} commands to {args.topic} at {args.rate:g} Hz"
              + (f" for {args.seconds:g} s" if args.seconds > 0 else " (Ctrl-C to stop)"))
        t0 = time.monotonic()
        k = 0
        while rclpy.ok():
            t = k / args.rate
            if args.seconds > 0 and t > args.seconds:
                break
            delay = t0 + t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            msg = message(t)
            pub.publish(msg)
            if args.verbose:
                print(f"t = {t:7.3f} s: {list(msg.data) if kind == 'axis_moments' else msg}")
            k += 1
    except (KeyboardInterrupt, interrupted):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim cmd` to the top-level subcommands."""
    c = sub.add_parser("cmd", help="publish axis moments or servo targets to a running gyro_sim_node",
                       description=__doc__.split("\n\n", 1)[1], formatter_class=_RawFormatter)
    _common_options(c, None)  # and again after the mode (each mode parser), where only given ones are set
    modes = c.add_subparsers(dest="mode", required=True)
    k = modes.add_parser("constant", help="the same moments all the time")
    k.add_argument("values", type=float, nargs="+", help="one per axis (N m)")
    _common_options(k, argparse.SUPPRESS)
    s = modes.add_parser("step", help="--before until --at seconds, then --after")
    s.add_argument("--before", type=float, nargs="+", default=[0.0])
    s.add_argument("--after", type=float, nargs="+", required=True)
    s.add_argument("--at", type=float, default=1.0, help="seconds after the start (default 1)")
    _common_options(s, argparse.SUPPRESS)
    w = modes.add_parser("sine", help="offset + amplitude sin(2 pi frequency t), per axis")
    w.add_argument("--amplitude", type=float, nargs="+", required=True)
    w.add_argument("--frequency", type=float, nargs="+", default=[1.0], help="Hz")
    w.add_argument("--offset", type=float, nargs="+", default=[0.0])
    _common_options(w, argparse.SUPPRESS)
    j = modes.add_parser("joints", help="the servos' targets by joint name, on ~/joint_commands")
    for kind, what in (("position", "a position servo's target (rad)"), ("velocity", "a velocity servo's "
                       "target (rad/s)"), ("effort", "a motor's control")):
        j.add_argument(f"--{kind}", nargs="+", metavar="JOINT=VALUE", help=what)
    j.add_argument("--once", action="store_true", help="publish one command and wait for the node's acknowledgement")
    _common_options(j, argparse.SUPPRESS)
    c.set_defaults(fn=cmd_publish)


def _common_options(parser, suppress) -> None:
    """The options of `gyro-sim cmd`, accepted before and after the mode (`cmd --seconds 10 sine
    ...` and `cmd sine ... --seconds 10`). With suppress=argparse.SUPPRESS no default is set,
    so an option given before the mode is not reset by the mode's parser."""
    def default(value):
        return suppress if suppress is not None else value

    parser.add_argument("--namespace", default=default("/"),
                        help="namespace of the node (as its --ros-args -r __ns:=/robot1); default: the root")
    parser.add_argument("--topic", default=default(None),
                        help=f"topic of the node's commands (default: ~/axis_moments of the node, {DEFAULT_TOPIC} "
                             "in the root namespace; joints: ~/joint_commands)")
    parser.add_argument("--rate", type=float, default=default(50.0), help="messages per second (default 50)")
    parser.add_argument("--seconds", type=float, default=default(0.0), help="seconds to publish; 0 = until Ctrl-C")
    parser.add_argument("--scene", default=default(None),
                        help="check the number of values against this scene's axes (joints: the joints against its "
                             "servos)")
    parser.add_argument("-v", "--verbose", action="store_true", default=default(False), help="print every command sent")


def _RawFormatter(prog):
    import argparse

    return argparse.RawDescriptionHelpFormatter(prog)
