"""`gyro-sim cmd joints`: the servos' targets by joint name on ~/joint_commands. Refusals
(unknown joint, a joint no servo drives, the wrong entry for its servo, malformed items) before
anything is published, exit 2 naming the joint; over DDS a lock-step node takes the one
command sent with --once for one control period, logs it as sent, and the log re-simulates bit
for bit."""
from __future__ import annotations

import subprocess
import sys

import pytest

from .test_joint_commands import TARGET, scene_file


def cmd(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    from .helpers import ROOT

    return subprocess.run([sys.executable, "-m", "gyro_sim.cli", "cmd", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("items, says", [
    (["--position", "elbow=0.5"], "joint 'elbow': no such joint"),
    (["--position", "arm_pos=0.5"], "joint 'arm_pos': no such joint"),
    (["--position", "tip=0.5"], "joint 'tip': no servo drives it"),
    (["--velocity", "arm=0.5"], "joint 'arm': its servo takes a position, not a velocity"),
    (["--position", "arm=high"], "--position 'arm=high': expected JOINT=VALUE"),
    (["--position", "arm=nan"], "--position 'arm=nan': expected JOINT=VALUE"),
    (["--position", "arm=0.1", "--effort", "arm=0.2"], "joint 'arm': given twice"),
    ([], "joints: give at least one"),
])
def test_bad_joint_targets_are_refused_naming_the_joint(tmp_path, items, says):
    r = cmd("--scene", scene_file(tmp_path), "joints", *items)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.startswith(f"gyro-sim cmd: {says}") and len(r.stderr.splitlines()) == 1, r.stderr
    if "arm_pos" in says:  # a servo's control name is not its joint's: the refusal says whose it is
        assert "'arm_pos' is the control of joint 'arm'" in r.stderr


def test_mixed_kinds_without_a_scene_are_refused():
    r = cmd("joints", "--position", "a=0.1", "--velocity", "b=0.2")
    assert r.returncode == 2 and "need --scene" in r.stderr and len(r.stderr.splitlines()) == 1


@pytest.mark.slow
def test_one_joint_target_drives_a_lockstep_node_for_one_period(tmp_path):
    pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")
    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.log.resim import resimulate

    from .helpers import NodeProcess, new_domain_id, wait_for

    scene, log = scene_file(tmp_path), tmp_path / "loop.mcap"
    # lock-step, one control period (100 Hz) of simulated time: the node ends after one command
    node = NodeProcess(tmp_path, new_domain_id(), f"scene:={scene}", "lockstep:=true", "duration:=0.01",
                       f"record:={log}")
    try:
        r = cmd("--scene", scene, "joints", "--position", f"arm={TARGET}", "--once", env=node.env)
        assert r.returncode == 0, r.stderr
        assert "servo joints: arm" in r.stdout and "/gyro_sim/joint_commands" in r.stdout
        wait_for(lambda: not node.alive(), 120, "the node's one lock-step period")
    finally:
        rc = node.stop()
    assert rc == 0, node.stderr
    commands = [m for _, _, _, m in iter_messages(log, ["/gyro_sim/joint_commands"])]
    assert [(list(m.name), list(m.position), list(m.velocity), list(m.effort)) for m in commands] == \
        [(["arm"], [TARGET], [], [])]
    rows = [(t, m.position[list(m.name).index("arm")]) for _, _, t, m in iter_messages(log, ["/joint_states"])]
    assert rows[0][1] == 0.0 and rows[-1][0] == 10_000_000 and rows[-1][1] > 0.0  # pulled towards the target
    res = resimulate(log)
    assert res.max_deviation == 0.0 and res.commands == 1 and res.compared == len(rows)
