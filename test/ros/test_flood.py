"""The physics thread first: a flood of 20,000 commands per second on ~/axis_moments, from two
other processes over real DDS, leaves /joint_states at >= 95 Hz (the measurement behind
`gyro-sim bench soak`, whose flood part this runs)."""
from __future__ import annotations

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from gyro_sim.bench import soak  # noqa: E402

from .helpers import new_domain_id  # noqa: E402


@pytest.mark.slow
def test_joint_states_hold_their_rate_under_a_command_flood(tmp_path):
    (tmp_path / "ros_log").mkdir()
    fl = soak.flood(tmp_path, rate=20_000.0, seconds=4.0, publishers=2, domain=new_domain_id())
    assert fl.sent >= 0.9 * 20_000 * 4.0, fl
    assert fl.hz_before >= 95.0, fl
    assert fl.hz_during >= 95.0, fl
    assert fl.rtf_during >= 0.99, fl
    assert fl.accepted > 0, "the node took commands in during the flood"
