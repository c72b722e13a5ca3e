"""A node running a URDF robot: /tf carries its links by name where the robot's own URDF and
/joint_states put them (docs/ros-interface.md, "A URDF robot as itself").

The judge is MuJoCo's forward kinematics of the robot's URDF (the text the node publishes on
robot_description) at the joint states the node recorded: every recorded link transform must
equal it to 1e-9, at every publication of the run.
"""
from __future__ import annotations

import subprocess

import numpy as np
import pytest

pytest.importorskip("rclpy")
mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")
pytest.importorskip("mcap_ros2")

from gyro_sim.paths import find_scene
from gyro_sim.scene.load import load_scene
from test.ros.helpers import new_domain_id, node_command, ros_env
from test.scene.test_robot_description import FK_AGREEMENT, published_fk


def test_the_nodes_link_frames_are_the_robots_urdf_at_its_joint_states(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    log = tmp_path / "ur5.mcap"
    cmd = node_command("scene:=ur5.urdf", "duration:=0.3", f"record:={log}", "real_time_factor:=0.0",
                       "demo:=true")
    run = subprocess.run(cmd, env=ros_env(new_domain_id(), tmp_path), capture_output=True, text=True, check=False,
                         timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    urdf = load_scene(find_scene("ur5.urdf")).robot.urdf  # what robot_description carries
    links: dict[int, dict] = {}
    states: dict[int, dict] = {}
    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(topics=["/tf", "/joint_states"]):
            if channel.topic == "/joint_states":
                states[message.log_time] = dict(zip(decoded.name, decoded.position))
            elif any(t.child_frame_id.endswith("_link") for t in decoded.transforms):
                links[message.log_time] = {t.child_frame_id: t.transform for t in decoded.transforms}
    assert len(links) >= 10 and set(links) <= set(states)
    worst = 0.0
    moved = 0.0
    for stamp, frames in links.items():
        fk = published_fk(urdf, states[stamp], tmp_path)
        moved = max(moved, max(abs(v) for v in states[stamp].values()))
        for name, tr in frames.items():
            p = np.array([tr.translation.x, tr.translation.y, tr.translation.z])
            q = np.array([tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z])
            R = np.zeros(9)
            mujoco.mju_quat2Mat(R, q)
            worst = max(worst, float(np.max(np.abs(p - fk[name][0]))),
                        float(np.max(np.abs(R.reshape(3, 3) - fk[name][1]))))
    print(f"node /tf links vs MuJoCo FK of the published URDF: {worst:.2g} over {len(links)} publications")
    assert moved > 0.0
    assert worst < FK_AGREEMENT
