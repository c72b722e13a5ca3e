"""The LQR example over DDS: the simulator node and examples/lqr_balance.py in their own
processes, 20 s of real time. A smoke test with a looser bound than the lockstep test
(test/examples/test_lqr_balance.py): upright the whole time, no command timeout; the node's
log of the closed loop re-simulates bit for bit."""
from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from .helpers import (
    DISCOVERY_TIMEOUT,
    Client,
    NodeProcess,
    diag_values,
    new_domain_id,
    stamp_s,
    wait_for,
)

ROOT = Path(__file__).resolve().parents[2]
SECONDS = 20.0


@pytest.mark.slow
def test_the_lqr_example_holds_the_pendulum_up_over_dds(tmp_path):
    domain = new_domain_id()
    client = Client(domain)
    client.subscribe("/joint_states", JointState, depth=5000)
    client.subscribe("/diagnostics", DiagnosticArray, depth=1000)
    log = tmp_path / "loop.mcap"
    node = NodeProcess(tmp_path, domain, "scene:=rw_pendulum", "duration:=0.0", f"record:={log}")
    ctrl_out = (tmp_path / "ctrl.out").open("w")
    ctrl = subprocess.Popen([sys.executable, str(ROOT / "examples" / "lqr_balance.py"),
                             "--duration", str(SECONDS + 60)],
                            cwd=tmp_path, env=node.env, stdout=ctrl_out, stderr=subprocess.STDOUT)
    try:
        def wheel_commanded():  # the controller's commands reach the node: the wheel's effort moves
            return any(m.effort[list(m.name).index("wheel")] != 0.0 for _, m in client.messages("/joint_states")[-50:])

        wait_for(lambda: (node.alive() and ctrl.poll() is None and wheel_commanded()) or not node.alive()
                 or ctrl.poll() is not None, 4 * DISCOVERY_TIMEOUT, "the controller's first commands")
        assert node.alive(), node.stderr
        assert ctrl.poll() is None, (tmp_path / "ctrl.out").read_text()
        # back to the scene's 0.1 rad tilt with the loop closed, and 20 s from there
        client.call(Trigger, "/gyro_sim/reset", Trigger.Request())
        wall0 = time.monotonic()
        time.sleep(SECONDS)
        wall1 = time.monotonic()  # the controller stops below: what comes after is not its doing
        assert node.alive() and ctrl.poll() is None, node.stderr
    finally:
        ctrl.terminate()
        ctrl.wait(20)
        ctrl_out.close()
        rc = node.stop()
        client.close()
    assert rc == 0, node.stderr
    after = [m for w, m in client.messages("/joint_states") if wall0 + 0.5 < w < wall1]
    i = list(after[0].name).index("pendulum")
    settled = [m for m in after if stamp_s(m) >= 3.0]
    assert stamp_s(after[-1]) > 0.5 * SECONDS and len(settled) > 100  # a loaded machine runs behind real time
    worst = max(abs(m.position[i]) for m in settled)
    assert worst < 0.1, f"the pendulum left upright: |angle| {worst:.3f} rad"
    assert all(math.isfinite(m.position[i]) for m in after)
    last = diag_values([m for w, m in client.messages("/diagnostics") if w < wall1][-1])
    assert last.get("command_timeouts") == "0", last
    from gyro_sim.log.resim import resimulate

    out = resimulate(log)
    assert out.max_deviation == 0.0, out.report()
