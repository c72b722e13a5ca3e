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
  thread) and posts requests (`request`: `Reset()`, `Pause(paused)`); nothing there touches
  the Simulator.

Each job has its own module: the commands (`command_path.CommandPath`), the pacing and the
physics thread's scheduling (`loop_pacing.LoopPacing`), the publications and diagnostics
(`loop_publication.Publications`), the watch over the recorder (`record_watch.RecordWatch`),
the requests (`requests.Mailbox`). This class holds the run's state (steps, node time,
paused, failure) and the order in which they act.

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

import dataclasses
import math
import threading
import time

from gyro_sim.simulator import SimulationError
from gyro_sim.msgs import messages as M
from gyro_sim.ros.command_path import CommandPath, check_command
from gyro_sim.ros.loop_pacing import LoopPacing
from gyro_sim.ros.loop_publication import Publications
from gyro_sim.ros.outputs import OutputsClosed
from gyro_sim.ros.record_watch import RecordWatch
from gyro_sim.ros.requests import Mailbox, Pause, Request, Reset

__all__ = ["SimLoop", "warm_up", "check_command", "Pause", "Reset"]

#: longest sleep while paused or stopped (s): how fast requests are served then
IDLE_PERIOD = 0.05
#: wall seconds between two publications of the held initial state while the node waits for its
#: first command (`hold:=until_command`, lock-step): for a controller started after the node,
#: which missed the first (DDS does not keep it for late subscribers); DDS only, not recorded
HOLD_REPEAT = 1.0


def warm_up(sim, dt: float) -> None:
    """Run every path the loop uses once (first calls pay for imports, caches, compilation),
    then put the Simulator back in its initial state. The node calls it before it builds its
    SimLoop, so that the loop's first steps pay for none of it."""
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


class SimLoop:
    """Step `sim` in real time and hand states to `outputs`.

    Parameters
    ----------
    sim : gyro_sim.simulator.Simulator (warmed up by `warm_up` first, for an even start)
    config : gyro_sim.ros.params.NodeConfig
    outputs : gyro_sim.ros.outputs.Outputs, or an object with the same methods:
        prepare_state(t_ns, sim, diagnostics_run) -> batch, send(t_ns, batch),
        publish_diagnostics(t_ns, sim, run_status), record_commands(t_ns, [raw, ...]),
        record_event(t_ns, text) (the log only), event(t_ns, text, level="info") (console and log),
        and optionally `recorder` (None, or the LiveRecorder to watch);
        t_ns: node time in integer nanoseconds
    clock, sleep, run_delay : injectable for tests (`loop_pacing.LoopPacing`)
    demo : the built-in demo commands (gyro_sim.ros.demo.Demo) while no command came from outside
    """

    def __init__(self, sim, config, outputs, clock=time.monotonic, sleep=time.sleep, run_delay=None, demo=None):
        self.sim, self.config, self.out = sim, config, outputs
        self.clock = clock
        self.dt = config.dt
        self.per_publish = config.steps_per_publish
        #: lock-step: one control period per command, no wall deadline (paced as real_time_factor 0)
        self.lockstep = bool(getattr(config, "lockstep", False))
        paced = dataclasses.replace(config, real_time_factor=0.0) if self.lockstep else config
        self.pacing = LoopPacing(paced, clock=clock, sleep=sleep, run_delay=run_delay)
        pacer = self.pacing.pacer
        self.commands = CommandPath(len(sim.axis_names), outputs, lambda: self.node_ns, config.command_timeout,
                                    self.dt, demo, clock=clock, due=pacer.deadline if pacer.rtf > 0 else None,
                                    window=int(2 * config.physics_rate), lockstep=self.lockstep,
                                    joint_controls=sim.joint_command_controls if sim.control_names else None,
                                    initial_controls=sim.initial_controls)
        self.publications = Publications(outputs, paced, clock=clock)
        #: the run waits for its first command (lock-step, hold until_command); cleared when it came
        self.holding = bool(getattr(config, "waits_for_command", False))
        recorder = getattr(outputs, "recorder", None)
        self.recording = RecordWatch(recorder, outputs, clock) if recorder is not None else None
        self.requests = Mailbox()
        self.steps = 0  # physics steps since start (all resets included)
        self.time = M.NodeTime(sim)  # node time: that of the last reset + the Simulator's
        self.paused = False
        self.failure: str | None = None
        self.crash: str | None = None  # traceback of an unexpected error that ended the loop
        self.out_of_memory = False  # a MemoryError ended the loop
        self.finished = threading.Event()
        #: a backend to switch to at the next step boundary (`promote`, from another thread)
        self._promotion: str | None = None
        #: set by the thread once its scheduling is known (pacing.priority, pacing.scheduling)
        self.started = threading.Event()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="gyro_sim-physics", daemon=True)

    # --- from other threads ----------------------------------------------------------------------
    def submit_command(self, raw: bytes, values) -> str | None:
        """A command received (raw CDR bytes and its values); returns why it is refused, if it is."""
        return self.commands.submit(raw, values)

    def submit_joint_command(self, raw: bytes, command) -> str | None:
        """From the executor thread: a joint command (its decoded fields, None if undecodable)."""
        return self.commands.submit_joint(raw, command)

    def request(self, request: Request, timeout: float = 2.0) -> tuple[bool, str]:
        """Ask the loop for a reset (`Reset()`) or a pause change (`Pause(paused)`); wait until it is done."""
        return self.requests.ask(request, timeout)

    def promote(self, backend: str) -> None:
        """Step on `backend` from the next step boundary on (its kernels loaded in this process
        already: gyro_sim.warmup.load_when_compiled); the physics thread switches and records it."""
        self._promotion = backend

    def start(self) -> None:
        """Start the physics thread (the start-up's objects frozen first: `loop_pacing.freeze_start_up`)."""
        self.pacing.freeze()
        self.thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(timeout)
        self.pacing.stop()

    # --- time --------------------------------------------------------------------------------------
    @property
    def node_ns(self) -> int:
        """Node time in integer ns: the stamps and log times (offset of the last reset + Simulator time)."""
        return self.time.ns

    @property
    def node_time(self) -> float:
        """Node time (s)."""
        return self.node_ns * 1e-9

    # --- requests ----------------------------------------------------------------------------------
    def _handle(self, req: Request) -> str:
        if isinstance(req, Reset):
            self.commands.discard(self.node_ns)  # received before the reset: logged before it, never applied
            self.time.offset_ns = self.node_ns
            self.sim.reset()
            self.failure = None
            self.publications.restart(reset=True)
            self.commands.counters.moments_since = self.node_time
            self.out.event(self.node_ns, "reset")
            republish = getattr(self.out, "publish_robot_description", None)
            if republish is not None:  # the robot is back at its initial pose: said to late joiners too
                republish()
            if self.lockstep:  # the controller answers the reset state: published now (same node time)
                self._send(self._prepare())
            self.pacing.restart(self.node_time)
            return f"reset to the initial state at node time {self.node_time:.6f} s"
        if isinstance(req, Pause):
            if req.paused != self.paused:
                self.paused = req.paused
                self.out.event(self.node_ns, "pause" if self.paused else "resume")
                self.pacing.restart(self.node_time)
                self.commands.time_from_now()
                self.publications.restart()
            return f"{'paused' if self.paused else 'running'} at node time {self.node_time:.6f} s"
        raise TypeError(f"not a request: {req!r}")

    # --- the loop ------------------------------------------------------------------------------------
    def _schedule(self) -> None:
        """This (the physics) thread's scheduling (`LoopPacing.schedule`); `started` then set."""
        self.pacing.schedule()
        self.started.set()

    def _run(self) -> None:
        try:
            self._schedule()
            self.pacing.begin(self.node_time)
            self.commands.time_from_now()
            self.publications.idle_from_now()
            first = self._prepare()
            self._send(first)
            if self.holding:
                self._hold(first)
            while not self._stop.is_set():
                if self.recording is not None and self.recording.check(self.node_ns):
                    self._idle_diagnostics(force=True)
                    break  # recording failed: the run ends (exit status 1)
                self.requests.serve(self._handle)
                if self.failure is not None and self.config.duration > 0:
                    break  # a bounded run that fails ends at once (exit status 1)
                if self.paused or self.failure is not None:
                    self.commands.log_superseded(self.node_ns)
                    self._idle_diagnostics()
                    self._stop.wait(IDLE_PERIOD)
                    continue
                if self._done():
                    break
                if self.lockstep:
                    self._period()
                    continue
                self._chunk()
                batch = self._prepare() if self.steps % self.per_publish == 0 and self.failure is None else None
                demoted = self.pacing.wait(self.node_time)
                if demoted:
                    self.out.event(self.node_ns, demoted)
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
                self.commands.log_remaining(self.node_ns)
                self.pacing.end()
            finally:
                self.started.set()
                self.finished.set()

    def _hold(self, first: list | None) -> None:
        """Hold the initial state (published) until the first command arrives: its publication
        again every HOLD_REPEAT wall seconds (DDS only), the requests served, idle diagnostics;
        then the run's clocks start from now."""
        repeat = getattr(self.out, "publish", None)
        next_repeat = self.clock() + HOLD_REPEAT
        while not self._stop.is_set() and not self.commands.wait_any(IDLE_PERIOD):
            self.requests.serve(self._handle)
            if self.recording is not None and self.recording.check(self.node_ns):
                return
            self._idle_diagnostics()
            if repeat is not None and first is not None and self.clock() >= next_repeat:
                next_repeat = self.clock() + HOLD_REPEAT
                repeat(first)
        self.holding = False
        if not self._stop.is_set():
            self.pacing.begin(self.node_time)
            self.commands.time_from_now()
            self.publications.restart()

    def _period(self) -> None:
        """Lock-step: the oldest command waiting applied to one control period, then its
        publication at once; with none waiting, the requests and diagnostics are served."""
        if not self.commands.next_command(IDLE_PERIOD):
            self._idle_diagnostics()
            return
        self._chunk(self.per_publish)
        self._send(self._prepare() if self.failure is None else None)

    def _done(self) -> bool:
        d = self.config.duration
        return d > 0 and self.node_time >= d - 0.5 * self.dt

    def _chunk(self, steps: int | None = None) -> None:
        """`steps` physics steps (default: one wake-up's), each taking the latest command."""
        t0 = time.perf_counter()
        n = 0
        try:
            for _ in range(self.pacing.per_chunk if steps is None else steps):
                if self._promotion is not None:
                    self._switch()
                self.commands.take(self.sim, self.node_ns, self.steps)
                self.sim.advance(self.dt)
                self.steps += 1
                n += 1
        except SimulationError as exc:
            self._fail(exc)
        if n:
            self.pacing.steps_took(time.perf_counter() - t0, n)

    def _switch(self) -> None:
        """The backend switch `promote` asked for, at this step boundary (before its command is
        taken), said in an event that re-simulation repeats at the same boundary
        (gyro_sim.log.resim: DYNAMICS_EVENT); "fixed" guarded again (its other rungs are loaded
        by `warm_up`'s thread when the cache's fill has ended)."""
        from gyro_sim.log.resim import DYNAMICS_EVENT

        backend, self._promotion = self._promotion, None
        before = self.sim.backend
        if backend == before:
            return
        self.sim.switch_backend(backend)
        if hasattr(self.sim.integrator, "guard"):  # its other rungs: loaded by `warm_up`'s thread
            self.sim.integrator.guard = True
        self.out.event(self.node_ns, f"{DYNAMICS_EVENT}{backend} from here ({before} until now, while its kernels "
                                     f"compiled)")

    def _fail(self, exc: SimulationError) -> None:
        self.failure = str(exc)
        self.out.event(self.node_ns, f"simulation stopped: {exc}")
        self._idle_diagnostics(force=True)

    def _prepare(self) -> list | None:
        """The messages of the state just computed (None if it cannot be published)."""
        try:
            return self.publications.prepare(self.node_ns, self.sim, self.report)
        except SimulationError as exc:
            self._fail(exc)
            return None

    def _send(self, batch: list | None) -> None:
        if batch is not None:
            self.publications.send(self.node_ns, batch, lambda now: self.pacing.pacer.lag(self.node_time, now))

    # --- diagnostics ---------------------------------------------------------------------------------
    def _idle_diagnostics(self, force: bool = False) -> None:
        self.publications.idle_diagnostics(self.node_ns, self.sim, self.report, force)

    def report(self) -> M.Status:
        """The ``gyro_sim: run`` status: level 0 OK / 1 WARN / 2 ERROR, a message, the figures
        (numbers with their units in the key; a figure without data yet is left out)."""
        c, sim, pacing, pubs = self.commands.counters, self.sim, self.pacing, self.publications
        rtf_target = pacing.rtf
        p50, p99 = pacing.step_time.window_percentiles(50, 99)
        j50, j99 = pubs.jitter_percentiles(50, 99)
        l50, l99 = self.commands.latency.window_percentiles(50, 99)
        rtf = float("nan") if (self.paused or self.failure) else pacing.rate.window_rtf(self.node_time)
        state = "stopped: simulation error" if self.failure else ("paused" if self.paused else "running")
        if state == "running" and self.holding:
            state = "holding the initial state until a command"
        elif state == "running" and self.lockstep and not self.commands.waiting:
            state = "lock-step: waiting for a command"

        values = {
            "state": state,
            "node_time_s": self.node_time,
            "physics_rate_Hz": self.config.physics_rate,
            "publish_rate_Hz": self.config.publish_rate,
            "real_time_factor_target": rtf_target,
            "real_time_factor_achieved": rtf,
            "step_time_p50_us": p50 * 1e6,
            "step_time_p99_us": p99 * 1e6,
            "publish_jitter_p50_us": j50 * 1e6,
            "publish_jitter_p99_us": j99 * 1e6,
            "command_latency_p50_us": l50 * 1e6,  # none before a command from outside was applied
            "command_latency_p99_us": l99 * 1e6,
            "sim_lag_max_ms": max(pubs.lag.window, default=math.nan) * 1e3,  # none before the first publication
            "deadline_misses": pacing.pacer.misses,
            "slipped_s": pacing.pacer.slipped,
            "steps_per_wakeup": pacing.per_chunk,
            "commands_accepted": c.accepted,
            "commands_rejected": c.rejected,
            "commands_superseded": c.superseded,
            "command_timeouts": c.timeouts,
            "last_command_effective_s": c.last_effective,
            "moments_applied_since_s": c.moments_since,
            "backend": sim.backend,
            "physics_thread_priority": pacing.priority,
        }
        if c.last_reject_reason:
            values["last_reject_reason"] = c.last_reject_reason
        if self.failure:
            values["reason"] = self.failure
        rec = self.recording
        if rec is not None:
            values.update(rec.values())
        values = {k: v for k, v in values.items() if isinstance(v, str) or math.isfinite(v)}
        if rec is not None and rec.failed:
            return self._status(M.ERROR, f"recording failed: {rec.failed}", values)
        if self.failure is not None:
            return self._status(M.ERROR, f"simulation stopped: {self.failure} (call ~/reset)", values)
        if self.paused:
            return self._status(M.OK, "paused", values)
        warn = []
        if rtf_target > 0 and math.isfinite(rtf) and rtf < 0.95 * rtf_target:
            warn.append(f"real-time factor {rtf:.2f} below {rtf_target:g}")
        if c.rejected:
            warn.append(f"{c.rejected} command{'s' if c.rejected != 1 else ''} rejected")
        if rec is not None and rec.recorder.dropped_records:
            warn.append(f"{rec.recorder.dropped_records} records dropped from the log (the writer fell behind)")
        if warn:
            return self._status(M.WARN, "; ".join(warn), values)
        if not math.isfinite(rtf):  # nothing simulated since the start or the reset: no rate to state
            return self._status(M.OK, "starting" if self.steps == 0 else "running", values)
        return self._status(M.OK, "running", values)

    def _status(self, level: int, message: str, values: dict) -> M.Status:
        topics = getattr(self.out, "topics", M.ROOT_TOPICS)
        return M.Status(topics.status_name(M.RUN_STATUS), values, level=level, message=message,
                        hardware_id=self.sim.scene.name)

    def summary(self) -> dict:
        """Whole-run timing statistics (for stats_file and the bench)."""
        pacing, pubs, c = self.pacing, self.publications, self.commands.counters
        p50, p99, pmax = pacing.step_time.run_percentiles(50, 99, 100)
        j50, j99 = pubs.jitter_percentiles(50, 99, run=True)
        # receipt to the step applying it; None when no command from outside was applied
        latency = self.commands.latency.run_percentiles(50, 99, 100)
        l50, l99, lmax = (None if math.isnan(x) else x * 1e6 for x in latency)
        wall, cpu = pacing.wall_cpu()
        pauses = pacing.gc_pauses.pauses
        return {
            "scene": self.config.scene.name,
            "bodies": len(self.config.scene.bodies),
            "physics_rate": self.config.physics_rate,
            "publish_rate": self.config.publish_rate,
            "real_time_factor_target": pacing.rtf,
            "integrator": self.sim.integrator_name,
            "backend": self.sim.backend,
            "steps_per_wakeup": pacing.per_chunk,
            "steps": self.steps,
            "node_time_s": self.node_time,
            "wall_s": wall,
            "cpu_s": cpu,
            "cpu_share": cpu / wall if wall > 0 else math.nan,
            "real_time_factor_achieved": self.node_time / wall if wall > 0 else math.nan,
            "step_time_p50_us": p50 * 1e6,
            "step_time_p99_us": p99 * 1e6,
            "step_time_max_us": pmax * 1e6,
            "publications": pubs.published,
            "publish_interval_mean_ms": pubs.interval.run.mean * 1e3,
            "publish_jitter_p50_us": j50 * 1e6,
            "publish_jitter_p99_us": j99 * 1e6,
            "output_time_p50_us": pubs.output_time.run_percentiles(50)[0] * 1e6,
            "sim_lag_max_ms": (pubs.lag.run.max if pubs.lag.run.n else 0.0) * 1e3,
            "deadline_misses": pacing.pacer.misses,
            "slipped_s": pacing.pacer.slipped,
            "commands_accepted": c.accepted,
            "commands_rejected": c.rejected,
            "commands_superseded": c.superseded,
            "commands_per_wall_s": c.accepted / wall if wall > 0 else math.nan,
            "commands_timed": self.commands.latency.run.n,
            "command_latency_p50_us": l50,
            "command_latency_p99_us": l99,
            "command_latency_max_us": lmax,
            "cpu_wait_misses": pacing.cpu_wait_misses,
            "physics_cpu_wait_s": pacing.cpu_wait,
            "host_steal_s": pacing.steal,
            "gc_frozen_objects": pacing.frozen,
            "physics_thread_priority": pacing.priority,
            "physics_thread_scheduling": pacing.scheduling,
            "gc_collections": pauses.n,
            "gc_pause_max_us": (pauses.max if pauses.n else 0.0) * 1e6,
            "gc_pause_total_ms": pauses.total * 1e3,
        }
