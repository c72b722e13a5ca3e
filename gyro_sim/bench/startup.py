"""`gyro-sim bench startup`: how long a fresh installation takes to its first output, cold
(an empty numba cache: every kernel compiled) and warm (the same cache, a second start).

    gyro-sim bench startup [--source DIR] [--keep-venv DIR | --venv DIR] [--warm-starts N]
                           [--announce-period S] [--json FILE]

The package is installed from a source tree (default: the one this gyro_sim runs from) into a
new virtual environment, as a user installs it: ``python -m venv`` and ``pip install
".[ros,sweep]"`` (not editable; pip's download cache is used). In that environment, with
NUMBA_CACHE_DIR pointing to a new empty directory for each cold case:

- the node: ``gyro_sim_node`` on the default scene, from its process start to the first
  /joint_states message a subscriber (a separate process, subscribed `SETTLE` s beforehand,
  on a private ROS_DOMAIN_ID) receives; with the node's CPU time to that moment. The
  subscriber's Fast DDS participant announces itself every `ANNOUNCE_PERIOD` s (a profile in
  FASTRTPS_DEFAULT_PROFILES_FILE, its own environment only; `--announce-period`, 0 for none)
  instead of Fast DDS's default 3 s:
  a participant started after a subscriber is often discovered only at the subscriber's next
  announcement, whatever the process (a bare rclpy publisher as much as the node), and the
  case times the node, not that period (docs/performance.md says what it adds);
- for comparison, the least rclpy node that publishes JointState, timed as the node is: what
  any ROS 2 Python node's start and discovery cost here;
- a subscriber started `SETTLE` s after the node runs (as a viewer opened on a running node):
  from its subscription to its first message;
- ``gyro-sim run --scene hinge_chain --duration 2``, to its end, with its CPU time;
- a one-point sweep on a LocalCluster of one worker: the worker's wall time from its process
  start to its first point written, and its CPU time (its start included); and the sweep's,
  from its call to the first point.

Each cold case is followed by a warm one on the same cache (`--warm-starts N`: N of them, the
median and the range shown). The table is printed with the date, the command and the core
count; `--json` also gives the 1-minute load average before and after.
"""
from __future__ import annotations

import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from datetime import date
from pathlib import Path

from gyro_sim.errors import GyroSimError
from gyro_sim.ros.discovery import (
    ANNOUNCE_PERIOD as ANNOUNCE_PERIOD_NODE, FAST_DDS_ANNOUNCE_PERIOD, PROFILE_VARIABLES, profile_xml,
)

#: the extras installed: the node needs [ros], the sweep case [sweep]
EXTRAS = "ros,sweep"
#: the files that make a directory a gyro_sim source tree
SOURCE_MARKERS = ("setup.py", "package.xml", "gyro_sim/__init__.py")
#: what is not copied from the source tree before installing (build products, caches, VCS)
COPY_IGNORE = (".git", "__pycache__", "build", "dist", "*.egg-info", ".venv", ".ci-venv", "out", ".pytest_cache",
               "*.mcap", "*.rrd")
#: the longest wait for one case (s): a cold compile on a busy 2-core machine takes minutes
CASE_TIMEOUT = 900.0
#: the longest wait for the install (s)
INSTALL_TIMEOUT = 3600.0
#: the least time (s) between two progress lines of the install
PROGRESS_PERIOD = 5.0
#: how long a stopped process may take to exit after SIGINT before it is killed (s)
STOP_TIMEOUT = 15.0
#: the scene and duration of the offline run
RUN_SCENE, RUN_DURATION = "hinge_chain", 2.0
#: the node's first message
TOPIC = "/joint_states"
#: how often (s) a waiting measurement checks that the measured process still runs
POLL = 0.2
#: the private ROS domain: this base plus the process id modulo DOMAIN_SPAN (0-232 are valid)
DOMAIN_BASE, DOMAIN_SPAN = 120, 100

#: how long (s) the subscriber runs before the measured process starts: past its first
#: announcements, as a viewer already running is
SETTLE = 3.5
#: what the node says on stderr once its physics thread runs (it publishes from then on)
NODE_READY = "physics thread:"
#: how often (s) the subscriber's participant announces itself
ANNOUNCE_PERIOD = 0.2
#: the window (wall s from the first /joint_states) over which the node's real-time factor is
#: measured: simulated time (the messages' stamps) over the wall time they came in
RTF_WINDOW = 10.0


#: the subscriber, run with the measured environment's Python: "ready" once subscribed, then
#: "first <time.monotonic()>" at the first message (or "none" after argv[1] s); "ready" gives
#: its time.monotonic() too. With a window argv[3] > 0 it listens that many seconds more and
#: then says "rtf <simulated s / wall s> <messages>": the stamps' span over the arrivals'
SUBSCRIBER = r"""
import sys, time
import rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

rclpy.init()
node = Node("gyro_sim_startup_probe")
got = []
node.create_subscription(JointState, sys.argv[2],
                         lambda m: got.append((time.monotonic(), m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)),
                         qos_profile_sensor_data)
print(f"ready {time.monotonic()!r}", flush=True)
end = time.monotonic() + float(sys.argv[1])
while not got and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
print(f"first {got[0][0]!r}" if got else "none", flush=True)
window = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
if got and window > 0:
    while got[-1][0] < got[0][0] + window:
        rclpy.spin_once(node, timeout_sec=0.05)
    last = [g for g in got if g[0] <= got[0][0] + window][-1]
    print(f"rtf {(last[1] - got[0][1]) / (last[0] - got[0][0])!r} {len(got)}", flush=True)
node.destroy_node()
rclpy.try_shutdown()
"""

#: the least ROS 2 Python node that publishes JointState, run with the measured environment's
#: Python: what any rclpy node's start and discovery cost, against which the node's is read
MINIMAL_NODE = r"""
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

rclpy.init()
node = Node("minimal_publisher")
pub = node.create_publisher(JointState, "/joint_states", 10)
message = JointState(name=["a"], position=[0.0])
while rclpy.ok():
    pub.publish(message)
    rclpy.spin_once(node, timeout_sec=0.01)
"""

#: a one-point sweep on a LocalCluster of one worker, run with the measured environment's
#: Python; prints one JSON line at the first point written
SWEEP = r"""
import json, os, sys, tempfile, time
from pathlib import Path

t0, c0 = time.perf_counter(), time.process_time()


def worker_times():
    tick = os.sysconf("SC_CLK_TCK")
    with open("/proc/self/stat") as f:
        start = int(f.read().rsplit(")", 1)[1].split()[19]) / tick
    with open("/proc/uptime") as f:
        uptime = float(f.read().split()[0])
    return uptime - start, time.process_time()


from gyro_sim.sweep import execute
from gyro_sim.sweep.spec import load_sweep

sweep = load_sweep({"name": "startup", "scene": sys.argv[1], "grid": {"run.horizon": [float(sys.argv[2])]},
                    "run": {"horizon": float(sys.argv[2])}, "measures": ["final_state"]})
first = {}


def on_batch(client, rows):
    if not first:
        first["sweep_wall"] = time.perf_counter() - t0
        first["client_cpu"] = time.process_time() - c0
        (wall, cpu), = client.run(worker_times).values()
        first["worker_wall"], first["worker_cpu"] = wall, cpu


with tempfile.TemporaryDirectory() as out:
    execute.run(sweep, Path(out), workers=1, on_batch=on_batch)
print(json.dumps(first), flush=True)
"""


class StartupError(GyroSimError, RuntimeError):
    """A case could not be measured (the install failed, a process never answered)."""


@dataclass
class Timing:
    """Wall and CPU seconds of one case (CPU: the measured process's own)."""

    wall: float
    cpu: float
    extra: dict = field(default_factory=dict)


def source_tree(path: str | os.PathLike | None) -> Path | None:
    """The gyro_sim source tree at `path` (default: the one this gyro_sim runs from), or None if
    it is not one (an installed package has no setup.py beside it)."""
    root = Path(path) if path is not None else Path(__file__).resolve().parents[2]
    return root.resolve() if all((root / m).is_file() for m in SOURCE_MARKERS) else None


def python_of(venv: Path) -> Path:
    return venv / "bin" / "python"


def script_of(venv: Path, name: str) -> Path:
    """A console script of the installed package (pip puts them in bin/)."""
    for where in (venv / "bin" / name, venv / "lib" / "gyro_sim" / name):
        if where.is_file():
            return where
    raise StartupError(f"{name} is not installed in {venv}")


def install(venv: Path, source: Path, say, extras: str = EXTRAS) -> None:
    """A new venv at `venv` with the package from `source` installed (not editable): a copy of
    the tree is installed, so nothing is written into it. Progress lines go to `say`."""
    with tempfile.TemporaryDirectory(prefix="gyro_sim_src_") as tmp:
        copy = Path(tmp) / "src"
        shutil.copytree(source, copy, ignore=shutil.ignore_patterns(*COPY_IGNORE))
        say(f"creating the venv {venv}")
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=INSTALL_TIMEOUT,
                       stdout=subprocess.DEVNULL)
        cmd = [str(python_of(venv)), "-m", "pip", "install", "--progress-bar", "off", f"{copy}[{extras}]"]
        say(f"pip install \".[{extras}]\" (a few minutes the first time)")
        t0 = time.monotonic()
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PIP_USER")}
        with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                              cwd=tmp) as pip:
            tail: list[str] = []
            collected, said = 0, t0
            for line in pip.stdout:
                line = line.rstrip()
                tail = (tail + [line])[-5:]
                if line.startswith("Collecting"):
                    collected += 1
                    if time.monotonic() - said < PROGRESS_PERIOD:
                        continue
                    line = f"{collected} packages collected"
                elif line.startswith("Installing collected packages"):
                    line = f"installing {line.count(',') + 1} packages"
                elif line.startswith("Successfully installed"):
                    line = f"installed {len(line.split()) - 2} packages"
                elif not line.startswith("Building wheel"):
                    continue
                said = time.monotonic()
                say(f"  [{said - t0:5.0f} s] {line[:120]}")
            if pip.wait() != 0:
                raise StartupError("pip install failed: " + " | ".join(tail))


def child_env(venv: Path, cache: Path, scratch: Path) -> dict:
    """The environment of the measured processes: the venv's, a private ROS domain, the numba
    cache `cache`, nothing of this process's PYTHONPATH."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT", "GYRO_SIM_VERBOSE")}
    env.update(VIRTUAL_ENV=str(venv), PATH=os.pathsep.join((str(venv / "bin"), env.get("PATH", ""))),
               AMENT_PREFIX_PATH=str(venv), NUMBA_CACHE_DIR=str(cache), ROS_LOG_DIR=str(scratch / "roslog"),
               ROS_DOMAIN_ID=str(DOMAIN_BASE + os.getpid() % DOMAIN_SPAN), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


def cache_fills(cache: Path) -> list[int]:
    """The processes whose environment names `cache` as their NUMBA_CACHE_DIR: the cache fill
    a measured start left behind (gyro_sim.warmup), in a session of its own."""
    mark = f"NUMBA_CACHE_DIR={cache}".encode()
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if mark in (entry / "environ").read_bytes().split(b"\0"):
                out.append(int(entry.name))
        except OSError:
            pass
    return out


def wait_cache_fills(cache: Path, timeout: float) -> None:
    """Until the cache fill of `cache` has ended (StartupError after `timeout` s)."""
    end = time.monotonic() + timeout
    while cache_fills(cache):
        if time.monotonic() > end:
            raise StartupError(f"the cache fill still runs after {timeout:.0f} s")
        time.sleep(1.0)


def end_cache_fills(cache: Path) -> None:
    """SIGKILL the cache fill of `cache` (`cache_fills`): the next case runs without it."""
    for pid in cache_fills(cache):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def process_cpu(pid: int) -> float:
    """CPU seconds (user + system) a running process has used so far (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def end_group(pgid: int) -> None:
    """SIGKILL whatever is left of a process group (a measured process's helpers): the next
    case runs on a machine without them."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def stop(proc: subprocess.Popen) -> None:
    """SIGINT to the process's group (it runs in its own session), SIGKILL if it lingers; then
    the rest of its group ended."""
    for sig in (signal.SIGINT, signal.SIGKILL):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            continue
    end_group(proc.pid)


def _read_line(proc: subprocess.Popen, what: str) -> str:
    line = proc.stdout.readline()
    if not line:
        raise StartupError(f"{what} ended without a word (exit {proc.wait()})")
    return line.strip()


class Terminal:
    """A pseudo-terminal for a measured process: its stdin and stdout, and its controlling
    terminal (as a start typed in a shell has); what the process writes on it is read and
    dropped, so that it never blocks on a full terminal."""

    def __init__(self):
        import pty
        import threading

        self.master, self.slave = pty.openpty()
        self._reader = threading.Thread(target=self._drain, name="gyro_sim-bench-pty", daemon=True)
        self._reader.start()

    def _drain(self) -> None:
        while True:
            try:
                if not os.read(self.master, 4096):
                    return
            except OSError:
                return

    @staticmethod
    def take_as_controlling() -> None:
        """In the child (preexec_fn, after setsid): its stdin, the terminal, becomes its
        controlling terminal."""
        import fcntl
        import termios

        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    def popen_options(self) -> dict:
        return {"stdin": self.slave, "stdout": self.slave, "preexec_fn": self.take_as_controlling}

    def close(self) -> None:
        for fd in (self.slave, self.master):
            try:
                os.close(fd)
            except OSError:
                pass


def first_message(python: str, node_cmd: list[str], env: dict, topic: str = TOPIC,
                  timeout: float = CASE_TIMEOUT, cwd: Path | None = None,
                  announce_period: float | None = ANNOUNCE_PERIOD, settle: float = SETTLE,
                  terminal: bool = False, rtf_window: float = 0.0) -> Timing:
    """Start a subscriber to `topic` (and wait until it is subscribed, and `settle` s more), then
    `node_cmd`: the wall seconds from the node's start to the first message received, and the
    node's CPU seconds then. The node is stopped afterwards (SIGINT, then SIGKILL). StartupError
    if the node ends or says nothing on `topic` within `timeout` s. The subscriber's participant
    announces itself every `announce_period` s (None: as the environment says). The node runs
    in a session of its own, its stdin /dev/null (no terminal: a launch file, systemd, CI), or
    with `terminal` on a pseudo-terminal of its own (a start typed in a shell: `Terminal`).
    With `rtf_window` > 0, extra["rtf"]: the real-time factor of the node's first `rtf_window`
    s of publications (the stamps' span over their arrivals')."""
    node = None
    term = Terminal() if terminal else None
    with tempfile.TemporaryFile("w+") as node_err, tempfile.TemporaryDirectory(prefix="gyro_sim_probe_") as tmp:
        sub_env = with_profile(env, Path(tmp), announce_period) if announce_period else env
        sub = subprocess.Popen([python, "-c", SUBSCRIBER, str(timeout), topic, repr(rtf_window)], env=sub_env,
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
                               cwd=cwd)
        try:
            if not _read_line(sub, "the subscriber").startswith("ready"):
                raise StartupError("the subscriber did not start")
            time.sleep(settle)
            t0 = time.monotonic()
            where = term.popen_options() if term is not None else {"stdin": subprocess.DEVNULL,
                                                                    "stdout": subprocess.DEVNULL}
            node = subprocess.Popen(node_cmd, env=env, stderr=node_err, start_new_session=True, cwd=cwd, **where)
            while not select.select([sub.stdout], [], [], POLL)[0]:
                if node.poll() is not None:
                    node_err.seek(0)
                    said = node_err.read().strip().splitlines()
                    raise StartupError(f"{Path(node_cmd[0]).name} ended (exit {node.returncode}) before its "
                                       f"first {topic}: {said[-1] if said else ''}")
            line = _read_line(sub, "the subscriber")
            cpu = process_cpu(node.pid) if node.poll() is None else float("nan")
            if not line.startswith("first "):
                raise StartupError(f"no {topic} message within {timeout:g} s")
            timing = Timing(float(line.split()[1]) - t0, cpu)
            if rtf_window > 0:
                said = _read_line(sub, "the subscriber").split()
                if said[:1] != ["rtf"] or node.poll() is not None:
                    raise StartupError(f"the node ended within {rtf_window:g} s of its first {topic}")
                timing.extra.update(rtf=float(said[1]), rtf_messages=int(said[2]), rtf_window=rtf_window)
            return timing
        finally:
            for p in (node, sub):
                if p is not None:
                    stop(p)
            sub.stdout.close()
            if term is not None:
                term.close()


def with_profile(env: dict, directory: Path, period: float) -> dict:
    """`env` with a Fast DDS profile (written in `directory`) whose participants announce
    themselves every `period` s."""
    profile = directory / f"announce_{period:g}s.xml"
    profile.write_text(profile_xml(period, "gyro_sim_startup"))
    return dict(env, **{PROFILE_VARIABLES[0]: str(profile)})


def late_subscriber(python: str, node_cmd: list[str], env: dict, topic: str = TOPIC,
                    timeout: float = CASE_TIMEOUT, cwd: Path | None = None, settle: float = SETTLE) -> Timing:
    """Start `node_cmd`, wait until it says NODE_READY on stderr and `settle` s more, then a
    subscriber to `topic`: the wall seconds from its subscription to its first message (no CPU
    time: NaN). Both are stopped afterwards. StartupError if the node ends
    first or nothing comes within `timeout` s."""
    sub = None
    with tempfile.TemporaryFile("w+") as node_err:
        node = subprocess.Popen(node_cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=node_err, start_new_session=True, cwd=cwd)
        try:
            end = time.monotonic() + timeout
            while True:
                node_err.seek(0)
                said = node_err.read()
                if NODE_READY in said:
                    break
                if node.poll() is not None or time.monotonic() > end:
                    last = said.strip().splitlines()
                    raise StartupError(f"{Path(node_cmd[0]).name} did not start (exit {node.poll()}): "
                                       f"{last[-1] if last else ''}")
                time.sleep(POLL)
            time.sleep(settle)
            sub = subprocess.Popen([python, "-c", SUBSCRIBER, str(timeout), topic], env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.DEVNULL, text=True, start_new_session=True, cwd=cwd)
            ready = _read_line(sub, "the subscriber").split()
            if ready[:1] != ["ready"]:
                raise StartupError("the subscriber did not start")
            t0 = float(ready[1])  # its own clock reading: not the pipe's latency
            line = _read_line(sub, "the subscriber")
            if not line.startswith("first "):
                raise StartupError(f"no {topic} message within {timeout:g} s")
            return Timing(float(line.split()[1]) - t0, float("nan"))
        finally:
            for p in (sub, node):
                if p is not None:
                    stop(p)
            if sub is not None:
                sub.stdout.close()


def timed_run(cmd: list[str], env: dict, timeout: float = CASE_TIMEOUT, cwd: Path | None = None) -> Timing:
    """Run `cmd` to its end: wall seconds and its CPU seconds (its own and its waited-for
    children's, from wait4). StartupError if it fails or outlasts `timeout`."""
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True, cwd=cwd)
    end = t0 + timeout
    try:
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() > end:
                raise StartupError(f"{Path(cmd[0]).name} did not end within {timeout:.0f} s")
            time.sleep(0.02)
        wall = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        end_group(proc.pid)  # what it left running would hold its stderr open
        err = proc.stderr.read().decode(errors="replace").strip().splitlines()
        if proc.returncode != 0:
            raise StartupError(f"{Path(cmd[0]).name} exited {proc.returncode}: {err[-1] if err else ''}")
        return Timing(wall, usage.ru_utime + usage.ru_stime)
    finally:
        if proc.returncode is None:
            stop(proc)
        end_group(proc.pid)
        proc.stderr.close()


def worker_first_point(python: str, env: dict, scene: str = RUN_SCENE, horizon: float = 0.1,
                       timeout: float = CASE_TIMEOUT, cwd: Path | None = None) -> Timing:
    """A one-point sweep on a LocalCluster of one worker: the worker's wall seconds from its
    process start to its first point and its CPU seconds (extra: the sweep's wall from its call,
    the calling process's CPU)."""
    proc = subprocess.Popen([python, "-c", SWEEP, scene, repr(horizon)], env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            cwd=cwd)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        raise StartupError(f"the sweep did not end within {timeout:.0f} s") from None
    finally:
        stop(proc)  # the cluster's processes with it (its session)
    lines = out.strip().splitlines()
    if proc.returncode != 0 or not lines:
        err = err.strip().splitlines()
        raise StartupError(f"the sweep failed (exit {proc.returncode}): {err[-1] if err else ''}")
    d = json.loads(lines[-1])
    return Timing(d["worker_wall"], d["worker_cpu"], {"sweep_wall": d["sweep_wall"], "client_cpu": d["client_cpu"]})


#: the cases, in the order they run: (key, label)
CASES = (("node", f"`gyro_sim_node` (default scene) without a terminal, to the first {TOPIC} a subscriber receives"),
         ("node_tty", f"`gyro_sim_node` (default scene) from a terminal, to the first {TOPIC} a subscriber receives"),
         ("run", f"`gyro-sim run --scene {RUN_SCENE} --duration {RUN_DURATION:g}`, to its end"),
         ("worker", "a Dask worker's first sweep point (dop853), from the worker's start"),
         ("rclpy", f"for comparison: a minimal rclpy node publishing JointState, to the first {TOPIC} received"),
         ("late", f"a subscriber started {SETTLE:g} s after the node runs, from its subscription to its first {TOPIC}"))


def scripts(venv: Path, source: Path | None) -> dict:
    """The command lines of the console scripts measured: the venv's installed ones, or with
    `source` the entry points that tree's setup.py names, called by the venv's Python as pip's
    wrapper calls them (the tree on PYTHONPATH, set by `measure`)."""
    names = ("gyro_sim_node", "gyro-sim")
    if source is None:
        return {name: [str(script_of(venv, name))] for name in names}
    import re

    setup = (source / "setup.py").read_text()
    out = {}
    for name in names:
        found = re.search(rf'"{re.escape(name)} = ([\w.]+):(\w+)"', setup)
        if found is None:
            raise StartupError(f"{source / 'setup.py'} names no console script {name}")
        module, func = found.groups()
        out[name] = [str(python_of(venv)), "-c", f"import sys; sys.argv[0] = {name!r}; from {module} import {func}; "
                                                 f"sys.exit({func}())"]
    return out


def measure(venv: Path, parts, say, timeout: float = CASE_TIMEOUT, warm_starts: int = 1,
            announce_period: float | None = ANNOUNCE_PERIOD, source: Path | None = None,
            rtf_window: float = RTF_WINDOW) -> dict:
    """Every case of `parts` cold (a new empty cache) then warm (the same cache again,
    `warm_starts` times: the median start, with every wall time in its ``walls``), each run
    from a scratch directory (not a source tree, whose gyro_sim `python -m` would find first).
    `announce_period`: the node case's subscriber's (`first_message`); None: Fast DDS's default
    for every process (the node's own shorter period, gyro_sim.ros.discovery, turned off).
    `source`: a source tree measured in `venv` without installing it (`scripts`). The node
    cases also give the real-time factor of the first `rtf_window` s of publications."""
    python = str(python_of(venv))
    run = scripts(venv, source)
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="gyro_sim_startup_") as tmp:
        scratch = Path(tmp)
        for key, _label in CASES:
            if key not in parts:
                continue
            cache = scratch / f"cache_{key}"
            cache.mkdir()
            env = child_env(venv, cache, scratch)
            if source is not None:
                env["PYTHONPATH"] = str(source)
            if not announce_period:  # Fast DDS's default for every process, the node's own period too
                env = with_profile(env, scratch, FAST_DDS_ANNOUNCE_PERIOD)
            try:
                for temp, starts in (("cold", 1), ("warm", warm_starts)):
                    if temp == "warm":  # a later start: once the first start's fill has ended
                        wait_cache_fills(cache, timeout)
                    timings = []
                    for i in range(starts):
                        say(f"{key}, {temp}" + (f" {i + 1}/{starts}" if starts > 1 else "") + " ...")
                        if key in ("node", "node_tty", "rclpy"):
                            cmd = run["gyro_sim_node"] if key != "rclpy" else [python, "-c", MINIMAL_NODE]
                            t = first_message(python, cmd, env, timeout=timeout, cwd=scratch,
                                              announce_period=announce_period, terminal=key == "node_tty",
                                              rtf_window=rtf_window if key != "rclpy" else 0.0)
                        elif key == "late":
                            t = late_subscriber(python, run["gyro_sim_node"], env, timeout=timeout,
                                                cwd=scratch)
                        elif key == "run":
                            t = timed_run([*run["gyro-sim"], "run", "--scene", RUN_SCENE, "--duration",
                                           str(RUN_DURATION)], env, timeout=timeout, cwd=scratch)
                        else:
                            t = worker_first_point(python, env, timeout=timeout, cwd=scratch)
                        say(f"{key}, {temp}: {t.wall:.1f} s, CPU {t.cpu:.1f} s"
                            + (f", real-time factor {t.extra['rtf']:.3f} over the first {rtf_window:g} s"
                               if "rtf" in t.extra else ""))
                        timings.append(t)
                    t = sorted(timings, key=lambda t: t.wall)[(len(timings) - 1) // 2]
                    if starts > 1:
                        t = Timing(t.wall, t.cpu, dict(t.extra, walls=[u.wall for u in timings]))
                    results.setdefault(key, {})[temp] = asdict(t)
            finally:  # what a start left filling this cache does not run into the next case
                end_cache_fills(cache)
    return results


def machine() -> dict:
    """Core count and the 1-minute load average now."""
    return {"cores": os.cpu_count(), "load": round(os.getloadavg()[0], 2)}


def table(results: dict, before: dict, command: str, day: str, announce_period: float = ANNOUNCE_PERIOD) -> str:
    """The Markdown table of `results` (measure's), with the date, command and core count, and
    how often the node case's subscriber announced itself (0: Fast DDS's default)."""
    lines = [f"{day}, `{command}`; {before['cores']} cores.", "",
             "| case | cold: wall (s) | cold: CPU (s) | warm: wall (s) | warm: CPU (s) |",
             "|---|---:|---:|---:|---:|"]
    for key, label in CASES:
        if key in results:
            c, w = results[key]["cold"], results[key]["warm"]
            walls = w["extra"].get("walls")
            spread = f" (median of {len(walls)}: {min(walls):.1f} to {max(walls):.1f})" if walls else ""
            lines.append(f"| {label} | {c['wall']:.1f} | {_seconds(c['cpu'])} | {w['wall']:.1f}{spread} "
                         f"| {_seconds(w['cpu'])} |")
    starts = [(key, where) for key, where in (("node", "without a terminal"), ("node_tty", "from a terminal"))
              if "rtf" in results.get(key, {}).get("cold", {}).get("extra", {})]
    if starts:
        window = results[starts[0][0]]["cold"]["extra"].get("rtf_window", RTF_WINDOW)
        lines += ["", f"The node's start, to its first {TOPIC} and its real-time factor over the {window:g} s after "
                      "it (simulated time over wall time):", "",
                  f"| start | cold: first {TOPIC} (s) | cold: real-time factor | warm: first {TOPIC} (s) "
                  "| warm: real-time factor |", "|---|---:|---:|---:|---:|"]
        for key, where in starts:
            c, w = results[key]["cold"], results[key]["warm"]
            lines.append(f"| {where} | {c['wall']:.1f} | {c['extra']['rtf']:.3f} | {w['wall']:.1f} "
                         f"| {w['extra'].get('rtf', float('nan')):.3f} |")
    if {"node", "node_tty", "rclpy", "late"} & set(results):
        lines += ["", (f"The node's subscriber announced itself every {announce_period:g} s, the node every "
                       f"{ANNOUNCE_PERIOD_NODE:g} s." if announce_period else
                       f"Every process announced itself every {FAST_DDS_ANNOUNCE_PERIOD:g} s (Fast DDS's "
                       "default).")]
    if "worker" in results:
        c = results["worker"]["cold"]["extra"]
        lines += ["", f"The one-point sweep, from its call to its first point: {c['sweep_wall']:.1f} s cold "
                      f"(the calling process: {c['client_cpu']:.1f} s CPU, its compile for the workers included)."]
    return "\n".join(lines)


def _seconds(x: float) -> str:
    return "-" if x != x else f"{x:.1f}"  # NaN: not measured


def command_of(args) -> str:
    """The command line that reproduces `args` (for the table)."""
    words = ["gyro-sim", "bench", "startup"]
    for option in ("source", "keep_venv", "venv"):
        if getattr(args, option):
            words += [f"--{option.replace('_', '-')}", str(getattr(args, option))]
    if list(args.parts) != [k for k, _ in CASES]:
        words += ["--parts", *args.parts]
    if args.warm_starts != 1:
        words += ["--warm-starts", str(args.warm_starts)]
    if args.announce_period != ANNOUNCE_PERIOD:
        words += ["--announce-period", f"{args.announce_period:g}"]
    return " ".join(words)


def cmd_bench_startup(args) -> int:
    prog = "gyro-sim bench startup"

    def say(line: str) -> None:
        print(f"{prog}: {line}", file=sys.stderr, flush=True)

    if args.warm_starts < 1 or not args.announce_period >= 0:
        print(f"{prog}: --warm-starts must be at least 1 and --announce-period not negative", file=sys.stderr)
        return 2
    if args.json and Path(args.json).exists() and not args.force:
        print(f"{prog}: {args.json} exists; --force replaces it", file=sys.stderr)
        return 2
    made: Path | None = None  # a venv this command creates (removed unless kept and complete)
    keep = False
    source_path = None  # a source tree measured in --venv without installing it
    if args.venv:
        venv = Path(args.venv)
        if not python_of(venv).is_file():
            print(f"{prog}: {venv} is not a virtual environment (no bin/python)", file=sys.stderr)
            return 2
        if args.source:
            source_path = source_tree(args.source)
            if source_path is None:
                print(f"{prog}: {args.source} is not a gyro_sim source tree (no setup.py, package.xml, gyro_sim/)",
                      file=sys.stderr)
                return 2
    else:
        source = source_tree(args.source)
        if source is None:
            where = args.source or Path(__file__).resolve().parents[2]
            print(f"{prog}: {where} is not a gyro_sim source tree (no setup.py, package.xml, gyro_sim/); "
                  "give one with --source", file=sys.stderr)
            return 2
        if args.keep_venv:
            venv = Path(args.keep_venv)
            if venv.exists() and any(venv.iterdir()):
                print(f"{prog}: {venv} exists and is not empty; reuse it with --venv", file=sys.stderr)
                return 2
        else:
            venv = Path(tempfile.mkdtemp(prefix="gyro_sim_venv_"))
        made = venv
    command = command_of(args)
    try:
        if made is not None:
            install(made, source, say)
            keep = bool(args.keep_venv)
        before = machine()
        results = measure(venv, args.parts, say, timeout=args.timeout, warm_starts=args.warm_starts,
                          announce_period=args.announce_period or None, source=source_path)
        after = machine()
    except StartupError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    except (OSError, subprocess.SubprocessError) as exc:
        print(f"{prog}: {type(exc).__name__}: {exc}".splitlines()[0], file=sys.stderr)
        return 1
    finally:
        if made is not None and not keep:
            shutil.rmtree(made, ignore_errors=True)
    print(table(results, before, command, date.today().isoformat(), args.announce_period))
    if args.json:
        from gyro_sim.safe_paths import OutputError, write_atomic

        try:
            write_atomic(args.json, json.dumps({"date": date.today().isoformat(), "command": command,
                                                "machine": {"before": before, "after": after},
                                                "announce_period": args.announce_period,
                                                "results": results}, indent=1), force=args.force, what="--json")
        except (OutputError, OSError) as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 1
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim bench startup`."""
    s = bench.add_parser("startup", help="time to the first output of a fresh install, cold and warm (minutes)")
    s.add_argument("--source", help="the gyro_sim source tree to install (default: the one this gyro_sim runs from); "
                                    "with --venv, measured in that venv as it is, not installed (PYTHONPATH)")
    where = s.add_mutually_exclusive_group()
    where.add_argument("--keep-venv", metavar="DIR", help="install into DIR (new or empty) and keep it")
    where.add_argument("--venv", metavar="DIR", help="measure in this installed venv (no install)")
    s.add_argument("--parts", nargs="+", default=[k for k, _ in CASES], choices=[k for k, _ in CASES])
    s.add_argument("--timeout", type=float, default=CASE_TIMEOUT, help="longest wait for one case (s)")
    s.add_argument("--warm-starts", type=int, default=1, metavar="N",
                   help="warm starts of each case (the table gives the median and the range)")
    s.add_argument("--announce-period", type=float, default=ANNOUNCE_PERIOD, metavar="S",
                   help=f"how often the node case's subscriber announces itself (s; default {ANNOUNCE_PERIOD:g}; "
                        f"0: Fast DDS's default, {FAST_DDS_ANNOUNCE_PERIOD:g} s, for every process, the node's own "
                        f"{ANNOUNCE_PERIOD_NODE:g} s too)")
    s.add_argument("--json", metavar="FILE", help="also write the figures to FILE")
    s.add_argument("--force", action="store_true", help="replace an existing --json FILE")
    s.set_defaults(fn=cmd_bench_startup)
