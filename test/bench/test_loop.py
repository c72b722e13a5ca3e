"""`gyro-sim bench loop`: the node and the LQR example over DDS, one short run per mode, a sane
table and JSON (the lock-step run's counts are exact; wall-clock figures are only checked to be
there), and its refusals."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("rclpy", reason="the loop bench runs the ROS 2 node (pip install '.[ros]')")

from test.ros.helpers import ROOT


@pytest.mark.slow
def test_bench_loop_writes_a_row_per_mode_and_rate(tmp_path):
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "bench", "loop", "--rates", "100", "--seconds", "2",
                        "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "loop.md").read_text()
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in text.splitlines()
            if line.startswith(("| realtime", "| lockstep"))]
    assert [(row[0], row[1]) for row in rows] == [("realtime", "100"), ("lockstep", "100")]
    for row in rows:
        assert float(row[2]) > 0 and 0 < float(row[3]) <= float(row[4]), row  # RTF, step p50 <= p99
        assert 0 < float(row[5]) <= float(row[6]), row  # command latency p50 <= p99
    runs = json.loads((tmp_path / "loop.json").read_text())
    lock = next(run for run in runs if run["mode"] == "lockstep")
    # lock-step: 200 periods, each of one command; the pendulum upright (the same run every time)
    assert lock["steps"] == 2000 and lock["commands_superseded"] == 0 and lock["commands_accepted"] >= 200
    assert lock["max_angle_after_settle"] < 0.01 and float(rows[1][9]) > 0  # commands per wall second
    assert all(run["node_time_s"] == pytest.approx(2.0) for run in runs)


@pytest.mark.parametrize("args", [["--rates", "0"], ["--seconds", "-1"]])
def test_bench_loop_refuses_bad_input(tmp_path, args):
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "bench", "loop", *args, "--out", str(tmp_path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
