"""The physics loop's commands: received from any thread, checked, held one at a time, taken
by the physics steps, logged in causal order (what is logged when: gyro_sim.ros.loop's
docstring), replaced by zeros after ``command_timeout`` simulated seconds of silence, and the
built-in demo's commands (gyro_sim.ros.demo) while none has come from outside.

Each command from outside that a step applies is timed, on the loop's monotonic wall clock,
from its receipt to the physics step that applies it (`CommandPath.latency`). A
Float64MultiArray carries no stamp, so the time starts at the node: the clock read when the
subscription callback hands the decoded command over (`submit`). It ends when that step starts
in wall time: the later of the moment the physics thread sets the command on the Simulator
(just before computing the step) and the step's wall deadline (the wall time its node time is
paced to: the thread computes up to one wake-up ahead, so a step computed early still starts,
as the outside sees it, at its deadline). Superseded commands, the demo's, and those received
while the loop was not running (before its start, paused) are not timed.

In lock-step (`lockstep`) every good command is kept, in the order received, in a queue of at
most LOCKSTEP_QUEUE: the physics thread takes the oldest (`next_command`) and applies it to a
whole control period; none is superseded. A command that finds the queue full is rejected
(logged as an event, never applied), so the commands applied are exactly those logged.

Joint commands (``~/joint_commands``, the servos' controls by joint name) take the same path
as the axis moments, each on its own log topic: a good one carries the whole controls vector,
the previous good one's (the servos' initial `control` after a reset) with its joints' entries
replaced, so that a reader applying the logged joint commands in file order ends with the
controls applied. A step applies the last axis moments and the last controls logged since the
previous step, so that neither kind supersedes the other; a timeout zeroes the axis moments and
holds the controls."""

from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from gyro_sim.log.resim import COMMAND_TIMEOUT_EVENT
from gyro_sim.msgs import messages as M
from gyro_sim.ros.demo import DEMO_RATE
from gyro_sim.ros.pacing import Samples

#: most commands waiting in lock-step (each one control period): beyond, a command is rejected
LOCKSTEP_QUEUE = 1000


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
    last_reject_reason: str = ""
    last_effective: float = float("nan")  # node time from which the last good command applies
    moments_since: float = 0.0  # node time from which the moments now applied have been applied


class CommandPath:
    """The commands of one Simulator's axes.

    Parameters
    ----------
    n_axes : number of actuated axes
    out : where commands and events go (gyro_sim.ros.loop.SimLoop's `outputs`)
    node_ns : the loop's node time (integer ns), read when a command is rejected
    timeout : command_timeout (simulated s); dt : the physics step (s)
    demo : the built-in demo (gyro_sim.ros.demo.Demo), or None
    clock : the loop's monotonic wall clock (s), injectable for tests
    due : node time (s) -> the wall time (clock units) at which a step starting then is due;
        None when nothing is paced (real_time_factor 0)
    window : how many of the last latencies the live percentiles take
    lockstep : keep every good command in a queue, taken one per control period (`next_command`)
    """

    def __init__(self, n_axes: int, out, node_ns: Callable[[], int], timeout: float, dt: float, demo=None,
                 clock: Callable[[], float] = time.monotonic, due: Callable[[float], float] | None = None,
                 window: int = 2000, lockstep: bool = False, joint_controls: Callable | None = None,
                 initial_controls: np.ndarray | None = None):
        self.n_axes, self.out, self._node_ns = n_axes, out, node_ns
        #: (names, position, velocity, effort, base) -> the controls after a joint command
        #: (Simulator.joint_command_controls; ValueError: refused), None without servos
        self._joint_controls = joint_controls
        #: the servos' controls at the start and after a reset (Simulator.initial_controls)
        self.initial_controls = np.zeros(0) if initial_controls is None else np.array(initial_controls, dtype=float)
        self._controls_submitted = self.initial_controls.copy()  # the last good joint command's controls
        #: per kind ("moments", "controls"), the values of the last command logged, and the kinds
        #: logged since the last step took a command
        self._logged: dict[str, tuple] = {}
        self._fresh: set[str] = set()
        self.lockstep = lockstep
        #: lock-step: the good commands received and not yet taken, oldest first (as _latest's items)
        self._queue: collections.deque = collections.deque()
        self._arrived = threading.Condition(threading.Lock())
        self._clock, self._due = clock, due
        #: receipt to the step that applies it (wall s), per command from outside that a step applied
        self.latency = Samples(window=window)
        self._timed_after = 0  # commands accepted up to this sequence number are not timed
        # the fallback comes at the first step starting more than `timeout` after the last good command
        self._timeout_steps = math.floor(timeout / dt * (1 + 1e-12))
        self.counters = Counters()
        # the latest good command: (sequence number, raw bytes, values, clock time of its receipt,
        # None for the demo's); one slot, replaced whole
        self._latest: tuple | None = None
        self._taken_seq = 0
        # every good command received and not yet logged: (sequence number, raw bytes, kind,
        # values), in order
        self._received: collections.deque = collections.deque()
        self._last_step: int | None = None  # step at which the last good command took effect
        #: the built-in demo commands while no command came from outside
        self.demo = demo
        self._demo_period_ns = M.time_ns(min(1.0 / DEMO_RATE, 0.5 * timeout))
        self._next_demo_ns = 0
        self._demo_stopped = False  # a command from outside arrived: the demo is over
        self._demo_stop_said = False
        self._submit_lock = threading.Lock()  # a demo command never lands after one from outside

    # --- from other threads ----------------------------------------------------------------------
    def submit(self, raw: bytes, values) -> str | None:
        """A command received (raw CDR bytes and its values); returns why it is refused, if it is.
        A good one replaces the latest (taken by the next physics step) and ends the demo."""
        received = self._clock()
        with self._submit_lock:
            reason = check_command(values, self.n_axes) or self._queue_full()
            if reason is None:
                self._demo_stopped = True
            return self._submit(raw, values, reason, received)

    def submit_joint(self, raw: bytes, command) -> str | None:
        """A joint command received (raw CDR bytes and its decoded (names, position, velocity,
        effort), None for bytes that are no JointState); returns why it is refused, if it is."""
        received = self._clock()
        with self._submit_lock:
            controls, reason = None, None
            if self._joint_controls is None:
                reason = "the scene has no servos"
            elif command is None:
                reason = "not a sensor_msgs/JointState"
            else:
                try:
                    controls = self._joint_controls(*command, self._controls_submitted)
                except ValueError as exc:
                    reason = str(exc)
            reason = reason or self._queue_full()
            if reason is None:
                self._demo_stopped = True
                self._controls_submitted = controls
            return self._submit(raw, controls, reason, received, "controls")

    def _queue_full(self) -> str | None:
        """Why a good command is refused in lock-step: the queue is full (None otherwise)."""
        if self.lockstep and len(self._queue) >= LOCKSTEP_QUEUE:
            return f"lock-step: {LOCKSTEP_QUEUE} commands already waiting"
        return None

    def _submit(self, raw: bytes, values, reason: str | None, received: float | None = None,
                kind: str = "moments") -> str | None:
        if reason is None:
            seq = self.counters.accepted + 1
            values = tuple(float(v) for v in values)
            # before it is the latest: a step taking it finds it here
            self._received.append((seq, raw, kind, values))
            self.counters.accepted = seq
            item = (seq, raw, values, received)
            with self._arrived:
                if self.lockstep:
                    self._queue.append(item)
                else:
                    self._latest = item
                self._arrived.notify()
        else:
            self.counters.rejected += 1
            self.counters.last_reject_reason = reason
            self.out.record_event(self._node_ns(), f"command rejected ({reason})")
        return reason

    # --- in the physics thread -------------------------------------------------------------------
    def next_command(self, timeout: float) -> bool:
        """Lock-step: make the oldest command waiting the latest (the next step takes it); False
        when none came within `timeout` wall seconds."""
        with self._arrived:
            if not self._queue:
                self._arrived.wait(timeout)
            if not self._queue:
                return False
            self._latest = self._queue.popleft()
            return True

    def wait_any(self, timeout: float) -> bool:
        """Whether a good command has come (waiting up to `timeout` wall seconds for one)."""
        with self._arrived:
            if self._latest is None and not self._queue:
                self._arrived.wait(timeout)
            return self._latest is not None or bool(self._queue)

    @property
    def waiting(self) -> int:
        """Lock-step: commands received and not yet taken."""
        return len(self._queue)

    def time_from_now(self) -> None:
        """The loop runs from now (its start, a resume): commands received before now waited for
        it, not for a step, and are applied untimed."""
        self._timed_after = self.counters.accepted

    def _log_received(self, t_ns: int, upto: int) -> None:
        """Log, at `t_ns`, the good commands received up to sequence number `upto` not yet logged."""
        received = self._received
        runs: list[tuple[str, list]] = []  # consecutive commands of one kind: one hand-over
        while received and received[0][0] <= upto:
            _, raw, kind, values = received.popleft()
            if not runs or runs[-1][0] != kind:
                runs.append((kind, []))
            runs[-1][1].append(raw)
            self._logged[kind] = values
            self._fresh.add(kind)
        for kind, raws in runs:
            if kind == "moments":
                self.out.record_commands(t_ns, raws)
            else:
                self.out.record_joint_commands(t_ns, raws)

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

    def take(self, sim, t_ns: int, step: int) -> None:
        """Before physics step number `step`, at node time `t_ns`: set the latest good command, if
        new, on `sim` (logged with those it superseded), or zeros once it has timed out."""
        t = t_ns * 1e-9
        if self.demo is not None:
            self._demo_command(t_ns)
        new = self._latest
        latest = controls = None
        if new is not None and new[0] != self._taken_seq:
            seq, raw, _, received = new
            self.counters.superseded += seq - self._taken_seq - 1
            self._taken_seq = seq
            self._log_received(t_ns, seq)  # the ones it superseded, then it
            # the last of each kind logged since the last step took one (a pause's log too)
            latest = self._logged["moments"] if "moments" in self._fresh else None
            controls = self._logged["controls"] if "controls" in self._fresh else None
            self._fresh.clear()
            if received is not None and seq > self._timed_after:
                starts = self._clock()
                if self._due is not None:
                    starts = max(starts, self._due(t))
                self.latency.add(starts - received)
        if latest is not None or controls is not None:
            if latest is not None:
                if np.any(sim.axis_moments != latest):
                    self.counters.moments_since = t
                sim.set_axis_moments(latest)
            if controls is not None:
                sim.set_controls(controls)
            self._last_step = step
            self.counters.last_effective = t
        elif self._last_step is not None and (step - self._last_step) > self._timeout_steps:
            self._last_step = None
            if np.any(sim.axis_moments != 0.0):
                sim.set_axis_moments(np.zeros(self.n_axes))
                self.counters.timeouts += 1
                self.counters.moments_since = t
                self.out.event(t_ns, f"{COMMAND_TIMEOUT_EVENT}: axis moments back to zero")

    def log_superseded(self, t_ns: int) -> None:
        """Paused or stopped: log the commands already superseded (all but the latest)."""
        latest = self._latest
        if latest is not None and self._received and self._received[0][0] < latest[0]:
            self._log_received(t_ns, latest[0] - 1)

    def discard(self, t_ns: int) -> None:
        """At a reset (logged just after this): the commands received before it are logged at
        `t_ns` and never applied after it; the timeout starts again with the next command."""
        with self._submit_lock:
            last = self._last_received()
            self._queue.clear()
            self._controls_submitted = self.initial_controls.copy()  # the reset restores the controls
        if last is not None:
            self._taken_seq = last
            self._log_received(t_ns, last)
        self._fresh.clear()  # logged, never applied
        self._last_step = None

    def _last_received(self) -> int | None:
        """The sequence number of the last good command received (None: none yet)."""
        if self._queue:
            return self._queue[-1][0]
        return None if self._latest is None else self._latest[0]

    def log_remaining(self, t_ns: int) -> None:
        """The loop ends: the commands received and never taken, logged at `t_ns`."""
        with self._submit_lock:
            last = self._last_received()
        if last is not None and self._received:
            self._log_received(t_ns, last)
