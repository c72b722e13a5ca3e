"""IMU messages in logs: sensor_msgs/Imu on /gyro_sim/imu/<name>, read by independent readers
(rosbags, mcap-ros2-support), and re-simulated bit for bit."""
from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from gyro_sim.msgs import messages as M

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "config" / "imu_pendulum.yaml"
DURATION, PUBLISH_RATE = 0.3, 100.0
SCHEDULE = [(0.1, [0.05, -0.01])]


def scene_with(imus: list) -> dict:
    data = yaml.safe_load(SCENE.read_text())
    data["imus"] = imus
    return data


#: the shipped IMU, and a second one at half the publish rate, turned, noise-free
SECOND = {"name": "slow_imu", "body": "pendulum", "position": [0.01, 0.0, -0.1],
          "orientation": [0.8, 0.0, 0.6, 0.0], "rate": 50.0}


@pytest.fixture(scope="module")
def imu_log(tmp_path_factory):
    from gyro_sim.simulator import Simulator
    from gyro_sim.log.record import record_run

    data = yaml.safe_load(SCENE.read_text())
    data["imus"].append(SECOND)
    path = tmp_path_factory.mktemp("imu") / "run.mcap"
    sim = Simulator(data, integrator="rk4", step=1e-3)
    record_run(sim, path, duration=DURATION, publish_rate=PUBLISH_RATE, schedule=SCHEDULE)
    return path, data


def expected_readings(data: dict) -> dict:
    """(imu, log time) -> reading, from a Simulator stepped by hand as the recorder does."""
    from gyro_sim.simulator import Simulator

    sim = Simulator(data, integrator="rk4", step=1e-3)
    sim.set_imu_default_rate(PUBLISH_RATE)
    out = {}
    steps = int(round(DURATION * PUBLISH_RATE))
    for i in range(steps + 1):
        t = i / PUBLISH_RATE
        for r in sim.imus():
            if r.name == "tip_imu" or i % 2 == 0:
                out[(r.name, M.time_ns(sim.time))] = r
        if i == steps:
            break
        sim.set_axis_moments(SCHEDULE[0][1] if t >= SCHEDULE[0][0] - 1e-9 else [0.0, 0.0])
        sim.advance(1 / PUBLISH_RATE)
    return out


def test_imu_messages_decode_with_rosbags_and_mcap(imu_log):
    """Every IMU sample at its rate, read by both independent readers, equal to what a
    Simulator stepped by hand reads (with its noise), covariances from the densities."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    path, data = imu_log
    expected = expected_readings(data)
    seen = {}
    with AnyReader([path]) as reader:
        for con, t, raw in reader.messages():
            if con.msgtype != M.IMU_TYPE:
                continue
            msg = reader.deserialize(raw, con.msgtype)
            name = msg.header.frame_id
            assert con.topic == f"/gyro_sim/imu/{name}"
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert stamp == t
            r = expected[(name, t)]
            q = msg.orientation
            assert [q.w, q.x, q.y, q.z] == r.orientation.tolist()
            assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == \
                r.angular_velocity.tolist()
            assert [msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z] == \
                r.linear_acceleration.tolist()
            assert np.array_equal(msg.orientation_covariance, np.zeros(9))
            seen[(name, t)] = (msg.angular_velocity_covariance, msg.linear_acceleration_covariance)
    assert set(seen) == set(expected)
    tip = data["imus"][0]
    gyro_cov, accel_cov = seen[("tip_imu", 0)]
    assert np.allclose(gyro_cov, np.diag([tip["gyro_noise_density"] ** 2 * PUBLISH_RATE] * 3).ravel(), rtol=1e-15)
    assert np.allclose(accel_cov, np.diag([tip["accel_noise_density"] ** 2 * PUBLISH_RATE] * 3).ravel(), rtol=1e-15)
    assert np.array_equal(seen[("slow_imu", 0)][0], np.zeros(9))  # noise-free
    times = sorted(t for name, t in seen if name == "slow_imu")
    assert np.all(np.diff(times) == 20_000_000)  # 50 Hz
    with open(path, "rb") as f:
        decoded = [m for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/gyro_sim/imu/tip_imu"])]
    assert len(decoded) == len([k for k in seen if k[0] == "tip_imu"]) == int(DURATION * PUBLISH_RATE) + 1
    assert decoded[3].header.frame_id == "tip_imu"


def test_a_log_with_imus_resimulates_bit_for_bit(imu_log):
    from gyro_sim.log.resim import resimulate

    path, _ = imu_log
    out = resimulate(path)
    assert out.imu_compared == 2 * (int(DURATION * PUBLISH_RATE) + 1) - int(DURATION * PUBLISH_RATE) // 2
    assert out.max_deviation == 0.0 and out.compared > 0
    assert "IMU message" in out.report()
    # not vacuous: another integrator's solution differs in the IMU readings too
    other = resimulate(path, integrator="dop853")
    assert other.by_field["imu_linear_acceleration"] > 0 and other.by_field["imu_angular_velocity"] > 0


@pytest.mark.slow
def test_run_refuses_an_imu_rate_the_publications_cannot_sample(tmp_path):
    scene = tmp_path / "scene.yaml"
    data = scene_with([dict(SECOND, rate=30.0)])
    scene.write_text(yaml.safe_dump(data))
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", str(scene), "--duration", "0.1",
                        "--record", str(tmp_path / "out.mcap")], cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().splitlines()[-1] == (
        "gyro-sim run: imus[0].rate: 30 Hz must divide the publish rate 100 Hz (publish_rate / rate a whole "
        "number): IMUs are sampled at publications")
    assert not (tmp_path / "out.mcap").exists()


def test_imu_builder_refuses_non_finite_values():
    from gyro_sim.dynamics.imu import ImuReading

    good = ImuReading("imu", 0.0, 0, np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([0, 0, 9.81]), 0.0, 0.0)
    M.imu(good, 0)
    bad = copy.copy(good)
    object.__setattr__(bad, "linear_acceleration", np.array([0.0, np.nan, 0.0]))
    with pytest.raises(M.NonFiniteError, match="imu imu.linear_acceleration"):
        M.imu(bad, 0)


def test_imu_definition_is_shipped_and_parses():
    from mcap_ros2._dynamic import generate_dynamic

    from gyro_sim.msgs import msgdefs

    text = msgdefs.definition(M.IMU_TYPE, shipped_only=True)
    assert text == msgdefs.definition(M.IMU_TYPE)
    assert M.IMU_TYPE in generate_dynamic(M.IMU_TYPE, text)
