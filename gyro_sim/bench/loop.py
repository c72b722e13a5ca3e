"""`gyro-sim bench loop`: the node closing a control loop with a controller over DDS.

For each publish rate (a family: `--rates`, default 100, 500 and 1000 Hz) and each mode
(`--modes`: ``realtime`` and ``lockstep``), the node runs ``rw_pendulum`` in its own process
and ROS domain, and the LQR example (examples/lqr_balance.py, designed for that control
period) in another: it answers each publication (joint state and IMU of one stamp) with a
command on ~/axis_moments. The node starts first and holds its initial state until the first
command (real time: ``hold:=until_command``; lock-step: ``lockstep:=true``), so every run
starts when the loop is closed. This process subscribes to /joint_states for the pendulum's
angle. Reported per run, from the node's stats_file:

- achieved real-time factor (simulated / wall time from the first command), step time p50 / p99
  (wall time of one physics step), deadline misses (real time);
- command latency p50 / p99: from the node's receipt of a command to the physics step that
  applies it (in real time it includes the wait for the next step's wall deadline: at most
  one control period when the controller answers within it);
- the commands the controller sent (its own count, printed when it stops) and those the node
  took (a command lost on the way, or superseded before a step took it, moves nothing);
- in lock-step, commands per wall second (each one control period: the loop's own pace);
- the pendulum's largest |angle| from 1 s of simulated time on.

The machine's load counts: other processes take CPUs from the node and the controller.
"""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gyro_sim.bench.realtime import NODE_COMMAND

DEFAULT_RATES = (100.0, 500.0, 1000.0)
MODES = ("realtime", "lockstep")
DEFAULT_SECONDS = 10.0
#: the example the controller runs (a source tree's)
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "lqr_balance.py"
#: the pendulum is said to be held when |angle| stays below this from SETTLE s on (rad)
UPRIGHT = 0.01
SETTLE = 1.0
SCENE = "rw_pendulum"


def _domain(i: int) -> int:
    """20..49: apart from the default (0), the tests' domains (50..199) and `bench realtime`'s
    (200..229); Fast DDS takes at most 232."""
    return 20 + (os.getpid() * 7 + i) % 30


def _env(workdir: Path, domain: int) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), OPENBLAS_NUM_THREADS="1")
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def run_loop(rate: float, mode: str, seconds: float, workdir: Path, index: int = 0,
             node_command=NODE_COMMAND) -> dict:
    """One closed-loop run: the node's statistics, and `max_angle_after_settle` (rad) from the
    /joint_states this process received."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import JointState

    from gyro_sim.msgs.messages import JOINT_STATES
    from gyro_sim.ros.discovery import announce_often

    stats = workdir / f"stats_{mode}_{rate:g}.json"
    domain = _domain(index)
    env = _env(workdir, domain)
    params = [f"scene:={SCENE}", f"publish_rate:={rate}", f"duration:={seconds}", f"stats_file:={stats}",
              "lockstep:=true" if mode == "lockstep" else "hold:=until_command"]
    cmd = [*node_command, "--ros-args"]
    for p in params:
        cmd += ["-p", p]
    angles: list[tuple[float, float]] = []

    def on_joints(msg) -> None:
        names, stamp = list(msg.name), msg.header.stamp
        if "pendulum" in names:
            angles.append((stamp.sec + 1e-9 * stamp.nanosec, msg.position[names.index("pendulum")]))

    announce_often()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    node_log, ctrl_log = workdir / f"node_{mode}_{rate:g}.log", workdir / f"ctrl_{mode}_{rate:g}.log"
    proc = ctrl = None
    try:
        node = rclpy.create_node("gyro_sim_bench_loop", context=context)
        node.create_subscription(JointState, JOINT_STATES, on_joints, 1000)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        with open(node_log, "w") as out:
            proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)
        with open(ctrl_log, "w") as out:
            ctrl = subprocess.Popen([sys.executable, str(EXAMPLE), "--rate", f"{rate:g}", "--duration",
                                     f"{10 * seconds + 120:g}"], env=env, stdout=out, stderr=subprocess.STDOUT)
        end = time.monotonic() + 10 * seconds + 120  # a run far behind real time is cut short
        while proc.poll() is None and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        if proc.poll() is None:
            proc.send_signal(2)
        proc.wait(timeout=30)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
    finally:
        for p in (ctrl, proc):
            if p is not None and p.poll() is None:
                p.terminate()
                p.wait(20)
        rclpy.try_shutdown(context=context)
    if proc.returncode != 0 or not stats.exists():
        raise RuntimeError(f"gyro_sim_node failed ({mode}, {rate:g} Hz, exit {proc.returncode}):\n"
                           f"{node_log.read_text(errors='replace')[-2000:]}")
    st = json.loads(stats.read_text())
    settled = [abs(a) for t, a in angles if t >= SETTLE]
    # the controller's own count, printed when it stops ("lqr_balance: N commands; ...")
    said = re.search(r"lqr_balance: (\d+) commands", ctrl_log.read_text(errors="replace"))
    st.update(mode=mode, rate=rate, joint_states_received=len(angles), commands_sent=int(said[1]) if said else None,
              max_angle_after_settle=max(settled) if settled else math.nan)
    return st


def measure(rates=DEFAULT_RATES, modes=MODES, seconds: float = DEFAULT_SECONDS, progress=None) -> list[dict]:
    runs = []
    with tempfile.TemporaryDirectory(prefix="gyro_sim_loop_") as tmp:
        cases = [(m, r) for m in modes for r in rates]
        for i, (mode, rate) in enumerate(cases):
            runs.append(run_loop(rate, mode, seconds, Path(tmp), i))
            if progress:
                progress(i + 1, len(cases), f"{mode} {rate:g} Hz")
    return runs


def _f(v, fmt: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def table(runs: list[dict]) -> str:
    lines = ["| mode | rate (Hz) | achieved RTF | step p50 (us) | step p99 (us) | command latency p50 (us) "
             "| command latency p99 (us) | deadline misses | commands sent / taken | commands / wall s "
             "| max abs(angle) after 1 s (rad) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in runs:
        lock = r["mode"] == "lockstep"
        lines.append(
            f"| {r['mode']} | {r['rate']:g} | {_f(r.get('real_time_factor_achieved'), '.3f')} "
            f"| {_f(r.get('step_time_p50_us'), '.0f')} | {_f(r.get('step_time_p99_us'), '.0f')} "
            f"| {_f(r.get('command_latency_p50_us'), '.0f')} | {_f(r.get('command_latency_p99_us'), '.0f')} "
            f"| {'-' if lock else int(r.get('deadline_misses', 0))} "
            f"| {r.get('commands_sent') if r.get('commands_sent') is not None else '-'} / {r.get('commands_accepted')} "
            f"| {_f(r.get('commands_per_wall_s'), '.0f') if lock else '-'} "
            f"| {_f(r.get('max_angle_after_settle'), '.4f')} |")
    return "\n".join(lines)


def plot(runs: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for mode, style in (("realtime", "o-"), ("lockstep", "s--")):
        rs = [r for r in runs if r["mode"] == mode]
        if not rs:
            continue
        x = [r["rate"] for r in rs]
        a1.plot(x, [r.get("real_time_factor_achieved") for r in rs], style, label=mode)
        a2.plot(x, [r.get("command_latency_p99_us") for r in rs], style, label=f"latency p99, {mode}")
        a2.plot(x, [r.get("step_time_p99_us") for r in rs], style, alpha=0.5, label=f"step p99, {mode}")
    a1.set_xlabel("control rate (Hz)")
    a1.set_ylabel("achieved real-time factor")
    a2.set_xlabel("control rate (Hz)")
    a2.set_ylabel("us")
    for a in (a1, a2):
        a.set_xscale("log")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"gyro_sim_node on {SCENE} with the LQR example over DDS")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def cmd_bench_loop(args) -> int:
    from gyro_sim.bench.report import refused, write_report
    from gyro_sim.progress import Progress

    if refused(args, "loop"):
        return 2
    bad = [r for r in args.rates if not (0 < r <= 1000)]
    if bad or not (args.seconds > 0 and math.isfinite(args.seconds)):
        print(f"gyro-sim bench loop: --rates must be in (0, 1000] Hz and --seconds > 0, got {bad or args.seconds}",
              file=sys.stderr)
        return 2
    if not EXAMPLE.exists():
        print(f"gyro-sim bench loop: the controller {EXAMPLE} is not there (a source tree has it)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    try:
        runs = measure(tuple(args.rates), tuple(args.modes), args.seconds, progress=Progress("loop"))
    except RuntimeError as exc:
        print(f"gyro-sim bench loop: {exc}", file=sys.stderr)
        return 1
    text = (f"### The control loop: {SCENE} with the LQR example over DDS, {args.seconds:g} s simulated per run\n\n"
            + table(runs) + f"\n\nMachine load (1-minute average, {os.cpu_count()} cores): {load0:.2f} at the start, "
            f"{os.getloadavg()[0]:.2f} at the end.")
    print(text)
    write_report(args.out, "loop", text + "\n", runs, lambda png: plot(runs, png), force=args.force, json_default=str)
    print(f"in {time.perf_counter() - t0:.0f} s")
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim bench loop`."""
    r = bench.add_parser("loop", help="the node closing a loop with the LQR example over DDS: RTF, step times, "
                         "command latency (needs rclpy)")
    r.add_argument("--rates", type=float, nargs="+", default=list(DEFAULT_RATES),
                   help=f"control (publish) rates, Hz (default {' '.join(f'{x:g}' for x in DEFAULT_RATES)})")
    r.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES),
                   help="realtime (hold:=until_command) and/or lockstep (lockstep:=true)")
    r.add_argument("--seconds", type=float, default=DEFAULT_SECONDS, help="simulated seconds per run")
    r.add_argument("--out", default="out/bench", help="directory for loop.md, loop.json, loop.png")
    r.add_argument("--force", action="store_true", help="replace existing report files in --out")
    r.set_defaults(fn=cmd_bench_loop)
