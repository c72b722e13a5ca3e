"""Shared fixtures of the log tests: a short recorded run with non-zero commands."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: hinge_chain has spherical joints, hinges, an actuated rotor: every kind of joint state
SCENE = ROOT / "config" / "hinge_chain.yaml"
#: (t, axis moments) for hinge_chain's axes (wheel2, arm3, arm4)
SCHEDULE = [(0.0, [0.001, 0.0, 0.0]), (0.1, [0.0, 0.02, -0.01]), (0.23, [-0.002, -0.01, 0.03])]
DURATION = 0.4
PUBLISH_RATE = 50.0
CHUNK = 0.005


def gyro_sim(*args, timeout=120, **kw):
    """Run the CLI in a subprocess (the whole environment passed on: the ROS wheels need theirs)."""
    return subprocess.run([sys.executable, "-m", "gyro_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=dict(os.environ), **kw)


@pytest.fixture(scope="session")
def recorded(tmp_path_factory):
    """(path, RunRecord) of a 0.4 s hinge_chain run with commands, published at 50 Hz."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    path = tmp_path_factory.mktemp("log") / "run.mcap"
    sim = Simulator(load_scene(SCENE))
    rec = record_run(sim, path, duration=DURATION, chunk=CHUNK, publish_rate=PUBLISH_RATE, schedule=SCHEDULE)
    return path, rec


def rosbags_messages(path) -> list[tuple[str, int]]:
    """(topic, log time) of every message in file order, each deserialised by rosbags (an
    independent reader)."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([Path(path)]) as reader:
        for con, t, raw in reader.messages():
            reader.deserialize(raw, con.msgtype)
            out.append((con.topic, t))
    return out


@pytest.fixture(scope="session")
def chunked(tmp_path_factory):
    """(path, [(chunk start, length)], rosbags messages) of a recorded log flushed every
    millisecond of wall time: many chunks."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.log.record import record_run

    from .crafted import chunk_offsets

    path = tmp_path_factory.mktemp("chunked") / "run.mcap"
    record_run(Simulator(load_scene(SCENE)), path, duration=DURATION, chunk=CHUNK, publish_rate=PUBLISH_RATE,
               schedule=SCHEDULE, flush_period=1e-3)
    chunks = chunk_offsets(path)
    assert len(chunks) >= 4, f"only {len(chunks)} chunks: the test needs a middle one"
    return path, chunks, rosbags_messages(path)
