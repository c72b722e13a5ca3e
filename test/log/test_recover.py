"""Crash safety: a recording killed with SIGKILL is recovered up to its last flush."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import LogError, read_info
from gyro_sim.log.recover import recover
from gyro_sim.safe_paths import PARTIAL, OutputError

from test.conftest import ROOT, gyro_sim, rosbags_messages

FLUSH_PERIOD = 0.25
KILL_AFTER = 2.0

# A long offline recording that prints, after every step, the simulated time it has written.
WRITER = f"""
import sys
from gyro_sim import Simulator, load_scene
from gyro_sim.log.record import record_run
sim = Simulator(load_scene("config/chain_4.yaml"), integrator="rk4", step=2e-3)
def progress(t, total):
    print(t, flush=True)
record_run(sim, sys.argv[1], duration=1000.0, chunk=0.01, publish_rate=100.0,
           flush_period={FLUSH_PERIOD}, progress=progress)
"""


@pytest.mark.slow
def test_sigkill_during_recording_loses_at_most_the_last_flush_period(tmp_path):
    log = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(log)], cwd=ROOT, env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = []  # (wall time the line arrived, simulated time written by then)

    def reader():
        for line in proc.stdout:
            written.append((time.monotonic(), float(line)))

    th = threading.Thread(target=reader, daemon=True)
    th.start()
    deadline = time.monotonic() + 60
    while not written and time.monotonic() < deadline:  # wait for the run to start (imports)
        time.sleep(0.05)
    assert written, proc.stderr.read() if proc.poll() is not None else "the writer never started"
    time.sleep(KILL_AFTER)
    proc.send_signal(signal.SIGKILL)
    killed_at = time.monotonic()
    proc.wait(timeout=10)
    th.join(timeout=5)
    assert proc.returncode == -signal.SIGKILL

    with pytest.raises(LogError, match="no summary"):
        read_info(log)  # the file really is cut short
    fixed = tmp_path / "fixed.mcap"
    rec = recover(log, fixed)
    assert not rec.complete and rec.messages > 0 and rec.attachments == 1 and rec.metadata == 1

    msgs = rosbags_messages(fixed)  # reads cleanly
    assert len(msgs) == rec.messages
    info = read_info(fixed)
    assert info.message_count == rec.messages and info.params["advance_dt"] == 0.01
    info.scene()  # the scene is embedded and loads
    # a contiguous prefix: every 10 ms from 0 to the end, no gap
    js = [t for topic, t in msgs if topic == M.JOINT_STATES]
    assert js[0] == 0 and all(b - a == 10_000_000 for a, b in zip(js, js[1:]))
    # it covers everything written before the last flush period (with 0.2 s of slack for scheduling)
    before = [t for wall, t in written if wall <= killed_at - FLUSH_PERIOD - 0.2]
    assert before, "the writer printed too little"
    assert rec.end_ns / 1e9 >= before[-1] - 0.01 - 1e-9, (rec.end_ns / 1e9, before[-1], written[-1])
    lost = written[-1][1] - rec.end_ns / 1e9
    print(f"written {written[-1][1]:.2f} s, recovered {rec.end_ns / 1e9:.2f} s of simulated time, lost {lost:.2f} s")


@pytest.mark.slow
def test_cli_recover_and_sigterm_closes_cleanly(tmp_path):
    log = tmp_path / "run.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", "heavy_top", "--duration", "1000",
                             "--record", str(log), "--flush-period", "0.2"], cwd=ROOT, env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def partial_size():  # the log is written under a temporary name until it is closed
        return max([p.stat().st_size for p in tmp_path.glob(f".run.*{PARTIAL}.mcap")] or [0])

    deadline = time.monotonic() + 120
    while partial_size() < 20_000 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert not log.exists()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1, err  # stopped mid-work
    assert "interrupted" in err and "closed and complete" in err
    info = read_info(log)  # well-formed: summary and footer
    assert info.message_count > 0
    r = gyro_sim("recover", log, "-o", tmp_path / "again.mcap")
    assert r.returncode == 0, r.stderr
    assert "the input was complete" in r.stdout and "nothing damaged" in r.stdout
    assert f"recovered {info.message_count} messages" in r.stdout


def test_recover_refuses_what_is_not_a_log(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(LogError):
        recover(bad, tmp_path / "out.mcap")
    with pytest.raises(OutputError, match="is the input"):  # the input is never the output
        recover(bad, bad)
