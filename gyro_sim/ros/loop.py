"""The physics loop of the node: a thread that steps the Simulator in real time (no rclpy here).

What runs where
---------------
- This thread owns the Simulator: it advances it one physics step (1/physics_rate) at a
  time in chunks, paced by `Pacer` (compute ahead, sleep to the wall deadline). At a
  publication boundary the state's messages are prepared (computed and serialised) right
  after the chunk, before the deadline, and sent at the deadline by `outputs` (publish, and
  the same bytes to the recorder). Diagnostics are built here once a wall second.
- The ROS executor thread only checks a command and keeps it as the latest (`submit_command`:
  bounded work, one slot, nothing queued, so a flood of commands cannot pile work on this
  thread) and posts requests (`request`: reset, pause); nothing there touches the Simulator.

Commands take effect from the next physics step: before each step the latest good command,
if new, is set on the Simulator (zero-order hold for the step). Every command received goes to
the log: the good ones on ~/axis_moments at the log time of the step that took the latest of
them, those it superseded (received since the previous step, never applied: counted as
superseded) just before it in the order received, so that a reader applying them in file order
ends with the one applied; while paused or stopped by a simulation error, those already
superseded at the current node time; those a reset discards, at the reset's time before its
event (the reset sets the moments to zero); those still waiting when the loop ends, at its
last node time. Rejected ones (wrong length, NaN or inf) go to the
log as events "command rejected (reason)" at the node time they were received (their values
never reach a log). When the last good command took effect
more than `command_timeout` *simulated* seconds ago, the moments are replaced by zeros
(marked by an event). Simulated, not wall, time: the fallback then depends only on the
command sequence and its log times, so a resimulation of the log reproduces it exactly,
whatever the CPU load or the real-time factor was.

Recording (outputs.recorder, gyro_sim.ros.recorder.LiveRecorder, when there is one) is
watched at every wake-up: when it fails (the writer process died, a write failed) the loop
says so once (console line and event), publishes the diagnostics with the run's ``record``
key saying why, and ends (`record_failure`: the node exits 1); when the writer falls behind
and publications are dropped from the log, events mark where the dropping starts and where it
stops (events are never dropped), and the diagnostics count them.

The time published ("node time") is the simulated time since the node started: after a
reset, the Simulator restarts from the scene's initial state at its own t = 0 while node
time keeps increasing (offset by the time of the reset), so stamps and log times never go
backwards; the log carries a "reset" event at that time.
"""
from __future__ import annotations

import collections
import gc
import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from gyro_sim.simulator import SimulationError
from gyro_sim.msgs import messages as M
from gyro_sim.log.resim import COMMAND_TIMEOUT_EVENT
from gyro_sim.ros.demo import DEMO_RATE
from gyro_sim.ros.outputs import OutputsClosed
from gyro_sim.ros.pacing import (
    Histogram, Pacer, RateMeter, RunDelay, Samples, chunk_steps, host_steal, normal_priority,
    realtime_priority,
)

#: wall seconds without a new publication dropped from the log after which the recorder counts
#: as caught up (an event says so)
RECORD_QUIET = 1.0
#: wall seconds between diagnostics while paused or stopped (running, they go with every
#: publication at least gyro_sim.msgs.messages.DIAGNOSTICS_PERIOD simulated seconds apart)
IDLE_DIAGNOSTICS_PERIOD = 1.0
#: longest sleep while paused or stopped (s): how fast requests are served then
IDLE_PERIOD = 0.05
#: a SCHED_FIFO physics thread that has not slept for this long (wall s: it cannot keep up with
#: real time) goes back to the normal scheduler: a FIFO thread that never sleeps holds its CPU
#: from every normal thread (on one core: the executor, the signals, the recorder) for 95 % of
#: every second
FIFO_DEMOTE_AFTER = 1.0


def warm_up(sim, dt: float) -> None:
    """Run every path the loop uses once (first calls pay for imports, caches, compilation),
    then put the Simulator back in its initial state."""
    from gyro_sim.warmup import background_fill_allowed, filling, warm_when_filled

    sim.snapshot()
    integ_warm_up = getattr(sim.integrator, "warm_up", None)
    # "fixed": the methods it may switch to later, compiled (or loaded) now; while a background
    # fill compiles them into the cache instead, a thread of this process loads them when it is
    # done, and until then the guard keeps them back (the physics thread compiles nothing:
    # docs/performance.md); without a background fill they are compiled here, before real time
    if hasattr(sim.integrator, "guard"):
        sim.integrator.guard = True
    if integ_warm_up is not None:
        if filling() and background_fill_allowed():
            warm_when_filled(sim)
        else:
            integ_warm_up(sim.time, sim.state)
    sim.advance(dt)
    sim.reset()


def freeze_start_up() -> int:
    """Collect the garbage, then move every object left (imports, compiled code, the scene,
    rclpy) into the collector's permanent generation; returns how many there are.

    A full (generation 2) collection scans every tracked object: on the start-up's heap that
    took 100-150 ms, on whichever thread allocated at the wrong moment, the physics thread
    included (measured in the node at n = 100; the collection holds the interpreter lock, so
    the physics thread waits for it in any thread). Frozen objects are never scanned: a full
    collection then scans what the run made, a few thousand objects."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


class GcPauses:
    """The collector's pauses in any thread of the process (gc.callbacks): a collection holds
    the interpreter lock, so the physics thread waits for it wherever it runs."""

    def __init__(self, clock=time.perf_counter):
        self.clock = clock
        self.pauses = Histogram()
        self._start: float | None = None

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._start = self.clock()
        elif self._start is not None:
            self.pauses.add(self.clock() - self._start)
            self._start = None

    def install(self) -> None:
        if self not in gc.callbacks:
            gc.callbacks.append(self)

    def remove(self) -> None:
        if self in gc.callbacks:
            gc.callbacks.remove(self)


def check_command(values, n_axes: int) -> str | None:
    """Why a command is refused (None if good): one finite value per actuated axis."""
    if len(values) != n_axes:
        return f"expected {n_axes} values (one per axis), got {len(values)}"
    if not all(map(math.isfinite, values)):
        return "holds NaN or inf"
    return None


@dataclass
class Counters:
    accepted: int = 0
    superseded: int = 0  # good commands replaced by a newer one before a step could take them
    rejected: int = 0
    timeouts: int = 0
    published: int = 0
    last_reject_reason: str = ""
    last_effective: float = float("nan")  # node time from which the last good command applies
    moments_since: float = 0.0  # node time from which the moments now applied have been applied


@dataclass
class Request:
    kind: str  # "reset" | "pause"
    value: bool = False
    done: threading.Event = field(default_factory=threading.Event)
    message: str = ""


class SimLoop:
    """Step `sim` in real time and hand states to `outputs`.

    Parameters
    ----------
    sim : gyro_sim.simulator.Simulator
    config : gyro_sim.ros.params.NodeConfig
    outputs : gyro_sim.ros.outputs.Outputs, or an object with the same methods:
        prepare_state(t_ns, sim, diagnostics_run) -> batch, send(t_ns, batch),
        publish_diagnostics(t_ns, sim, run_status), record_commands(t_ns, [raw, ...]),
        record_event(t_ns, text) (the log only), event(t_ns, text, level="info") (console and log),
        and optionally `recorder` (None, or the LiveRecorder to watch);
        t_ns: node time in integer nanoseconds
    clock, sleep : injectable for tests
    run_delay : seconds the calling thread has waited for a CPU so far (pacing.RunDelay; tests
        inject their own): a deadline miss is counted as a *CPU-wait miss* too when the physics
        thread waited, runnable, more than one physics period for a CPU since the previous
        deadline check (the OS gave the CPUs to others: diagnostics of a miss, not a change to it)
    """

    def __init__(self, sim, config, outputs, clock=time.monotonic, sleep=time.sleep, run_delay=None, demo=None):
        self.sim, self.config, self.out = sim, config, outputs
        #: the built-in demo commands (gyro_sim.ros.demo.Demo) while no command came from outside
        self.demo = demo
        self._demo_period_ns = M.time_ns(min(1.0 / DEMO_RATE, 0.5 * config.command_timeout))
        self._next_demo_ns = 0
        self._demo_stopped = False  # a command from outside arrived: the demo is over
        self._demo_stop_said = False
        self._submit_lock = threading.Lock()  # a demo command never lands after one from outside
        self.clock = clock
        self.dt = config.dt
        self.rtf = config.real_time_factor
        self.per_publish = config.steps_per_publish
        self.per_chunk = chunk_steps(self.per_publish, self.dt, self.rtf)
        self.pacer = Pacer(self.rtf, self.dt / self.rtf if self.rtf > 0 else 0.0, clock=clock, sleep=sleep)
        self.rate = RateMeter(clock)
        self.n_axes = len(sim.axis_names)
        # the fallback comes at the first step starting more than command_timeout after the last good command
        self._timeout_steps = math.floor(config.command_timeout / self.dt * (1 + 1e-12))
        self.counters = Counters()
        # the latest good command: (sequence number, raw bytes, values); one slot, replaced whole
        self._latest: tuple | None = None
        self._taken_seq = 0
        # every good command received and not yet logged: (sequence number, raw bytes), in order
        self._received: collections.deque = collections.deque()
        self.recorder = getattr(outputs, "recorder", None)
        self.record_failure: str | None = None  # why recording failed (the run then ended)
        self._drops_seen = 0  # records dropped from the log, as last seen
        self._last_drop: float | None = None  # wall time a new drop was last seen; None: not dropping
        self.requests: collections.deque = collections.deque()
        self.step_time = Samples(window=int(2 * config.physics_rate))
        self.pub_interval = Samples(window=int(2 * config.publish_rate) + 1)
        # |interval - nominal| between publications (none when running as fast as possible)
        self.pub_jitter = Samples(window=int(2 * config.publish_rate) + 1, offset=self.nominal_publish_interval) \
            if self.rtf > 0 else None
        self.lag = Samples(window=int(2 * config.publish_rate) + 1)
        self.output_time = Samples(window=int(2 * config.publish_rate) + 1)
        self.steps = 0  # physics steps since start (all resets included)
        self.offset_ns = 0  # node time (ns) of the last reset
        self.paused = False
        self.failure: str | None = None
        self.crash: str | None = None  # traceback of an unexpected error that ended the loop
        self.out_of_memory = False  # a MemoryError ended the loop
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._last_cmd_step: int | None = None  # step at which the last good command took effect
        self._last_pub_wall: float | None = None
        # diagnostics go with every diag_every-th publication (simulated time, as offline logs);
        # while paused or stopped, once per IDLE_DIAGNOSTICS_PERIOD of wall time
        self.diag_every = max(1, round(M.DIAGNOSTICS_PERIOD * config.publish_rate))
        self._publications = 0
        self._next_idle_diag = 0.0
        warm_up(sim, self.dt)
        self.thread = threading.Thread(target=self._run, name="gyro_sim-physics", daemon=True)
        self.wall_start = self.cpu_start = None
        self.wall_end = self.cpu_end = None
        self.gc_pauses = GcPauses()
        self.run_delay = RunDelay() if run_delay is None else run_delay
        self.cpu_wait_misses = 0  # deadline misses with more than a period of waiting for a CPU before them
        self._cpu_wait = [math.nan, math.nan]  # the physics thread's wait for a CPU at its start, at the last check
        self._steal = [math.nan, math.nan]  # the host's steal at the start and the end
        self.frozen = 0  # objects of the start-up frozen out of the collector's reach
        #: the physics thread's SCHED_FIFO priority in effect (0: normal scheduler) and one line
        #: saying how it is scheduled, set by the thread when it starts (`started` then set)
        self.priority = 0
        self.scheduling = ""
        self.started = threading.Event()

    # --- from other threads ----------------------------------------------------------------------
    def submit_command(self, raw: bytes, values) -> str | None:
        """A command received (raw CDR bytes and its values); returns why it is refused, if it is.
        A good one replaces the latest (taken by the next physics step) and ends the demo."""
        with self._submit_lock:
            reason = check_command(values, self.n_axes)
            if reason is None:
                self._demo_stopped = True
            return self._submit(raw, values, reason)

    def _submit(self, raw: bytes, values, reason: str | None) -> str | None:
        if reason is None:
            seq = self.counters.accepted + 1
            self._received.append((seq, raw))  # before it is the latest: a step taking it finds it here
            self.counters.accepted = seq
            self._latest = (seq, raw, tuple(float(v) for v in values))
        else:
            self.counters.rejected += 1
            self.counters.last_reject_reason = reason
            self.out.record_event(self.node_ns, f"command rejected ({reason})")
        return reason

    def _log_received(self, t_ns: int, upto: int) -> None:
        """Log, at `t_ns`, the good commands received up to sequence number `upto` not yet logged."""
        received = self._received
        raws = []
        while received and received[0][0] <= upto:
            raws.append(received.popleft()[1])
        if raws:
            self.out.record_commands(t_ns, raws)

    def request(self, kind: str, value: bool = False, timeout: float = 2.0) -> tuple[bool, str]:
        """Ask the loop for a reset or a pause change; wait until it is done."""
        req = Request(kind, value)
        self.requests.append(req)
        if not req.done.wait(timeout):
            return False, f"{kind}: the physics loop did not answer within {timeout} s"
        return True, req.message

    def start(self) -> None:
        """Start the physics thread (the start-up's objects frozen first: `freeze_start_up`)."""
        self.frozen = freeze_start_up()
        self.gc_pauses.install()
        self.thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(timeout)
        self.gc_pauses.remove()

    # --- time --------------------------------------------------------------------------------------
    @property
    def node_ns(self) -> int:
        """Node time in integer ns: the stamps and log times (offset of the last reset + Simulator time)."""
        return self.offset_ns + M.time_ns(self.sim.time)

    @property
    def node_time(self) -> float:
        """Node time (s)."""
        return self.node_ns * 1e-9

    def _serve_requests(self) -> None:
        while self.requests:
            req = self.requests.popleft()
            if req.kind == "reset":
                latest = self._latest  # received before the reset: not applied after it
                if latest is not None:
                    self._taken_seq = latest[0]
                    self._log_received(self.node_ns, latest[0])  # before the reset that zeroes them
                self.offset_ns = self.node_ns
                self.sim.reset()
                self.failure = None
                self._last_cmd_step = None
                self._publications = 0
                self.counters.moments_since = self.node_time
                self.out.event(self.node_ns, "reset")
                republish = getattr(self.out, "publish_robot_description", None)
                if republish is not None:  # the robot is back at its initial pose: said to late joiners too
                    republish()
                self.pacer.restart(self.node_time)
                self.rate.mark(self.node_time)
                req.message = f"reset to the initial state at node time {self.node_time:.6f} s"
            elif req.kind == "pause":
                if req.value != self.paused:
                    self.paused = req.value
                    self.out.event(self.node_ns, "pause" if self.paused else "resume")
                    self.pacer.restart(self.node_time)
                    self.rate.mark(self.node_time)
                    self._last_pub_wall = None
                req.message = f"{'paused' if self.paused else 'running'} at node time {self.node_time:.6f} s"
            req.done.set()

    # --- the loop ------------------------------------------------------------------------------------
    def _schedule(self) -> None:
        """This (the physics) thread's scheduling: SCHED_FIFO at config.thread_priority while
        pacing in real time (pacing.realtime_priority); as fast as possible it never sleeps, and a
        FIFO thread that never sleeps would take its CPU from everything else: normal then."""
        wanted = int(self.config.thread_priority)
        if self.rtf > 0:
            self.priority, self.scheduling = realtime_priority(wanted)
        else:
            self.scheduling = "normal scheduler (real_time_factor 0: as fast as possible, never sleeping)"
        self.started.set()

    def _demote(self) -> None:
        """Back to the normal scheduler (the thread cannot keep up: it never sleeps); said in the
        log and its events, the diagnostics and the stats."""
        normal_priority()
        self.scheduling = (f"normal scheduler since node time {self.node_time:.3f} s: SCHED_FIFO priority "
                           f"{self.priority} dropped, the physics thread had not slept for {FIFO_DEMOTE_AFTER:g} s "
                           f"(behind real time)")
        self.priority = 0
        self.out.event(self.node_ns, f"physics thread: {self.scheduling}")

    def _run(self) -> None:
        try:
            self._schedule()
            self.wall_start, self.cpu_start = self.clock(), time.process_time()
            self._cpu_wait = [self.run_delay()] * 2
            self._steal[0] = host_steal()
            self.pacer.restart(self.node_time)
            self.rate.mark(self.node_time)
            self._next_idle_diag = self.clock()
            self._send(self._prepare())
            while not self._stop.is_set():
                if self.recorder is not None and self._watch_recording():
                    break  # recording failed: the run ends (exit status 1)
                self._serve_requests()
                if self.failure is not None and self.config.duration > 0:
                    break  # a bounded run that fails ends at once (exit status 1)
                if self.paused or self.failure is not None:
                    self._log_superseded()
                    self._idle_diagnostics()
                    self._stop.wait(IDLE_PERIOD)
                    continue
                if self._done():
                    break
                self._chunk()
                batch = self._prepare() if self.steps % self.per_publish == 0 and self.failure is None else None
                waited = self.run_delay()
                if not self.pacer.wait(self.node_time) and waited - self._cpu_wait[1] > self.pacer.tolerance:
                    self.cpu_wait_misses += 1
                if self.priority and self.clock() - self.pacer.last_sleep > FIFO_DEMOTE_AFTER:
                    self._demote()
                self._cpu_wait[1] = waited
                self._send(batch)
        except OutputsClosed:
            pass
        except MemoryError:
            self.out_of_memory = True
        except Exception:  # noqa: BLE001 - a bug: reported by the node's exit status
            import traceback

            self.crash = traceback.format_exc()
        finally:
            try:
                latest = self._latest  # received, never taken: logged at the end
                if latest is not None and self._received:
                    self._log_received(self.node_ns, latest[0])
                if self.wall_start is not None:
                    self.wall_end, self.cpu_end = self.clock(), time.process_time()
                self._cpu_wait[1] = self.run_delay()
                self._steal[1] = host_steal()
                if isinstance(self.run_delay, RunDelay):
                    self.run_delay.close()
            finally:
                self.started.set()
                self.finished.set()

    def _watch_recording(self) -> bool:
        """Follow the recorder (module docstring); True when recording failed."""
        rec = self.recorder
        if rec.failure is not None:
            self.record_failure = rec.failure
            self.out.event(self.node_ns, f"recording failed: {rec.failure}; the run stops", level="error")
            self._idle_diagnostics(force=True)
            return True
        dropped = rec.dropped_records
        if dropped != self._drops_seen:
            if self._last_drop is None:
                self.out.event(self.node_ns, "log writer behind: the oldest publications waiting are dropped from "
                                             "the log", level="warning")
            self._drops_seen = dropped
            self._last_drop = self.clock()
        elif self._last_drop is not None and self.clock() - self._last_drop > RECORD_QUIET:
            self._last_drop = None
            self.out.event(self.node_ns, f"log writer caught up: {rec.dropped_records} records of "
                                         f"{rec.dropped_publications} publications dropped from the log so far")
        return False

    def _log_superseded(self) -> None:
        """Paused or stopped: log the commands already superseded (all but the latest)."""
        latest = self._latest
        if latest is not None and self._received and self._received[0][0] < latest[0]:
            self._log_received(self.node_ns, latest[0] - 1)

    def _done(self) -> bool:
        d = self.config.duration
        return d > 0 and self.node_time >= d - 0.5 * self.dt

    def _chunk(self) -> None:
        t0 = time.perf_counter()
        n = 0
        try:
            for _ in range(self.per_chunk):
                self._take_commands()
                self.sim.advance(self.dt)
                self.steps += 1
                n += 1
        except SimulationError as exc:
            self._fail(exc)
        if n:
            per_step = (time.perf_counter() - t0) / n
            for _ in range(n):
                self.step_time.add(per_step)

    def _demo_command(self, t_ns: int) -> None:
        """The demo's command for node time t_ns, through the command path, when one is due."""
        if self._demo_stopped:
            if not self._demo_stop_said:
                self._demo_stop_said = True
                self.out.event(t_ns, "demo stopped: a command arrived")
            return
        if t_ns < self._next_demo_ns:
            return
        self._next_demo_ns = t_ns + self._demo_period_ns
        values = self.demo.moments(t_ns * 1e-9)
        with self._submit_lock:
            if not self._demo_stopped:
                self._submit(M.axis_moments(values), values, None)

    def _take_commands(self) -> None:
        t_ns = self.node_ns
        t = t_ns * 1e-9
        if self.demo is not None:
            self._demo_command(t_ns)
        new = self._latest
        latest = None
        if new is not None and new[0] != self._taken_seq:
            seq, raw, latest = new
            self.counters.superseded += seq - self._taken_seq - 1
            self._taken_seq = seq
            self._log_received(t_ns, seq)  # the ones it superseded, then it
        if latest is not None:
            if np.any(self.sim.axis_moments != latest):
                self.counters.moments_since = t
            self.sim.set_axis_moments(latest)
            self._last_cmd_step = self.steps
            self.counters.last_effective = t
        elif self._last_cmd_step is not None and (self.steps - self._last_cmd_step) > self._timeout_steps:
            self._last_cmd_step = None
            if np.any(self.sim.axis_moments != 0.0):
                self.sim.set_axis_moments(np.zeros(self.n_axes))
                self.counters.timeouts += 1
                self.counters.moments_since = t
                self.out.event(t_ns, f"{COMMAND_TIMEOUT_EVENT}: axis moments back to zero")

    def _fail(self, exc: SimulationError) -> None:
        self.failure = str(exc)
        self.out.event(self.node_ns, f"simulation stopped: {exc}")
        self._idle_diagnostics(force=True)

    def _prepare(self) -> list | None:
        """The messages of the state just computed (None if it cannot be published); the
        diagnostics go with every diag_every-th publication since the start or the last reset."""
        t0 = time.perf_counter()
        with_diag = self._publications % self.diag_every == 0
        try:
            batch = self.out.prepare_state(self.node_ns, self.sim, self.report() if with_diag else False)
        except SimulationError as exc:
            self._fail(exc)
            return None
        self._publications += 1
        self.output_time.add(time.perf_counter() - t0)
        return batch

    def _send(self, batch: list | None) -> None:
        if batch is None:
            return
        now = self.clock()
        if self._last_pub_wall is not None:
            self.pub_interval.add(now - self._last_pub_wall)
            if self.pub_jitter is not None:
                self.pub_jitter.add(now - self._last_pub_wall)
        self._last_pub_wall = now
        self.lag.add(self.pacer.lag(self.node_time, now))
        self.out.send(self.node_ns, batch)
        self.counters.published += 1

    # --- diagnostics ---------------------------------------------------------------------------------
    def _idle_diagnostics(self, force: bool = False) -> None:
        """Diagnostics alone, once per IDLE_DIAGNOSTICS_PERIOD of wall time (paused, stopped)."""
        if force or self.clock() >= self._next_idle_diag:
            self._next_idle_diag = self.clock() + IDLE_DIAGNOSTICS_PERIOD
            self.out.publish_diagnostics(self.node_ns, self.sim, self.report())

    def report(self) -> M.Status:
        """The ``gyro_sim: run`` status: level 0 OK / 1 WARN / 2 ERROR, a message, the figures
        (numbers with their units in the key; a figure without data yet is left out)."""
        c, sim = self.counters, self.sim
        p50, p99 = self.step_time.window_percentiles(50, 99)
        j50, j99 = self.pub_jitter.window_percentiles(50, 99) if self.pub_jitter else (math.nan, math.nan)
        rtf = float("nan") if (self.paused or self.failure) else self.rate.window_rtf(self.node_time)
        state = "stopped: simulation error" if self.failure else ("paused" if self.paused else "running")
        values = {
            "state": state,
            "node_time_s": self.node_time,
            "physics_rate_Hz": self.config.physics_rate,
            "publish_rate_Hz": self.config.publish_rate,
            "real_time_factor_target": self.rtf,
            "real_time_factor_achieved": rtf,
            "step_time_p50_us": p50 * 1e6,
            "step_time_p99_us": p99 * 1e6,
            "publish_jitter_p50_us": j50 * 1e6,
            "publish_jitter_p99_us": j99 * 1e6,
            "sim_lag_max_ms": max(self.lag.window, default=math.nan) * 1e3,  # none before the first publication
            "deadline_misses": self.pacer.misses,
            "slipped_s": self.pacer.slipped,
            "steps_per_wakeup": self.per_chunk,
            "commands_accepted": c.accepted,
            "commands_rejected": c.rejected,
            "commands_superseded": c.superseded,
            "command_timeouts": c.timeouts,
            "last_command_effective_s": c.last_effective,
            "moments_applied_since_s": c.moments_since,
            "backend": sim.backend,
            "physics_thread_priority": self.priority,
        }
        if c.last_reject_reason:
            values["last_reject_reason"] = c.last_reject_reason
        if self.failure:
            values["reason"] = self.failure
        rec = self.recorder
        if rec is not None:
            failure = self.record_failure or rec.failure
            values["record"] = (f"failed: {failure}" if failure else
                                "behind: dropping the oldest publications" if self._last_drop is not None else "recording")
            values["records_dropped"] = rec.dropped_records
            values["publications_dropped"] = rec.dropped_publications
        values = {k: v for k, v in values.items() if isinstance(v, str) or math.isfinite(v)}
        if rec is not None and (self.record_failure or rec.failure):
            return self._status(M.ERROR, f"recording failed: {self.record_failure or rec.failure}", values)
        if self.failure is not None:
            return self._status(M.ERROR, f"simulation stopped: {self.failure} (call ~/reset)", values)
        if self.paused:
            return self._status(M.OK, "paused", values)
        warn = []
        if self.rtf > 0 and math.isfinite(rtf) and rtf < 0.95 * self.rtf:
            warn.append(f"real-time factor {rtf:.2f} below {self.rtf:g}")
        if c.rejected:
            warn.append(f"{c.rejected} command{'s' if c.rejected != 1 else ''} rejected")
        if rec is not None and rec.dropped_records:
            warn.append(f"{rec.dropped_records} records dropped from the log (the writer fell behind)")
        if warn:
            return self._status(M.WARN, "; ".join(warn), values)
        if not math.isfinite(rtf):  # nothing simulated since the start or the reset: no rate to state
            return self._status(M.OK, "starting" if self.steps == 0 else "running", values)
        return self._status(M.OK, "running", values)

    def _status(self, level: int, message: str, values: dict) -> M.Status:
        topics = getattr(self.out, "topics", M.ROOT_TOPICS)
        return M.Status(topics.status_name(M.RUN_STATUS), values, level=level, message=message,
                        hardware_id=self.sim.scene.name)

    @property
    def nominal_publish_interval(self) -> float:
        return float("nan") if self.rtf <= 0 else 1.0 / (self.config.publish_rate * self.rtf)

    def summary(self) -> dict:
        """Whole-run timing statistics (for stats_file and the bench)."""
        p50, p99, pmax = self.step_time.run_percentiles(50, 99, 100)
        j50, j99 = self.pub_jitter.run_percentiles(50, 99) if self.pub_jitter else (math.nan, math.nan)
        if self.wall_start is None:  # never started (stopped during start-up)
            wall = cpu = 0.0
        else:
            wall = (self.wall_end or self.clock()) - self.wall_start
            cpu = (self.cpu_end or time.process_time()) - self.cpu_start
        return {
            "scene": self.config.scene.name,
            "bodies": len(self.config.scene.bodies),
            "physics_rate": self.config.physics_rate,
            "publish_rate": self.config.publish_rate,
            "real_time_factor_target": self.rtf,
            "integrator": self.sim.integrator_name,
            "backend": self.sim.backend,
            "steps_per_wakeup": self.per_chunk,
            "steps": self.steps,
            "node_time_s": self.node_time,
            "wall_s": wall,
            "cpu_s": cpu,
            "cpu_share": cpu / wall if wall > 0 else math.nan,
            "real_time_factor_achieved": self.node_time / wall if wall > 0 else math.nan,
            "step_time_p50_us": p50 * 1e6,
            "step_time_p99_us": p99 * 1e6,
            "step_time_max_us": pmax * 1e6,
            "publications": self.counters.published,
            "publish_interval_mean_ms": self.pub_interval.run.mean * 1e3,
            "publish_jitter_p50_us": j50 * 1e6,
            "publish_jitter_p99_us": j99 * 1e6,
            "output_time_p50_us": self.output_time.run_percentiles(50)[0] * 1e6,
            "sim_lag_max_ms": (self.lag.run.max if self.lag.run.n else 0.0) * 1e3,
            "deadline_misses": self.pacer.misses,
            "slipped_s": self.pacer.slipped,
            "commands_accepted": self.counters.accepted,
            "commands_rejected": self.counters.rejected,
            "commands_superseded": self.counters.superseded,
            "cpu_wait_misses": self.cpu_wait_misses,
            "physics_cpu_wait_s": self._cpu_wait[1] - self._cpu_wait[0],
            "host_steal_s": self._steal[1] - self._steal[0],
            "gc_frozen_objects": self.frozen,
            "physics_thread_priority": self.priority,
            "physics_thread_scheduling": self.scheduling,
            "gc_collections": self.gc_pauses.pauses.n,
            "gc_pause_max_us": (self.gc_pauses.pauses.max if self.gc_pauses.pauses.n else 0.0) * 1e6,
            "gc_pause_total_ms": self.gc_pauses.pauses.total * 1e3,
        }
