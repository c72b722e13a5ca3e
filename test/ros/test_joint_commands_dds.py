"""~/joint_commands over DDS: a servo pendulum in lock-step (`lockstep:=true`) tracks a position
target a client sends by joint name after each joint state, as a topic-based ros2_control
hardware interface would; it settles where the servo balances gravity, every command is in the
log on ~/joint_commands, and the log re-simulates bit for bit."""
from __future__ import annotations

import json
import math
import time

import pytest
from scipy.optimize import brentq

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from sensor_msgs.msg import JointState

from .helpers import Client, NodeProcess, new_domain_id, wait_for
from .test_joint_commands import G_, KP, L_, M_, TARGET, scene_file

#: simulated seconds of the closed loop (at 100 Hz: 200 commands)
SECONDS = 2.0


@pytest.mark.slow
def test_a_servo_tracks_a_position_target_sent_on_joint_commands_in_lockstep(tmp_path):
    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.log.resim import resimulate

    log, stats = tmp_path / "loop.mcap", tmp_path / "stats.json"
    domain = new_domain_id()
    node = NodeProcess(tmp_path, domain, f"scene:={scene_file(tmp_path)}", "lockstep:=true",
                       f"duration:={SECONDS}", f"record:={log}", f"stats_file:={stats}")
    client = Client(domain)
    try:
        states = client.subscribe("/joint_states", JointState)
        pub = client.publisher("/gyro_sim/joint_commands", JointState)
        answered = 0
        deadline = time.monotonic() + 300
        while node.alive() and time.monotonic() < deadline:
            if len(client.messages("/joint_states")) > answered:  # answer each state with the target
                answered = len(client.messages("/joint_states"))
                msg = JointState()
                msg.name, msg.position = ["arm"], [TARGET]
                pub.publish(msg)
            time.sleep(0.002)
        wait_for(lambda: not node.alive(), 60, "the node's lock-step run to its end")
        assert states
    finally:
        client.close()
        rc = node.stop()
    assert rc == 0, node.stderr
    s = json.loads(stats.read_text())
    assert s["node_time_s"] == pytest.approx(SECONDS)
    commands = list(iter_messages(log, ["/gyro_sim/joint_commands"]))
    assert len(commands) >= round(SECONDS * 100)
    assert all(list(m.name) == ["arm"] and list(m.position) == [TARGET] for _, _, _, m in commands)
    rows = [(t, m.position[list(m.name).index("arm")]) for _, _, t, m in iter_messages(log, ["/joint_states"])]
    mgl = G_ * (M_ * L_ + 1e-3 * 2 * L_)
    phi = brentq(lambda q: KP * (TARGET - q) - mgl * math.sin(q), 0.0, TARGET)
    assert abs(rows[-1][1] - phi) < 1e-6, rows[-5:]
    r = resimulate(log)
    assert r.max_deviation == 0.0 and r.commands == len(commands) and r.compared == len(rows)
