"""The node over real DDS, one node process for the module (hinge chain, physics 250 Hz).

The node reads its parameters from a params file, with publish_rate overridden on the
command line. The rates (physics 100 Hz, publish 20 Hz) are kept low enough for a loaded
2-core machine to hold real time with the numpy core (about 1 ms per RK4 step of this chain);
`gyro-sim bench realtime` measures the 1 kHz / 100 Hz configuration.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from gyro_sim.simulator import Simulator
from gyro_sim.paths import find_scene

from .helpers import (
    DISCOVERY_TIMEOUT, Client, NodeProcess, all_finite, diag_values, new_domain_id, stamp_ns, stamp_s, wait_for,
)

#: these tests share real nodes over DDS, started for the module (seconds each): outside the fast lane
pytestmark = pytest.mark.slow

SCENE = "hinge_chain"
PHYSICS_RATE = 100.0
PUBLISH_RATE = 20.0  # from the command line; the file says 10
DT = 1.0 / PHYSICS_RATE
BODIES = ("arm1", "arm2", "arm3", "arm4")
COMMAND = [0.002, 0.05, -0.03]  # wheel2, arm3, arm4 (N m)
TIMEOUT = 0.5

PARAMS_FILE = f"""
gyro_sim:
  ros__parameters:
    scene: {SCENE}
    physics_rate: {PHYSICS_RATE}
    publish_rate: 10.0
    real_time_factor: 1.0
    integrator: rk4
    command_timeout: {TIMEOUT}
"""

TOPICS = {
    "/joint_states": JointState,
    "/clock": Clock,
    "/diagnostics": DiagnosticArray,
    "/gyro_sim/poses": PoseArray,
    **{f"/gyro_sim/wrench/{b}": WrenchStamped for b in BODIES},
}


@pytest.fixture(scope="module")
def ros(module_tmp):
    domain = new_domain_id()
    pfile = module_tmp / "params.yaml"
    pfile.write_text(PARAMS_FILE)
    client = Client(domain)
    for topic, typ in TOPICS.items():
        client.subscribe(topic, typ, depth=1000)
    node = NodeProcess(module_tmp, domain, f"publish_rate:={PUBLISH_RATE}", params_file=pfile)
    try:
        wait_for(lambda: client.messages("/joint_states") or not node.alive(), DISCOVERY_TIMEOUT, "first /joint_states")
        assert node.alive(), node.stderr
        client.cmd = client.publisher("/gyro_sim/axis_moments", Float64MultiArray)
        yield node, client
    finally:
        client.close()
        rc = node.stop()
        assert rc == 0, node.stderr
        assert "gyro_sim_node: simulated" in node.stdout


def latest_diag(client, after_wall: float = 0.0, cond=lambda v: True, timeout: float = 10.0, with_wall=False):
    """Values of the first /diagnostics received after `after_wall` satisfying `cond`."""

    def find():
        for wall, msg in client.messages("/diagnostics"):
            v = diag_values(msg)
            if wall > after_wall and v and cond(v):
                return (wall, v)
        return None

    wall, v = wait_for(find, timeout, "diagnostics")
    return (wall, v) if with_wall else v


def received_after(client, topic: str, wall: float) -> list:
    return [m for w, m in client.messages(topic) if w > wall]


def reference_sim() -> Simulator:
    return Simulator(find_scene(SCENE), integrator="rk4", step=DT)


def offline_positions(t0: float, schedule: list[tuple[float, list]], stamps: list[float]) -> dict:
    """Joint positions at `stamps` (node times) of the core started from the initial state at
    node time t0, commands changed at the node times of `schedule` (zero before the first)."""
    sim = reference_sim()
    k_of = {round((s - t0) / DT): s for s in stamps}
    changes = {round((t - t0) / DT): v for t, v in schedule}
    out = {}
    for k in range(max(k_of) + 1):
        if k in k_of:
            out[k_of[k]] = np.array(sim.joint_states().position)
        if k in changes:
            sim.set_axis_moments(changes[k])
        sim.advance(DT)
    return out


def node_time_of(message: str) -> float:
    """'... at node time 12.340000 s' -> 12.34"""
    return float(message.split("node time")[1].split()[0])


def test_params_file_and_override_honoured(ros):
    node, client = ros
    v = latest_diag(client)
    assert float(v["physics_rate_Hz"]) == 100.0  # file
    assert float(v["publish_rate_Hz"]) == 20.0  # -p wins over the file
    assert v["integrator"] == "rk4"
    assert [k for k in v if k.startswith("axis_moment_")] == [f"axis_moment_{a}_Nm" for a in ("wheel2", "arm3", "arm4")]


def test_the_node_says_how_its_physics_thread_is_scheduled(ros):
    """thread_priority defaults to 50: SCHED_FIFO where the system allows it, else the normal
    scheduler with the reason; the start-up log and /diagnostics agree on which."""
    node, client = ros
    prio = int(latest_diag(client)["physics_thread_priority"])
    line = wait_for(lambda: [x for x in (node.stderr + node.stdout).splitlines() if "physics thread:" in x],
                    5.0, "the physics thread's scheduling line")[0]
    if prio:
        assert prio == 50 and line.endswith("physics thread: SCHED_FIFO priority 50"), line
    else:
        assert "normal scheduler: SCHED_FIFO priority 50 refused" in line, line


def test_joint_states_rate_names_and_stamps(ros):
    node, client = ros
    t0 = time.monotonic()
    wait_for(lambda: time.monotonic() - t0 > 3.0 and len(received_after(client, "/joint_states", t0)) > 10, 15.0,
             "3 s of /joint_states")
    msgs = [(w, m) for w, m in client.messages("/joint_states") if w > t0]
    walls = np.array([w for w, _ in msgs])
    # wall time on purpose (rate and real-time factor within 10 %): the real node's pace through
    # DDS on a shared machine; the pacing's arithmetic is checked exactly on a fake clock
    # (test_pacing.py)
    rate = (len(msgs) - 1) / (walls[-1] - walls[0])
    assert abs(rate - PUBLISH_RATE) < 0.1 * PUBLISH_RATE, rate
    assert list(msgs[0][1].name) == reference_sim().joint_states().name
    ns = np.array([stamp_ns(m) for _, m in msgs])
    assert np.all(np.abs(np.diff(ns) - 1e9 / PUBLISH_RATE) <= 1), "stamps every 1/publish_rate of simulated time"
    assert ns[0] < 600e9, "stamps are simulated time since the start, not wall time"
    sim_span, wall_span = (ns[-1] - ns[0]) * 1e-9, walls[-1] - walls[0]
    assert abs(sim_span / wall_span - 1.0) < 0.1, (sim_span, wall_span)
    clocks = {c.clock.sec * 1_000_000_000 + c.clock.nanosec for _, c in client.messages("/clock")}
    assert set(ns[:-2]) <= clocks, "/clock carries the same simulated time"


def test_commanded_hinge_chain_moves_as_the_core_predicts(ros):
    """Reset, then a constant command (sent repeatedly) until the timeout zeroes it: the node's
    joint positions agree with the core run offline on the same command sequence to 1e-9;
    effort shows the moments applied over the step ending at each stamp."""
    node, client = ros
    resp = client.call(Trigger, "/gyro_sim/reset", Trigger.Request())
    assert resp.success, resp.message
    t_reset = node_time_of(resp.message)
    wall0 = time.monotonic()

    def effort_is(values):
        return [m for m in received_after(client, "/joint_states", wall0) if list(m.effort[-3:]) == values]

    # send the command until the node applies it, and 1 s more
    while not effort_is(COMMAND):
        client.cmd.publish(Float64MultiArray(data=COMMAND))
        time.sleep(0.05)
        assert time.monotonic() - wall0 < DISCOVERY_TIMEOUT, "command never applied"
    first = stamp_s(effort_is(COMMAND)[0])
    while stamp_s(received_after(client, "/joint_states", wall0)[-1]) < first + 1.0:
        client.cmd.publish(Float64MultiArray(data=COMMAND))
        time.sleep(0.05)
    v = latest_diag(client, cond=lambda v: float(v["node_time_s"]) > first and v["moments_applied_since_s"] != "")
    t_cmd = float(v["moments_applied_since_s"])
    # stop sending: the timeout brings the moments back to zero
    wall_stop = time.monotonic()
    wait_for(lambda: [m for m in received_after(client, "/joint_states", wall_stop)
                      if list(m.effort[-3:]) == [0.0] * 3], 10.0, "effort back to zero after the command timeout")
    v = latest_diag(client, after_wall=wall_stop,
                    cond=lambda v: int(v["command_timeouts"]) >= 1 and float(v["moments_applied_since_s"]) > t_cmd)
    t_zero, t_last = float(v["moments_applied_since_s"]), float(v["last_command_effective_s"])
    # zero from the first step starting more than command_timeout (simulated s) after the last good command
    assert t_zero - t_last == pytest.approx((math.floor(TIMEOUT / DT + 1e-9) + 1) * DT, abs=1e-9)

    msgs = [m for m in received_after(client, "/joint_states", wall0) if t_reset < stamp_s(m) < t_zero + 0.5]
    stamps = [stamp_s(m) for m in msgs]
    assert t_reset < t_cmd < first <= t_cmd + 1.0 / PUBLISH_RATE
    pred = offline_positions(t_reset, [(t_cmd, COMMAND), (t_zero, [0.0] * 3)], stamps)
    worst = max(float(np.max(np.abs(np.array(m.position) - pred[s]))) for m, s in zip(msgs, stamps))
    assert worst < 1e-9, worst
    assert any(s > t_zero for s in stamps) and any(t_cmd < s <= t_zero for s in stamps)
    for m, s in zip(msgs, stamps):  # effort: the moments applied over the step ending at the stamp
        expect = COMMAND if t_cmd < s - DT / 2 < t_zero else [0.0] * 3
        assert list(m.effort[-3:]) == expect, (s, list(m.effort), t_cmd, t_zero)


def test_wrenches_and_poses(ros):
    node, client = ros
    for b in BODIES:
        msgs = wait_for(lambda b=b: client.messages(f"/gyro_sim/wrench/{b}"), 10.0, f"wrench of {b}")
        m = msgs[-1][1]
        assert m.header.frame_id == b
        assert all_finite(m) and stamp_ns(m) % int(1e9 / PUBLISH_RATE) == 0
    poses = wait_for(lambda: client.messages("/gyro_sim/poses"), 10.0, "poses")[-1][1]
    assert poses.header.frame_id == "world" and len(poses.poses) == len(BODIES)
    q = poses.poses[0].orientation
    assert math.isclose(q.w**2 + q.x**2 + q.y**2 + q.z**2, 1.0, rel_tol=1e-9)
    assert poses.poses[0].position.z == pytest.approx(1.0)  # O^1 = the base position


def test_bad_commands_rejected_node_keeps_rate(ros):
    node, client = ros
    before = int(latest_diag(client)["commands_rejected"])
    bad = [[1.0], [], [math.nan, 0.0, 0.0], [0.0, math.inf, 0.0], [0.0, 0.0, -math.inf], [1.0] * 4]
    for d in bad:
        client.cmd.publish(Float64MultiArray(data=d))
    for i in range(10_000):  # a burst at once
        client.cmd.publish(Float64MultiArray(data=bad[i % len(bad)]))
    wall = time.monotonic()
    v = latest_diag(client, after_wall=wall, cond=lambda v: int(v["commands_rejected"]) >= before + len(bad))
    assert node.alive()
    assert all(float(v[f"axis_moment_{a}_Nm"]) == 0.0 for a in ("wheel2", "arm3", "arm4")), \
        "the last good command (none: timed out) stays in force"
    wait_for(lambda: time.monotonic() - wall > 3.0, 6.0, "3 s after the burst")
    msgs = received_after(client, "/joint_states", wall)
    walls = [w for w, _ in client.messages("/joint_states") if w > wall]
    rate = (len(walls) - 1) / (walls[-1] - walls[0])
    assert abs(rate - PUBLISH_RATE) < 0.1 * PUBLISH_RATE, rate
    assert all(list(m.effort) == [0.0] * len(m.effort) for m in msgs)
    for topic in TOPICS:
        assert all(all_finite(m) for _, m in client.messages(topic)), f"non-finite value on {topic}"
    assert "rejected" in node.err_path.read_text() + node.out_path.read_text()


def test_pause_and_reset(ros):
    node, client = ros
    resp = client.call(SetBool, "/gyro_sim/pause", SetBool.Request(data=True))
    assert resp.success, resp.message
    t_pause, wall = node_time_of(resp.message), time.monotonic()
    # two diagnostics (1 s apart) while paused: no joint state beyond the pause, time frozen
    w1, v1 = latest_diag(client, after_wall=wall, cond=lambda v: v["state"] == "paused", with_wall=True)
    v2 = latest_diag(client, after_wall=w1, cond=lambda v: v["state"] == "paused")
    assert float(v1["node_time_s"]) == float(v2["node_time_s"]) == pytest.approx(t_pause)
    assert all(stamp_s(m) <= t_pause + 1e-9 for m in received_after(client, "/joint_states", wall))
    # reset while paused, then resume: the motion restarts from the scene's initial state
    resp = client.call(Trigger, "/gyro_sim/reset", Trigger.Request())
    assert resp.success, resp.message
    t_reset = node_time_of(resp.message)
    assert t_reset == pytest.approx(t_pause)
    wall = time.monotonic()
    resp = client.call(SetBool, "/gyro_sim/pause", SetBool.Request(data=False))
    assert resp.success and "running" in resp.message
    msgs = wait_for(lambda: received_after(client, "/joint_states", wall)[:5] if len(
        received_after(client, "/joint_states", wall)) >= 5 else None, 10.0, "joint states after resume")
    stamps = [stamp_s(m) for m in msgs]
    assert stamps[0] > t_reset and np.all(np.diff(stamps) > 0)
    pred = offline_positions(t_reset, [], stamps)
    for m, s in zip(msgs, stamps):
        assert np.max(np.abs(np.array(m.position) - pred[s])) < 1e-9


def test_gyro_sim_cmd_publishes_commands(ros):
    """`gyro-sim cmd` (no ros2 CLI here) drives the node; its command shows in the effort."""
    import subprocess
    import sys

    from .helpers import ROOT

    node, client = ros
    wall = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "cmd", "--scene", SCENE, "--seconds", "1.0",
                        "--rate", "20", "constant", "0", "0.01", "0"], cwd=ROOT, env=node.env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "axes: wheel2, arm3, arm4" in r.stdout
    assert any(list(m.effort[-3:]) == [0.0, 0.01, 0.0] for m in received_after(client, "/joint_states", wall))


def test_simulation_error_stops_stepping_reports_and_reset_recovers(ros):
    """A command that makes the state blow up: stepping stops before any NaN is published,
    /diagnostics says ERROR, the node stays up, and ~/reset brings it back."""
    node, client = ros
    wall = time.monotonic()
    while True:
        client.cmd.publish(Float64MultiArray(data=[0.0, 1e300, 0.0]))  # finite, so accepted
        errors = [msg for w, msg in client.messages("/diagnostics") if w > wall
                  and any(st.level == b"\x02" and "simulation stopped" in st.message for st in msg.status)]
        if errors:
            break
        assert time.monotonic() - wall < DISCOVERY_TIMEOUT, "no ERROR on /diagnostics"
        time.sleep(0.05)
    assert node.alive()
    assert diag_values(errors[0])["state"] == "stopped: simulation error"
    for topic in TOPICS:
        assert all(all_finite(m) for _, m in client.messages(topic)), f"non-finite value on {topic}"
    resp = client.call(Trigger, "/gyro_sim/reset", Trigger.Request())
    assert resp.success, resp.message
    t_reset, wall = node_time_of(resp.message), time.monotonic()
    wait_for(lambda: [m for m in received_after(client, "/joint_states", wall) if stamp_s(m) > t_reset], 10.0,
             "joint states after the reset")
    latest_diag(client, after_wall=wall, cond=lambda v: v["state"] == "running")


def test_wrench_publishers_add_no_event_waitables_to_the_executor(tmp_path, monkeypatch):
    """The per-joint wrench publishers have no QoS event handlers (each would be a waitable in
    every wait set of the executor thread); the other topics keep rclpy's default ones."""
    import os
    from types import SimpleNamespace

    import rclpy

    from gyro_sim.msgs import messages as M
    from gyro_sim.ros.outputs import Outputs

    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + os.getpid() % 50)
    try:
        node = rclpy.create_node("gyro_sim", context=context)
        sim = reference_sim()
        out = Outputs(node, sim, SimpleNamespace(publish_wrenches=True, publish_poses=True))
        assert len(out.wrench_topics) == len(BODIES)
        for topic in out.wrench_topics:
            assert out.pubs[topic].event_handlers == [], topic
        assert len(out.pubs[M.JOINT_STATES].event_handlers) > 0  # rclpy's defaults, as any publisher
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
