"""`gyro-sim bench realtime --quick`: runs the node and writes a sane table, JSON and plot."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

pytest.importorskip("rclpy", reason="the realtime bench runs the ROS 2 node (pip install '.[ros]')")

from .helpers import ROOT  # noqa: E402


def test_bench_realtime_quick(tmp_path):
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "bench", "realtime", "--quick", "--out", str(tmp_path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=170)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "realtime.md").read_text()
    rows = [line for line in text.splitlines() if re.match(r"\| \d+ \|", line)]
    assert [(int(line.split("|")[1]), line.split("|")[2].strip()) for line in rows] == [(2, "no"), (2, "yes")]
    for line in rows:
        cells = [c.strip() for c in line.split("|")[1:-1]]
        p50, p99 = float(cells[2]), float(cells[3])
        assert 0 < p50 <= p99
        assert 0 < float(cells[6].rstrip(" %")) < 250  # CPU share of a 2-core machine, in %
        assert 0.05 < float(cells[7]) < 1.2  # achieved real-time factor, target 1
        assert int(cells[8]) >= 0
        assert 0 <= int(cells[9]) <= int(cells[8])  # misses after waiting for a CPU
        assert float(cells[10]) >= 0 and float(cells[11]) >= 0  # waiting for a CPU, steal (ms)
        assert float(cells[12]) >= 0  # longest GC pause (us)
        load_start, load_end = (float(x) for x in cells[13].split("/"))
        assert load_start >= 0 and load_end >= 0
    assert "Largest n holding real time" in text
    runs = json.loads((tmp_path / "realtime.json").read_text())
    assert len(runs) == 2 and runs[1]["records_written"] > 100 and runs[1]["recorder_error"] is None
    assert all(abs(run["node_time_s"] - 2.0) < 1e-6 for run in runs)
    assert (tmp_path / "realtime.png").stat().st_size > 1000
