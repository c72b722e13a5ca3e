"""`gyro-sim view --live` against a real gyro_sim node over DDS (private ROS_DOMAIN_ID).

The node publishes its URDF on robot_description (reliable, transient local); where no node
runs, a stand-in publisher in the test process gives it as a robot_state_publisher would.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("rerun")
pytest.importorskip("sensor_msgs.msg")

from test.ros.helpers import ROOT, Client, NodeProcess, new_domain_id, ros_env, wait_for

#: a node's start (a cold numba cache compiles for ~30 s), DDS discovery, a capture (s)
START_TIMEOUT = 180.0
EVENT_TIMEOUT = 60.0
SCENE = "hinge_chain"
#: hinge_chain's axes are wheel2, arm3, arm4: the command the test holds on them (N m)
COMMAND = [0.0, 0.02, -0.01]
COMMAND_PERIOD = 0.05


def chunks(rrd):
    """entity path -> record batches of an .rrd (rerun's own reader)."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for c in RrdReader(str(rrd)).stream():
        out.setdefault(c.entity_path, []).append(c.to_record_batch())
    return out


def column(batches, name):
    return [v for b in batches if name in b.schema.names for v in b.column(name).to_pylist()]


def times(batches):
    """The sim_time of every row (s)."""
    out = []
    for b in batches:
        if "sim_time" in b.schema.names:
            out.append(b.column("sim_time").cast(pa.int64()).to_numpy() / 1e9)
    return np.concatenate(out) if out else np.zeros(0)


class Live:
    """`gyro-sim view --live ...` in a subprocess, its stderr in a file."""

    def __init__(self, tmp: Path, env: dict, *args: str, name: str = "live"):
        self.err_path = tmp / f"{name}.err"
        self.out_path = tmp / f"{name}.out"
        self.proc = subprocess.Popen([sys.executable, "-m", "gyro_sim.cli", "view", "--live", *map(str, args)],
                                     cwd=ROOT, env=env, stdout=open(self.out_path, "w"),
                                     stderr=open(self.err_path, "w"))

    @property
    def stderr(self) -> str:
        return self.err_path.read_text()

    def says(self, text: str, timeout: float = EVENT_TIMEOUT) -> None:
        wait_for(lambda: text in self.stderr or self.proc.poll() is not None, timeout, f"'{text}'")
        assert text in self.stderr, f"the live view ended without saying '{text}':\n{self.stderr}"

    def wait(self, timeout: float = START_TIMEOUT) -> int:
        return self.proc.wait(timeout)


def describe(client: Client):
    """Publish the scene's URDF on /robot_description as a robot_state_publisher would."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from gyro_sim import load_scene
    from gyro_sim.paths import find_scene
    from gyro_sim.scene.urdf import urdf

    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pub = client.node.create_publisher(String, "/robot_description", qos)
    pub.publish(String(data=urdf(load_scene(find_scene(SCENE)))))
    return pub


class Commander:
    """Holds COMMAND on the node's axes (published every COMMAND_PERIOD s) while on."""

    def __init__(self, client: Client):
        from std_msgs.msg import Float64MultiArray

        self.pub = client.publisher("/gyro_sim/axis_moments", Float64MultiArray)
        self.msg = Float64MultiArray(data=COMMAND)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop.wait(COMMAND_PERIOD):
            self.pub.publish(self.msg)

    def close(self):
        self.stop.set()
        self.thread.join(5)


@pytest.fixture
def domain(tmp_path):
    d = new_domain_id()
    (tmp_path / "ros_log").mkdir()
    client = Client(d)
    try:
        yield d, ros_env(d, tmp_path / "ros_log"), client
    finally:
        client.close()


def node(tmp_path, d, name="node"):
    return NodeProcess(tmp_path, d, f"scene:={SCENE}", "real_time_factor:=1.0", name=name)


@pytest.mark.slow
def test_save_for_seconds_holds_the_moving_chain_and_the_commanded_plots(tmp_path, domain):
    d, env, client = domain
    n = node(tmp_path, d)
    try:
        wait_for(lambda: client.node.count_publishers("/joint_states") > 0 or not n.alive(), START_TIMEOUT, "the node")
        assert n.alive(), n.stderr
        cmd = Commander(client)
        rrd = tmp_path / "live.rrd"
        live = Live(tmp_path, env, "--save", rrd, "--seconds", 6)
        live.says("receiving from the node")
        from std_srvs.srv import Trigger

        assert client.call(Trigger, "/gyro_sim/reset", Trigger.Request()).success
        publishes_events = client.node.count_publishers("/gyro_sim/events") > 0
        assert live.wait() == 0, live.stderr
        cmd.close()
    finally:
        n.stop()
    assert "waiting for /robot_description" in live.stderr and "robot description received: 4 bodies" in live.stderr
    assert live.stderr.count("waiting for") == 1
    got = chunks(rrd)
    from gyro_sim import load_scene
    from gyro_sim.paths import find_scene

    scene = load_scene(find_scene(SCENE))
    for b in scene.bodies:
        t = times(got[f"/world/{b.name}"])
        assert t.size > 40 and np.all(np.diff(t) > 0), f"{b.name}: {t.size} poses"
        trans = np.array([v[0] if isinstance(v[0], list) else v
                          for v in column(got[f"/world/{b.name}"], "Transform3D:translation")])
        assert len(trans) == t.size
        assert column(got[f"/world/{b.name}/body"], "Capsules3D:lengths")
    # the chain moves: the last body's origin is not where it started
    last = np.array(column(got[f"/world/{scene.bodies[-1].name}"], "Transform3D:translation"), float).reshape(-1, 3)
    assert np.linalg.norm(last[-1] - last[0]) > 1e-6
    # the plots grow during the capture, at most --rate (30 by default) rows a second of the
    # node's 100 publications (real_time_factor 1: wall and simulated seconds alike)
    euler_t = times(got["/plots/euler/arm1"])
    assert euler_t.size > 40 and euler_t[-1] - euler_t[0] > 3.0
    assert np.median(np.diff(euler_t)) >= 0.9 / 30
    # the commands the test held are drawn as held
    arm3 = np.array(column(got["/plots/axis_moments/arm3"], "Scalars:scalars"), float).ravel()
    arm4 = np.array(column(got["/plots/axis_moments/arm4"], "Scalars:scalars"), float).ravel()
    assert np.sum(np.isclose(arm3, COMMAND[1])) > 30 and np.sum(np.isclose(arm4, COMMAND[2])) > 30
    assert "lag:" in live.stderr
    # the reset is marked where it happened, and the view goes on after it
    if publishes_events:  # a node that publishes its events (not only records them)
        events = column(got["/events"], "TextLog:text")
        assert any("reset" in str(e) for e in events), events
    assert "node restarted" not in live.stderr  # a reset keeps the node's time going
    assert np.all(np.diff(times(got["/plots/euler/arm1"])) > 0)


@pytest.mark.slow
def test_follows_a_node_that_stops_and_starts_again_and_ends_on_sigint(tmp_path, domain):
    d, env, client = domain
    rrd = tmp_path / "live.rrd"
    live = Live(tmp_path, env, "--save", rrd, "--rate", 0)  # every message drawn
    live.says("waiting for /robot_description")
    n1 = node(tmp_path, d, "node1")
    try:
        from sensor_msgs.msg import JointState

        states = client.subscribe("/joint_states", JointState)
        live.says("receiving from the node", START_TIMEOUT)
        live.says("robot description received")
        # the first run goes on long enough for its restart at time 0 to be a step back
        wait_for(lambda: states and states[-1][1].header.stamp.sec >= 2, EVENT_TIMEOUT, "2 s of the first run")
    finally:
        assert n1.stop() == 0, n1.stderr
    live.says("the node stopped: waiting for it to start again")
    n2 = node(tmp_path, d, "node2")
    try:
        live.says("the node restarted", START_TIMEOUT)  # the view has a message of the second run
    finally:
        n2.stop()
    live.proc.send_signal(signal.SIGINT)
    assert live.wait() == 0, live.stderr
    assert "Traceback" not in live.stderr
    got = chunks(rrd)
    events = [str(e) for e in column(got["/events"], "TextLog:text")]
    marks = [float(re.search(r"node restarted at sim_time ([0-9.]+) s", e).group(1)) for e in events
             if "node restarted" in e]
    assert len(marks) == 1, events
    # the second run is drawn after the first on sim_time, not over it: every series goes
    # forward, the first run's before the mark, the second's from it
    stamped = [times(b) for e, b in got.items() if e.startswith("/plots/") or e.startswith("/world/arm")]
    assert all(np.all(np.diff(t) > 0) for t in stamped if t.size > 1)
    every = np.concatenate([t for t in stamped if t.size])
    assert np.any(every < marks[0]) and np.any(every >= marks[0])


@pytest.mark.slow
def test_sigterm_ends_with_exit_0_and_a_readable_file(tmp_path, domain):
    d, env, client = domain
    describe(client)
    rrd = tmp_path / "live.rrd"
    live = Live(tmp_path, env, "--save", rrd)
    live.says("waiting for /robot_description")
    live.says("robot description received")
    live.proc.send_signal(signal.SIGTERM)
    assert live.wait() == 0, live.stderr
    got = chunks(rrd)
    assert "/world/arm1/body" in got  # the shapes from the description


@pytest.mark.slow
def test_an_existing_file_is_refused_without_force(tmp_path):
    rrd = tmp_path / "taken.rrd"
    rrd.write_bytes(b"not mine")
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "view", "--live", "--save", str(rrd), "--seconds", "1"],
                       cwd=ROOT, env=dict(os.environ), capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and rrd.read_bytes() == b"not mine"
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("args", [["--live", "some.mcap"], [], ["x.mcap", "--serve"], ["--live", "--seconds", "0"]])
@pytest.mark.slow
def test_bad_combinations_are_refused_in_one_line(args, tmp_path):
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "view", *args], cwd=ROOT, env=dict(os.environ),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_new_robot_description_replaces_the_shapes(tmp_path):
    """A reset to another scene publishes another description: its bodies are drawn, the old
    ones' shapes cleared."""
    import rerun as rr

    from gyro_sim import load_scene
    from gyro_sim.msgs import messages as M
    from gyro_sim.paths import find_scene
    from gyro_sim.scene.urdf import urdf
    from gyro_sim.viz.translate import Translator

    class Text:
        def __init__(self, data):
            self.data = data

    rrd = tmp_path / "two.rrd"
    rec = rr.RecordingStream("gyro_sim_test", recording_id="two")
    rec.save(str(rrd))
    tr = Translator(rec)
    first, second = load_scene(find_scene(SCENE)), load_scene(find_scene("chain_4"))
    tr.message(M.ROBOT_DESCRIPTION, 0.0, Text(urdf(first)))
    drawn = tr.chain
    tr.message(M.ROBOT_DESCRIPTION, 0.5, Text(urdf(first)))  # again (a late joiner's copy): kept
    assert tr.chain is drawn
    tr.message(M.ROBOT_DESCRIPTION, 1.0, Text(urdf(second)))
    tr.message(M.ROBOT_DESCRIPTION, 2.0, Text("<robot><oops"))
    tr.flush()
    rec.flush()
    rec.disconnect()
    assert [b.name for b in tr.chain.bodies] == [b.name for b in second.bodies]
    assert len(tr.notes) == 1 and "not XML" in tr.notes[0]
    got = chunks(rrd)
    for b in second.bodies:
        assert f"/world/{b.name}/body" in got
    gone = {b.name for b in first.bodies} - {b.name for b in second.bodies}
    for name in gone:  # cleared: its last static value is a Clear
        assert any("Clear" in str(bt.schema.names) for bt in got[f"/world/{name}/body"]), name


@pytest.mark.slow
def test_serve_on_a_port_in_use_is_refused_in_one_line(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("0.0.0.0", 0))
        s.listen()
        port = s.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "view", "--live", "--serve", "--seconds", "1",
                            "--grpc-port", str(port)], cwd=ROOT, env=dict(os.environ), capture_output=True,
                           text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert f"port {port} is in use" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
