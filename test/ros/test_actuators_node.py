"""The node and a scene's actuator limits: a method the actuators do not take is refused at
start in one line, nothing created."""
from __future__ import annotations

import pytest
import yaml

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from test.dynamics.test_actuators import wheel_scene

from .helpers import NodeProcess, new_domain_id


@pytest.mark.slow
def test_node_refuses_a_method_the_actuators_do_not_take_in_one_line(tmp_path):
    scene = tmp_path / "wheel.yaml"
    scene.write_text(yaml.safe_dump(wheel_scene("held", friction={"viscous": 1e-3})), encoding="utf-8")
    log = tmp_path / "refused.mcap"
    node = NodeProcess(tmp_path, new_domain_id(), f"scene:={scene}", "integrator:=lie4", f"record:={log}")
    rc = node.proc.wait(timeout=300)
    assert rc == 2, node.stderr
    said = [line for line in node.stderr.splitlines() if line.startswith("gyro_sim_node:")]
    assert said == ["gyro_sim_node: invalid parameters, nothing started: wheel.friction: integrator 'lie4' does "
                    "not take speed-dependent actuator terms (friction, max_speed); use one of auto, dop853, "
                    "fixed, gauss4, radau, rk4"], node.stderr
    assert "Traceback" not in node.stderr and not log.exists()
