"""`gyro-sim view --live`: the options the live view adds to `gyro-sim view`.

Registered by :func:`register` (see ``gyro_sim.cli.PLUGINS``, after the log commands that
create `view`): the log becomes optional, and `view --live` follows a running node
(gyro_sim.viz.live) instead of reading a log.
"""
from __future__ import annotations

import sys


def _err(msg) -> int:
    print(f"gyro-sim view: {msg}", file=sys.stderr)
    return 2


def register(sub, bench) -> None:
    """Add --live and its options to the `view` subparser."""
    v = sub.choices.get("view")
    if v is None:
        return
    for action in v._actions:  # the log is not needed with --live
        if action.dest == "log":
            action.nargs, action.default = "?", None
            action.help = f"{action.help}; not with --live"
    v.add_argument("--live", action="store_true",
                   help="follow a running gyro_sim node over ROS 2 instead of a log (a viewer window by default)")
    v.add_argument("--namespace", default="", metavar="NS",
                   help="--live: the node's namespace (topics NS/joint_states, NS/robot_description, ...; default: root)")
    v.add_argument("--serve", action="store_true",
                   help="--live on a machine without a display: serve rerun's web viewer and print the URL to open")
    v.add_argument("--seconds", type=float, metavar="S", help="--live: stop after S wall-clock seconds")
    v.add_argument("--rate", type=float, default=30.0, metavar="HZ",
                   help="--live: messages drawn per topic and second at most (default 30; 0: every one)")
    v.add_argument("--grpc-port", type=int, default=9876, help="--serve: port of rerun's gRPC server")
    v.add_argument("--web-port", type=int, default=9090, help="--serve: port of the web viewer")
    log_view = v.get_default("fn")
    v.set_defaults(fn=lambda args: cmd_view(args, log_view))


def cmd_view(args, log_view) -> int:
    if not args.live:
        if args.log is None:
            return _err("give a log (gyro-sim view RUN.mcap) or --live")
        if args.serve or args.seconds is not None or args.namespace:
            return _err("--serve, --seconds and --namespace go with --live")
        return log_view(args)
    if args.log is not None:
        return _err("--live follows a running node: give no log with it")
    if args.screenshot:
        return _err("--screenshot is for a log: save the live view (--save F.rrd --seconds S), then view F.rrd")
    if args.serve and args.save:
        return _err("--serve or --save, not both")
    if args.seconds is not None and not args.seconds > 0:
        return _err("--seconds must be > 0")
    if not args.rate >= 0:
        return _err("--rate must be >= 0")
    try:
        import rclpy  # noqa: F401
        import rerun  # noqa: F401
    except ImportError as exc:
        return _err(f"--live needs rclpy and rerun-sdk ({exc}); install them with: pip install 'gyro_sim[ros,viz]'")
    from gyro_sim.safe_paths import AtomicOutput, OutputError
    from gyro_sim.viz import live

    mode = "save" if args.save else "serve" if args.serve else "spawn"
    output = None
    try:
        if args.save:
            output = AtomicOutput(args.save, force=args.force, what="--save")
        try:
            code = live.run(args.namespace, mode=mode, save=output.tmp if output else None, seconds=args.seconds,
                            grpc_port=args.grpc_port, web_port=args.web_port, rate=args.rate)
        except live.LiveError as exc:
            print(f"gyro-sim view: {exc}", file=sys.stderr)
            return 2 if "in use" in str(exc) else 1
        if output is not None:
            print(f"wrote {output.publish()}; open it with: rerun {args.save}")
        return code
    except OutputError as exc:
        return _err(exc)
    finally:
        if output is not None:
            output.discard()
