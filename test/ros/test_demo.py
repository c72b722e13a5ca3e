"""The demo's amplitudes, the log names `record` takes and the frame prefixes the node accepts
(no rclpy needed)."""
from __future__ import annotations

import math
import re

import pytest

from gyro_sim.ros.demo import DEMO_ANGLE, DEMO_FREQUENCY, Demo, effective_inertias
from gyro_sim.ros.params import ParameterError, record_path, validate
from gyro_sim.simulator import Simulator

#: transverse inertia (kg m^2) about the joint point of the one hinged body below
TRANSVERSE = 2.5e-3
ONE_HINGE = {
    "name": "one hinged rod, no gravity",
    "gravity": [0.0, 0.0, 0.0],
    "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
    "bodies": [{
        "name": "rod",
        "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]},
        "mass": 0.1,
        "com": [0.0, 0.0, 0.1],
        "inertia": {"axial": 2.0e-5, "transverse": TRANSVERSE},
        "initial": {"angle": 0.0, "rate": 0.0},
    }],
}


def test_the_effective_inertia_of_a_hinge_is_the_bodys_inertia_about_it():
    """One body on a hinge about a transverse axis through its joint point, nothing else acting:
    its inertia about the axis is the scene's transverse inertia about that point."""
    from gyro_sim.scene.load import load_scene

    sim = Simulator(load_scene(ONE_HINGE), integrator="rk4", backend="numpy", step=1e-3)
    (j,) = effective_inertias(sim, 1e-3)
    assert j == pytest.approx(TRANSVERSE, rel=1e-9)
    assert sim.time == 0.0 and list(sim.axis_moments) == [0.0]  # left at its initial state
    demo = Demo.for_scene(sim, 1e-3)
    assert demo.amplitudes[0] == pytest.approx(TRANSVERSE * (2 * math.pi * DEMO_FREQUENCY) ** 2 * DEMO_ANGLE, rel=1e-9)
    # a quarter period in, the one axis is at its full amplitude
    assert demo.moments(0.25 / DEMO_FREQUENCY)[0] == pytest.approx(demo.amplitudes[0])


def test_record_auto_names_the_log_after_the_start():
    import time

    now = time.mktime((2026, 11, 26, 17, 4, 5, 0, 0, -1))
    assert record_path("auto", now) == "gyro_sim_20261126_170405.mcap"
    assert record_path("runs/robot1_{time}.mcap", now) == "runs/robot1_20261126_170405.mcap"
    assert record_path("plain.mcap", now) == "plain.mcap"
    assert re.fullmatch(r"gyro_sim_\d{8}_\d{6}\.mcap", record_path("auto"))


def test_a_time_named_log_that_exists_is_still_refused(tmp_path, monkeypatch):
    import time

    from gyro_sim.ros import params

    now = time.mktime((2026, 11, 26, 17, 4, 5, 0, 0, -1))
    monkeypatch.setattr(params, "record_path", lambda text: record_path(text, now))
    existing = tmp_path / "run_20261126_170405.mcap"
    existing.write_bytes(b"kept")
    with pytest.raises(ParameterError, match="exists"):
        validate({"scene": "hinge_chain", "record": str(tmp_path / "run_{time}.mcap")})
    assert existing.read_bytes() == b"kept"
    cfg = validate({"scene": "hinge_chain", "record": str(tmp_path / "other_{time}.mcap")})
    assert cfg.record == str(tmp_path / "other_20261126_170405.mcap")


@pytest.mark.parametrize("prefix", ["/robot1/", "robot 1/", "robot1\n"])
def test_a_frame_prefix_that_is_no_frame_name_start_is_refused(prefix):
    with pytest.raises(ParameterError, match="frame_prefix"):
        validate({"scene": "hinge_chain", "frame_prefix": prefix})
    assert validate({"scene": "hinge_chain", "frame_prefix": "robot1/"}).frame_prefix == "robot1/"
