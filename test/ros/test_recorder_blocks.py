"""The recorder's block transfer (no rclpy): a publication handed over with one call
(`LiveRecorder.raw_batch`) goes to the writer process as its frame's bytes block, the layout
once per frame; the log holds exactly the records handed over, in the order handed over, each
with its own log time, whether they came as blocks, as plain batches or one at a time (`raw`);
a node killed by SIGKILL still leaves a complete, readable log."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import iter_messages
from gyro_sim.ros import recorder as R
from gyro_sim.ros.recorder import LiveRecorder

ROOT = str(Path(__file__).resolve().parents[2])


def logged(path) -> list[tuple[str, int, bytes]]:
    return [(topic, t, bytes(data)) for topic, _, t, data in iter_messages(path, decode=False, log_time_order=False)
            if topic != M.ROBOT_DESCRIPTION]


def frame_batches(sim, pub, frame, count: int, t0: int = 0):
    """`count` publications cut from `frame`, the state advancing between them."""
    for _ in range(count):
        sim.advance(0.01)
        sim.snapshot(bodies=True, wrenches=True, invariants=False, into=frame.scatter)
        yield M.time_ns(sim.time) + t0, frame.messages(M.time_ns(sim.time) + t0)


def test_blocks_plain_batches_and_lone_records_are_logged_as_handed_over(tmp_path):
    sim = Simulator(load_scene("hinge_chain"))
    pub = M.Publication(sim.model.names)
    names = sim.snapshot().joint_names
    frames = [pub.frame(names, wrenches=True, poses=True, tf=True),
              pub.frame(names, wrenches=False, poses=False, tf=True)]
    rec = LiveRecorder(str(tmp_path / "blocks.mcap"), scene=sim.scene, params={})
    sent = []
    for i in range(12):
        frame = frames[(i // 3) % 2]  # a second layout, then the first again
        (t, batch), = frame_batches(sim, pub, frame, 1)
        assert isinstance(batch, M.FrameBatch) and batch.layout is frame.layout
        if i % 4 == 0:  # the diagnostics ride after the block's records
            batch.append((M.DIAGNOSTICS, M.DIAGNOSTICS_TYPE, M.diagnostic_array(t, [M.Status("run", {"i": i})])))
        rec.raw_batch(t, batch)
        sent += [(topic, t, data) for topic, _, data in batch]
        cmd = M.string(f"command {i}")  # a lone record with its own, earlier time
        rec.raw("/gyro_sim/events", M.STRING_TYPE, t - 1000, cmd)
        sent.append(("/gyro_sim/events", t - 1000, cmd))
        if i == 5:  # a plain list, as the first publication of a node or diagnostics alone
            plain = pub.messages(sim.snapshot(), t + 1)
            rec.raw_batch(t + 1, plain)
            sent += [(topic, t + 1, data) for topic, _, data in plain]
        if i % 3 == 2:
            time.sleep(2 * R.SEND_PERIOD)  # some wake-ups with one item, some with many
    rec.close()
    assert rec.error is None and rec.written == len(sent)
    assert logged(tmp_path / "blocks.mcap") == sent  # file order = hand-over order, the exact bytes


def test_packer_sends_each_layout_once_and_blocks_unpickled():
    sim = Simulator(load_scene("hinge_chain"))
    pub = M.Publication(sim.model.names)
    frame = pub.frame(sim.snapshot().joint_names, wrenches=True, poses=True, tf=True)
    items = list(frame_batches(sim, pub, frame, 3))
    p = R._Packer()
    bufs, count = p.pack(items)
    kinds = [b[:1] for b in bufs[::2]]
    assert kinds == [b"L", b"B", b"B", b"B"] and count == 3 * len(frame.layout)
    assert all(block is batch.block for block, (_, batch) in zip(bufs[3::2], items))  # not copied
    bufs, _ = p.pack(items[:1])
    assert [b[:1] for b in bufs[::2]] == [b"B"]


def test_partial_pipe_writes_are_completed():
    r, w = os.pipe()
    try:
        data = [b"a" * 70_000, b"b" * 3, memoryview(b"c" * 100_000)]
        got = bytearray()

        def drain():
            while len(got) < 170_003:
                got.extend(os.read(r, 65536))

        import threading

        th = threading.Thread(target=drain)
        th.start()
        R._write_all(w, list(data))  # more than a default pipe holds: partial writes
        th.join(10)
        assert bytes(got) == b"".join(bytes(d) for d in data)
    finally:
        os.close(r)
        os.close(w)


_KILLED = r"""
import sys, time
from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.ros.recorder import LiveRecorder, SEND_PERIOD
sim = Simulator(load_scene("hinge_chain"))
pub = M.Publication(sim.model.names)
frame = pub.frame(sim.snapshot().joint_names, wrenches=True, poses=True, tf=True)
rec = LiveRecorder(sys.argv[1], scene=sim.scene, params={})
n = 0
for i in range(20):
    sim.advance(0.01)
    sim.snapshot(bodies=True, wrenches=True, invariants=False, into=frame.scatter)
    batch = frame.messages(M.time_ns(sim.time))
    rec.raw_batch(M.time_ns(sim.time), batch)
    n += len(batch)
time.sleep(10 * SEND_PERIOD)  # handed over to the writer process
print(n, flush=True)
time.sleep(60)
"""


@pytest.mark.slow
def test_sigkill_leaves_a_complete_log(tmp_path):
    from mcap.reader import make_reader

    log = tmp_path / "killed.mcap"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", _KILLED, str(log)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        sent = int(proc.stdout.readline())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 20.0  # the writer process sees the end of its input and writes the summary
    summary = None
    while summary is None and time.monotonic() < deadline:
        try:
            with open(log, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - not finished yet
            summary = None
        if summary is None:
            time.sleep(0.1)
    assert summary is not None, "no summary: the log was not finished"
    assert len(logged(log)) == sent == summary.statistics.message_count - 1  # and the robot description


def test_an_existing_log_is_refused_in_the_node(tmp_path):
    from gyro_sim.safe_paths import OutputError

    path = tmp_path / "kept.mcap"
    path.write_bytes(b"keep me")
    with pytest.raises(OutputError):
        LiveRecorder(str(path), scene=load_scene("hinge_chain"), params={})
    assert path.read_bytes() == b"keep me"
