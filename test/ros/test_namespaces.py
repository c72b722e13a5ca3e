"""Two nodes in two namespaces on one DDS domain (real processes, real DDS), each recording.

robot1 runs the built-in demo until it is commanded from outside; robot2 is commanded with
`gyro-sim cmd --namespace /robot2`. Checked: neither's joint states or commands reach the
other, the robot description is held for a subscriber that comes late (transient local), the
logs carry the real (namespaced) names with each publisher's QoS, and every reader of logs
(re-simulation, the schedule reader, the viewer's loader, rosbags) reads them.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from .helpers import DISCOVERY_TIMEOUT, ROOT, Client, NodeProcess, new_domain_id, wait_for

#: these tests share real nodes over DDS, started for the module (seconds each): outside the fast lane
pytestmark = pytest.mark.slow

SCENE = "hinge_chain"
AXES = ("wheel2", "arm3", "arm4")
COMMAND_1 = [0.001, 0.02, -0.01]
COMMAND_2 = [0.0, -0.015, 0.005]
PARAMS = ("scene:=" + SCENE, "integrator:=rk4", "physics_rate:=100.0", "publish_rate:=20.0", "command_timeout:=600.0")
#: simulated seconds of demo before robot1 is commanded from outside
DEMO_SECONDS = 1.5
#: least range (rad) of each commanded hinge over the demo: motion one sees in a viewer
VISIBLE_RANGE = 0.05


def efforts(client, topic: str) -> list[list[float]]:
    return [list(m.effort[-len(AXES):]) for _, m in client.messages(topic)]


@pytest.fixture(scope="module")
def robots(module_tmp):
    domain = new_domain_id()
    client = Client(domain)
    for ns in ("", "/robot1", "/robot2"):
        client.subscribe(f"{ns}/joint_states", JointState, depth=1000)
    logs = {ns: module_tmp / f"{ns.strip('/')}_{{time}}.mcap" for ns in ("/robot1", "/robot2")}
    nodes = {
        "/robot1": NodeProcess(module_tmp, domain, *PARAMS, "demo:=true", "frame_prefix:=robot1/",
                               f"record:={logs['/robot1']}",
                               name="robot1", remaps=("__ns:=/robot1",)),
        "/robot2": NodeProcess(module_tmp, domain, *PARAMS, f"record:={logs['/robot2']}", name="robot2",
                               remaps=("__ns:=/robot2",)),
    }
    out = {"client": client, "nodes": nodes, "domain": domain}
    try:
        for ns, node in nodes.items():
            wait_for(lambda: client.messages(f"{ns}/joint_states") or not node.alive(), 2 * DISCOVERY_TIMEOUT,
                     f"first {ns}/joint_states")
            assert node.alive(), node.stderr
        # the late subscriber: after the node has published its description (before its first state)
        late = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        client.subscribe("/robot1/robot_description", String, depth=late)
        wait_for(lambda: client.messages("/robot1/robot_description"), DISCOVERY_TIMEOUT, "the robot description")
        out["qos"] = {t: client.node.get_publishers_info_by_topic(t)
                      for t in ("/robot1/robot_description", "/robot1/joint_states")}
        # robot1: its demo, then a command from outside
        wait_for(lambda: any(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 > DEMO_SECONDS
                             for _, m in client.messages("/robot1/joint_states")), 30.0, "the demo's seconds")
        pub = client.publisher("/robot1/gyro_sim/axis_moments", Float64MultiArray)
        wait_for(lambda: pub.get_subscription_count() > 0, DISCOVERY_TIMEOUT, "robot1's command subscription")
        pub.publish(Float64MultiArray(data=COMMAND_1))
        wait_for(lambda: COMMAND_1 in efforts(client, "/robot1/joint_states"), 20.0, "robot1 commanded")
        # robot2: commanded by the command line tool, in its namespace
        r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "cmd", "--namespace", "/robot2", "--seconds", "1.0",
                            "--rate", "20", "constant", *map(str, COMMAND_2)], cwd=ROOT, env=nodes["/robot2"].env,
                           capture_output=True, text=True, timeout=60)
        out["cmd"] = r
        wait_for(lambda: COMMAND_2 in efforts(client, "/robot2/joint_states"), 20.0, "robot2 commanded")
        out["root_states"] = len(client.messages("/joint_states"))
        out["efforts"] = {ns: efforts(client, f"{ns}/joint_states") for ns in nodes}
        out["description"] = client.messages("/robot1/robot_description")[0][1].data
        # a reset puts the robot back at its initial pose: the description is published again
        client.subscribe("/robot2/robot_description", String, depth=late)
        wait_for(lambda: client.messages("/robot2/robot_description"), DISCOVERY_TIMEOUT, "robot2's description")
        assert client.call(Trigger, "/robot2/gyro_sim/reset", Trigger.Request()).success
        wait_for(lambda: len(client.messages("/robot2/robot_description")) >= 2, DISCOVERY_TIMEOUT,
                 "robot2's description again after its reset")
        out["descriptions_2"] = [m.data for _, m in client.messages("/robot2/robot_description")]
    finally:
        client.close()
        codes = {ns: node.stop() for ns, node in nodes.items()}
    for ns, node in nodes.items():
        assert codes[ns] == 0, node.stderr
    out["logs"] = {ns: next(module_tmp.glob(f"{ns.strip('/')}_2*.mcap")) for ns in nodes}
    yield out


def test_commands_and_joint_states_stay_in_their_namespace(robots):
    assert robots["cmd"].returncode == 0, robots["cmd"].stderr
    assert "/robot2/gyro_sim/axis_moments" in robots["cmd"].stdout
    assert robots["root_states"] == 0  # nothing on the root namespace's /joint_states
    e1, e2 = robots["efforts"]["/robot1"], robots["efforts"]["/robot2"]
    assert COMMAND_1 in e1 and COMMAND_2 not in e1
    assert COMMAND_2 in e2 and COMMAND_1 not in e2
    # the demo ran on robot1 only, and never after the command from outside
    assert any(any(v != 0.0 for v in e) for e in e1[:e1.index(COMMAND_1)])
    assert all(e == COMMAND_1 for e in e1[e1.index(COMMAND_1):])
    assert all(e == [0.0, 0.0, 0.0] for e in e2[:e2.index(COMMAND_2)])


def test_a_late_subscriber_gets_the_robot_description(robots):
    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.paths import find_scene
    from gyro_sim.scene.load import load_scene
    from gyro_sim.scene.urdf import urdf

    assert robots["description"] == urdf(load_scene(find_scene(SCENE)))
    assert robots["descriptions_2"] == [robots["description"]] * 2  # at start, and after the reset
    logged = [m.data for _, _, _, m in iter_messages(robots["logs"]["/robot1"], ["/robot1/robot_description"])]
    assert logged == [robots["description"]]


def test_logs_carry_the_namespaced_names_and_each_publishers_qos(robots):
    from mcap.reader import make_reader

    with open(robots["logs"]["/robot1"], "rb") as f:
        channels = {c.topic: c for c in make_reader(f).get_summary().channels.values()}
    assert {"/robot1/joint_states", "/robot1/robot_description", "/robot1/gyro_sim/axis_moments",
            "/robot1/gyro_sim/events", "/robot1/gyro_sim/poses", "/tf", "/clock", "/diagnostics"} <= set(channels)
    assert not any(t.startswith("/robot2") or t in ("/joint_states", "/gyro_sim/axis_moments") for t in channels)
    graph = robots["qos"]
    for topic, ch in channels.items():
        (profile,) = yaml.safe_load(ch.metadata["offered_qos_profiles"])
        assert profile["reliability"] == "reliable", topic
        assert profile["durability"] == ("transient_local" if topic.endswith("/robot_description") else "volatile")
        if topic in graph:  # against what DDS says the node's publisher offers
            (info,) = graph[topic]
            q = info.qos_profile
            assert profile["durability"] == {DurabilityPolicy.TRANSIENT_LOCAL: "transient_local",
                                             DurabilityPolicy.VOLATILE: "volatile"}[q.durability]
            assert q.reliability == ReliabilityPolicy.RELIABLE
            for key in ("deadline", "lifespan", "liveliness_lease_duration"):
                d = profile[key]
                assert d["sec"] * 10**9 + d["nsec"] == getattr(q, key).nanoseconds


def viewed(log, tmp_path) -> dict:
    """entity path -> the rerun chunks `gyro-sim view LOG --save` wrote for the log."""
    rerun_chunk = pytest.importorskip("rerun.chunk", reason="the view needs rerun-sdk (pip install '.[viz]')")
    rrd = tmp_path / (Path(log).stem + ".rrd")
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "view", str(log), "--save", str(rrd)], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out: dict = {}
    for c in rerun_chunk.RrdReader(rrd).stream():
        out.setdefault(c.entity_path, []).append(c)
    return out


def test_readers_find_the_channels_of_a_namespaced_log(robots, tmp_path):
    from rosbags.highlevel import AnyReader

    from gyro_sim.log.record import read_schedule
    from gyro_sim.log.resim import resimulate

    for ns, log in robots["logs"].items():
        res = resimulate(log)
        assert res.compared > 10 and res.commands > 0 and res.max_deviation == 0.0, res.report()
        assert read_schedule(log, AXES)
        drawn = viewed(log, tmp_path)
        assert {"/world/arm1", "/plots/hinge/arm3", "/plots/axis_moments/arm3"} <= set(drawn), sorted(drawn)
        with AnyReader([Path(log)]) as reader:
            topics = {c.topic for c in reader.connections}
            assert f"{ns}/joint_states" in topics
            n = sum(1 for conn, _, raw in reader.messages() if reader.deserialize(raw, conn.msgtype) is not None)
        assert n > 10


def test_the_demo_log_shows_commands_and_hinge_motion(robots):
    from gyro_sim.log.mcap_log import iter_messages

    log = robots["logs"]["/robot1"]
    commands = [list(m.data) for _, _, t, m in iter_messages(log, ["/robot1/gyro_sim/axis_moments"])
                if t <= DEMO_SECONDS * 1e9]
    assert len(commands) > 5 and all(np.any(np.array(c) != 0.0) for c in commands)
    states = [m for _, _, t, m in iter_messages(log, ["/robot1/joint_states"]) if t <= DEMO_SECONDS * 1e9]
    names = list(states[0].name)
    for hinge in ("arm3", "arm4"):
        angles = [m.position[names.index(hinge)] for m in states]
        assert max(angles) - min(angles) > VISIBLE_RANGE, hinge
    events = [m.data for _, _, _, m in iter_messages(log, ["/robot1/gyro_sim/events"])]
    assert "demo stopped: a command arrived" in events


def test_the_first_diagnostics_are_not_a_warning(robots):
    from gyro_sim.log.mcap_log import iter_messages

    for log in robots["logs"].values():
        _, _, t, first = next(iter_messages(log, ["/diagnostics"]))
        assert t == 0
        for status in first.status:
            assert status.level == 0, (status.name, status.message)
            measured = {"real_time_factor_achieved", "step_time_p50_us", "publish_jitter_p50_us", "sim_lag_max_ms"}
            assert not measured & {kv.key for kv in status.values}
        run = [s for s in first.status if s.name.endswith("gyro_sim: run")]
        assert run and run[0].message == "starting"


def test_diagnostics_status_names_say_the_robot(robots):
    from gyro_sim.log.mcap_log import iter_messages

    for ns, log in robots["logs"].items():
        _, _, _, first = next(iter_messages(log, ["/diagnostics"]))
        prefix = ns.strip("/")
        assert {s.name for s in first.status} == {f"{prefix}/gyro_sim: dynamics", f"{prefix}/gyro_sim: run"}


def test_the_frame_prefix_names_the_bodies_frames(robots, tmp_path):
    """robot1 runs with frame_prefix robot1/ (as robot_state_publisher's), robot2 without."""
    from gyro_sim.log.mcap_log import iter_messages

    bodies = ["arm1", "arm2", "arm3", "arm4"]
    for ns, prefix in (("/robot1", "robot1/"), ("/robot2", "")):
        log = robots["logs"][ns]
        _, _, _, tf = next(iter_messages(log, ["/tf"]))
        assert [t.child_frame_id for t in tf.transforms] == [prefix + b for b in bodies]
        assert {t.header.frame_id for t in tf.transforms} == {"world"}
        _, _, _, wrench = next(iter_messages(log, [f"{ns}/gyro_sim/wrench/arm2"]))
        assert wrench.header.frame_id == prefix + "arm2"
        drawn = viewed(log, tmp_path)  # the viewer finds the bodies either way
        assert {f"/world/{b}" for b in bodies} <= set(drawn) and not any("robot1" in e for e in drawn)
