"""SIGINT and SIGTERM in the middle of `gyro-sim recover`, `run`, `view` and `sweep`: each ends
within END_SECONDS with exit status 1 and one line, no traceback, and nothing half-written under
an output's final name (`run --record` publishes its log closed, complete up to the signal, and
says so)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from gyro_sim.log.mcap_log import read_info
from gyro_sim.safe_paths import PARTIAL

from .conftest import ROOT

#: how long a command may take to end after the signal
END_SECONDS = 2.0
#: how long a command may take to start its work (imports, a cold numba cache, a Dask cluster)
START_TIMEOUT = 300.0
SIGNALS = [signal.SIGINT, signal.SIGTERM]


class Command:
    """A `gyro-sim` subprocess whose stderr is collected as it comes."""

    def __init__(self, *args, cwd=ROOT):
        self.proc = subprocess.Popen([sys.executable, "-m", "gyro_sim.cli", *map(str, args)], cwd=cwd,
                                     env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)
        self.err: list[str] = []
        self.changed = threading.Condition()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for chunk in iter(lambda: self.proc.stderr.read(1), ""):
            with self.changed:
                self.err.append(chunk)
                self.changed.notify_all()
        with self.changed:
            self.changed.notify_all()

    @property
    def stderr(self) -> str:
        return "".join(self.err)

    def wait_until(self, ready, what: str) -> None:
        """Wait until `ready()` (polled as stderr grows, and at least every 20 ms), failing if
        the command ends first."""
        deadline = time.monotonic() + START_TIMEOUT
        with self.changed:
            while not ready():
                assert self.proc.poll() is None, f"the command ended before {what}: {self.stderr}"
                assert time.monotonic() < deadline, f"never {what}: {self.stderr}"
                self.changed.wait(0.02)

    def interrupt(self, sig) -> tuple[int, float, str]:
        """(exit status, seconds from the signal to the exit, what it wrote on stderr after
        the signal)."""
        with self.changed:
            before = len(self.err)
        self.proc.send_signal(sig)
        t0 = time.monotonic()
        try:
            self.proc.wait(timeout=60)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        took = time.monotonic() - t0
        print(f"{' '.join(self.proc.args[3:5])}: ended {took:.2f} s after {signal.Signals(sig).name}")
        self.reader.join(timeout=10)
        self.proc.stdout.close()
        return self.proc.returncode, took, "".join(self.err[before:])


def _said_in_one_line(err: str, command: str) -> str:
    """The one line the command wrote after the signal (progress bars aside)."""
    assert "Traceback" not in err, err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    said = [line for line in lines if line.startswith(f"gyro-sim {command}:")]
    assert len(said) == 1 and all(line in said or "%" in line for line in lines), err
    return said[0]


def _partials(directory: Path) -> list[Path]:
    return [p for p in directory.iterdir() if PARTIAL in p.name]


# --- recover ------------------------------------------------------------------------------------------
#: messages of the large log `recover` is interrupted in (about 100 MB: seconds of work)
BIG_MESSAGES = 400_000
BIG_PAYLOAD = 256


@pytest.fixture(scope="module")
def big_log(tmp_path_factory):
    """A large MCAP log cut short (no summary): recovering it takes seconds."""
    import random

    from mcap.writer import Writer

    path = tmp_path_factory.mktemp("big") / "big.mcap"
    rng = random.Random(1)
    payloads = [bytes(rng.getrandbits(8) for _ in range(BIG_PAYLOAD)) for _ in range(64)]
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1 << 16)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        cid = w.register_channel("/big", "cdr", sid)
        for i in range(BIG_MESSAGES):
            w.add_message(cid, i * 1000, payloads[i % len(payloads)], i * 1000, i)
        # no finish(): a log cut short, as after SIGKILL
    return path


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_recover_interrupted_ends_at_once_and_leaves_no_output(big_log, tmp_path, sig):
    out = tmp_path / "fixed.mcap"
    cmd = Command("recover", big_log, "-o", out)
    cmd.wait_until(lambda: any(p.stat().st_size > 1 << 20 for p in _partials(tmp_path)), "recover wrote 1 MB")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    line = _said_in_one_line(err, "recover")
    assert sig.name in line and "interrupted" in line
    assert not out.exists() and not _partials(tmp_path)


# --- run ------------------------------------------------------------------------------------------------
def test_run_interrupted_while_recording_publishes_the_closed_log_and_says_so(tmp_path):
    log = tmp_path / "run.mcap"
    cmd = Command("run", "--scene", "heavy_top", "--duration", "100000", "--record", log, "--flush-period", "0.05")
    cmd.wait_until(lambda: any(p.stat().st_size > 50_000 for p in _partials(tmp_path)), "the log grew")
    assert not log.exists()  # nothing under the final name while the run goes on
    status, took, err = cmd.interrupt(signal.SIGTERM)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    line = _said_in_one_line(err, "run")
    assert "interrupted at t = " in line and f"closed and complete in {log}" in line
    assert read_info(log).message_count > 0  # well-formed: summary, footer, every CRC
    assert not _partials(tmp_path)


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_run_without_a_log_interrupted_says_so_in_one_line(sig):
    cmd = Command("run", "--scene", "heavy_top", "--duration", "100000")
    cmd.wait_until(lambda: "t = " in cmd.stderr, "the run started")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    assert sig.name in _said_in_one_line(err, "run")


# --- view ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def long_log(tmp_path_factory):
    """A 60 s heavy-top log at 200 Hz: drawing it takes seconds."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    path = tmp_path_factory.mktemp("long") / "long.mcap"
    record_run(Simulator(load_scene("heavy_top"), integrator="rk4", step=2e-3), path, duration=60.0,
               chunk=0.005, publish_rate=200.0)
    return path


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_view_interrupted_leaves_no_recording(long_log, tmp_path, sig):
    pytest.importorskip("rerun", reason="view needs rerun-sdk")
    out = tmp_path / "view.rrd"
    cmd = Command("view", long_log, "--save", out)
    # the temporary file is made before the log is read: wait until reading has begun
    cmd.wait_until(lambda: bool(_partials(tmp_path)), "view started")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    assert sig.name in _said_in_one_line(err, "view")
    assert not out.exists() and not _partials(tmp_path)


# --- sweep ---------------------------------------------------------------------------------------------
SWEEP = """
name: a grid to interrupt
scene: heavy_top
grid:
  bodies[0].com[2]: {linspace: [0.02, 0.1, 8]}
  bodies[0].initial.euler_rates[2]: [10.0, 30.0, 50.0, 70.0]
run: {integrator: dop853, rtol: 1.0e-9, atol: 1.0e-11, horizon: 3.0, chunk: 0.01}
measures: [max_tilt, cpu_time]
batch: 1
"""


@pytest.mark.parametrize("workers", [0, 2])
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_sweep_interrupted_keeps_finished_parts_and_writes_no_results(tmp_path, sig, workers):
    pytest.importorskip("distributed", reason="sweeps need dask.distributed")
    spec = tmp_path / "grid.yaml"
    spec.write_text(SWEEP)
    out = tmp_path / "out"
    cmd = Command("sweep", spec, "--out", out, "--workers", workers)
    parts = out / "parts"
    cmd.wait_until(lambda: parts.is_dir() and any(parts.glob("points-*.parquet")), "a batch finished")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    assert "interrupted" in _said_in_one_line(err, "sweep")
    assert not (out / "results.parquet").exists() and not (out / "summary.md").exists()
    import pyarrow.parquet as pq

    for part in parts.glob("points-*.parquet"):
        pq.read_table(part)  # every part there is whole
    assert not list(parts.glob(f".*{PARTIAL}*")) and not _partials(out)
