"""The physics loop of the node: a thread that steps the Simulator in real time (no rclpy here).

What runs where
---------------
- This thread owns the Simulator: it advances it one physics step (1/physics_rate) at a
  time in chunks, paced by `Pacer` (compute ahead, sleep to the wall deadline). At a
  publication boundary the state's messages are prepared (computed and serialised) right
  after the chunk, before the deadline, and sent at the deadline by `outputs` (publish, and
  the same bytes to the recorder). Diagnostics are built here once a wall second.
- The ROS executor thread only fills the command inbox (`submit_command`) and posts requests
  (`request`: reset, pause); nothing there touches the Simulator.

Commands take effect from the next physics step: before each step the inbox is drained, the
last good command is set on the Simulator (zero-order hold for the step) and every command
received is recorded with the log time of that step. When the last good command took effect
more than `command_timeout` *simulated* seconds ago, the moments are replaced by zeros
(marked by an event). Simulated, not wall, time: the fallback then depends only on the
command sequence and its log times, so a resimulation of the log reproduces it exactly,
whatever the CPU load or the real-time factor was.

The time published ("node time") is the simulated time since the node started: after a
reset, the Simulator restarts from the scene's initial state at its own t = 0 while node
time keeps increasing (offset by the time of the reset), so stamps and log times never go
backwards; the log carries a "reset" event at that time.
"""
from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..core.invariants import conserved
from ..core.simulator import SimulationError
from .pacing import Pacer, RateMeter, Samples, chunk_steps
from ..io.resim import COMMAND_TIMEOUT_EVENT


def time_ns(t: float) -> int:
    """Simulated time (s) as integer ns, rounded as gyro_sim.io.messages.time_ns (log times)."""
    return int(round(t * 1e9))

#: wall seconds between diagnostics
DIAGNOSTICS_PERIOD = 1.0
#: longest sleep while paused or stopped (s): how fast requests are served then
IDLE_PERIOD = 0.05


def backend_name(sim) -> str:
    """"numba" or "numpy": which dynamics the Simulator runs."""
    return "numba" if type(sim.system).__name__.startswith("Fast") else "numpy"


def warm_up(sim, dt: float) -> None:
    """Run every path the loop uses once (first calls pay for imports, caches, compilation),
    then put the Simulator back in its initial state."""
    sim.joint_states()
    sim.wrenches()
    sim.body_states()
    sim.invariants()
    sim.advance(dt)
    sim.reset()


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
    sim : gyro_sim.core.simulator.Simulator
    config : gyro_sim.ros.params.NodeConfig
    outputs : object with prepare_state(t_ns, sim) -> batch, send(t_ns, batch),
        publish_diagnostics(t_ns, level, message, values), record_command(t_ns, raw), event(t_ns, text);
        t_ns: node time in integer nanoseconds
    clock, sleep : injectable for tests
    """

    def __init__(self, sim, config, outputs, clock=time.monotonic, sleep=time.sleep):
        self.sim, self.config, self.out = sim, config, outputs
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
        self.inbox: collections.deque = collections.deque()
        self.requests: collections.deque = collections.deque()
        self.step_time = Samples(window=int(2 * config.physics_rate))
        self.pub_interval = Samples(window=int(2 * config.publish_rate) + 1)
        self.lag = Samples(window=int(2 * config.publish_rate) + 1)
        self.output_time = Samples(window=int(2 * config.publish_rate) + 1)
        self.steps = 0  # physics steps since start (all resets included)
        self.offset_ns = 0  # node time (ns) of the last reset
        self.paused = False
        self.failure: str | None = None
        self.crash: str | None = None  # traceback of an unexpected error that ended the loop
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._last_cmd_step: int | None = None  # step at which the last good command took effect
        self._commanded = False  # a non-zero moment was applied since the last reset
        self._last_pub_wall: float | None = None
        self._next_diag = 0.0
        warm_up(sim, self.dt)
        self._inv0 = sim.invariants()
        self._conserved = conserved(sim.model)
        self.thread = threading.Thread(target=self._run, name="gyro_sim-physics", daemon=True)
        self.wall_start = self.cpu_start = None
        self.wall_end = self.cpu_end = None

    # --- from other threads ----------------------------------------------------------------------
    def submit_command(self, raw: bytes, values) -> str | None:
        """A command received (raw CDR bytes and its values); returns why it is refused, if it is."""
        reason = check_command(values, self.n_axes)
        if reason is None:
            self.counters.accepted += 1
        else:
            self.counters.rejected += 1
            self.counters.last_reject_reason = reason
        self.inbox.append((raw, None if reason else tuple(float(v) for v in values)))
        return reason

    def request(self, kind: str, value: bool = False, timeout: float = 2.0) -> tuple[bool, str]:
        """Ask the loop for a reset or a pause change; wait until it is done."""
        req = Request(kind, value)
        self.requests.append(req)
        if not req.done.wait(timeout):
            return False, f"{kind}: the physics loop did not answer within {timeout} s"
        return True, req.message

    def start(self) -> None:
        self.thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(timeout)

    # --- time --------------------------------------------------------------------------------------
    @property
    def node_ns(self) -> int:
        """Node time in integer ns: the stamps and log times (offset of the last reset + Simulator time)."""
        return self.offset_ns + time_ns(self.sim.time)

    @property
    def node_time(self) -> float:
        """Node time (s)."""
        return self.node_ns * 1e-9

    def _serve_requests(self) -> None:
        while self.requests:
            req = self.requests.popleft()
            if req.kind == "reset":
                while self.inbox:  # received before the reset: recorded, not applied
                    self.out.record_command(self.node_ns, self.inbox.popleft()[0])
                self.offset_ns = self.node_ns
                self.sim.reset()
                self.failure = None
                self._last_cmd_step = None
                self._commanded = False
                self.counters.moments_since = self.node_time
                self._inv0 = self.sim.invariants()
                self.out.event(self.node_ns, "reset")
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
    def _run(self) -> None:
        self.wall_start, self.cpu_start = self.clock(), time.process_time()
        self.pacer.restart(self.node_time)
        self.rate.mark(self.node_time)
        self._next_diag = self.clock()
        try:
            self._send(self._prepare())
            while not self._stop.is_set():
                self._serve_requests()
                if self.paused or self.failure is not None:
                    self._diagnostics_if_due()
                    self._stop.wait(IDLE_PERIOD)
                    continue
                if self._done():
                    break
                self._chunk()
                batch = self._prepare() if self.steps % self.per_publish == 0 and self.failure is None else None
                self.pacer.wait(self.node_time)
                self._send(batch)
                self._diagnostics_if_due()
        except OutputsClosed:
            pass
        except Exception:  # noqa: BLE001 - a bug: reported by the node's exit status
            import traceback

            self.crash = traceback.format_exc()
        finally:
            self.wall_end, self.cpu_end = self.clock(), time.process_time()
            self.finished.set()

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
            self.failure = str(exc)
            self.out.event(self.node_ns, f"simulation stopped: {exc}")
            self._diagnostics()
        if n:
            per_step = (time.perf_counter() - t0) / n
            for _ in range(n):
                self.step_time.add(per_step)

    def _take_commands(self) -> None:
        t_ns = self.node_ns
        t = t_ns * 1e-9
        latest = None
        while self.inbox:
            raw, values = self.inbox.popleft()
            self.out.record_command(t_ns, raw)
            if values is not None:
                latest = values
        if latest is not None:
            if np.any(self.sim.axis_moments != latest):
                self.counters.moments_since = t
            self.sim.set_axis_moments(latest)
            self._last_cmd_step = self.steps
            self.counters.last_effective = t
            self._commanded = self._commanded or any(v != 0.0 for v in latest)
        elif self._last_cmd_step is not None and (self.steps - self._last_cmd_step) > self._timeout_steps:
            self._last_cmd_step = None
            if np.any(self.sim.axis_moments != 0.0):
                self.sim.set_axis_moments(np.zeros(self.n_axes))
                self.counters.timeouts += 1
                self.counters.moments_since = t
                self.out.event(t_ns, f"{COMMAND_TIMEOUT_EVENT}: axis moments back to zero")

    def _prepare(self) -> list | None:
        """The messages of the state just computed (None if it cannot be published)."""
        t0 = time.perf_counter()
        try:
            batch = self.out.prepare_state(self.node_ns, self.sim)
        except SimulationError as exc:
            self.failure = str(exc)
            self.out.event(self.node_ns, f"simulation stopped: {exc}")
            self._diagnostics()
            return None
        self.output_time.add(time.perf_counter() - t0)
        return batch

    def _send(self, batch: list | None) -> None:
        if batch is None:
            return
        now = self.clock()
        if self._last_pub_wall is not None:
            self.pub_interval.add(now - self._last_pub_wall)
        self._last_pub_wall = now
        self.lag.add(self.pacer.lag(self.node_time, now))
        self.out.send(self.node_ns, batch)
        self.counters.published += 1

    # --- diagnostics ---------------------------------------------------------------------------------
    def _diagnostics_if_due(self) -> None:
        if self.clock() >= self._next_diag:
            self._diagnostics()

    def _diagnostics(self) -> None:
        self._next_diag = self.clock() + DIAGNOSTICS_PERIOD
        level, message, values = self.report()
        self.out.publish_diagnostics(self.node_ns, level, message, values)

    def report(self) -> tuple[int, str, dict]:
        """(level 0 OK / 1 WARN / 2 ERROR, message, key -> value) for /diagnostics."""
        c, sim = self.counters, self.sim
        p50, p99 = self.step_time.window_percentiles(50, 99)
        j50, j99 = (abs_dev_percentiles(self.pub_interval.window, self.nominal_publish_interval))
        rtf = float("nan") if (self.paused or self.failure) else self.rate.window_rtf(self.node_time)
        values = {
            "state": "stopped: simulation error" if self.failure else ("paused" if self.paused else "running"),
            "node_time_s": f"{self.node_time:.6f}",
            "sim_time_since_reset_s": f"{sim.time:.6f}",
            "physics_rate_hz": f"{self.config.physics_rate:g}",
            "publish_rate_hz": f"{self.config.publish_rate:g}",
            "real_time_factor_target": f"{self.rtf:g}",
            "real_time_factor_achieved": fmt(rtf, ".4f"),
            "step_time_p50_us": fmt(p50, ".1f", 1e6),
            "step_time_p99_us": fmt(p99, ".1f", 1e6),
            "publish_jitter_p50_us": fmt(j50, ".1f", 1e6),
            "publish_jitter_p99_us": fmt(j99, ".1f", 1e6),
            "sim_lag_max_ms": f"{max(self.lag.window, default=0.0) * 1e3:.3f}",
            "deadline_misses": str(self.pacer.misses),
            "slipped_s": f"{self.pacer.slipped:.6f}",
            "commands_accepted": str(c.accepted),
            "commands_rejected": str(c.rejected),
            "last_reject_reason": c.last_reject_reason,
            "command_timeouts": str(c.timeouts),
            "last_command_effective_s": fmt(c.last_effective, ".9f"),
            "moments_applied_since_s": f"{c.moments_since:.9f}",
            "axis_names": ",".join(sim.axis_names),
            "axis_moments": ",".join(f"{v:.6g}" for v in sim.axis_moments),
            "integrator": sim.integrator_name,
            "backend": backend_name(sim),
            "error_estimate": "n/a (fixed step)" if sim.error_estimate is None else f"{sim.error_estimate:.3e}",
            "steps_per_wakeup": str(self.per_chunk),
        }
        if self.failure is None:
            inv = sim.invariants()
            for name, x in inv.items():  # energy, momenta (vectors as x,y,z), and what else applies
                values[name] = ",".join(f"{float(c):.12g}" for c in np.ravel(x))
            for name in self._conserved:
                # commands are internal moments: they change the energy, not the momenta
                if self._commanded and name in ("energy", "jacobi"):
                    values[f"{name}_drift"] = "n/a (commanded since reset)"
                else:
                    values[f"{name}_drift"] = f"{relative_drift(self._inv0[name], inv[name]):.3e}"
        if self.failure is not None:
            return 2, f"simulation stopped: {self.failure} (call ~/reset)", values
        if self.paused:
            return 0, "paused", values
        warn = []
        if self.rtf > 0 and math.isfinite(rtf) and rtf < 0.95 * self.rtf:
            warn.append(f"real-time factor {rtf:.2f} below {self.rtf:g}")
        if c.rejected:
            warn.append(f"{c.rejected} commands rejected")
        if warn:
            return 1, "; ".join(warn), values
        return 0, "running", values

    @property
    def nominal_publish_interval(self) -> float:
        return float("nan") if self.rtf <= 0 else 1.0 / (self.config.publish_rate * self.rtf)

    def summary(self) -> dict:
        """Whole-run timing statistics (for stats_file and the bench)."""
        p50, p99, pmax = self.step_time.run_percentiles(50, 99, 100)
        j50, j99 = abs_dev_percentiles(self.pub_interval.all, self.nominal_publish_interval)
        wall = (self.wall_end or self.clock()) - self.wall_start
        cpu = (self.cpu_end or time.process_time()) - self.cpu_start
        intervals = np.asarray(self.pub_interval.all) if self.pub_interval.all else np.array([np.nan])
        return {
            "scene": self.config.scene.name,
            "bodies": len(self.config.scene.bodies),
            "physics_rate": self.config.physics_rate,
            "publish_rate": self.config.publish_rate,
            "real_time_factor_target": self.rtf,
            "integrator": self.sim.integrator_name,
            "backend": backend_name(self.sim),
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
            "publish_interval_mean_ms": float(np.mean(intervals)) * 1e3,
            "publish_jitter_p50_us": j50 * 1e6,
            "publish_jitter_p99_us": j99 * 1e6,
            "output_time_p50_us": self.output_time.run_percentiles(50)[0] * 1e6,
            "sim_lag_max_ms": max(self.lag.all, default=0.0) * 1e3,
            "deadline_misses": self.pacer.misses,
            "slipped_s": self.pacer.slipped,
            "commands_accepted": self.counters.accepted,
            "commands_rejected": self.counters.rejected,
        }


class OutputsClosed(Exception):
    """Raised by outputs when the ROS context is gone: the loop ends quietly."""


def fmt(x: float, spec: str, scale: float = 1.0) -> str:
    """`x * scale` formatted, or "n/a" when not finite (no NaN text on /diagnostics)."""
    return format(x * scale, spec) if math.isfinite(x) else "n/a"


def abs_dev_percentiles(intervals, nominal: float) -> tuple[float, float]:
    """p50 and p99 of |interval - nominal| (s); NaN without data or without a nominal."""
    if not len(intervals) or not math.isfinite(nominal):
        return float("nan"), float("nan")
    dev = np.abs(np.fromiter(intervals, float) - nominal)
    p50, p99 = np.percentile(dev, [50, 99])
    return float(p50), float(p99)


def relative_drift(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = max(float(np.max(np.abs(a))), 1e-300)
    return float(np.max(np.abs(b - a))) / scale
