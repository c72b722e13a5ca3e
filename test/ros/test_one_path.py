"""One message path: a node log and an offline log of the same run hold the same things.

The node runs the hinge chain over real DDS with recording while this test sends a step and a
sine on every axis; then `gyro-sim run --record` runs the same scene with the same commands
(taken from the node's log, at the log times they took effect). Both logs must have the same
topics and types, the same diagnostics keys (numbers where numbers), the same rerun entities
(`gyro-sim view --save`, read back with rerun's own reader), and the same joint states at
matching stamps.
"""
from __future__ import annotations

import math
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")
rr = pytest.importorskip("rerun", reason="the view needs rerun-sdk (pip install '.[viz]')")

from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import iter_messages, read_info

from .helpers import DISCOVERY_TIMEOUT, Client, NodeProcess, new_domain_id, ros_env, wait_for

#: these tests share real nodes over DDS, started for the module (seconds each): outside the fast lane
pytestmark = pytest.mark.slow

DURATION = 3.0
STEP_AT = 1.0


def command(t: float) -> list[float]:
    """wheel2, arm3, arm4 (N m): a step at STEP_AT plus a sine, different on each axis."""
    step = 1.0 if t >= STEP_AT else 0.0
    return [0.002 * step + 0.001 * math.sin(4.0 * t), -0.04 * step + 0.03 * math.sin(3.0 * t),
            0.03 * step + 0.02 * math.cos(5.0 * t)]


def diagnostics_keys(path) -> tuple[set, dict]:
    """Keys of the dynamics status, and every (key, value) of both statuses."""
    keys, values = None, {}
    for _, _, _, msg in iter_messages(path, [M.DIAGNOSTICS]):
        for st in msg.status:
            if st.name == M.DYNAMICS_STATUS:
                k = {kv.key for kv in st.values}
                keys = k if keys is None else keys | k
            for kv in st.values:
                values.setdefault(kv.key, []).append(kv.value)
    return keys, values


def joint_states(path) -> dict:
    return {t: (list(m.name), np.array(m.position), np.array(m.velocity))
            for _, _, t, m in iter_messages(path, [M.JOINT_STATES])}


def rerun_entities(rrd) -> set:
    """Entity paths with data in a .rrd, read with rerun's own chunk reader."""
    from rerun.chunk import RrdReader

    return {str(c.entity_path) for c in RrdReader(rrd).stream()}


@pytest.fixture(scope="module")
def logs(module_tmp):
    node_log, offline_log = module_tmp / "node.mcap", module_tmp / "offline.mcap"
    domain = new_domain_id()
    client = Client(domain)
    js = client.subscribe("/joint_states", JointState)
    # no duration: discovery may take seconds, and the node must outlive it; stopped by SIGINT
    node = NodeProcess(module_tmp, domain, "scene:=hinge_chain", "integrator:=rk4", "physics_rate:=1000.0",
                       "publish_rate:=100.0", "command_timeout:=100.0", f"record:={node_log}")
    try:
        wait_for(lambda: js or not node.alive(), DISCOVERY_TIMEOUT, "first /joint_states")
        assert node.alive(), node.stderr
        pub = client.publisher("/gyro_sim/axis_moments", Float64MultiArray)
        t_first = None
        while node.alive():
            msgs = client.messages("/joint_states")
            t = msgs[-1][1].header.stamp.sec + msgs[-1][1].header.stamp.nanosec * 1e-9
            t_first = t if t_first is None else t_first
            if t > t_first + DURATION:  # DURATION s of commands, however long discovery took
                break
            pub.publish(Float64MultiArray(data=command(t)))
            time.sleep(0.02)
    finally:
        client.close()
        rc = node.stop()
    assert rc == 0, node.stderr
    env = ros_env(domain, module_tmp)
    last = max(joint_states(node_log))  # the offline run covers the node's whole log
    run = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", "hinge_chain", "--integrator", "rk4",
                          "--step", "0.001", "--chunk", "0.001", "--duration", f"{last * 1e-9:.2f}",
                          "--commands", str(node_log), "--record", str(offline_log)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return node_log, offline_log


def test_same_topics_and_types(logs):
    node_log, offline_log = logs
    a, b = read_info(node_log).topics, read_info(offline_log).topics
    a.pop(M.EVENTS, None)  # events only where something happened
    b.pop(M.EVENTS, None)
    assert a == b
    assert {M.JOINT_STATES, M.TF, M.DIAGNOSTICS, M.CLOCK, M.POSES, M.AXIS_MOMENTS, "/gyro_sim/wrench/arm1"} <= set(a)


def test_same_diagnostics_keys_all_numeric_where_numeric(logs):
    node_log, offline_log = logs
    ka, va = diagnostics_keys(node_log)
    kb, vb = diagnostics_keys(offline_log)
    assert ka == kb
    assert {M.BALANCE_REL_KEY, M.WORK_KEY, "angular_momentum_O1_x_Nms", "energy_drift_rel"} <= ka
    for values in (va, vb):
        for key, vs in values.items():
            if key not in M.STRING_KEYS:
                assert all(math.isfinite(float(v)) for v in vs), (key, vs[:3])
    # the node's run status: figures a user plots are numbers too
    for key in ("real_time_factor_achieved", "step_time_p50_us", "deadline_misses", "commands_accepted"):
        assert key in va and all(math.isfinite(float(v)) for v in va[key]), key
    # the commands did work and the balance kept: the energy drift is the work, not an error
    work = max(abs(float(v)) for v in va[M.WORK_KEY])
    balance = max(abs(float(v)) for v in va[M.BALANCE_REL_KEY])
    assert work > 1e-4 and balance < 1e-6, (work, balance)


def test_joint_states_agree_at_matching_stamps(logs):
    node_log, offline_log = logs
    a, b = joint_states(node_log), joint_states(offline_log)
    common = sorted(set(a) & set(b))
    assert len(common) >= 100 * DURATION, len(common)
    worst = 0.0
    for t in common:
        assert a[t][0] == b[t][0]
        worst = max(worst, float(np.max(np.abs(a[t][1] - b[t][1]))), float(np.max(np.abs(a[t][2] - b[t][2]))))
    assert worst <= 1e-9, worst


def test_same_rerun_entities(logs, module_tmp):
    node_log, offline_log = logs
    got = {}
    for name, log in (("node", node_log), ("offline", offline_log)):
        rrd = module_tmp / f"{name}.rrd"
        r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "view", str(log), "--save", str(rrd)],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        got[name] = rerun_entities(rrd)
    assert got["node"] == got["offline"]
    for entity in ("/world/angular_momentum", "/plots/rotor_rate/wheel2", "/plots/balance/energy_balance",
                   "/world/arm1/wrench/force", "/plots/axis_moments/arm3"):
        assert entity in got["node"], (entity, sorted(got["node"]))
