"""The node's recorder (no rclpy): the exact bytes handed to it, in a log flushed every 0.2 s
by default (what SIGKILL can lose: at most that and the sender's period, 0.02 s), refusing an
existing file unless told."""
from __future__ import annotations

import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import DEFAULT_FLUSH_PERIOD, iter_messages
from gyro_sim.safe_paths import OutputError
from gyro_sim.ros.recorder import SEND_PERIOD, WRITER_NICE, LiveRecorder


@pytest.mark.slow
def test_live_recorder_writes_the_bytes_it_gets(tmp_path):
    sim = Simulator(load_scene("hinge_chain"))
    pub = M.Publication(sim.model.names)
    rec = LiveRecorder(str(tmp_path / "live.mcap"), scene=sim.scene, params={})
    assert rec.writer.flush_period == DEFAULT_FLUSH_PERIOD <= 0.2 and SEND_PERIOD <= 0.05
    sent = []
    for _ in range(5):
        t = M.time_ns(sim.time)
        for topic, msgtype, data in pub.messages(sim.snapshot(), t):
            rec.raw(topic, msgtype, t, data)
            sent.append((topic, t, data))
        sim.advance(0.01)
    rec.close()
    got = [(topic, t, data) for topic, _, t, data in iter_messages(tmp_path / "live.mcap", decode=False)
           if topic != M.ROBOT_DESCRIPTION]
    assert sorted(got) == sorted(sent) and rec.error is None
    with pytest.raises(OutputError):
        LiveRecorder(str(tmp_path / "live.mcap"), scene=sim.scene, params={})
    LiveRecorder(str(tmp_path / "live.mcap"), scene=sim.scene, params={}, overwrite=True).close()


def test_the_writer_process_runs_at_a_lower_priority_than_the_node(tmp_path):
    """The writer process yields the CPU to the node (its niceness WRITER_NICE above the node's,
    as far as the system's maximum of 19 allows)."""
    import os

    sim = Simulator(load_scene("hinge_chain"))
    rec = LiveRecorder(str(tmp_path / "nice.mcap"), scene=sim.scene, params={})
    try:
        assert WRITER_NICE > 0
        assert rec.writer.nice == min(19, os.getpriority(os.PRIO_PROCESS, 0) + WRITER_NICE)
    finally:
        rec.close()


#: publications handed over once the stopped writer has resumed and caught up
AFTER_RESUME = 10


@pytest.mark.slow
def test_a_stopped_writer_drops_the_oldest_publications_never_commands(tmp_path):
    """The writer process stopped (SIGSTOP): past max_backlog_bytes the oldest publications
    waiting are dropped whole and counted, the commands and events never; resumed, the log holds
    exactly what was not dropped, in the order handed over, and says how many records it holds."""
    import os
    import signal
    import time

    from gyro_sim.log.mcap_log import iter_messages
    from gyro_sim.ros.recorder import SEND_PERIOD

    sim = Simulator(load_scene("hinge_chain"))
    pub = M.Publication(sim.model.names)
    frame = pub.frame(sim.snapshot().joint_names, wrenches=True, poses=True, tf=True)
    rec = LiveRecorder(str(tmp_path / "stall.mcap"), scene=sim.scene, params={}, max_backlog_bytes=100_000)
    os.kill(rec._proc.pid, signal.SIGSTOP)
    sent, commands = [], []

    def publish() -> int:
        """One step and its publication handed over (kept in `sent`); its log time."""
        sim.advance(0.001)
        t = M.time_ns(sim.time)
        sim.snapshot(bodies=True, wrenches=True, invariants=False, into=frame.scatter)
        batch = frame.messages(t)
        rec.raw_batch(t, batch)
        sent.append((t, [(topic, bytes(data)) for topic, _, data in batch]))
        return t

    try:
        for i in range(3000):  # ~3 MB of publications: the pipe (1 MB) and the bound (0.1 MB) overflow
            t = publish()
            if i % 10 == 0:
                cmd = M.axis_moments([0.0, 1e-3 * i, 0.0])
                rec.raw_many("/gyro_sim/axis_moments", M.COMMAND_TYPE, t, [cmd])
                commands.append((t, cmd))
            if i % 100 == 0:
                time.sleep(2 * SEND_PERIOD)  # the sender takes what waits, drops, and writes what the pipe takes
        assert rec.dropped_publications > 0 and rec.failure is None
    finally:
        os.kill(rec._proc.pid, signal.SIGCONT)
    # resumed, the writer catches up; what comes after is kept whole
    deadline = time.monotonic() + 60.0
    while rec.backlog_bytes and time.monotonic() < deadline:
        time.sleep(SEND_PERIOD)
    assert rec.backlog_bytes == 0, "the writer did not catch up in 60 s"
    for _ in range(AFTER_RESUME):
        publish()
    rec.close()
    assert rec.complete and rec.error is None and rec.file == str(tmp_path / "stall.mcap")
    got = [(topic, t, bytes(d)) for topic, _, t, d in iter_messages(rec.file, decode=False, log_time_order=False)]
    assert rec.records_in_file == len(got)
    logged_cmds = [(t, d) for topic, t, d in got if topic == "/gyro_sim/axis_moments"]
    assert logged_cmds == commands  # every command, in order
    js_times = [t for topic, t, _ in got if topic == M.JOINT_STATES]
    kept = [(t, msgs) for t, msgs in sent if t in set(js_times)]
    assert len(sent) - len(kept) == rec.dropped_publications
    kept_times = {t for t, _ in kept}
    dropped = [i for i, (t, _) in enumerate(sent) if t not in kept_times]
    # the oldest waiting go first: those in the pipe before the stop stay, then one run is dropped;
    # everything after the writer resumed stays
    assert dropped == list(range(dropped[0], dropped[-1] + 1)) and 0 < dropped[0]
    assert dropped[-1] < len(sent) - AFTER_RESUME
    assert sum(len(m) for t, m in sent) - sum(len(m) for t, m in kept) == rec.dropped_records
    # what is kept is whole and in order: the records of each kept publication, as handed over
    pubs = [(topic, t, d) for topic, t, d in got if topic not in ("/gyro_sim/axis_moments", M.ROBOT_DESCRIPTION)]
    assert pubs == [(topic, t, d) for t, msgs in kept for topic, d in msgs]
