"""Running the node in its own process and talking to it from the test process over real DDS.

Every node gets its own ROS_DOMAIN_ID (100..199, from the pid and a counter) with discovery
limited to localhost, and ROS_LOG_DIR under the test's tmp directory. The whole environment
is passed on (the ROS wheels need their LD_LIBRARY_PATH). Waits are
on conditions with generous timeouts: DDS discovery takes 0.1 s or 2-4 s.
"""
from __future__ import annotations

import itertools
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from gyro_sim.bench import procs
from gyro_sim.bench.procs import children, running  # noqa: F401 - the tests take them from here

ROOT = Path(__file__).resolve().parents[2]
DISCOVERY_TIMEOUT = 20.0
_counter = itertools.count()


def new_domain_id() -> int:
    return 100 + (os.getpid() * 7 + next(_counter)) % 100


def ros_env(domain_id: int, log_dir: Path) -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(log_dir),
               PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    return env


def node_command(*params: str, params_file: str | None = None, remaps: tuple[str, ...] = ()) -> list[str]:
    """`python -m gyro_sim.ros.start --ros-args [--params-file F] -p a:=b ... [-r from:=to ...]`: the
    console script's entry point"""
    cmd = [sys.executable, "-m", "gyro_sim.ros.start", "--ros-args"]
    if params_file:
        cmd += ["--params-file", str(params_file)]
    for p in params:
        cmd += ["-p", p]
    for r in remaps:
        cmd += ["-r", r]
    return cmd


class NodeProcess:
    """The node in a subprocess, its output in files."""

    def __init__(self, tmp: Path, domain_id: int, *params: str, params_file=None, name: str = "node",
                 env: dict | None = None, new_session: bool = False, remaps: tuple[str, ...] = ()):
        self.out_path, self.err_path = tmp / f"{name}.out", tmp / f"{name}.err"
        (tmp / "ros_log").mkdir(exist_ok=True)
        self.env = {**ros_env(domain_id, tmp / "ros_log"), **(env or {})}
        self.proc = subprocess.Popen(
            node_command(*params, params_file=params_file, remaps=remaps), cwd=ROOT, env=self.env,
            stdout=open(self.out_path, "w"), stderr=open(self.err_path, "w"), start_new_session=new_session,
        )

    @property
    def stdout(self) -> str:
        return self.out_path.read_text()

    @property
    def stderr(self) -> str:
        return self.err_path.read_text()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, sig=signal.SIGINT, timeout: float = 20.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode


def writer_of(node: "NodeProcess", timeout: float = 60.0) -> int:
    """The pid of the node's log writer process (gyro_sim.ros.recorder's child), once it exists."""
    def find():
        assert node.alive(), f"the node ended before its writer started:\n{node.stderr[-2000:]}"
        for pid in children(node.proc.pid):
            try:
                if b"_child_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    return pid
            except OSError:
                pass
        return None

    return wait_for(find, timeout, "the log writer process", poll=0.005)


def rss_mb(pid: int) -> float:
    """Resident memory of a process (MB)."""
    mb = procs.rss_mb(pid)
    assert mb == mb, f"no VmRSS for {pid}"
    return mb


class Client:
    """An rclpy node in the test process, in its own context for `domain_id`, spun in a thread."""

    def __init__(self, domain_id: int, name: str = "test_client"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.received: dict[str, list] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)
        except Exception:  # noqa: BLE001 - shutdown under way
            pass

    def subscribe(self, topic: str, msg_type, depth: int = 100, raw: bool = False) -> list:
        """Record (wall time, message) of `topic` into the returned list (message: the CDR bytes
        on the wire with raw=True, kept under the key "<topic> raw")."""
        box = self.received.setdefault(topic + (" raw" if raw else ""), [])

        def cb(msg):
            with self.lock:
                box.append((time.monotonic(), msg))

        self.node.create_subscription(msg_type, topic, cb, depth, raw=raw)
        return box

    def messages(self, topic: str) -> list:
        with self.lock:
            return list(self.received.get(topic, []))

    def publisher(self, topic: str, msg_type, depth: int = 10):
        return self.node.create_publisher(msg_type, topic, depth)

    def call(self, srv_type, name: str, request, timeout: float = DISCOVERY_TIMEOUT):
        cli = self.node.create_client(srv_type, name)
        assert cli.wait_for_service(timeout_sec=timeout), f"service {name} not available"
        fut = cli.call_async(request)
        wait_for(fut.done, timeout, f"answer of {name}")
        return fut.result()

    def close(self) -> None:
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        finally:
            self.rclpy.try_shutdown(context=self.context)
            self._thread.join(2.0)


def wait_for(cond, timeout: float, what: str = "condition", poll: float = 0.02):
    """Poll `cond()` until truthy (returned) or fail after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        v = cond()
        if v:
            return v
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll)


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def diag_values(msg) -> dict:
    """key -> value of the gyro_sim statuses (dynamics and run) in a DiagnosticArray."""
    return {kv.key: kv.value for st in msg.status if st.name.startswith("gyro_sim") for kv in st.values}


def all_finite(msg) -> bool:
    """No NaN or inf in any float field of a message, nested (sequences included)."""
    if isinstance(msg, float):
        return math.isfinite(msg)
    if isinstance(msg, (str, bytes, int, bool)) or msg is None:
        if isinstance(msg, str):
            return msg.strip().lower() not in ("nan", "inf", "-inf")
        return True
    if hasattr(msg, "get_fields_and_field_types"):
        return all(all_finite(getattr(msg, f)) for f in msg.get_fields_and_field_types())
    try:
        return all(all_finite(x if not hasattr(x, "item") else float(x)) for x in msg)
    except TypeError:
        return True
