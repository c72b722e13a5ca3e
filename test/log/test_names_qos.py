"""The names and QoS a log records: offline logs keep the root names, every channel carries the
QoS its publisher offers (read by rosbags, an independent reader), and a log mixing two robots'
namespaces is refused by every reader in one line."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from gyro_sim import load_scene
from gyro_sim.log.mcap_log import LogError, LogWriter
from gyro_sim.msgs import messages as M

from test.conftest import SCENE, gyro_sim


def _channels(path) -> dict:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return {c.topic: c for c in make_reader(f).get_summary().channels.values()}


def test_offline_log_keeps_the_root_names(recorded):
    path, _ = recorded
    topics = set(_channels(path))
    assert {"/joint_states", "/robot_description", "/gyro_sim/axis_moments", "/gyro_sim/poses", "/tf", "/clock",
            "/diagnostics"} <= topics
    assert M.log_topic_names(topics) == M.ROOT_TOPICS


def test_every_channel_carries_its_publishers_qos_as_rosbag2_writes_it(recorded):
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability, QosHistory, QosReliability

    path, _ = recorded
    for topic, ch in _channels(path).items():
        (profile,) = yaml.safe_load(ch.metadata["offered_qos_profiles"])
        assert set(profile) == {"history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                                "liveliness_lease_duration", "avoid_ros_namespace_conventions"}, topic
    with AnyReader([Path(path)]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        count = sum(1 for conn, _, raw in reader.messages() if reader.deserialize(raw, conn.msgtype) is not None)
    assert count > 0
    for topic, profiles in qos.items():
        (q,) = profiles
        latched = topic == "/robot_description"
        assert q.history == QosHistory.KEEP_LAST and q.reliability == QosReliability.RELIABLE, topic
        assert q.durability == (QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE), topic
        assert q.depth == (1 if latched else 10), topic


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """A log holding the joint states of two namespaces (two robots' topics in one file)."""
    from gyro_sim.log.record import run_params
    from gyro_sim.simulator import Simulator

    path = tmp_path_factory.mktemp("mixed") / "mixed.mcap"
    scene = load_scene(SCENE)
    sim = Simulator(scene, integrator="rk4", backend="numpy")
    with LogWriter(path, scene=scene, params=run_params(sim, advance_dt=0.01, publish_rate=10.0, source="test")) as w:
        for ns in ("/robot1", "/robot2"):
            pub = M.Publication(sim.model.names, topics=M.TopicNames(ns, f"{ns}/gyro_sim"))
            for topic, msgtype, data in pub.messages(sim.snapshot(), 0):
                w.write_raw(w.add_channel(topic, msgtype), 0, data)
    return path


@pytest.mark.slow
def test_a_log_mixing_two_robots_is_refused_in_one_line(mixed):
    from gyro_sim.log.record import read_schedule
    from gyro_sim.log.resim import resimulate
    readers = [resimulate, lambda p: read_schedule(p, ["wheel2", "arm3", "arm4"])]
    try:
        import rerun as rr

        from gyro_sim.viz.rerun_view import build_recording

        readers.append(lambda p: build_recording(p, rr.RecordingStream("gyro_sim_test")))
    except ImportError:  # the view needs rerun-sdk (pip install '.[viz]')
        pass
    for read in readers:
        with pytest.raises((LogError, ValueError), match="joint states of 2 namespaces") as exc:
            read(mixed)
        assert "\n" not in str(exc.value)
    r = gyro_sim("replay", "--resimulate", mixed)
    assert r.returncode == 2 and "2 namespaces" in r.stderr and "Traceback" not in r.stderr


def test_log_topic_names_of_a_namespaced_node():
    names = M.log_topic_names(["/robot1/joint_states", "/robot1/robot_description", "/robot1/gyro_sim/axis_moments",
                               "/robot1/gyro_sim/wrench/arm1", "/tf", "/clock", "/diagnostics"])
    assert (names.namespace, names.node) == ("/robot1", "/robot1/gyro_sim")
    assert names.events == "/robot1/gyro_sim/events" and names.joint_states == "/robot1/joint_states"
    assert names.status_name(M.RUN_STATUS) == "robot1/gyro_sim: run"
    assert M.ROOT_TOPICS.status_name(M.RUN_STATUS) == M.RUN_STATUS


def test_replay_offers_the_robot_description_transient_local(recorded):
    from gyro_sim.ros.replay import recorded_durability

    path, _ = recorded
    durability = {t: recorded_durability(c.metadata) for t, c in _channels(path).items()}
    assert durability.pop("/robot_description") == "transient_local"
    assert set(durability.values()) == {"volatile"}
    assert recorded_durability({}) == "" and recorded_durability({"offered_qos_profiles": "[: not yaml"}) == ""
