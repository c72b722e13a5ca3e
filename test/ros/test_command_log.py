"""Every command the node receives goes to its log: the good ones on ~/axis_moments (those
superseded before a step could apply them included, in the order received), the rejected ones
as events with their reason; counted against the node's own counters, read back with rosbags,
and the log still re-simulates bit for bit.

"Received": the node's intake is bounded (its executor yields most of the interpreter to the
physics thread, its subscription holds 10), so a fast sender can lose commands in DDS before
the node sees them; the node's counters say how many it received, and each sent command has
a unique value, so the log is checked against both."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool

from .helpers import DISCOVERY_TIMEOUT, Client, NodeProcess, diag_values, new_domain_id, wait_for

#: commands sent while running and while paused, in bursts (shorter than a physics step of 4 ms:
#: the later ones of a burst supersede the earlier) that fit the node's subscription depth (10)
RUNNING, PAUSED, BURST = 150, 30, 3
#: pause between bursts (s): the node's executor, which yields most of the interpreter to the
#: physics thread, takes a burst in a few ms
BURST_GAP = 0.03
#: rejected ones sent: wrong length, NaN
REJECTED = 10
#: first commands sent, one at a time, until the node counts one; how long to wait for each
#: (the diagnostics come once a simulated second)
PROBES, PROBE_WAIT = 10, 3.0


@pytest.mark.slow
def test_every_command_received_is_in_the_log(tmp_path):
    from rosbags.highlevel import AnyReader

    log, stats = tmp_path / "commands.mcap", tmp_path / "stats.json"
    domain = new_domain_id()
    client = Client(domain)
    diags = client.subscribe("/diagnostics", DiagnosticArray, depth=1000)
    node = NodeProcess(tmp_path, domain, "scene:=hinge_chain", "physics_rate:=250.0", "publish_rate:=50.0",
                       "command_timeout:=100.0", f"record:={log}", f"stats_file:={stats}")
    sent = []  # the second value of each good command, in the order sent (unique)

    def counted():
        if not client.messages("/diagnostics"):
            return 0
        v = diag_values(client.messages("/diagnostics")[-1][1])
        return int(v.get("commands_accepted", 0)) + int(v.get("commands_rejected", 0))

    def stable():
        msgs = client.messages("/diagnostics")
        keys = ("commands_accepted", "commands_rejected")
        return len(msgs) > 2 and all(diag_values(msgs[-1][1]).get(k) == diag_values(msgs[-3][1]).get(k) for k in keys)

    def send(pub, n, bad: bool = False):
        for i in range(n):
            if bad:
                data = [1.0] if i % 2 else [math.nan, 0.0, 0.0]
            else:
                sent.append(1e-5 * (len(sent) + 1))
                data = [0.0, sent[-1], 0.0]
            pub.publish(Float64MultiArray(data=data))
            if i % BURST == BURST - 1:
                time.sleep(BURST_GAP)

    try:
        wait_for(lambda: diags or not node.alive(), DISCOVERY_TIMEOUT, "a first /diagnostics")
        assert node.alive(), node.stderr[-3000:]
        pub = client.publisher("/gyro_sim/axis_moments", Float64MultiArray, depth=1000)
        # discovery is not symmetric (the publisher may see the node's subscription before the
        # node sees it): commands go on once the node has counted a first one
        for _ in range(PROBES):
            send(pub, 1)
            try:
                wait_for(lambda: counted() > 0 or not node.alive(), PROBE_WAIT, "a first command counted")
                break
            except AssertionError:
                continue
        assert counted() > 0, node.stderr[-3000:]
        send(pub, RUNNING)
        send(pub, REJECTED, bad=True)
        assert client.call(SetBool, "/gyro_sim/pause", SetBool.Request(data=True)).success
        send(pub, PAUSED)  # all but the last superseded: nothing steps while paused
        # everything in flight taken: two diagnostics (one a simulated second apart) agree
        wait_for(lambda: stable(), 30.0, "the node's counts to settle")
        assert client.call(SetBool, "/gyro_sim/pause", SetBool.Request(data=False)).success
        n = len(client.messages("/diagnostics"))
        wait_for(lambda: len(client.messages("/diagnostics")) > n + 1, 10.0, "the run going on")
        rc = node.stop()
    finally:
        client.close()
        node.stop()
    assert rc == 0, node.stderr[-3000:]
    st = json.loads(Path(stats).read_text())
    received = st["commands_accepted"]
    assert received > len(sent) // 2 and 0 < st["commands_rejected"] <= REJECTED, st
    assert st["commands_superseded"] > 0

    logged, rejected = [], []
    with AnyReader([log]) as reader:
        for conn, t, raw in reader.messages():
            if conn.topic == "/gyro_sim/axis_moments":
                logged.append((t, list(reader.deserialize(raw, conn.msgtype).data)))
            elif conn.topic == "/gyro_sim/events":
                text = reader.deserialize(raw, conn.msgtype).data
                if text.startswith("command rejected"):
                    rejected.append(text)
    values = [v[1] for _, v in logged]
    assert len(values) == received and set(values) <= set(sent)  # every good command received, once ...
    assert values == sorted(values)  # ... in the order sent
    assert len(rejected) == st["commands_rejected"] and set(rejected) <= {
        "command rejected (expected 3 values (one per axis), got 1)", "command rejected (holds NaN or inf)"}
    assert all(math.isfinite(x) for _, v in logged for x in v)

    from gyro_sim.log import resim

    r = resim.resimulate(log)
    assert r.commands == received and r.compared > 20
    assert r.max_deviation == 0.0, r.report()
