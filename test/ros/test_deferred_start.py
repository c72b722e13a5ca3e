"""A start on an empty kernel cache, without a terminal (stdin /dev/null, a session of its own:
a launch file, systemd, CI with the fill allowed): the node publishes from the start on the numpy
reference while a helper compiles its first step at the lowest priority, then switches to the
compiled kernels at a step boundary, and the log of that run re-simulates bit for bit (the
switch repeated at the same step).

What is asserted does not depend on the machine's speed: the start's line, that the run went on
numpy first and switched once (said on the console and in the log), and the re-simulation's
deviation, 0. The physics step is 10 ms (physics_rate 100 Hz), ten times what the numpy reference
takes on hinge_chain: the node's check that numpy keeps up (NUMPY_STEP_SHARE) passes however
busy the machine. How fast the first /joint_states comes is a benchmark (gyro-sim bench startup).
"""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from gyro_sim.log.mcap_log import read_info
from gyro_sim.log.resim import resimulate

from .helpers import ROOT, new_domain_id, node_command, ros_env, wait_for

#: the longest wait for the helper's compile of the first step at the lowest priority (s)
COMPILE_TIMEOUT = 900.0


def helpers_of(pid: int) -> list[int]:
    """The cache-fill helpers `pid` started (their environment names it: gyro_sim.warmup)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if f"GYRO_SIM_WARMUP_PARENT={pid}".encode() in (entry / "environ").read_bytes().split(b"\0"):
                    out.append(int(entry.name))
            except OSError:
                pass
    return out


@pytest.mark.slow
def test_a_cold_start_without_a_terminal_steps_on_numpy_then_switches_and_resimulates(tmp_path):
    (tmp_path / "ros_log").mkdir()
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    log = tmp_path / "run.mcap"
    env = ros_env(new_domain_id(), tmp_path / "ros_log")
    env.update(NUMBA_CACHE_DIR=str(cache), GYRO_SIM_BACKGROUND_FILL="1")
    env.pop("CI", None)
    err_path = tmp_path / "node.err"
    with open(err_path, "w") as err:
        node = subprocess.Popen(node_command("scene:=hinge_chain", "physics_rate:=100.0", "publish_rate:=50.0",
                                             "demo:=true", f"record:={log}"),
                                cwd=ROOT, env=env, stdin=subprocess.DEVNULL, stdout=err, stderr=subprocess.STDOUT,
                                start_new_session=True)
    helpers = []
    try:
        wait_for(lambda: "dynamics: numba from here" in err_path.read_text() or node.poll() is not None,
                 COMPILE_TIMEOUT, "the switch to the compiled kernels")
        helpers = helpers_of(node.pid)
        time.sleep(0.5)  # some steps on the compiled kernels
        node.send_signal(signal.SIGINT)
        assert node.wait(60) == 0, err_path.read_text()[-2000:]
    finally:
        if node.poll() is None:
            node.kill()
        for pid in helpers + helpers_of(node.pid):  # the rest of the fill: minutes of CPU, not this test's
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    said = err_path.read_text()
    assert "compiling the dynamics in the background" in said and "numpy dynamics" in said, said[-2000:]
    assert said.count("dynamics: numba from here") == 1
    assert read_info(log).params["dynamics"] == "numpy"
    res = resimulate(log)
    assert res.switches == 1 and res.compared > 0
    assert res.max_deviation == 0.0, res.report()


def test_a_scene_too_slow_on_numpy_for_its_rate_is_said_in_one_line_and_compiled_first(monkeypatch, capsys):
    """Where a physics step on numpy takes more than NUMPY_STEP_SHARE of the step, the node
    says so in one line and steps on the compiled kernels from the start (the compile done
    before real time, as without a background compile)."""
    from types import SimpleNamespace

    from gyro_sim import Simulator, warmup
    from gyro_sim.ros import node as node_module

    compiled = []
    monkeypatch.setattr(warmup, "_deferred", object())
    monkeypatch.setattr(warmup, "precompile", lambda *a, **kw: compiled.append(kw["integrator"]) or True)
    monkeypatch.setattr(node_module, "numpy_step_cost", lambda sim, dt: 0.95 * dt)
    cfg = SimpleNamespace(scene="hinge_chain", integrator="fixed", rtol=1e-8, atol=1e-10, dt=1e-3, backend="auto")
    stub = SimpleNamespace(sim=Simulator("hinge_chain", integrator="fixed", step=1e-3, backend="numpy"))
    node_module.GyroSimNode._numpy_or_compiled(stub, cfg)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "more than 90% of the 1 ms step: compiling the kernels before real time" in lines[0]
    assert compiled == ["fixed"] and not warmup.deferred() and stub.sim.backend == "numba"
    monkeypatch.setattr(warmup, "_deferred", object())
    monkeypatch.setattr(node_module, "numpy_step_cost", lambda sim, dt: 0.5 * dt)
    stub.sim = Simulator("hinge_chain", integrator="fixed", step=1e-3, backend="numpy")
    node_module.GyroSimNode._numpy_or_compiled(stub, cfg)
    assert stub.sim.backend == "numpy" and warmup.deferred() and compiled == ["fixed"]
    assert capsys.readouterr().err == ""
