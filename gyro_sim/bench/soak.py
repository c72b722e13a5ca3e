"""`gyro-sim bench soak`: what the node keeps under abuse and over time (needs rclpy).

Three parts, each a real node process on real DDS (hinge chain, physics 1 kHz, publish 100 Hz,
RK4, recording on), watched from this process:

- **flood**: other processes (at the lowest CPU priority, nice 19: the property measured is
  the node's own intake, not the OS's sharing of two cores) publish commands on
  ``~/axis_moments`` at a total rate (20,000 msg/s by default, raw CDR bytes, valid commands)
  for a few seconds; measured: the rate of
  /joint_states received here during the flood and before it, the node's deadline misses and
  achieved real-time factor during the flood (its /diagnostics), commands accepted/superseded;
- **soak**: the node runs for `minutes`; its resident memory (/proc/<pid>/status VmRSS) is
  sampled every few seconds and the growth rate fitted over the second half (after warm-up,
  MB per hour); deadline misses and the real-time factor over the run (its stats file);
- **kill**: `kills` runs each killed with SIGKILL at a random moment (seeded), the node alone:
  its log writer outlives it and finishes the log (gyro_sim.ros.recorder), which is then read
  through gyro_sim.log.recover; the simulated time lost is the node's last /clock seen here
  minus the last log time recovered (promised: at most 0.25 s with the default 0.2 s flush period).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyro_sim.bench.procs import children, rss_mb, running
from gyro_sim.log.mcap_log import DEFAULT_FLUSH_PERIOD

PHYSICS_RATE = 1000.0
PUBLISH_RATE = 100.0
FLOOD_RATE = 20_000.0
FLOOD_PUBLISHERS = 2
FLOOD_SECONDS = 5.0
SOAK_MINUTES = 60.0
KILLS = 20
#: seconds between two memory samples of the soak
RSS_PERIOD = 5.0
#: longest wait (s) for the log writer of a killed node to finish the log
WRITER_END = 30.0
#: the killed runs live this long (wall s) before SIGKILL, uniformly
KILL_AFTER = (1.0, 4.0)
NODE_COMMAND = (sys.executable, "-m", "gyro_sim.ros.node")
SEED = 13

#: the flood publisher: publishes the same valid command (raw CDR bytes) at `rate` per second
FLOODER = r"""
import sys, time, rclpy
from std_msgs.msg import Float64MultiArray
from gyro_sim.msgs.messages import axis_moments
rate, seconds, values = float(sys.argv[1]), float(sys.argv[2]), [float(v) for v in sys.argv[3:]]
rclpy.init()
node = rclpy.create_node("gyro_sim_flood")
pub = node.create_publisher(Float64MultiArray, "/gyro_sim/axis_moments", 10)
data = axis_moments(values)
while pub.get_subscription_count() == 0:
    time.sleep(0.05)
print("ready", flush=True)
sys.stdin.readline()
t0 = time.monotonic(); sent = 0
while True:
    now = time.monotonic() - t0
    if now >= seconds:
        break
    due = int(now * rate)
    while sent < due:
        pub.publish(data); sent += 1
    time.sleep(0.001)
print(sent, flush=True)
"""


def _env(domain: int, workdir: Path) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), OPENBLAS_NUM_THREADS="1")
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _domain(i: int) -> int:
    """200..229: apart from the tests' domains (50..199), so a bench and the tests can share a machine."""
    return 200 + (os.getpid() * 17 + i) % 30


def _start_node(workdir: Path, domain: int, name: str, *params: str, node_command=NODE_COMMAND):
    cmd = [*node_command, "--ros-args"]
    for p in ("scene:=hinge_chain", f"physics_rate:={PHYSICS_RATE}", f"publish_rate:={PUBLISH_RATE}",
              "integrator:=rk4", "command_timeout:=1000.0", *params):
        cmd += ["-p", p]
    return subprocess.Popen(cmd, env=_env(domain, workdir), stdout=open(workdir / f"{name}.out", "w"),
                            stderr=open(workdir / f"{name}.err", "w"))


class _Watcher:
    """An rclpy context in this process for one domain: /joint_states stamps (wall, node time)
    and the latest run status of /diagnostics."""

    def __init__(self, domain: int):
        import threading

        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState

        self.rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node("gyro_sim_soak_watch", context=self.ctx)
        self.js: list[float] = []
        self.stamps: list[int] = []  # header stamps (ns) of the /joint_states received, in order
        self.clock = float("nan")
        self.run: dict = {}
        self.node.create_subscription(JointState, "/joint_states", self._js, 1000)
        self.node.create_subscription(Clock, "/clock", self._clock, 100)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._diag, 100)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _js(self, m) -> None:
        self.js.append(time.monotonic())
        self.stamps.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)

    def missing(self, t0: float, t1: float, period_ns: int) -> tuple[int, float]:
        """Publications absent between the first and last /joint_states received in [t0, t1)
        (wall): stamp steps beyond one publish period, counted in periods; and the simulated
        time (s) those stamps span."""
        st = [s for t, s in zip(self.js, self.stamps) if t0 <= t < t1]
        if len(st) < 2:
            return 0, 0.0
        return sum(max(0, round((b - a) / period_ns) - 1) for a, b in zip(st, st[1:])), (st[-1] - st[0]) * 1e-9

    def _clock(self, m) -> None:
        self.clock = m.clock.sec + 1e-9 * m.clock.nanosec

    def _diag(self, m) -> None:
        for st in m.status:
            if st.name == "gyro_sim: run":
                self.run = {kv.key: kv.value for kv in st.values}

    def _spin(self) -> None:
        try:
            while self.ctx.ok():
                self.ex.spin_once(timeout_sec=0.05)
        except Exception:  # noqa: BLE001 - shutdown under way
            pass

    def rate(self, t0: float, t1: float) -> float:
        return sum(t0 <= t < t1 for t in self.js) / (t1 - t0)

    def wait(self, cond, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > end:
                raise RuntimeError(f"timed out waiting for {what}")
            time.sleep(0.02)

    def close(self) -> None:
        self.ex.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _stop(proc, sig=signal.SIGINT, timeout: float = 30.0) -> int:
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
    return proc.returncode


@dataclass
class Flood:
    rate: float
    seconds: float
    sent: int = 0
    hz_before: float = float("nan")
    hz_during: float = float("nan")
    #: publications (stamp steps of one publish period) absent from /joint_states during the flood
    missing_during: int = -1
    #: simulated time (s) spanned by the stamps of the /joint_states received during the flood
    stamps_span_during: float = 0.0
    misses_before: int = 0
    misses_during: int = 0
    rtf_during: float = float("nan")
    accepted: int = 0
    superseded: int = 0


def flood(workdir: Path, rate: float = FLOOD_RATE, seconds: float = FLOOD_SECONDS,
          publishers: int = FLOOD_PUBLISHERS, domain: int | None = None) -> Flood:
    domain = _domain(0) if domain is None else domain
    out = Flood(rate, seconds)
    w = _Watcher(domain)
    node = _start_node(workdir, domain, "flood", f"record:={workdir / 'flood.mcap'}", "overwrite:=true")
    floods = []
    try:
        w.wait(lambda: len(w.js) > 0 or node.poll() is not None, 60.0, "the node's first /joint_states")
        if node.poll() is not None:
            raise RuntimeError(f"the node ended: {(workdir / 'flood.err').read_text()[-1500:]}")
        # the flooders run at the lowest CPU priority: what is measured is whether the node's own
        # command intake steals its physics thread's time, not how the OS shares 2 cores among
        # three busy processes
        floods = [subprocess.Popen(["nice", "-n", "19", sys.executable, "-c", FLOODER, str(rate / publishers),
                                    str(seconds), "0.001", "0.01", "-0.01"], env=_env(domain, workdir),
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True) for _ in range(publishers)]
        for f in floods:
            if f.stdout.readline().strip() != "ready":
                raise RuntimeError("a flood publisher did not start")
        time.sleep(2.0)
        t0 = time.monotonic()
        w.wait(lambda: bool(w.run), 10.0, "/diagnostics")
        before = dict(w.run)
        out.hz_before = w.rate(t0 - 2.0, t0)
        for f in floods:
            f.stdin.write("go\n")
            f.stdin.flush()
        out.sent = sum(int(f.stdout.readline() or 0) for f in floods)
        t1 = time.monotonic()
        time.sleep(0.5)  # the diagnostics of the flood's end
        after = dict(w.run)
        out.hz_during = w.rate(t0 + 0.1, t1)
        out.missing_during, out.stamps_span_during = w.missing(t0, t1, round(1e9 / PUBLISH_RATE))
        out.misses_before = int(before.get("deadline_misses", 0))
        out.misses_during = int(after.get("deadline_misses", 0)) - int(before.get("deadline_misses", 0))
        out.rtf_during = float(after.get("real_time_factor_achieved", "nan"))
        out.accepted = int(after.get("commands_accepted", 0))
        out.superseded = int(after.get("commands_superseded", 0))
    finally:
        for f in floods:
            f.kill()
        _stop(node)
        w.close()
    return out


@dataclass
class Soak:
    minutes: float
    t: list = field(default_factory=list)  # wall s since start
    rss_mb: list = field(default_factory=list)
    slope_mb_per_hour: float = float("nan")
    stats: dict = field(default_factory=dict)


def soak(workdir: Path, minutes: float = SOAK_MINUTES, progress=None, domain: int | None = None) -> Soak:
    import json

    domain = _domain(1) if domain is None else domain
    out = Soak(minutes)
    stats = workdir / "soak_stats.json"
    node = _start_node(workdir, domain, "soak", f"record:={workdir / 'soak.mcap'}", "overwrite:=true",
                       f"duration:={minutes * 60.0}", f"stats_file:={stats}")
    t0 = time.monotonic()
    try:
        while node.poll() is None:
            try:
                out.rss_mb.append(rss_mb(node.pid))
                out.t.append(time.monotonic() - t0)
            except OSError:
                break
            if progress:
                progress(time.monotonic() - t0, minutes * 60.0, f"RSS {out.rss_mb[-1]:.1f} MB")
            time.sleep(RSS_PERIOD)
        node.wait(minutes * 120.0 + 60.0)
    finally:
        _stop(node)
    if node.returncode != 0:
        raise RuntimeError(f"the soak node exited {node.returncode}: {(workdir / 'soak.err').read_text()[-1500:]}")
    out.stats = json.loads(stats.read_text())
    t, m = np.array(out.t), np.array(out.rss_mb)
    half = t >= t[-1] / 2 if t.size else t
    if half.sum() >= 3:
        out.slope_mb_per_hour = float(np.polyfit(t[half], m[half], 1)[0]) * 3600.0
    return out


@dataclass
class Kills:
    lost_s: list = field(default_factory=list)  # simulated seconds lost per kill
    kept_messages: list = field(default_factory=list)


def kills(workdir: Path, n: int = KILLS, progress=None, domain: int | None = None) -> Kills:
    from gyro_sim.log.recover import recover

    domain = _domain(2) if domain is None else domain
    rng = np.random.default_rng(SEED)
    out = Kills()
    w = _Watcher(domain)
    try:
        for i in range(n):
            log, fixed = workdir / f"kill{i}.mcap", workdir / f"kill{i}.recovered.mcap"
            w.clock = float("nan")
            node = _start_node(workdir, domain, f"kill{i}", f"record:={log}", "overwrite:=true")
            try:
                w.wait(lambda: w.clock == w.clock or node.poll() is not None, 60.0, "the node's /clock")
                time.sleep(rng.uniform(*KILL_AFTER))
                last_seen = w.clock
                writers = children(node.pid)
                node.send_signal(signal.SIGKILL)
                node.wait(10)
                # the log writer outlives the node: it finishes the log and renames it onto `log`
                w.wait(lambda: not any(map(running, writers)), WRITER_END, "the log writer to finish")
            finally:
                _stop(node, signal.SIGKILL)
            r = recover(log, fixed, overwrite=True)
            out.lost_s.append(max(0.0, last_seen - (r.end_ns or 0) * 1e-9))
            out.kept_messages.append(r.messages)
            if progress:
                progress(i + 1, n, f"lost {out.lost_s[-1]:.3f} s")
    finally:
        w.close()
    return out


def report(fl: Flood | None, so: Soak | None, ki: Kills | None) -> str:
    lines = ["### Soak: floods, memory over time, SIGKILL", ""]
    if fl is not None:
        lines += [f"Flood: {fl.sent} commands in {fl.seconds:g} s ({fl.sent / fl.seconds:.0f} msg/s from "
                  f"{FLOOD_PUBLISHERS} processes) on ~/axis_moments; /joint_states received at "
                  f"{fl.hz_before:.1f} Hz before and **{fl.hz_during:.1f} Hz during** the flood "
                  f"({fl.missing_during} publications missing during it); "
                  f"{fl.misses_during} deadline misses during it, real-time factor {fl.rtf_during:.3f}; "
                  f"{fl.accepted} commands taken in by the node, {fl.superseded} superseded before a step "
                  "could apply them.", ""]
    if so is not None:
        st = so.stats
        lines += [f"Soak: {so.minutes:g} min at physics {PHYSICS_RATE:g} Hz / publish {PUBLISH_RATE:g} Hz, "
                  f"recording: resident memory {so.rss_mb[0]:.1f} -> {so.rss_mb[-1]:.1f} MB, growth over the "
                  f"second half **{so.slope_mb_per_hour:+.2f} MB per hour**; real-time factor "
                  f"{st.get('real_time_factor_achieved', float('nan')):.4f}, {st.get('deadline_misses')} deadline "
                  f"misses, {st.get('slipped_s', float('nan')):.3f} s slipped, CPU share "
                  f"{100 * st.get('cpu_share', float('nan')):.0f} %.", ""]
    if ki is not None and ki.lost_s:
        lost = np.array(ki.lost_s)
        lines += [f"SIGKILL: {len(lost)} runs killed at random moments; simulated time lost after "
                  f"`gyro-sim recover`: median {np.median(lost):.3f} s, **max {lost.max():.3f} s** "
                  f"(flush period {DEFAULT_FLUSH_PERIOD:g} s; promised at most 0.25 s).", ""]
    return "\n".join(lines)


def plot(so: Soak | None, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    if so is not None and so.t:
        ax.plot(np.array(so.t) / 60.0, so.rss_mb, lw=1.2)
        ax.set_title(f"node resident memory, {so.minutes:g} min soak: {so.slope_mb_per_hour:+.2f} MB/h")
    ax.set_xlabel("wall time (min)")
    ax.set_ylabel("RSS (MB)")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cmd_bench_soak(args) -> int:
    from gyro_sim.progress import Progress
    from gyro_sim.bench.report import refused, write_report

    if refused(args, "soak"):
        return 2
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        print(f"gyro-sim bench soak: needs rclpy ({exc}): pip install 'gyro_sim[ros]'", file=sys.stderr)
        return 2
    minutes = 0.5 if args.quick else args.minutes
    n_kills = 3 if args.quick else args.kills
    parts = set(args.parts)
    with tempfile.TemporaryDirectory(prefix="gyro_sim_soak_") as tmp:
        work = Path(tmp)
        try:
            fl = flood(work, rate=args.rate, seconds=2.0 if args.quick else FLOOD_SECONDS) if "flood" in parts else None
            ki = kills(work, n_kills, progress=Progress("kills")) if "kill" in parts else None
            so = soak(work, minutes, progress=Progress("soak")) if "soak" in parts else None
        except RuntimeError as exc:
            print(f"gyro-sim bench soak: {exc}", file=sys.stderr)
            return 1
    text = report(fl, so, ki)
    print(text)
    data = {"flood": fl.__dict__ if fl else None, "soak": so.__dict__ if so else None,
            "kills": ki.__dict__ if ki else None}
    write_report(args.out, "soak", text + "\n", data, lambda png: plot(so, png), force=args.force, json_default=str)
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim bench soak`."""
    s = bench.add_parser("soak", help="the node under a command flood, over a long run, and killed (needs rclpy)")
    s.add_argument("--minutes", type=float, default=SOAK_MINUTES, help="length of the soak run (wall minutes)")
    s.add_argument("--kills", type=int, default=KILLS, help="runs killed with SIGKILL")
    s.add_argument("--rate", type=float, default=FLOOD_RATE, help="commands per second of the flood")
    s.add_argument("--parts", nargs="+", default=["flood", "kill", "soak"], choices=["flood", "kill", "soak"])
    s.add_argument("--quick", action="store_true", help="a 30 s soak, 3 kills, a 2 s flood")
    s.add_argument("--out", default="out/bench", help="directory for soak.md, soak.json, soak.png")
    s.add_argument("--force", action="store_true", help="replace existing report files in --out")
    s.set_defaults(fn=cmd_bench_soak)
