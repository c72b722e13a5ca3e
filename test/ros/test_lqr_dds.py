"""The LQR example over DDS in the README's order: the simulator node started first, in
lock-step, the controller (examples/lqr_balance.py) a few seconds later in its own process.
In lock-step the node advances one control period per command, so the closed loop's outcome
cannot depend on the machine's load: the pendulum, held at its initial 0.1 rad tilt until the
first command, is balanced within 0.01 rad from 1 s on, every period's command is counted, and
the node's log re-simulates bit for bit."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from .helpers import NodeProcess, new_domain_id, wait_for

ROOT = Path(__file__).resolve().parents[2]
#: simulated seconds of the closed loop (at 100 Hz: 500 commands)
SECONDS = 5.0
#: the controller starts this long (wall s) after the node, as a user would start it
LATE = 3.0


@pytest.mark.slow
def test_the_lqr_example_started_after_the_node_balances_in_lockstep(tmp_path):
    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.log.resim import resimulate

    log, stats = tmp_path / "loop.mcap", tmp_path / "stats.json"
    node = NodeProcess(tmp_path, new_domain_id(), "scene:=rw_pendulum", "lockstep:=true", f"duration:={SECONDS}",
                       f"record:={log}", f"stats_file:={stats}")
    time.sleep(LATE)
    ctrl_out = (tmp_path / "ctrl.out").open("w")
    ctrl = subprocess.Popen([sys.executable, str(ROOT / "examples" / "lqr_balance.py"), "--duration", "600"],
                            cwd=tmp_path, env=node.env, stdout=ctrl_out, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: not node.alive() or ctrl.poll() is not None, 600, "the node's lock-step run to its end")
    finally:
        ctrl.terminate()
        ctrl.wait(20)
        ctrl_out.close()
        rc = node.stop()
    assert rc == 0, node.stderr + (tmp_path / "ctrl.out").read_text()
    s = json.loads(stats.read_text())
    periods = round(SECONDS * 100)
    assert s["node_time_s"] == pytest.approx(SECONDS) and s["steps"] == 10 * periods
    assert s["commands_superseded"] == 0
    # one command per period, each logged at its period's start (the answer to the final state,
    # if it came before the node ended, at the end: never applied); no timeout
    end_ns = round(SECONDS * 1e9)
    applied = [t for _, _, t, _ in iter_messages(log, ["/gyro_sim/axis_moments"], decode=False) if t < end_ns]
    assert applied == [k * 10_000_000 for k in range(periods)]
    events = [m.data for _, _, _, m in iter_messages(log, ["/gyro_sim/events"])]
    assert not [e for e in events if "timeout" in e], events
    rows = np.array([(t * 1e-9, m.position[list(m.name).index("pendulum")])
                     for _, _, t, m in iter_messages(log, ["/joint_states"])])
    assert len(rows) == periods + 1 and np.all(np.diff(rows[:, 0]) > 0)
    assert rows[0, 1] == pytest.approx(0.1)  # held at the initial tilt until the controller came
    worst = np.abs(rows[rows[:, 0] >= 1.0, 1]).max()
    assert worst < 0.01, f"the pendulum left upright: |angle| {worst:.4f} rad"
    out = resimulate(log)
    assert out.max_deviation == 0.0 and out.compared == periods + 1, out.report()
