"""Fixtures and helpers shared across the test tree; the run's ROS log directory; the check
that the tests write nothing into the clone."""
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# rclpy writes a log file per process: keep them out of ~/.ros and out of the tree, in a
# directory of this run's own (removed at its end), unless the caller chose one
_OWN_ROS_LOG_DIR = None
if "ROS_LOG_DIR" not in os.environ:
    _OWN_ROS_LOG_DIR = tempfile.mkdtemp(prefix="gyro_sim-test-ros-log-")
    os.environ["ROS_LOG_DIR"] = _OWN_ROS_LOG_DIR
# no kernel-cache fill left behind by a test's start: it would take the cores from the other
# tests (the tests of the fill opt in with "1" and a private NUMBA_CACHE_DIR)
os.environ["GYRO_SIM_BACKGROUND_FILL"] = "0"

# --- shared by the tests of logs, messages, replay and views: a short recorded run ---------------
#: hinge_chain has spherical joints, hinges, an actuated rotor: every kind of joint state
SCENE = ROOT / "config" / "hinge_chain.yaml"
#: (t, axis moments) for hinge_chain's axes (wheel2, arm3, arm4)
SCHEDULE = [(0.0, [0.001, 0.0, 0.0]), (0.1, [0.0, 0.02, -0.01]), (0.23, [-0.002, -0.01, 0.03])]
DURATION = 0.4
PUBLISH_RATE = 50.0
CHUNK = 0.005


def gyro_sim(*args, timeout=120, **kw):
    """Run the CLI in a subprocess (the whole environment passed on: the ROS wheels need theirs)."""
    return subprocess.run([sys.executable, "-m", "gyro_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=dict(os.environ), **kw)


def catches(pid: int, signum: int) -> bool:
    """Whether process `pid` has a handler of its own for `signum` (its SigCgt mask in /proc):
    for SIGTERM, which Python leaves at the system's default, the moment the package's first
    statement has run."""
    try:
        with open(f"/proc/{pid}/status") as f:
            mask = next(int(line.split()[1], 16) for line in f if line.startswith("SigCgt:"))
    except (OSError, StopIteration):
        return False
    return bool(mask >> (signum - 1) & 1)


def signal_during_start(cmd: list[str], env: dict, signum: int, delay: float, timeout: float = 120.0):
    """Start `cmd`, wait until its own SIGTERM handler is there (`catches`: its first statement
    ran; before it the interpreter's own start is the system's business), `delay` s more, send
    `signum`; (exit status, stdout, stderr) once it has ended (killed after `timeout` s: status
    None)."""
    import signal as _signal
    import time

    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + timeout
        while not catches(proc.pid, _signal.SIGTERM) and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.001)
        time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(signum)
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out, err
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        return None, out, err


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """(path, RunRecord) of a 0.4 s hinge_chain run with commands, published at 50 Hz."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    path = tmp_path_factory.mktemp("log") / "run.mcap"
    sim = Simulator(load_scene(SCENE))
    rec = record_run(sim, path, duration=DURATION, chunk=CHUNK, publish_rate=PUBLISH_RATE, schedule=SCHEDULE)
    return path, rec


def rosbags_messages(path) -> list[tuple[str, int]]:
    """(topic, log time) of every message in file order, each deserialised by rosbags (an
    independent reader)."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([Path(path)]) as reader:
        for con, t, raw in reader.messages():
            reader.deserialize(raw, con.msgtype)
            out.append((con.topic, t))
    return out


#: what a run may leave in the clone: caches of Python, numba, pytest and ruff, build metadata, venvs
_TREE_OWN = {"__pycache__", ".git", ".pytest_cache", ".ruff_cache", ".ci-venv", ".ci-peers-venv", ".venv", "build",
             "dist"}


def _tree_files() -> dict[str, float]:
    """Every file of the clone outside caches and venvs, with its modification time."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(ROOT):
        dirnames[:] = [d for d in dirnames if d not in _TREE_OWN and not d.endswith(".egg-info")]
        for f in filenames:
            p = os.path.join(dirpath, f)
            try:
                out[os.path.relpath(p, ROOT)] = os.stat(p).st_mtime
            except OSError:
                pass
    return out


def pytest_sessionstart(session):
    session.config._gyro_sim_tree = _tree_files()


def pytest_sessionfinish(session, exitstatus):
    """Tests run in their own temporary directories: a file the run created or changed in the
    clone fails the run, named."""
    if _OWN_ROS_LOG_DIR is not None:
        import shutil

        shutil.rmtree(_OWN_ROS_LOG_DIR, ignore_errors=True)
    before = getattr(session.config, "_gyro_sim_tree", None)
    if before is None:
        return
    after = _tree_files()
    touched = sorted(p for p, m in after.items() if before.get(p) != m)
    if touched:
        sys.stderr.write("\nthe tests wrote into the clone (they must use temporary directories): "
                         + ", ".join(touched[:20]) + "\n")
        session.exitstatus = 1
