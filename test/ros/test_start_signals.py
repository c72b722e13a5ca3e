"""A SIGINT or SIGTERM at any moment of the node's start, its imports included, ends it with one
line and the exit status the node's own handling gives (0; docs/ros-interface.md): never
Python's KeyboardInterrupt traceback (exit -2).

The node is started as its console script starts it (gyro_sim.ros.start, whose first statement
sets what a signal does, before it imports rclpy, numpy and numba: about a second). Each case
waits until that statement has run (the process catches SIGTERM, which Python leaves at the
system's default: `catches`), then a fixed delay of a sweep over the imports, the parameters,
rclpy's start, the scene and the warm-up and the first moments of the run. Whatever the delay
hits, the outcome is one of two, both checked: the start given up ("during start-up: not
started"), or the run stopped ("stopped at node time"), exit 0 either way; the verdict does not
depend on which one a loaded machine makes of a given delay.
"""
from __future__ import annotations

import concurrent.futures
import signal

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from gyro_sim.ros import start_signal_line
from test.conftest import signal_during_start

from .helpers import new_domain_id, node_command, ros_env

#: seconds after the entry point's first statement: the imports take about 1 s, the start 1-3 s
DELAYS = (0.0, 0.01, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.65, 0.8, 1.0, 1.3, 1.7, 2.2, 3.0)
CASES = [(sig, d) for d in DELAYS for sig in (signal.SIGINT, signal.SIGTERM)]
WORKERS = 2


def verdict(signum: int, code, out: str, err: str) -> str | None:
    """None when the run ended as promised, else what went wrong."""
    name = signal.Signals(signum).name
    said = out + err
    if code is None:
        return "did not end"
    if "Traceback" in said or "KeyboardInterrupt" in said:
        return f"a traceback (exit {code}):\n{err[-1500:]}"
    if code != 0:
        return f"exit {code}:\n{err[-800:]}"
    gave_up = said.count(start_signal_line(name))
    stopped = said.count(f"gyro_sim_node: {name}: stopped at node time")
    if gave_up + stopped != 1:
        return f"{gave_up} start-up lines and {stopped} stop lines:\n{said[-800:]}"
    return None


@pytest.mark.slow
def test_a_signal_anywhere_in_the_start_ends_it_with_one_line(tmp_path):
    (tmp_path / "ros_log").mkdir()
    cmd = node_command("scene:=hinge_chain", "physics_rate:=250.0", "publish_rate:=50.0")

    def run(case):
        sig, delay = case
        env = ros_env(new_domain_id(), tmp_path / "ros_log")
        return case, verdict(sig, *signal_during_start(cmd, env, sig, delay))

    with concurrent.futures.ThreadPoolExecutor(WORKERS) as pool:
        failures = [f"{signal.Signals(s).name} after {d} s: {why}" for (s, d), why in pool.map(run, CASES) if why]
    assert not failures, "\n".join(failures)
