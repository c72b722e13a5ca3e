"""LogReader: a log opened once, verified on entry, its info and messages as the functions give them."""
from __future__ import annotations

import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.log import mcap_log
from gyro_sim.log.mcap_log import LogError, LogReader, iter_messages, read_info
from gyro_sim.log.record import record_run

from test.conftest import SCENE
from test.log.crafted import chunk_offsets, flip


@pytest.fixture
def log(tmp_path):
    """A short offline log of the shipped test scene, in several chunks."""
    path = tmp_path / "run.mcap"
    record_run(Simulator(load_scene(SCENE)), path, duration=0.5, flush_period=1e-3)
    return path


def test_one_open_gives_the_info_and_the_messages_the_functions_give(log, monkeypatch):
    opened = []
    real = mcap_log._open
    monkeypatch.setattr(mcap_log, "_open", lambda path: opened.append(path) or real(path))
    with LogReader(log) as reader:
        info = reader.info
        names = reader.topic_names()
        first = list(reader.messages(decode=False))
        again = list(reader.messages([names.joint_states], decode=False))
    assert len(opened) == 1
    expected = read_info(log)
    assert (info.params, info.topics, info.scene_yaml, info.message_count) == \
        (expected.params, expected.topics, expected.scene_yaml, expected.message_count)
    assert first == list(iter_messages(log, decode=False)) and len(first) == info.message_count
    assert again == [m for m in first if m[0] == names.joint_states] and again


def test_a_damaged_log_is_refused_on_entry_naming_the_chunk(log, tmp_path):
    start, length = chunk_offsets(log)[-1]
    damaged = flip(log, tmp_path / "damaged.mcap", start + length // 2)  # inside its compressed records
    with pytest.raises(LogError, match=rf"damaged log: chunk at byte {start}: .*gyro-sim recover"):
        with LogReader(damaged):
            pass
