"""`gyro-sim bench realtime --quick`: runs the node and writes a sane table, JSON and plot."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

pytest.importorskip("rclpy", reason="the realtime bench runs the ROS 2 node (pip install '.[ros]')")

from test.ros.helpers import ROOT


@pytest.mark.slow
def test_bench_realtime_quick(tmp_path):
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "bench", "realtime", "--quick", "--out", str(tmp_path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=170)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "realtime.md").read_text()
    rows = [line for line in text.splitlines() if re.match(r"\| \d+ \|", line)]
    assert [(int(line.split("|")[1]), line.split("|")[2].strip()) for line in rows] == [(2, "no"), (2, "yes")]
    for line in rows:
        cells = [c.strip() for c in line.split("|")[1:-1]]
        asked, got = (int(x) for x in cells[2].split("/"))  # the physics thread's FIFO priority
        assert asked == 50 and got in (0, 50), line  # the node's default; 0 where the system refuses it
        p50, p99 = float(cells[3]), float(cells[4])
        assert 0 < p50 <= p99, line
        assert 0 < float(cells[7].rstrip(" %")) < 250, line  # CPU share of a 2-core machine, in %
        assert 0.05 < float(cells[8]) < 1.2, line  # achieved real-time factor, target 1
        assert int(cells[9]) >= 0, line
        assert 0 <= int(cells[10]) <= int(cells[9]), line  # misses after waiting for a CPU
        assert float(cells[11]) >= 0 and float(cells[12]) >= 0, line  # waiting for a CPU, steal (ms)
        assert int(cells[13]) >= 0, line  # the floor's misses (a bare paced thread beside the node)
        assert float(cells[14]) >= 0, line  # longest GC pause (us)
        load_start, load_end = (float(x) for x in cells[15].split("/"))
        assert load_start >= 0 and load_end >= 0, line
    assert "Largest n holding real time" in text
    runs = json.loads((tmp_path / "realtime.json").read_text())
    assert len(runs) == 2 and runs[1]["records_written"] > 100 and runs[1]["recorder_error"] is None
    assert all(abs(run["node_time_s"] - 2.0) < 1e-6 for run in runs)
    # the floor thread woke every 2 ms from the node's start to its exit (several s): it ran
    assert all(run["floor_wall_s"] > 2.0 and run["floor_priority"] in (0, 50) for run in runs)
    assert (tmp_path / "realtime.png").stat().st_size > 1000
