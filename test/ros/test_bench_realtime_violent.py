"""The node given the violent step by `gyro-sim bench realtime --violent` (run_violent_node):
it takes the command, steps with "fixed", and publishes through it."""
from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy", reason="the violent step's node run needs the ROS 2 node (pip install '.[ros]')")


@pytest.mark.slow
def test_the_node_publishes_through_the_violent_step(tmp_path):
    """Counts, not rates: the command was taken once, the node ran its simulated time with "fixed"
    (no simulation error), and /joint_states kept arriving after it."""
    from gyro_sim.bench.realtime import PUBLISH_RATE, run_violent_node

    seconds = 2.0
    v = run_violent_node(tmp_path, seconds=seconds)
    assert v["integrator"] == "fixed" and v["commands_accepted"] == 1 and v["commands_rejected"] == 0
    assert v["node_time_s"] == pytest.approx(seconds, abs=0.011)
    assert v["received"] > 1 and math.isfinite(v["longest_gap_s"])
    assert v["received"] <= seconds * PUBLISH_RATE + 1  # what it received is what the node published
