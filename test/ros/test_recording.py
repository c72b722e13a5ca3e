"""Live recording: SIGTERM (and SIGINT) during a recording leave an MCAP file that independent
readers (rosbags' AnyReader, mcap's own reader) read completely, with the exact wire bytes."""
from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from .helpers import DISCOVERY_TIMEOUT, Client, NodeProcess, new_domain_id, stamp_ns, wait_for

COMMAND = [0.001, 0.02, -0.01]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
@pytest.mark.slow
def test_signal_during_recording_leaves_a_complete_log(tmp_path, sig):
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    log = tmp_path / "live.mcap"
    domain = new_domain_id()
    client = Client(domain)
    received = client.subscribe("/joint_states", JointState, depth=1000)
    wire = client.subscribe("/joint_states", JointState, depth=1000, raw=True)
    node = NodeProcess(tmp_path, domain, "scene:=hinge_chain", "physics_rate:=250.0", "publish_rate:=50.0",
                       f"record:={log}")
    try:
        wait_for(lambda: (received and wire) or not node.alive(), DISCOVERY_TIMEOUT, "first /joint_states")
        assert node.alive(), node.stderr
        pub = client.publisher("/gyro_sim/axis_moments", Float64MultiArray)
        sent = 0
        while not any(list(m.effort[-3:]) == COMMAND for _, m in client.messages("/joint_states")):
            pub.publish(Float64MultiArray(data=COMMAND))
            sent += 1
            time.sleep(0.05)
            assert sent < 400, "command never applied"
        n0 = len(client.messages("/joint_states"))
        assert client.call(Trigger, "/gyro_sim/reset", Trigger.Request()).success
        wait_for(lambda: len(client.messages("/joint_states")) > n0 + 40, 20.0, "40 more joint states")
        rc = node.stop(sig)
    finally:
        client.close()
        node.stop()
    assert rc == 0, node.stderr
    assert f"log written: {log}" in node.stdout and f"rerun {log}" in node.stdout

    # rosbags: every record deserialises with the schemas stored in the file
    counts = {}
    with AnyReader([Path(log)]) as reader:
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic == "/joint_states":
                assert stamp_ns(msg) == t, "log time = simulated time = the stamp"
    for topic in ("/joint_states", "/clock", "/diagnostics", "/gyro_sim/poses", "/gyro_sim/wrench/arm1", "/tf",
                  "/gyro_sim/axis_moments", "/gyro_sim/events"):
        assert counts.get(topic, 0) > 0, (topic, counts)
    assert counts["/gyro_sim/axis_moments"] <= sent

    # mcap's reader: summary written on close, the scene embedded, the exact bytes received
    with open(log, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == sum(counts.values())
        assert any(a.name == "scene.yaml" for a in reader.iter_attachments())
        events = [bytes(m.data) for _, ch, m in reader.iter_messages(topics=["/gyro_sim/events"])]
        assert any(b"reset" in e for e in events)
        logged = {m.log_time: bytes(m.data) for _, ch, m in reader.iter_messages(topics=["/joint_states"])}
    wire = [raw for _, raw in client.messages("/joint_states raw")]
    assert len(wire) > 20, (len(wire), len(client.messages("/joint_states")))
    for raw in wire:  # the exact bytes (CDR alignment padding is not zeroed: compare bytes, not re-serialised)
        m = deserialize_message(raw, JointState)
        assert logged[stamp_ns(m)] == raw

    # the log keeps the re-simulation contract (gyro_sim.log.record): the core, fed the recorded
    # commands and the reset, reproduces every logged joint state bit for bit
    from gyro_sim.log import resim
    r = resim.resimulate(log)
    assert r.compared > 20 and r.resets == 1 and r.commands > 0
    assert r.max_deviation == 0.0, r.report()
