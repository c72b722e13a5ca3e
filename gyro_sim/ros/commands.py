"""`gyro-sim cmd`: publish axis-moment commands to the node (there is no `ros2 topic pub` here).

    gyro-sim cmd constant 0.0 0.05 -0.03                  # one value per axis, in sim.axis_names order
    gyro-sim cmd step --before 0 0 0 --after 0 0.05 0 --at 2
    gyro-sim cmd --seconds 10 sine --amplitude 0.002 0.05 0 --frequency 0.5
    gyro-sim cmd sine --amplitude 0.002 0.05 0 --frequency 0.5 --seconds 10   # options go on either side
    gyro-sim cmd --scene hinge_chain constant 0 0.05 0    # checks the count, prints the axis names
    gyro-sim cmd --namespace /robot1 constant 0 0.05 0    # the node started with -r __ns:=/robot1

Values are N m, one per axis (with --scene, a single value stands for every axis). Commands are sent
at --rate Hz (keep it above 1 / command_timeout of the node) from the moment the node's
subscription is seen, the profile's time being wall seconds since then. Needs rclpy
(pip install 'gyro_sim[ros]') and the node in the same ROS_DOMAIN_ID.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

DEFAULT_TOPIC = "/gyro_sim/axis_moments"
DISCOVERY_TIMEOUT = 15.0


def command_topic(namespace: str) -> str:
    """~/axis_moments of gyro_sim_node started in `namespace` ("/", "robot1" or "/robot1")."""
    from gyro_sim.msgs.messages import NODE_NAME, TopicNames

    ns = "/" + namespace.strip("/")
    return TopicNames(namespace=ns, node=f"{ns.rstrip('/')}/{NODE_NAME}").axis_moments


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
    if not args.rate > 0:
        print("gyro-sim cmd: --rate must be > 0", file=sys.stderr)
        return 2
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException
        from rclpy.validate_full_topic_name import validate_full_topic_name
        from std_msgs.msg import Float64MultiArray
    except ImportError as exc:
        print(f"gyro-sim cmd: needs rclpy ({exc}); install it with: pip install 'gyro_sim[ros]'", file=sys.stderr)
        return 2

    topic = args.topic or command_topic(args.namespace)
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
    pub = node.create_publisher(Float64MultiArray, args.topic, 10)
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
            values = [float(v) for v in f(t)]
            pub.publish(Float64MultiArray(data=values))
            if args.verbose:
                print(f"t = {t:7.3f} s: {values}")
            k += 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim cmd` to the top-level subcommands."""
    c = sub.add_parser("cmd", help="publish axis-moment commands to a running gyro_sim_node",
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
                             "in the root namespace)")
    parser.add_argument("--rate", type=float, default=default(50.0), help="messages per second (default 50)")
    parser.add_argument("--seconds", type=float, default=default(0.0), help="seconds to publish; 0 = until Ctrl-C")
    parser.add_argument("--scene", default=default(None), help="check the number of values against this scene's axes")
    parser.add_argument("-v", "--verbose", action="store_true", default=default(False), help="print every command sent")


def _RawFormatter(prog):
    import argparse

    return argparse.RawDescriptionHelpFormatter(prog)
