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


def test_live_recorder_writes_the_bytes_it_gets(tmp_path):
    sim = Simulator(load_scene("hinge_chain"))
    pub = M.Publication(sim.model.names)
    rec = LiveRecorder(str(tmp_path / "live.mcap"), scene=sim.scene, params={})
    assert rec.writer.flush_period == DEFAULT_FLUSH_PERIOD <= 0.2 and SEND_PERIOD <= 0.05
    sent = []
    for i in range(5):
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
