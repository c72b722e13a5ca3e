"""The physics loop in lock-step and holding its initial state, without ROS: one control period
per command, in the order received, the same states as the Simulator stepped offline with the
same commands, bit for bit; resets, the queue's bound, the duration; the hold until a command."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from gyro_sim.msgs import messages as M
from gyro_sim.ros.command_path import LOCKSTEP_QUEUE
from gyro_sim.ros.loop import Reset, SimLoop, warm_up
from gyro_sim.ros.params import ParameterError, validate
from gyro_sim.simulator import Simulator

from .test_pacing import FakeClock, Outputs

PARAMS = {"scene": "rw_pendulum", "physics_rate": 1000.0, "publish_rate": 100.0, "thread_priority": 0,
          "lockstep": True}


class Controller(Outputs):
    """The fake outputs, answering each state sent with a command computed from it (a
    proportional law on the pendulum's angle), submitted to the loop at once."""

    def __init__(self, answers: int):
        super().__init__()
        self.loop, self.answers = None, answers

    def send(self, t, batch):
        super().send(t, batch)
        if self.answers > 0:
            self.answers -= 1
            angle = float(batch[1][0])  # the pendulum's position
            self.loop.submit_command(M.axis_moments([0.0, 2.0 * angle]), [0.0, 2.0 * angle])


def make(out, **params):
    cfg = validate({**PARAMS, **params})
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    warm_up(sim, cfg.dt)
    clock = FakeClock()
    loop = SimLoop(sim, cfg, out, clock=clock, sleep=clock.sleep)
    out.loop = loop
    return loop, cfg


def run(loop, cond, limit=60.0):
    th = threading.Thread(target=loop._run, daemon=True)
    th.start()
    t0 = time.monotonic()
    while not cond() and th.is_alive() and time.monotonic() - t0 < limit:
        time.sleep(0.002)
    loop._stop.set()
    th.join(10)


def offline(cfg, commands):
    """The states the Simulator reaches with `commands`, each held one control period."""
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    warm_up(sim, cfg.dt)
    states = [np.array(sim.joint_states().position)]
    for u in commands:
        sim.set_axis_moments(u)
        for _ in range(cfg.steps_per_publish):
            sim.advance(cfg.dt)
        states.append(np.array(sim.joint_states().position))
    return states


def test_one_period_per_command_the_same_states_as_offline_bit_for_bit():
    out = Controller(answers=30)
    loop, cfg = make(out)
    run(loop, lambda: len(out.states) >= 31)
    time.sleep(0.2)  # nothing more comes: no command, no period
    assert len(out.states) == 31
    t = [s[0] for s in out.states]
    assert t == [k * 10_000_000 for k in range(31)]  # the initial state, then one per period
    commands = [s[2] for s in out.states[1:]]  # the moments applied over each period
    assert all(c == [0.0, 2.0 * float(s[1][0])] for c, s in zip(commands, out.states))
    for mine, ref in zip([s[1] for s in out.states], offline(cfg, commands)):
        np.testing.assert_array_equal(mine, ref)
    # every command applied, each logged at the start of its period, none superseded or timed out
    c = loop.commands.counters
    assert c.accepted == 30 and c.superseded == 0 and c.timeouts == 0
    assert [t for t, _ in out.commands] == [k * 10_000_000 for k in range(30)]
    assert loop.commands.latency.run.n == 29  # the first came while the loop held: not timed
    assert loop.summary()["real_time_factor_target"] == 0.0


def test_commands_waiting_are_applied_in_order_one_period_each():
    out = Outputs()
    loop, cfg = make(out)
    sent = [[0.0, 0.01 * k] for k in range(5)]
    for u in sent:
        loop.submit_command(M.axis_moments(u), u)
    run(loop, lambda: len(out.states) >= 6)
    assert [s[2] for s in out.states[1:]] == sent
    assert loop.commands.counters.superseded == 0 and [t for t, _ in out.commands] == [k * 10_000_000
                                                                                      for k in range(5)]


def test_duration_ends_a_lockstep_run_after_its_last_period():
    out = Controller(answers=1000)
    loop, cfg = make(out, duration=0.2)
    run(loop, lambda: loop.finished.is_set())
    assert loop.finished.is_set() and loop.node_time == pytest.approx(0.2)
    assert len(out.states) == 21 and loop.commands.counters.accepted == 21  # the last one never applied
    assert out.commands[-1][0] == 200_000_000  # logged at the end, at the last node time


def test_a_reset_discards_the_commands_waiting_and_publishes_the_reset_state():
    out = Outputs()
    loop, cfg = make(out)
    for u in ([0.0, 0.05], [0.0, 0.05]):
        loop.submit_command(M.axis_moments(u), u)
    run(loop, lambda: len(out.states) >= 3)
    for u in ([0.0, 0.1], [0.0, 0.1]):
        loop.submit_command(M.axis_moments(u), u)  # waiting: the loop takes them once it runs again
    assert loop._handle(Reset()).startswith("reset")
    assert loop.commands.waiting == 0
    # the reset state published at the reset's node time; the discarded commands logged before the reset
    assert out.states[-1][0] == 20_000_000 and out.states[-1][1][0] == pytest.approx(0.1)
    assert [t for t, _ in out.commands] == [0, 10_000_000, 20_000_000, 20_000_000]
    events = [(t, text) for kind, t, text in out.log if kind == "event"]
    assert events[-1] == (20_000_000, "reset")


def test_a_full_queue_rejects_commands():
    out = Outputs()
    loop, cfg = make(out)
    for _ in range(LOCKSTEP_QUEUE):
        assert loop.submit_command(b"u", [0.0, 0.0]) is None
    assert "already waiting" in loop.submit_command(b"u", [0.0, 0.0])
    assert loop.commands.counters.rejected == 1 and loop.commands.waiting == LOCKSTEP_QUEUE


def test_hold_until_command_holds_the_initial_state_then_runs_in_real_time():
    out = Outputs()
    loop, cfg = make(out, lockstep=False, hold="until_command", command_timeout=1e6)
    clock = loop.clock
    th = threading.Thread(target=loop._run, daemon=True)
    th.start()
    time.sleep(0.3)  # held: the fake clock does not move without a sleep of the loop, nor does the state
    assert len(out.states) == 1 and loop.steps == 0 and loop.holding
    start = clock.t
    loop.submit_command(b"u", [0.0, 0.02])
    t0 = time.monotonic()
    while len(out.states) < 11 and time.monotonic() - t0 < 30:
        time.sleep(0.002)
    loop._stop.set()
    th.join(10)
    assert not loop.holding and out.states[1][2] == [0.0, 0.02]  # the first command from the first step
    assert out.commands[0][0] == 0
    # paced from the command on: node time 0.1 s at 0.1 s of (fake) wall time after it
    assert loop.pacing.pacer.deadline(0.1) == pytest.approx(start + 0.1, abs=0.01)


@pytest.mark.parametrize("params, message", [({"demo": True}, "demo: not with lockstep"),
                                             ({"lockstep": False, "hold": "until_command", "demo": True},
                                              "demo: not with hold until_command"),
                                             ({"lockstep": False, "hold": "later"}, "hold: unknown 'later'")])
def test_refused(params, message):
    with pytest.raises(ParameterError, match=message):
        validate({**PARAMS, **params})


def test_paused_no_period_advances_and_the_commands_wait_in_order():
    from gyro_sim.ros.loop import Pause

    out = Outputs()
    loop, cfg = make(out)
    th = threading.Thread(target=loop._run, daemon=True)
    th.start()
    try:
        loop.submit_command(M.axis_moments([0.0, 0.01]), [0.0, 0.01])
        t0 = time.monotonic()
        while len(out.states) < 2 and time.monotonic() - t0 < 30:  # the initial state, the first period
            time.sleep(0.002)
        assert loop.request(Pause(True), timeout=10)[0]
        n = len(out.states)
        assert n == 2
        sent = [[0.0, 0.02], [0.0, 0.03]]
        for u in sent:
            loop.submit_command(M.axis_moments(u), u)
        time.sleep(0.3)  # paused: nothing advances, nothing more is logged
        assert len(out.states) == n and loop.commands.waiting == 2 and len(out.commands) == 1
        assert loop.request(Pause(False), timeout=10)[0]
        t0 = time.monotonic()
        while len(out.states) < 4 and time.monotonic() - t0 < 30:
            time.sleep(0.002)
    finally:
        loop._stop.set()
        th.join(10)
    assert [s[2] for s in out.states[2:]] == sent and [t for t, _ in out.commands] == [0, 10_000_000, 20_000_000]
