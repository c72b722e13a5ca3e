"""SIGINT and SIGTERM in the middle of `gyro-sim recover`, `run`, `view` and `sweep`.

What is promised: each command stops its work at the signal (at the next chunk, message, step
or batch) and ends with exit status 1 and one line, no traceback, and nothing half-written under
an output's final name; `run --record` publishes its log closed, complete up to the signal, and
says so; a sweep keeps the parts it finished. A signal that lands while a class is created (a
module being imported: Python 3.11 wraps its exception in a RuntimeError) is an interrupt all the
same, not a "damaged log" (exit 2) nor a traceback: the last section makes that moment, which
the commands meet by chance (`view` when it first opens its log).

How soon: after the signal a command only closes or removes its outputs, says its line and
ends, leaving out the interpreter's final garbage collections (`gyro_sim.safe_paths.end_after_interrupt`:
with numba and scipy loaded they cost 0.2 s of CPU, most of what the exit took); a sweep's
nannies are told not to start new workers, which closing the cluster would wait for
(`gyro_sim.sweep.execute.stop_local_workers`). The module prints each command's time from the
signal to its exit: tenths of a second.

Why the bound is END_SECONDS: a wall-clock time measures the share of the processor the command
gets as much as the command, so the bound leaves that share room (more than 10 times the worst
time measured). What makes it a test of the command is the work left when the signal comes: each
command is interrupted with several times the bound of work ahead of it (a slower or busier
processor slows that work as much as the exit; each fixture below says how much): a command that
finished its work before heeding the signal, or ignored it, fails.
"""
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
from gyro_sim.safe_paths import PARTIAL, Interrupted

from test.conftest import ROOT

#: how long a command may take to end after the signal (s): generous for a command that has
#: other processes beside it on the same cores (module docstring)
END_SECONDS = 5.0
#: how long to wait for a command that does not end before killing it (s)
KILL_AFTER = 60.0
#: how long a command may take to start its work (imports, a cold numba cache, a Dask cluster)
START_TIMEOUT = 300.0
SIGNALS = [signal.SIGINT, signal.SIGTERM]


class Command:
    """A `gyro-sim` subprocess whose stderr is collected as it comes."""

    def __init__(self, *args, cwd=ROOT):
        #: how the printed times name the command (its arguments without the paths)
        self.label = " ".join(str(a) for a in args if os.sep not in str(a))
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
            self.proc.wait(timeout=KILL_AFTER)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        took = time.monotonic() - t0
        print(f"{self.label}: ended {took:.2f} s after {signal.Signals(sig).name}")
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
#: the big log of `recover`: the complete chunks of a log of BLOCK_MESSAGES messages, written
#: BLOCK_COPIES times over (3.2e6 messages, 76 MB): recovering it takes tens of seconds,
#: and the test interrupts it after 1 MB of its 69 MB of output
BLOCK_MESSAGES = 20_000
BLOCK_COPIES = 160
BIG_PAYLOAD = 32
#: the recovered output written when the signal is sent (bytes)
RECOVER_WRITTEN = 1 << 20


@pytest.fixture(scope="module")
def big_log(tmp_path_factory):
    """A large MCAP log cut short (no summary, no footer), made in a fraction of a second:
    recover checks and rewrites each chunk on its own, so the same chunks over and over (with
    the same log times) are as much work as as many different ones."""
    import io
    import random

    from mcap.writer import Writer

    rng = random.Random(1)
    payloads = [bytes(rng.getrandbits(8) for _ in range(BIG_PAYLOAD)) for _ in range(64)]
    buf = io.BytesIO()
    w = Writer(buf, chunk_size=1 << 16)
    w.start(profile="ros2", library="test")
    head = buf.tell()  # magic and header; the schema and channel go into the first chunk
    sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
    cid = w.register_channel("/big", "cdr", sid)
    for i in range(BLOCK_MESSAGES):
        w.add_message(cid, i * 1000, payloads[i % len(payloads)], i * 1000, i)
    # no finish(): a log cut short, as after SIGKILL; what is in `buf` are whole chunks, each
    # followed by its message indexes
    data = buf.getvalue()
    path = tmp_path_factory.mktemp("big") / "big.mcap"
    with open(path, "wb") as f:
        f.write(data[:head])
        for _ in range(BLOCK_COPIES):
            f.write(data[head:])
    return path


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.slow
def test_recover_interrupted_ends_at_once_and_leaves_no_output(big_log, tmp_path, sig):
    out = tmp_path / "fixed.mcap"
    cmd = Command("recover", big_log, "-o", out)
    cmd.wait_until(lambda: any(p.stat().st_size > RECOVER_WRITTEN for p in _partials(tmp_path)), "recover wrote 1 MB")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    line = _said_in_one_line(err, "recover")
    assert sig.name in line and "interrupted" in line
    assert not out.exists() and not _partials(tmp_path)


# --- run ------------------------------------------------------------------------------------------------
#: the simulated seconds of the interrupted runs: heavy_top runs at some 100 times real time (30
#: with --record), so they have a quarter of an hour of work left or more
RUN_DURATION = 100_000


@pytest.mark.slow
def test_run_interrupted_while_recording_publishes_the_closed_log_and_says_so(tmp_path):
    log = tmp_path / "run.mcap"
    cmd = Command("run", "--scene", "heavy_top", "--duration", RUN_DURATION, "--record", log, "--flush-period", "0.05")
    cmd.wait_until(lambda: any(p.stat().st_size > 50_000 for p in _partials(tmp_path)), "the log grew")
    assert not log.exists()  # nothing under the final name while the run goes on
    status, took, err = cmd.interrupt(signal.SIGTERM)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    line = _said_in_one_line(err, "run")
    assert "interrupted at t = " in line and f"closed and complete in {log}" in line
    assert read_info(log).message_count > 0  # well-formed: summary, footer, every CRC
    assert not _partials(tmp_path)


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.slow
def test_run_without_a_log_interrupted_says_so_in_one_line(sig):
    cmd = Command("run", "--scene", "heavy_top", "--duration", RUN_DURATION)
    cmd.wait_until(lambda: "t = " in cmd.stderr, "the run started")
    status, took, err = cmd.interrupt(sig)
    assert status == 1 and took < END_SECONDS, (status, took, err)
    assert sig.name in _said_in_one_line(err, "run")


# --- view ------------------------------------------------------------------------------------------------
#: the log `view` is interrupted in: heavy_top for LONG_SECONDS published at LONG_RATE (4e5
#: messages, made in 8 s): drawing it takes tens of seconds, all of it after the
#: temporary output the test waits for is made
LONG_SECONDS = 16.0
LONG_RATE = 5000.0
LONG_STEP = 2e-4  # rk4's fixed step, no longer than the publish period


@pytest.fixture(scope="module")
def long_log(tmp_path_factory):
    """A long heavy-top log: drawing it takes tens of seconds."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    path = tmp_path_factory.mktemp("long") / "long.mcap"
    record_run(Simulator(load_scene("heavy_top"), integrator="rk4", step=LONG_STEP), path, duration=LONG_SECONDS,
               chunk=0.005, publish_rate=LONG_RATE)
    return path


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.slow
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
#: 32 points of 600 s of heavy_top each (2.4 s of CPU a point): after the first part, 70 s of work
#: are left serially, 45 s on two workers
SWEEP = """
name: a grid to interrupt
scene: heavy_top
grid:
  bodies[0].com[2]: {linspace: [0.02, 0.1, 8]}
  bodies[0].initial.euler_rates[2]: [10.0, 30.0, 50.0, 70.0]
run: {integrator: dop853, rtol: 1.0e-9, atol: 1.0e-11, horizon: 600.0, chunk: 0.01}
measures: [max_tilt, cpu_time]
batch: 1
"""


@pytest.mark.parametrize("workers", [0, 2])
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.slow
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


# --- a signal that Python wraps -------------------------------------------------------------------------
class _SignalHere:
    """A class attribute whose ``__set_name__`` is where a signal's exception is raised."""

    def __set_name__(self, owner, name):
        raise Interrupted(signal.SIGINT)


def _class_created_under_a_signal(*args, **kwargs):
    """What a signal during the creation of a class raises (a module being imported that defines
    a dataclass, as mcap's records are when a log is first opened): Python 3.11 wraps it in a
    RuntimeError, later versions let it through."""
    class Chunk:
        data = _SignalHere()


def test_a_signal_while_a_log_is_opened_is_an_interrupt_not_a_damaged_log(recorded, monkeypatch):
    from gyro_sim.log import mcap_log

    log, _ = recorded
    monkeypatch.setattr(mcap_log, "_read_info", _class_created_under_a_signal)
    with pytest.raises(KeyboardInterrupt):
        with mcap_log.LogReader(log):
            pass


def test_view_interrupted_while_opening_the_log_says_so_and_leaves_nothing(recorded, tmp_path, monkeypatch,
                                                                           capsys):
    pytest.importorskip("rerun", reason="view needs rerun-sdk")
    from gyro_sim import cli
    from gyro_sim.log import mcap_log

    log, _ = recorded
    out = tmp_path / "view.rrd"
    monkeypatch.setattr(mcap_log, "_read_info", _class_created_under_a_signal)
    monkeypatch.setattr(cli, "end_after_interrupt", lambda: None)  # this process goes on
    assert cli.main(["view", str(log), "--save", str(out)]) == 1
    assert "SIGINT" in _said_in_one_line(capsys.readouterr().err, "view")
    assert not out.exists() and not _partials(tmp_path)


def test_a_wrapped_signal_that_reaches_the_cli_is_an_interrupt_not_a_traceback(recorded, tmp_path, monkeypatch,
                                                                               capsys):
    from gyro_sim import cli
    from gyro_sim.log import recover

    log, _ = recorded
    monkeypatch.setattr(recover, "recover", _class_created_under_a_signal)
    monkeypatch.setattr(cli, "end_after_interrupt", lambda: None)
    assert cli.main(["recover", str(log), "-o", str(tmp_path / "fixed.mcap")]) == 1
    assert "SIGINT" in _said_in_one_line(capsys.readouterr().err, "recover")


def test_a_signal_while_a_sweep_prepares_its_workers_is_not_swallowed(tmp_path, monkeypatch):
    from gyro_sim.scene import load
    from gyro_sim.sweep.execute import prepare_scene
    from gyro_sim.sweep.spec import load_sweep

    spec = tmp_path / "grid.yaml"
    spec.write_text(SWEEP)
    sweep = load_sweep(spec)
    monkeypatch.setattr(load, "load_scene", _class_created_under_a_signal)
    with pytest.raises(KeyboardInterrupt):
        prepare_scene(sweep, sweep.points[0])


# --- the start: imports, the parser, the first compile ---------------------------------------------
#: seconds after the entry point's first statement (main's): the subcommands' imports take a few
#: tenths of a second, the scene and the Simulator's start (kernels loaded) about a second more
START_DELAYS = (0.0, 0.005, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.8, 1.2, 2.0)
#: as the console script `gyro-sim` calls it (pip's wrapper imports gyro_sim.cli, then calls main)
CONSOLE_SCRIPT = "import sys; from gyro_sim.cli import main; sys.exit(main())"


@pytest.mark.slow
def test_a_signal_anywhere_in_the_start_of_a_command_ends_it_with_one_line():
    """A SIGINT or SIGTERM from the entry point's first statement on (the imports of the
    subcommands, the parser, the scene, the kernels' load, the run): exit 1 and the command's
    one line, as a later interrupt gives, never a traceback."""
    from test.conftest import signal_during_start

    cmd = [sys.executable, "-c", CONSOLE_SCRIPT, "run", "--scene", "hinge_chain", "--duration", "600"]
    failures = []
    for delay in START_DELAYS:
        for sig in SIGNALS:
            code, out, err = signal_during_start(cmd, dict(os.environ), sig, delay)
            said = [line for line in err.splitlines() if "interrupted" in line]  # (a cold cache's line before)
            ok = (code == 1 and "Traceback" not in err and len(said) == 1
                  and said[0].startswith(f"gyro-sim run: interrupted ({sig.name})"))
            if not ok:
                failures.append(f"{sig.name} after {delay} s: exit {code}: {err[-600:]}")
    assert not failures, "\n".join(failures)
