"""The node's IMUs: sensor_msgs/Imu on ~/imu/<name> at the IMU's rate, recorded, re-simulated bit
for bit; a rate the publications cannot sample refused before anything starts."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from sensor_msgs.msg import Imu

from .helpers import DISCOVERY_TIMEOUT, Client, NodeProcess, new_domain_id, stamp_ns, wait_for

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "config" / "imu_pendulum.yaml"


def scene_file(tmp_path: Path, rate: float) -> Path:
    data = yaml.safe_load(SCENE.read_text())
    data["imus"][0]["rate"] = rate
    path = tmp_path / "imu_scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.slow
def test_node_publishes_and_records_imus_that_resimulate(tmp_path):
    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.log.resim import resimulate

    log = tmp_path / "live.mcap"
    domain = new_domain_id()
    client = Client(domain)
    received = client.subscribe("/gyro_sim/imu/tip_imu", Imu, depth=1000)
    node = NodeProcess(tmp_path, domain, f"scene:={scene_file(tmp_path, 50.0)}", "physics_rate:=500.0",
                       "publish_rate:=100.0", "duration:=60.0", f"record:={log}")  # stopped once it has 10
    try:
        wait_for(lambda: len(received) > 10 or not node.alive(), DISCOVERY_TIMEOUT, "10 IMU messages")
        assert node.alive(), node.stderr
        rc = node.stop()
    finally:
        client.close()
        node.stop()
    assert rc == 0, node.stderr
    msgs = [m for _, m in client.messages("/gyro_sim/imu/tip_imu")]
    assert all(m.header.frame_id == "tip_imu" for m in msgs)
    stamps = [stamp_ns(m) for m in msgs]
    assert all(s % 20_000_000 == 0 for s in stamps)  # 50 Hz: every other publication
    logged = [(t, m) for _, _, t, m in iter_messages(log, ["/gyro_sim/imu/tip_imu"])]
    assert len(logged) >= len(msgs) > 10
    assert all(t % 20_000_000 == 0 for t, _ in logged)
    out = resimulate(log)
    assert out.imu_compared == len(logged)
    assert out.max_deviation == 0.0, out.report()


@pytest.mark.slow
def test_node_refuses_an_imu_rate_the_publications_cannot_sample(tmp_path):
    node = NodeProcess(tmp_path, new_domain_id(), f"scene:={scene_file(tmp_path, 30.0)}", "publish_rate:=100.0")
    rc = node.proc.wait(timeout=120)
    assert rc == 2, node.stderr
    assert "invalid parameters, nothing started: imus[0].rate: 30 Hz must divide the publish rate 100 Hz" \
        in node.stderr
    assert "Traceback" not in node.stderr
