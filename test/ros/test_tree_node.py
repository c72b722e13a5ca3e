"""A node running a tree (docs/ros-interface.md): /tf carries every body's frame from the world,
each child's joint point where its parent's frame and `joint.at` put it, and the URDF on
robot_description joins each body's link to its parent's (not to the body listed before it).

The node records its run (real_time_factor 0: as fast as it computes, every publication
logged); the checks read the log: deterministic quantities only (frame names, parents, the
kinematics of every publication to 1e-12).
"""
from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")
pytest.importorskip("mcap_ros2")

from gyro_sim.dynamics.rotations import quat_to_matrix
from test.ros.helpers import new_domain_id, node_command, ros_env
from test.viz.test_view_tree import PARENTS, TREE


def test_a_trees_frames_and_description_name_each_bodys_parent(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    scene = tmp_path / "tree.yaml"
    scene.write_text(yaml.safe_dump(TREE))
    log = tmp_path / "tree.mcap"
    cmd = node_command(f"scene:={scene}", "duration:=0.3", f"record:={log}", "real_time_factor:=0.0")
    run = subprocess.run(cmd, env=ros_env(new_domain_id(), tmp_path), capture_output=True, text=True, check=False,
                         timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    frames, description = [], None
    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages(topics=["/tf", "/robot_description"]):
            if channel.topic == "/tf":
                frames.append(decoded.transforms)
            else:
                description = decoded.data
    names = [b["name"] for b in TREE["bodies"]]
    joints = ET.fromstring(description).findall("joint")
    assert [(j.find("parent").get("link"), j.find("child").get("link")) for j in joints] == \
        [(p or "world", n) for p, n in zip(PARENTS, names)]
    assert len(frames) >= 20
    bodies = {b["name"]: b for b in TREE["bodies"]}
    for transforms in frames:
        assert [t.header.frame_id for t in transforms] == ["world"] * len(names)
        assert [t.child_frame_id for t in transforms] == names
        pose = {t.child_frame_id: (np.array([t.transform.translation.x, t.transform.translation.y,
                                             t.transform.translation.z]),
                                   quat_to_matrix(np.array([t.transform.rotation.w, t.transform.rotation.x,
                                                            t.transform.rotation.y, t.transform.rotation.z])))
                for t in transforms}
        for name, parent in zip(names, PARENTS):
            if parent is not None:
                O, R = pose[parent]
                at = bodies[name]["joint"].get("at", bodies[parent].get("next_joint"))
                np.testing.assert_allclose(pose[name][0], O + R @ np.asarray(at), rtol=0, atol=1e-12)
