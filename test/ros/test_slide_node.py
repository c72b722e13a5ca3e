"""A node running a cart on a slide: /joint_states carries the cart's position (m), velocity (m/s)
and force (N) under its body's name, and /tf carries the cart's frame where that position puts
it along the slide's axis, unturned, at every publication of a recorded run."""
from __future__ import annotations

import subprocess

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")
pytest.importorskip("mcap_ros2")

from test.dynamics.test_slide import cart_pole
from test.ros.helpers import new_domain_id, node_command, ros_env


@pytest.mark.slow
def test_the_nodes_slide_frame_rides_its_joint_state(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    axis = np.array([1.0, 0.0, 0.5]) / np.linalg.norm([1.0, 0.0, 0.5])
    scene = tmp_path / "cart.yaml"
    scene.write_text(yaml.safe_dump(cart_pole(0.1, 0.6, 0.4, 0.0, axis=tuple(axis.tolist()))))
    log = tmp_path / "cart.mcap"
    cmd = node_command(f"scene:={scene}", "duration:=0.3", f"record:={log}", "real_time_factor:=0.0")
    run = subprocess.run(cmd, env=ros_env(new_domain_id(), tmp_path), capture_output=True, text=True, check=False,
                         timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    frames: dict[int, object] = {}
    states: dict[int, tuple] = {}
    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(topics=["/tf", "/joint_states"]):
            if channel.topic == "/joint_states":
                i = list(decoded.name).index("cart")
                states[message.log_time] = (decoded.position[i], decoded.velocity[i], decoded.effort[i])
            else:
                for t in decoded.transforms:
                    if t.child_frame_id == "cart":
                        frames[message.log_time] = t.transform
    assert len(frames) >= 10 and set(frames) <= set(states)
    worst = 0.0
    for stamp, tr in frames.items():
        d = states[stamp][0]
        p = np.array([tr.translation.x, tr.translation.y, tr.translation.z])
        q = np.array([tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z])
        worst = max(worst, float(np.max(np.abs(p - d * axis))), float(np.max(np.abs(q - [1.0, 0.0, 0.0, 0.0]))))
    positions = [s[0] for s in states.values()]
    assert max(positions) - min(positions) > 0.05 and all(s[2] == 0.0 for s in states.values())
    assert worst < 1e-12
