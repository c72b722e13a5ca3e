"""`gyro-sim view`: a log in rerun (gyro_sim.viz.rerun_view), or with `--live` a running node
(gyro_sim.viz.live).

Registered by :func:`register` (see ``gyro_sim.cli.PLUGINS``); heavy imports (rerun, rclpy)
happen when the command runs, not when the parser is built.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

from gyro_sim.log.commands import input_file


def _say(msg) -> None:
    print(f"gyro-sim view: {msg}", file=sys.stderr)


def _err(msg) -> int:
    _say(msg)
    return 2


# --- view ------------------------------------------------------------------------------------------
def rerun_binary() -> str | None:
    """The `rerun` viewer of rerun-sdk: the binary itself (rerun_cli/rerun), else the `rerun`
    next to this Python, else on PATH. The binary first: the `rerun` script of a venv is a
    Python wrapper that runs the binary as its child, and stopping the wrapper (the headless
    screenshot's viewer) would leave the viewer running."""
    try:
        import rerun_cli

        binary = Path(rerun_cli.__file__).with_name("rerun")
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    except ImportError:
        pass
    here = Path(sys.executable).with_name("rerun")
    return str(here) if here.is_file() else shutil.which("rerun")


def _view_log(args) -> int:
    if not input_file("view", args.log):
        return 2
    try:  # rerun_view imports rerun only when it draws: check the optional package here
        import rerun  # noqa: F401

        from gyro_sim.viz.rerun_view import view
    except ImportError as exc:
        _say(f"needs rerun-sdk ({exc}); install it with: pip install 'gyro_sim[viz]'")
        return 2
    from gyro_sim.safe_paths import AtomicOutput, OutputError

    outputs = {}
    try:  # no silent overwrite, never the log itself; each written whole under a temporary name
        for opt, out in (("--save", args.save), ("--screenshot", args.screenshot)):
            if out:
                outputs[opt] = AtomicOutput(out, inputs=[args.log], force=args.force, what=opt)
        return _view(args, view, outputs)
    except OutputError as exc:
        _say(exc)
        return 2
    finally:
        for out in outputs.values():
            out.discard()  # nothing if published


def _view(args, view, outputs) -> int:
    from gyro_sim.log.mcap_log import LogError

    tmp = None
    save = outputs["--save"].tmp if "--save" in outputs else None
    if args.screenshot and save is None:
        tmp = tempfile.TemporaryDirectory()
        save = str(Path(tmp.name) / "view.rrd")
    try:
        drawn = view(args.log, save=save, spawn=save is None,
                     play_state="paused" if (args.screenshot or args.paused) else None)
    except (LogError, OSError) as exc:  # a damaged or crafted log is bad input
        _say(exc)
        return 2
    if args.save:
        outputs["--save"].publish()
        try:  # done and published: a signal now does not change that
            print(f"wrote {args.save}: {len(drawn['entities'])} entities, views {', '.join(drawn['views'])}")
            print(f"open it with: rerun {args.save}")
        except KeyboardInterrupt:
            if not args.screenshot:
                return 0
            raise
    if args.screenshot:
        rrd = outputs["--save"].path if args.save else save  # published by now
        return _screenshot(str(rrd), outputs["--screenshot"], args.window_size)
    return 0


def _screenshot(rrd: str, png, size: str) -> int:
    """A PNG of the viewer (`png`: its AtomicOutput), headless (needs Vulkan: mesa-vulkan-drivers
    + libvulkan1 on Linux).

    Taken once the viewer has loaded and drawn the whole recording (rerun_view.screenshot), not
    a fixed number of frames after start as ``rerun --screenshot-to`` does.
    """
    exe = rerun_binary()
    if exe is None:
        _say("the rerun viewer binary was not found (pip install 'gyro_sim[viz]')")
        return 2
    from gyro_sim.viz.rerun_view import ScreenshotError, screenshot

    try:
        screenshot(exe, rrd, png.tmp, size)
    except (ScreenshotError, OSError) as exc:
        _say(f"screenshot failed: {(str(exc).splitlines() or [type(exc).__name__])[0]}")
        return 1
    print(f"wrote {png.publish()}")
    return 0


# --- the command -----------------------------------------------------------------------------------
def register(sub, bench) -> None:
    """Add `view` (a log, or --live and its options) to the `gyro-sim` subparsers."""
    v = sub.add_parser("view", help="show a log in rerun: the chain in 3D and plots (rerun-sdk)")
    v.add_argument("log", nargs="?", default=None,
                   help="an MCAP log (gyro-sim run --record, or the node's record parameter); not with --live")
    v.add_argument("--save", metavar="OUT.rrd", help="write a rerun recording instead of opening the viewer")
    v.add_argument("--screenshot", metavar="OUT.png", help="save a PNG of the viewer (headless; needs Vulkan)")
    v.add_argument("--window-size", default="1200x800", help="size of the screenshot, WxH (logical points)")
    v.add_argument("--paused", action="store_true", help="open paused at the start instead of playing")
    v.add_argument("--force", action="store_true", help="replace an existing --save / --screenshot file")
    v.add_argument("--live", action="store_true",
                   help="follow a running gyro_sim node over ROS 2 instead of a log (a viewer window by default)")
    v.add_argument("--namespace", default="", metavar="NS",
                   help="--live: the node's namespace "
                        "(topics NS/joint_states, NS/robot_description, ...; default: root)")
    v.add_argument("--serve", action="store_true",
                   help="--live on a machine without a display: serve rerun's web viewer and print the URL to open")
    v.add_argument("--seconds", type=float, metavar="S", help="--live: stop after S wall-clock seconds")
    v.add_argument("--rate", type=float, default=30.0, metavar="HZ",
                   help="--live: messages drawn per topic and second at most (default 30; 0: every one)")
    v.add_argument("--grpc-port", type=int, default=9876, help="--serve: port of rerun's gRPC server")
    v.add_argument("--web-port", type=int, default=9090, help="--serve: port of the web viewer")
    v.set_defaults(fn=cmd_view)


def cmd_view(args) -> int:
    if not args.live:
        if args.log is None:
            return _err("give a log (gyro-sim view RUN.mcap) or --live")
        if args.serve or args.seconds is not None or args.namespace:
            return _err("--serve, --seconds and --namespace go with --live")
        return _view_log(args)
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
