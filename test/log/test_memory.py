"""A long recording does not grow the writer's memory by the summary's chunk indexes: with a
chunk every 0.2 s, mcap's own ChunkIndex objects (about 1.3 kB each) would cost about 23 MB
per hour; gyro_sim's writer packs them (gyro_sim.log.mcap_log._PackedChunkIndexes)."""
from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest

from gyro_sim import load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import LogWriter

CHUNKS = 2000
CHANNELS = 12
#: bytes of memory per chunk kept until close (8 int64 + 2 uint32 per channel, with slack)
MAX_BYTES_PER_CHUNK = 300


@pytest.mark.slow
def test_chunk_indexes_cost_little_memory_and_the_summary_is_whole(tmp_path):
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    path = tmp_path / "long.mcap"
    w = LogWriter(path, scene=load_scene("hinge_chain"), params={}, flush_period=1e9)
    chs = [w.add_channel(f"/t{i}", "std_msgs/msg/String") for i in range(CHANNELS)]
    data = M.string("payload")
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for k in range(CHUNKS):
        for c in chs:
            w.write_raw(c, 1000 * k, data)
        w.flush()  # one chunk each, as the 0.2 s flush period makes them
    grown = sum(d.size_diff for d in tracemalloc.take_snapshot().compare_to(before, "filename"))
    tracemalloc.stop()
    w.close()
    assert grown / CHUNKS < MAX_BYTES_PER_CHUNK, grown / CHUNKS
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert len(summary.chunk_indexes) == CHUNKS  # the URDF's chunk and the first one share
    assert all(len(ci.message_index_offsets) >= CHANNELS for ci in summary.chunk_indexes[1:])
    with AnyReader([Path(path)]) as reader:  # an independent reader follows the indexes
        assert sum(1 for _ in reader.messages()) == CHUNKS * CHANNELS + 1
