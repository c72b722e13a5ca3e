"""`gyro-sim replay` over DDS: a second process receives the log's messages, in order, at pace."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import iter_messages
from gyro_sim.log.record import record_run

from test.conftest import ROOT

pytest.importorskip("rclpy")

TOPICS = [M.JOINT_STATES, M.CLOCK]
DURATION = 2.0
#: pace tolerance of the SPEC: within 5 % of the recorded span
PACE_TOLERANCE = 0.05

# Subscribes raw to the topics, records (arrival time, topic, bytes) until `expected` messages
# arrived or the timeout, then pickles them to argv[1].
SUBSCRIBER = """
import pickle, sys, time
import rclpy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
out, expected, timeout = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("replay_test_listener")
got = []
def cb(topic):
    return lambda data: got.append((time.monotonic(), topic, bytes(data)))
node.create_subscription(JointState, "/joint_states", cb("/joint_states"), 1000, raw=True)
node.create_subscription(Clock, "/clock", cb("/clock"), 1000, raw=True)
print("ready", flush=True)
deadline = time.monotonic() + timeout
while len(got) < expected and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.01)
pickle.dump(got, open(out, "wb"))
node.destroy_node()
rclpy.shutdown()
"""


def ros_env(tmp_path) -> dict:
    env = dict(os.environ)  # everything (LD_LIBRARY_PATH of the ROS wheels)
    env["ROS_DOMAIN_ID"] = str(50 + os.getpid() % 50)  # 50..99: apart from the node tests and benches
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(tmp_path / "ros_log")
    return env


@pytest.mark.slow
def test_replay_publishes_the_same_messages_in_order_at_the_recorded_pace(tmp_path):
    log = tmp_path / "replay.mcap"
    record_run(Simulator(load_scene(ROOT / "config" / "heavy_top.yaml")), log, duration=DURATION, chunk=0.02,
               publish_rate=50.0)
    logged = [(t, topic, data) for topic, _, t, data in iter_messages(log, TOPICS, decode=False)]
    env = ros_env(tmp_path)
    out = tmp_path / "got.pkl"
    sub = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, str(out), str(len(logged)), "20"], cwd=ROOT, env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert sub.stdout.readline().strip() == "ready", sub.stderr.read()
        rep = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "replay", str(log), "--topics", *TOPICS,
                              "--wait-for-subscribers", "30"], cwd=ROOT, env=env, capture_output=True, text=True,
                             timeout=120)
        assert rep.returncode == 0, rep.stderr
        assert f"published {len(logged)} messages" in rep.stdout, rep.stdout
        sub.wait(timeout=60)
    finally:
        if sub.poll() is None:
            sub.kill()
    got = pickle.load(open(out, "rb"))
    assert len(got) == len(logged), _missing(got, logged)
    # the same messages (byte for byte), in the same order, per topic
    for topic in TOPICS:
        assert [d for _, tp, d in got if tp == topic] == [d for _, tp, d in logged if tp == topic], topic
    # and across topics: in arrival order, log times never go back (messages of the same log
    # time on two topics may swap: two DDS writers)
    index = {(tp, d): t for t, tp, d in logged}
    times = [index[(tp, d)] for _, tp, d in got]
    assert times == sorted(times)
    # at the recorded pace: every arrival within 5 % of the span of its due time. Wall time on
    # purpose: this is the product's pace through a real DDS stack in another process (the
    # pacing arithmetic itself is checked on a fake clock, exactly, below)
    arrival = np.array([a for a, _, _ in got])
    due = np.array(times) / 1e9
    span = due[-1] - due[0]
    lag = (arrival - arrival[0]) - (due - due[0])
    assert abs(arrival[-1] - arrival[0] - span) <= PACE_TOLERANCE * span, (arrival[-1] - arrival[0], span)
    assert np.max(np.abs(lag)) <= PACE_TOLERANCE * span, np.max(np.abs(lag))
    print(f"replayed {span:.3f} s in {arrival[-1] - arrival[0]:.3f} s, largest lag {1e3 * np.max(np.abs(lag)):.1f} ms")


class _FakeTime:
    """perf_counter / sleep of the replay module: time passes only by sleeping, exactly."""

    def __init__(self):
        self.now = 1000.0

    def perf_counter(self):
        return self.now

    def sleep(self, s):
        self.now += max(s, 0.0)


class _Publisher:
    def __init__(self, clock, sent, topic):
        self.clock, self.sent, self.topic = clock, sent, topic

    def publish(self, data):
        self.sent.append((self.clock.now, self.topic, bytes(data)))


@pytest.mark.parametrize("rate", [1.0, 4.0])
def test_replay_publishes_each_message_at_its_log_time_over_the_rate(tmp_path, monkeypatch, rate):
    """The pacing of a pass on a fake clock: every message leaves exactly at its log time
    (relative to the first) divided by the rate, in the log's order, none early, none late."""
    from types import SimpleNamespace

    from gyro_sim.ros import replay as replay_module

    log = tmp_path / "paced.mcap"
    record_run(Simulator(load_scene(ROOT / "config" / "heavy_top.yaml")), log, duration=0.4, chunk=0.02,
               publish_rate=50.0)
    logged = [(t, topic, bytes(data)) for topic, _, t, data in iter_messages(log, TOPICS, decode=False)]
    clock, sent = _FakeTime(), []
    monkeypatch.setattr(replay_module, "time", SimpleNamespace(perf_counter=clock.perf_counter, sleep=clock.sleep))
    stats = replay_module.ReplayStats()
    pubs = {topic: _Publisher(clock, sent, topic) for topic in TOPICS}
    assert replay_module._one_pass(log, pubs, rate, stats, None)
    assert [(tp, d) for _, tp, d in sent] == [(tp, d) for _, tp, d in logged]
    t0 = logged[0][0]
    due = [1000.0 + (t - t0) / 1e9 / rate for t, _, _ in logged]
    assert [w for w, _, _ in sent] == pytest.approx(due, abs=1e-9)
    assert stats.published == len(logged) and stats.max_late == pytest.approx(0.0, abs=1e-9)
    assert stats.wall_span == pytest.approx(stats.log_span / rate, abs=1e-9)


def _missing(got, logged) -> str:
    have = {(tp, d) for _, tp, d in got}
    lost = [(t / 1e9, tp) for t, tp, d in logged if (tp, d) not in have]
    return f"{len(got)} of {len(logged)} arrived; lost {len(lost)}: first {lost[:3]}, last {lost[-3:]}"


@pytest.mark.slow
def test_replay_without_subscribers_and_skipped_types(tmp_path):
    """Types that are not installed (tf2_msgs from PyPI) are skipped with a note; --rate speeds up."""
    log = tmp_path / "all.mcap"
    record_run(Simulator(load_scene(ROOT / "config" / "heavy_top.yaml")), log, duration=0.4, chunk=0.02,
               publish_rate=50.0)
    rep = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "replay", str(log), "--rate", "4"], cwd=ROOT,
                         env=ros_env(tmp_path), capture_output=True, text=True, timeout=120)
    assert rep.returncode == 0, rep.stderr
    try:
        import tf2_msgs  # noqa: F401
    except ImportError:
        assert "skipped /tf: message type tf2_msgs/msg/TFMessage is not installed" in rep.stdout
    # the whole log went out (the 4x pace itself: the fake-clock test above, exactly)
    assert "0.400 s of log in " in rep.stdout, rep.stdout
