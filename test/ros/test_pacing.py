"""The physics loop without ROS: pacing against a fake clock, commands, timeout, reset, pause."""
from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from gyro_sim.simulator import Simulator
from gyro_sim.paths import find_scene
from gyro_sim.ros.loop import Pause, Reset, SimLoop, check_command, warm_up
from gyro_sim.ros.pacing import Floor, Pacer, chunk_steps, realtime_priority
from gyro_sim.ros.params import ParameterError, validate


class FakeClock:
    """A time.monotonic / time.sleep pair: time passes only by sleeping (or as a test says)."""

    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def sleep(self, s):
        self.t += max(s, 0.0) + 5e-5  # a sleep overshoots a little


class Outputs:
    def __init__(self):
        self.states, self.events, self.commands, self.diags = [], [], [], []
        self.log = []  # what would go to the log, in order: ("command" | "event", t, bytes or text)

    def prepare_state(self, t, sim, diagnostics_run=False):
        if diagnostics_run is not False:
            self.diags.append((t, diagnostics_run))
        return (t, np.array(sim.joint_states().position), list(sim.axis_moments))

    def send(self, t, batch):
        self.states.append(batch)

    def publish_diagnostics(self, t, sim, run):
        self.diags.append((t, run))

    def record_commands(self, t, raws):
        self.commands += [(t, raw) for raw in raws]
        self.log += [("command", t, raw) for raw in raws]

    def record_event(self, t, text):
        self.log.append(("event", t, text))

    def event(self, t, text, level="info"):
        self.events.append((t, text))
        self.record_event(t, text)


def make_loop(clock, step_cost=0.0, **params):
    # the fake clock's loop never sleeps: a SCHED_FIFO thread that never sleeps would hold a CPU
    params = {"thread_priority": 0, **params}
    cfg = validate({"scene": "hinge_chain", "physics_rate": 250.0, "publish_rate": 50.0, **params})
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    if step_cost:
        advance = sim.advance

        def slow(dt):
            advance(dt)
            clock.t += step_cost

        sim.advance = slow
    out = Outputs()
    warm_up(sim, cfg.dt)
    return SimLoop(sim, cfg, out, clock=clock, sleep=clock.sleep), out


def test_chunk_steps():
    assert chunk_steps(10, 1e-3, 1.0) == 2  # 1 kHz / 100 Hz: wake every 2 ms
    assert chunk_steps(5, 4e-3, 1.0) == 1
    assert chunk_steps(10, 1e-3, 0.0) == 10  # as fast as possible: a publication per wake-up
    assert chunk_steps(10, 1e-4, 1.0) == 10


def test_pacer_absorbs_jitter_catches_up_a_little_and_slips_when_far_behind():
    clock = FakeClock()
    p = Pacer(1.0, tolerance=1e-3, catch_up=0.02, clock=clock, sleep=clock.sleep)
    assert p.wait(0.002) and clock.t == pytest.approx(100.002, abs=1e-4)
    clock.t += 0.0025  # 0.5 ms late: within a physics period, not a miss
    assert p.wait(0.004) and p.misses == 0
    clock.t += 0.007  # 5 ms late (a delayed wake-up): a miss, made up without slipping
    assert not p.wait(0.006) and p.misses == 1 and p.slipped == 0
    assert p.lag(0.006) == pytest.approx(0.005, abs=1e-3)
    assert not p.wait(0.008) and p.misses == 2  # due at once: the steps run back to back
    clock.t += 0.050  # far behind: a miss, the schedule slips, no catching up
    assert not p.wait(0.010) and p.misses == 3
    assert p.slipped == pytest.approx(0.053, abs=2e-3) and p.lag(0.010) == pytest.approx(0.0, abs=1e-9)
    assert p.wait(0.012) and clock.t == pytest.approx(p.deadline(0.012), abs=1e-4)


def run_until(loop, cond, limit=10_000):
    """Run the loop's thread body until `cond()` (the fake clock makes it deterministic)."""
    loop._stop.clear()
    th = threading.Thread(target=loop._run, daemon=True)
    th.start()
    t0 = time.monotonic()
    while not cond() and time.monotonic() - t0 < 60:
        time.sleep(0.001)
    loop._stop.set()
    th.join(10)


def test_loop_tracks_wall_time_and_applies_commands_at_the_next_step():
    clock = FakeClock()
    loop, out = make_loop(clock, command_timeout=1e6)
    loop.submit_command(b"x", [0.0, 0.05, -0.03])
    assert loop.submit_command(b"bad", [1.0]) and loop.submit_command(b"nan", [np.nan, 0, 0])
    run_until(loop, lambda: len(out.states) >= 50)
    t = np.array([s[0] for s in out.states])
    assert np.all(np.diff(t) == 20_000_000)  # ns
    assert loop.pacing.pacer.misses == 0 and abs(loop.pacing.pacer.lag(loop.node_time)) <= loop.dt
    # the good command recorded at the step it took effect; the bad ones counted and logged as
    # events with their reasons (their values never reach the log)
    assert out.commands == [(0, b"x")]
    rejected = [text for kind, _, text in out.log if kind == "event" and text.startswith("command rejected")]
    assert rejected == ["command rejected (expected 3 values (one per axis), got 1)",
                        "command rejected (holds NaN or inf)"]
    assert out.states[0][2] == [0.0, 0.0, 0.0] and out.states[1][2] == [0.0, 0.05, -0.03]
    assert loop.commands.counters.accepted == 1 and loop.commands.counters.rejected == 2


def test_loop_slow_cpu_counts_misses_and_never_bursts():
    clock = FakeClock()
    loop, out = make_loop(clock, step_cost=6e-3)  # a step costs 6 ms of wall time for 4 ms simulated
    run_until(loop, lambda: len(out.states) >= 20)
    s = loop.summary()
    assert loop.pacing.pacer.misses > 10
    assert s["real_time_factor_achieved"] == pytest.approx(4 / 6, rel=0.05)


def test_loop_timeout_zeroes_moments_and_reset_restarts():
    clock = FakeClock()
    loop, out = make_loop(clock, command_timeout=0.1)
    loop.submit_command(b"x", [0.0, 0.05, 0.0])
    run_until(loop, lambda: loop.node_time > 0.3)
    assert loop.commands.counters.timeouts == 1 and np.all(loop.sim.axis_moments == 0)
    assert any("timeout" in e for _, e in out.events)
    n = len(out.states)
    loop.requests.post(Reset())
    run_until(loop, lambda: len(out.states) > n + 2)
    t_reset = [t for t, e in out.events if e == "reset"][0]
    assert loop.time.offset_ns == t_reset
    ref = Simulator(find_scene("hinge_chain"), integrator="rk4", step=0.004)
    after = [s for s in out.states if s[0] > t_reset][0]
    for _ in range(round((after[0] - t_reset) / 4e6)):
        ref.advance(0.004)
    assert np.max(np.abs(after[1] - np.array(ref.joint_states().position))) < 1e-12


def test_check_command_and_validate():
    assert check_command([1.0, 2.0], 2) is None
    assert "expected 2" in check_command([1.0], 2)
    assert "NaN" in check_command([np.inf, 0.0], 2)
    with pytest.raises(ParameterError) as e:
        validate({"physics_rate": 0.0, "publish_rate": 7.0, "integrator": "x", "scene": ""})
    msg = str(e.value)
    assert "physics_rate: must be >= 1" in msg and "integrator: unknown 'x'" in msg and "scene: empty" in msg
    cfg = validate({"physics_rate": 1000, "duration": 5})  # integers accepted for numbers
    assert cfg.physics_rate == 1000.0 and cfg.steps_per_publish == 10


def test_diagnostics_go_with_every_tenth_of_a_simulated_second():
    clock = FakeClock()
    loop, out = make_loop(clock)  # publish 50 Hz: every 5th publication
    run_until(loop, lambda: loop.node_time > 0.45)
    times = [t for t, _ in out.diags]
    assert times[:5] == [0, 100_000_000, 200_000_000, 300_000_000, 400_000_000]
    run = out.diags[-1][1]
    assert run.name == "gyro_sim: run" and run.values["state"] == "running"
    assert all(isinstance(v, (int, float)) for k, v in run.values.items() if k not in ("state", "backend"))


def test_a_bounded_run_that_fails_ends_at_once():
    """duration set, then a divergent command: the loop stops with the failure (node exit 1)."""
    clock = FakeClock()
    loop, out = make_loop(clock, duration=8.0)
    loop.submit_command(b"x", [1e300, 1e300, 1e300])
    loop.start()
    assert loop.finished.wait(60.0), "the loop did not end"
    loop.stop()
    assert loop.failure is not None and loop.node_time < 8.0
    assert any("simulation stopped" in e for _, e in out.events)
    assert out.diags[-1][1].level == 2 and "reason" in out.diags[-1][1].values


def test_histogram_quantiles_in_constant_memory():
    """Whole-run statistics do not grow with the run (issue: 2.1 MB/min of sample lists)."""
    from gyro_sim.ros.pacing import HIST_RATIO, Histogram

    rng = np.random.default_rng(1)
    xs = rng.lognormal(mean=np.log(1e-4), sigma=0.8, size=200_000)
    h = Histogram()
    nbytes = h.counts.nbytes
    for x in xs:
        h.add(float(x))
    assert h.counts.nbytes == nbytes and h.n == xs.size
    for q, ref in zip((50, 90, 99), np.percentile(xs, [50, 90, 99])):
        assert abs(h.quantiles(q)[0] / ref - 1) < HIST_RATIO - 1 + 1e-3, q
    assert h.quantiles(100)[0] == xs.max() and h.mean == pytest.approx(xs.mean(), rel=1e-9)
    assert all(np.isnan(Histogram().quantiles(50, 100)))


def test_a_command_flood_keeps_only_the_latest_for_the_next_step():
    """Bounded intake: 10,000 commands between two steps are one command applied, the rest
    counted as superseded; all of them go to the log at that step's time, in the order
    received, the applied one last (one hand-over); bad ones are counted, never applied."""
    clock = FakeClock()
    # no timeout: on the fake clock the loop may run far past `steps >= 3` before it is stopped
    loop, out = make_loop(clock, command_timeout=1e6)
    for i in range(10_000):
        assert loop.submit_command(b"%d" % i, [0.0, 1e-6 * i, 0.0]) is None
    assert loop.submit_command(b"bad", [0.0, float("nan"), 0.0]) is not None
    run_until(loop, lambda: loop.steps >= 3)
    assert out.commands == [(0, b"%d" % i) for i in range(10_000)]
    assert loop.sim.axis_moments[1] == pytest.approx(1e-6 * 9999)
    counters = loop.commands.counters
    assert counters.accepted == 10_000 and counters.superseded == 9_999 and counters.rejected == 1


def test_gc_pauses_are_timed_from_the_collectors_callbacks():
    from gyro_sim.ros.loop_pacing import GcPauses

    clock = FakeClock()
    meter = GcPauses(clock=clock)
    meter("stop", {"generation": 0})  # a stop without its start (installed mid-collection): not counted
    for pause in (2e-4, 3e-3):
        meter("start", {"generation": 2})
        clock.t += pause
        meter("stop", {"generation": 2})
    assert meter.pauses.n == 2
    assert meter.pauses.max == pytest.approx(3e-3)
    assert meter.pauses.total == pytest.approx(3.2e-3)


def test_start_freezes_the_start_up_heap_and_times_collections():
    import gc

    clock = FakeClock()
    loop, out = make_loop(clock)
    before = [object(), [1, 2]]  # a tracked container made during the start-up
    assert any(o is before for o in gc.get_objects())
    loop.start()
    try:
        # the physics thread, running by now, may free frozen objects (it replaces lists made at
        # start-up): the count can only have gone down since the freeze, never up
        assert 0 < gc.get_freeze_count() <= loop.pacing.frozen
        assert not any(o is before for o in gc.get_objects())  # out of every generation the collector scans
        assert loop.pacing.gc_pauses in gc.callbacks
        n = loop.pacing.gc_pauses.pauses.n
        gc.collect()
        assert loop.pacing.gc_pauses.pauses.n == n + 1
    finally:
        loop.stop()
    assert loop.pacing.gc_pauses not in gc.callbacks
    s = loop.summary()
    assert s["gc_collections"] >= 1 and s["gc_frozen_objects"] == loop.pacing.frozen


def test_run_delay_and_host_steal_read_the_kernels_figures(tmp_path):
    import math

    from gyro_sim.ros.pacing import RunDelay, host_steal

    f = tmp_path / "schedstat"
    f.write_text("123456 4500000000 7\n")  # ns on the CPU, ns waiting for one, time slices
    rd = RunDelay(str(f))
    assert rd() == pytest.approx(4.5)
    f.write_text("123456 4750000000 9\n")  # read again through the same descriptor
    assert rd() == pytest.approx(4.75)
    rd.close()
    assert math.isnan(RunDelay(str(tmp_path / "none"))())
    st = tmp_path / "stat"
    st.write_text("cpu  10 20 30 40 50 60 70 250 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\n")
    assert host_steal(str(st)) == pytest.approx(250 / os.sysconf("SC_CLK_TCK"))
    assert math.isnan(host_steal(str(tmp_path / "none")))


def test_misses_after_waiting_for_a_cpu_are_told_apart():
    """A miss preceded by more than a physics period of waiting for a CPU (the run delay the
    kernel reports) counts as a CPU-wait miss; the misses themselves are counted as before."""
    for wait_per_check, expect_all in ((0.0, False), (5e-3, True)):
        clock = FakeClock()
        waited = [0.0]

        def run_delay():
            waited[0] += wait_per_check
            return waited[0]

        cfg = validate({"scene": "hinge_chain", "physics_rate": 250.0, "publish_rate": 50.0, "thread_priority": 0})
        sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
        advance = sim.advance

        def slow(dt):
            advance(dt)
            clock.t += 6e-3  # late at every check

        sim.advance = slow
        out = Outputs()
        loop = SimLoop(sim, cfg, out, clock=clock, sleep=clock.sleep, run_delay=run_delay)
        run_until(loop, lambda: len(out.states) >= 20)
        assert loop.pacing.pacer.misses > 10
        assert loop.pacing.cpu_wait_misses == (loop.pacing.pacer.misses if expect_all else 0)
        s = loop.summary()
        assert s["cpu_wait_misses"] == loop.pacing.cpu_wait_misses
        assert s["physics_cpu_wait_s"] == pytest.approx(waited[0] - wait_per_check)  # the last read less the first


def test_realtime_priority_asks_fifo_and_says_when_refused():
    calls = []

    def granted(pid, policy, param):
        calls.append((pid, policy, param.sched_priority))

    assert realtime_priority(50, granted) == (50, "SCHED_FIFO priority 50")
    assert calls == [(0, os.SCHED_FIFO, 50)]  # 0: the calling thread

    def refused(pid, policy, param):
        raise PermissionError(1, "Operation not permitted")

    prio, line = realtime_priority(50, refused)
    assert prio == 0 and "refused (Operation not permitted)" in line and "thread_priority:=0" in line
    calls.clear()
    assert realtime_priority(0, granted)[0] == 0 and not calls  # 0: never asked


def test_thread_priority_is_a_whole_number_from_0_to_99():
    assert validate({"thread_priority": 10}).thread_priority == 10
    for bad, says in ((2.5, "whole number"), (100, "<= 99"), (-1, ">= 0")):
        with pytest.raises(ParameterError, match=f"thread_priority: .*{says}"):
            validate({"thread_priority": bad})


def test_the_physics_thread_is_fifo_only_while_pacing_in_real_time():
    """A real thread, the real scheduler: FIFO at the priority asked for while pacing (if the
    system allows it: then the thread reads SCHED_FIFO back itself), never as fast as possible."""
    for rtf, prio in ((1.0, 7), (0.0, 7)):
        clock = FakeClock()
        loop, _ = make_loop(clock, real_time_factor=rtf, thread_priority=prio, duration=0.02)
        seen = []
        body = loop._run

        def run():
            body()
            seen.append((os.sched_getscheduler(0), os.sched_getparam(0).sched_priority))

        loop.thread = threading.Thread(target=run, daemon=True)
        loop.start()
        loop.thread.join(10)
        assert loop.started.is_set() and not loop.crash
        if rtf == 0.0:
            assert loop.pacing.priority == 0 and "as fast as possible" in loop.pacing.scheduling
            assert seen == [(os.SCHED_OTHER, 0)]
        elif loop.pacing.priority:
            assert loop.pacing.scheduling == "SCHED_FIFO priority 7" and seen == [(os.SCHED_FIFO, 7)]
        else:  # refused here (no rtprio limit): said so, and the thread is as it was
            assert "refused" in loop.pacing.scheduling and seen == [(os.SCHED_OTHER, 0)]
        assert loop.summary()["physics_thread_priority"] == loop.pacing.priority


def test_the_floor_counts_the_wake_ups_the_machine_delays():
    """Floor: a thread sleeping to 2 ms deadlines; every 50th sleep overshoots by 3 ms (a
    stolen CPU): exactly those are misses (beyond the 1 ms tolerance), the rest are not."""
    clock = FakeClock()
    sleeps = [0]
    floors = []

    def sleep(s):
        sleeps[0] += 1
        clock.sleep(s + (3e-3 if sleeps[0] % 50 == 0 else 0.0))
        if sleeps[0] == 1001:  # the thread stops itself here: the miss after the 1000th is counted
            floors[0].stop_soon()

    floor = Floor(2e-3, 1e-3, clock=clock, sleep=sleep)
    floors.append(floor)
    floor.start()
    while sleeps[0] < 1001:
        time.sleep(0.001)
    misses = floor.stop()  # joins the thread, which ends after the wait of its 1001st sleep
    assert sleeps[0] == 1001
    assert misses == 1000 // 50 and floor.got_priority == 0


def test_a_fifo_thread_that_cannot_keep_up_goes_back_to_the_normal_scheduler(monkeypatch):
    """Steps that cost 3x real time: the thread never sleeps; after FIFO_DEMOTE_AFTER of wall
    time without a sleep it drops SCHED_FIFO (scheduler calls faked: the fake clock's loop
    must not really run under FIFO), says so in an event and the stats, and goes on."""
    from gyro_sim.ros import loop_pacing as loop_module

    calls = []
    monkeypatch.setattr(loop_module, "realtime_priority",
                        lambda p: (calls.append(("fifo", p)) or (p, f"SCHED_FIFO priority {p}")))
    monkeypatch.setattr(loop_module, "normal_priority", lambda: calls.append(("normal",)))
    clock = FakeClock()
    loop, out = make_loop(clock, step_cost=3 * 4e-3, thread_priority=7)  # a 4 ms step costs 12 ms
    run_until(loop, lambda: clock.t > 100.0 + 3 * loop_module.FIFO_DEMOTE_AFTER)
    assert calls[:2] == [("fifo", 7), ("normal",)] and len(calls) == 2
    assert loop.pacing.priority == 0 and "SCHED_FIFO priority 7 dropped" in loop.pacing.scheduling
    demoted = [(t, text) for t, text in out.events if "physics thread: normal scheduler since" in text]
    assert len(demoted) == 1
    # demoted about FIFO_DEMOTE_AFTER of wall time after the start (node time runs at 1/3 of it)
    assert 0.2 < demoted[0][0] * 1e-9 < 0.6, demoted
    assert loop.summary()["physics_thread_priority"] == 0


def test_commands_received_while_paused_or_before_a_reset_are_all_logged_in_causal_order():
    """Paused: the commands already superseded are logged at the pause's node time; the latest
    at the first step after the resume (the same node time), or when the loop ends, whichever
    comes first, once. At a reset, the commands not yet taken are logged at its time before its
    event (the reset zeroes the moments): a reader applying the log in file order ends with
    what the loop applied."""
    clock = FakeClock()
    loop, out = make_loop(clock, command_timeout=1e6)
    run_until(loop, lambda: loop.steps >= 5)
    loop.requests.post(Pause(True))
    run_until(loop, lambda: loop.paused)
    t_pause = loop.node_ns
    for i in range(3):
        assert loop.submit_command(b"p%d" % i, [0.0, 0.01 * (i + 1), 0.0]) is None
    run_until(loop, lambda: len(out.commands) >= 2)  # the idle loop logs the superseded two
    assert out.commands[:2] == [(t_pause, b"p0"), (t_pause, b"p1")] and loop.node_ns == t_pause
    loop.requests.post(Pause(False))
    steps = loop.steps
    run_until(loop, lambda: loop.steps > steps)
    assert out.commands[2] == (t_pause, b"p2") and loop.sim.axis_moments[1] == pytest.approx(0.03)
    assert loop.commands.latency.run.n == 0  # it waited for the resume, not for a step: not timed
    loop.requests.post(Pause(True))
    run_until(loop, lambda: loop.paused)
    assert loop.submit_command(b"r0", [0.0, 0.5, 0.0]) is None
    loop.requests.post(Reset())
    run_until(loop, lambda: any(e == "reset" for _, e in out.events))
    t_reset = [t for t, e in out.events if e == "reset"][0]
    order = [(kind, t, x) for kind, t, x in out.log if t == t_reset]
    assert order[-2:] == [("command", t_reset, b"r0"), ("event", t_reset, "reset")]
    assert np.all(loop.sim.axis_moments == 0.0)
    assert loop.commands.counters.accepted == 4 == len(out.commands)


def test_a_physics_thread_failing_at_its_start_still_says_it_finished():
    """MemoryError before the loop proper (its scheduling, its first figures): `finished` is set
    and the failure kept, so that nothing waits on a thread that is gone."""
    clock = FakeClock()
    loop, out = make_loop(clock)

    def no_memory():
        raise MemoryError()

    loop._schedule = no_memory
    loop.start()
    try:
        assert loop.finished.wait(10.0) and loop.started.is_set()
        assert loop.out_of_memory and loop.crash is None
    finally:
        loop.stop()


def test_building_the_loop_runs_nothing_on_the_simulator():
    """The loop's constructor only sets up its jobs: no step, no snapshot, no reset (the node
    warms the Simulator up itself, before it builds the loop)."""
    cfg = validate({"scene": "hinge_chain", "physics_rate": 250.0, "publish_rate": 50.0, "thread_priority": 0})
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    calls = []
    for name in ("advance", "snapshot", "reset", "set_axis_moments"):
        real = getattr(sim, name)
        setattr(sim, name, lambda *a, _real=real, _name=name, **kw: calls.append(_name) or _real(*a, **kw))
    clock = FakeClock()
    loop = SimLoop(sim, cfg, Outputs(), clock=clock, sleep=clock.sleep)
    assert calls == [] and loop.steps == 0 and not loop.thread.is_alive()
    warm_up(sim, cfg.dt)
    assert "advance" in calls and calls[-1] == "reset" and sim.time == 0.0


class _Sim:
    """What CommandPath asks of a Simulator."""

    def __init__(self, n):
        self.axis_moments = np.zeros(n)

    def set_axis_moments(self, m):
        self.axis_moments = np.array(m, float)


def test_a_command_is_timed_from_its_receipt_to_the_start_of_the_step_applying_it():
    """On a fake clock: the later of the take and the step's wall deadline, minus the receipt;
    a superseded command, the demo's, and one received before the loop ran are not timed."""
    from gyro_sim.ros.command_path import CommandPath
    from gyro_sim.ros.demo import Demo

    clock = FakeClock()
    deadlines = {}  # node time (s) -> wall deadline, as the test sets it
    path = CommandPath(1, Outputs(), lambda: 0, timeout=1e6, dt=1e-3, clock=clock, due=deadlines.__getitem__)
    sim = _Sim(1)
    assert path.submit(b"early", [1.0]) is None  # before the loop runs: waits for its start
    clock.t = 100.010
    path.time_from_now()
    deadlines[0.0] = 100.0105
    path.take(sim, 0, 0)
    assert path.latency.run.n == 0 and sim.axis_moments[0] == 1.0
    # computed ahead: the step starts at its deadline, 1.3 ms after the receipt
    clock.t = 100.0200
    assert path.submit(b"a", [2.0]) is None
    clock.t = 100.0202
    deadlines[0.001] = 100.0213
    path.take(sim, 1_000_000, 1)
    # behind: the step's deadline is past when the thread takes the command, 0.7 ms after it came
    clock.t = 100.0300
    for i in range(3):  # two superseded: only the one applied is timed
        assert path.submit(b"s%d" % i, [3.0 + i]) is None
    clock.t = 100.0307
    deadlines[0.002] = 100.0250
    path.take(sim, 2_000_000, 2)
    got = list(path.latency.window)
    assert got == pytest.approx([1.3e-3, 0.7e-3], abs=1e-9) and path.counters.superseded == 2
    # unpaced (real_time_factor 0): the take alone
    free = CommandPath(1, Outputs(), lambda: 0, timeout=1e6, dt=1e-3, clock=clock, due=None)
    free.time_from_now()
    assert free.submit(b"f", [1.0]) is None
    clock.t += 4e-4
    free.take(sim, 0, 0)
    assert list(free.latency.window) == pytest.approx([4e-4], abs=1e-9)
    # the demo's commands are not timed
    demo_path = CommandPath(1, Outputs(), lambda: 0, timeout=1e6, dt=1e-3, clock=clock, due=None,
                            demo=Demo(np.array([1.0])))
    demo_path.time_from_now()
    demo_path.take(sim, 0, 0)
    assert demo_path.counters.accepted == 1 and demo_path.latency.run.n == 0


class _ClockWithArrival(FakeClock):
    """A fake clock whose sleep runs `arrive()` once, half-way through the first sleep after it
    is set: a command received while the physics thread waits for its deadline."""

    def __init__(self):
        super().__init__()
        self.arrive = None
        self.received = self.woke = None

    def sleep(self, s):
        if self.arrive is not None and self.received is None:
            self.t += 0.5 * s
            self.received = self.t
            self.arrive()
            self.t += 0.5 * s + 5e-5
            self.woke = self.t
            return
        super().sleep(s)


def test_the_loop_times_commands_and_reports_the_latency_in_its_diagnostics():
    """1 kHz physics, two steps per wake-up. A command received while the thread sleeps is
    applied by the first step after the wake-up: timed from the receipt to the wake-up. One
    received while a chunk is computed is applied by the chunk's next step: timed to that
    step's wall deadline, 1 ms of node time after the loop's start on the clock."""
    clock = _ClockWithArrival()
    loop, out = make_loop(clock, physics_rate=1000.0, publish_rate=100.0, command_timeout=1e6)
    assert loop.pacing.per_chunk == 2
    assert "command_latency_p50_us" not in loop.report().values  # nothing timed yet
    run_until(loop, lambda: loop.steps >= 10)
    clock.arrive = lambda: loop.submit_command(b"asleep", [0.0, 0.01, 0.0])
    run_until(loop, lambda: loop.commands.latency.run.n >= 1)
    (asleep,) = loop.commands.latency.window
    assert asleep == pytest.approx(clock.woke - clock.received, abs=1e-12)
    assert 0.9e-3 < asleep < 1.1e-3  # half of a 2 ms sleep, and the sleep's overshoot

    # a command arriving during the first step of a chunk
    advance, arrived = loop.sim.advance, []

    def advance_and_receive(dt):
        advance(dt)
        if not arrived and loop.steps % 2 == 0:
            arrived.append((clock.t, loop.time.offset_ns * 1e-9 + loop.sim.time))
            loop.submit_command(b"computing", [0.0, 0.02, 0.0])

    loop.sim.advance = advance_and_receive
    begin_clock, begin_node = clock.t, loop.node_time  # the loop restarts its pacing from here
    run_until(loop, lambda: loop.commands.latency.run.n >= 2)
    assert loop.pacing.pacer.misses == 0 and loop.pacing.pacer.slipped == 0
    received, step_node_time = arrived[0]
    mid = list(loop.commands.latency.window)[-1]
    assert loop.commands.counters.last_effective == pytest.approx(step_node_time, abs=1e-12)
    assert mid == pytest.approx(begin_clock + (step_node_time - begin_node) - received, abs=1e-9)
    assert 0.9e-3 < mid < 1e-3 + 1e-9  # the step is due 1 ms after the chunk began

    values = loop.report().values
    assert float(values["command_latency_p99_us"]) == pytest.approx(1e6 * max(asleep, mid), rel=0.02)
    s = loop.summary()
    assert s["commands_timed"] == 2 and s["commands_accepted"] == 2
    assert s["command_latency_max_us"] == pytest.approx(1e6 * max(asleep, mid), rel=1e-9)


def test_the_executors_share_lets_a_steady_1khz_through_and_holds_a_flood_to_its_share():
    from gyro_sim.ros.pacing import ShareLimit

    clock = FakeClock()
    limit = ShareLimit(0.2, 0.005, clock=clock)
    for _ in range(10_000):  # a command every ms, 0.15 ms of CPU each: never a sleep
        clock.t += 1e-3
        assert limit.after(1.5e-4) == 0.0
    cpu = wall = 0.0
    t0 = clock.t
    for _ in range(100_000):  # back to back, 0.1 ms each: held to the share on average
        clock.t += 1e-4
        cpu += 1e-4
        pause = limit.after(1e-4)
        clock.t += pause
    wall = clock.t - t0
    assert cpu / wall == pytest.approx(0.2, rel=0.01)
    assert limit.over <= 0.005 + 1e-4
