"""`gyro-sim view | replay | recover`: the log subcommands (`run --record` lives in cli.py).

Registered by :func:`register` (see ``gyro_sim.cli.PLUGINS``); heavy imports (rerun, rclpy)
happen when a command runs, not when the parser is built.
"""
from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
from pathlib import Path


def _err(cmd: str, msg) -> None:
    print(f"gyro-sim {cmd}: {msg}", file=sys.stderr)


def _exists(cmd: str, path) -> bool:
    """Whether the input `path` is a regular file (else one line said, for exit status 2)."""
    if not Path(path).is_file():
        _err(cmd, f"{path}: " + ("not a regular file" if os.path.exists(path) else "no such file"))
        return False
    return True


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


def cmd_view(args) -> int:
    if not _exists("view", args.log):
        return 2
    try:  # rerun_view imports rerun only when it draws: check the optional package here
        import rerun  # noqa: F401

        from gyro_sim.viz.rerun_view import view
    except ImportError as exc:
        _err("view", f"needs rerun-sdk ({exc}); install it with: pip install 'gyro_sim[viz]'")
        return 2
    from gyro_sim.safe_paths import AtomicOutput, OutputError

    outputs = {}
    try:  # no silent overwrite, never the log itself; each written whole under a temporary name
        for opt, out in (("--save", args.save), ("--screenshot", args.screenshot)):
            if out:
                outputs[opt] = AtomicOutput(out, inputs=[args.log], force=args.force, what=opt)
        return _view(args, view, outputs)
    except OutputError as exc:
        _err("view", exc)
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
        _err("view", exc)
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
        _err("view", "the rerun viewer binary was not found (pip install 'gyro_sim[viz]')")
        return 2
    from gyro_sim.viz.rerun_view import ScreenshotError, screenshot

    try:
        screenshot(exe, rrd, png.tmp, size)
    except (ScreenshotError, OSError) as exc:
        _err("view", f"screenshot failed: {(str(exc).splitlines() or [type(exc).__name__])[0]}")
        return 1
    print(f"wrote {png.publish()}")
    return 0


# --- replay ------------------------------------------------------------------------------------------
def cmd_replay(args) -> int:
    from gyro_sim.log.mcap_log import LogError

    if not _exists("replay", args.log):
        return 2
    if args.resimulate:
        from gyro_sim.simulator import SimulationError
        from gyro_sim.log.resim import resimulate

        try:
            res = resimulate(args.log, integrator=args.integrator, rtol=args.rtol, atol=args.atol)
        except SimulationError as exc:
            _err("replay", exc)
            return 1
        except (LogError, ValueError, OSError) as exc:  # damaged or crafted log, bad option: bad input
            _err("replay", exc)
            return 2
        print(res.report())
        return 0 if (res.max_deviation <= args.tolerance and res.compared) else 1
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        _err("replay", f"needs rclpy ({exc}): pip install 'gyro_sim[ros]', or source a ROS 2 Jazzy install")
        return 2
    from gyro_sim.ros.replay import replay

    stop = []
    old = signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    try:
        stats = replay(args.log, rate=args.rate, loop=args.loop, topics=args.topics,
                       wait_for_subscribers=args.wait_for_subscribers, should_stop=lambda: bool(stop))
    except (LogError, OSError) as exc:
        _err("replay", exc)
        return 2
    except KeyboardInterrupt:
        return 0
    finally:
        signal.signal(signal.SIGTERM, old)
    print(stats.report())
    return 0


# --- recover ------------------------------------------------------------------------------------------
def cmd_recover(args) -> int:
    from gyro_sim.log.mcap_log import LogError
    from gyro_sim.log.recover import recover

    if not _exists("recover", args.log):
        return 2
    from gyro_sim.safe_paths import OutputError

    out = args.output or str(Path(args.log).with_suffix("")) + ".recovered.mcap"
    try:  # written under a temporary name, published when complete (recover.py)
        r = recover(args.log, out, overwrite=args.force)
    except (LogError, OutputError, OSError) as exc:
        _err("recover", exc)
        return 2
    try:  # done and published: a signal now does not change that
        print(r.report())
        print(f"wrote {out}")
    except KeyboardInterrupt:
        pass
    return 0


def register(sub, bench) -> None:
    """Add view, replay and recover to the `gyro-sim` subparsers."""
    v = sub.add_parser("view", help="show a log in rerun: the chain in 3D and plots (rerun-sdk)")
    v.add_argument("log", help="an MCAP log (gyro-sim run --record, or the node's record parameter)")
    v.add_argument("--save", metavar="OUT.rrd", help="write a rerun recording instead of opening the viewer")
    v.add_argument("--screenshot", metavar="OUT.png", help="save a PNG of the viewer (headless; needs Vulkan)")
    v.add_argument("--window-size", default="1200x800", help="size of the screenshot, WxH (logical points)")
    v.add_argument("--paused", action="store_true", help="open paused at the start instead of playing")
    v.add_argument("--force", action="store_true", help="replace an existing --save / --screenshot file")
    v.set_defaults(fn=cmd_view)

    r = sub.add_parser("replay", help="publish a log's topics on ROS 2 at recorded pace, or re-simulate it")
    r.add_argument("log", help="an MCAP log")
    r.add_argument("--rate", type=float, default=1.0, help="speed factor (2: twice as fast as recorded)")
    r.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    r.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    r.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds for a subscriber on every topic before starting")
    r.add_argument("--resimulate", action="store_true",
                   help="no ROS: re-run the embedded scene with the recorded commands and report the "
                        "largest deviation from the logged joint states (0 expected)")
    r.add_argument("--integrator", help="re-simulate with another integrator than the recorded one")
    r.add_argument("--rtol", type=float, help="re-simulate with another rtol")
    r.add_argument("--atol", type=float, help="re-simulate with another atol")
    r.add_argument("--tolerance", type=float, default=0.0,
                   help="exit status 1 when the deviation exceeds this (default 0: bit for bit)")
    r.set_defaults(fn=cmd_replay)

    c = sub.add_parser("recover", help="rewrite a log cut short (SIGKILL, power loss) as a well-formed file")
    c.add_argument("log", help="the damaged MCAP file (not modified)")
    c.add_argument("-o", "--output", help="the recovered file (default: <log>.recovered.mcap)")
    c.add_argument("--force", action="store_true", help="replace an existing output file (never the input)")
    c.set_defaults(fn=cmd_recover)
