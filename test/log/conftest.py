"""The log tests' own fixture: a log of many chunks."""
from __future__ import annotations

import pytest

from test.conftest import CHUNK, DURATION, PUBLISH_RATE, SCENE, SCHEDULE, rosbags_messages


@pytest.fixture(scope="session")
def chunked(tmp_path_factory):
    """(path, [(chunk start, length)], rosbags messages) of a recorded log flushed every
    millisecond of wall time: many chunks."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    from test.log.crafted import chunk_offsets

    path = tmp_path_factory.mktemp("chunked") / "run.mcap"
    record_run(Simulator(load_scene(SCENE)), path, duration=DURATION, chunk=CHUNK, publish_rate=PUBLISH_RATE,
               schedule=SCHEDULE, flush_period=1e-3)
    chunks = chunk_offsets(path)
    assert len(chunks) >= 4, f"only {len(chunks)} chunks: the test needs a middle one"
    return path, chunks, rosbags_messages(path)
