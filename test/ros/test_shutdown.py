"""Every shutdown leaves the record path either holding a complete log or nothing: 30 SIGTERM
and 30 SIGINT at random moments of a recording node (during start-up and warm-up, in the first
second, during a reset, later). A signal during start-up gives the start up (exit 0, one line,
the file created for the log removed: nothing was recorded); later, the node exits 0 with its
summary and a log that rosbags reads completely.

The node owns its signal handling (gyro_sim.ros.node.Shutdown): after start-up a signal only
sets a flag, and the log is closed before rclpy's context goes away, so there is no race to
lose. The moments are drawn from a seeded generator: a failure names its case and can be
replayed.
"""
from __future__ import annotations

import concurrent.futures
import signal
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from std_srvs.srv import Trigger

from .helpers import DISCOVERY_TIMEOUT, Client, NodeProcess, new_domain_id, wait_for

RUNS_PER_SIGNAL = 30
SEED = 20261123
#: (mode, share of the runs): when the signal comes, counted from the moment the log file
#: exists (start-up: the node creates it early in its start) or the run starts (the others)
MODES = (("start-up", 0.25), ("first second", 0.35), ("reset", 0.2), ("later", 0.2))
WORKERS = 2


def cases() -> list[tuple[int, signal.Signals, str, float]]:
    rng = np.random.default_rng(SEED)
    names, shares = zip(*MODES)
    out = []
    for i in range(2 * RUNS_PER_SIGNAL):
        sig = signal.SIGTERM if i % 2 == 0 else signal.SIGINT
        mode = str(rng.choice(names, p=shares))
        delay = {"start-up": rng.uniform(0.0, 0.3), "first second": rng.uniform(0.3, 1.3),
                 "reset": rng.uniform(0.0, 0.5), "later": rng.uniform(1.3, 3.0)}[mode]
        out.append((i, sig, mode, float(delay)))
    return out


def read_completely(path: Path) -> dict:
    """topic -> count, every message deserialised by rosbags with the schemas in the file."""
    from rosbags.highlevel import AnyReader

    counts: dict[str, int] = {}
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


def one_run(tmp: Path, domain: int, client: Client, case) -> str | None:
    """Run one case; None if all is well, else what went wrong."""
    i, sig, mode, delay = case
    log = tmp / f"run{i}.mcap"
    node = NodeProcess(tmp, domain, "scene:=hinge_chain", "physics_rate:=250.0", "publish_rate:=50.0",
                       f"record:={log}", name=f"run{i}")
    try:
        wait_for(lambda: log.exists() or not node.alive(), 60.0, f"case {i}: the log file")
        if mode != "start-up":  # the others count from the run's start
            wait_for(lambda: "physics thread:" in node.stderr or not node.alive(), 60.0, f"case {i}: the run")
        if mode == "reset":
            cli = client.node.create_client(Trigger, "/gyro_sim/reset")
            if cli.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT):
                time.sleep(delay)
                cli.call_async(Trigger.Request())  # the signal follows while the reset is served
                time.sleep(0.002)
            client.node.destroy_client(cli)
        else:
            time.sleep(delay)
        rc = node.stop(sig, timeout=30.0)
    finally:
        node.stop(signal.SIGKILL)
    what = f"case {i} ({sig.name}, {mode}, {delay:.3f} s)"
    if rc != 0:
        return f"{what}: exit {rc}\n{node.stderr[-1500:]}"
    if f"{sig.name} during start-up: not started" in node.stderr:
        if log.exists() or list(tmp.glob(f"{log.name}.*")):
            return f"{what}: start given up, yet a file is left: {sorted(p.name for p in tmp.glob(log.name + '*'))}"
        return None
    if f"log written: {log}" not in node.stdout:
        return f"{what}: no 'log written' line\n{node.stdout[-500:]}"
    try:
        counts = read_completely(log)
    except Exception as exc:  # noqa: BLE001 - any reader error is the failure being tested for
        return f"{what}: rosbags cannot read the log: {type(exc).__name__}: {exc}"
    if "/robot_description" not in counts:
        return f"{what}: the log lacks the URDF: {counts}"
    return None


@pytest.mark.slow
def test_every_signal_at_every_moment_leaves_a_complete_log(tmp_path):
    todo = cases()
    assert {m for _, _, m, _ in todo} == {m for m, _ in MODES}
    lanes = [todo[k::WORKERS] for k in range(WORKERS)]

    def lane(runs):
        domain = new_domain_id()
        client = Client(domain, name=f"shutdown_test_{domain}")
        try:
            return [one_run(tmp_path, domain, client, c) for c in runs]
        finally:
            client.close()

    with concurrent.futures.ThreadPoolExecutor(WORKERS) as pool:
        results = [r for rs in pool.map(lane, lanes) for r in rs]
    failures = [r for r in results if r is not None]
    assert not failures, f"{len(failures)} of {len(results)} runs failed:\n" + "\n".join(failures)
