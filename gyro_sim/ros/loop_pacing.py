"""The physics loop's pacing (gyro_sim.ros.pacing's `Pacer` against the wall clock), the
physics thread's scheduling, and what the run's timing shows: step times, deadline misses
with a wait for a CPU before them, the host's steal, the collector's pauses."""
from __future__ import annotations

import gc
import math
import time

from gyro_sim.ros.pacing import (
    Histogram, Pacer, RateMeter, RunDelay, Samples, chunk_steps, host_steal, normal_priority, realtime_priority,
)

#: a SCHED_FIFO physics thread that has not slept for this long (wall s: it cannot keep up with
#: real time) goes back to the normal scheduler: a FIFO thread that never sleeps holds its CPU
#: from every normal thread (on one core: the executor, the signals, the recorder) for 95 % of
#: every second
FIFO_DEMOTE_AFTER = 1.0


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


class LoopPacing:
    """When the physics thread wakes, how it is scheduled, and the timing figures of its run.

    Parameters
    ----------
    config : gyro_sim.ros.params.NodeConfig (dt, real_time_factor, steps_per_publish,
        physics_rate, thread_priority)
    clock, sleep : injectable for tests
    run_delay : seconds the calling thread has waited for a CPU so far (pacing.RunDelay; tests
        inject their own): a deadline miss is counted as a *CPU-wait miss* too when the physics
        thread waited, runnable, more than one physics period for a CPU since the previous
        deadline check (the OS gave the CPUs to others: diagnostics of a miss, not a change to it)
    """

    def __init__(self, config, clock=time.monotonic, sleep=time.sleep, run_delay=None):
        self.config, self.clock = config, clock
        self.rtf = config.real_time_factor
        self.per_chunk = chunk_steps(config.steps_per_publish, config.dt, self.rtf)
        self.pacer = Pacer(self.rtf, config.dt / self.rtf if self.rtf > 0 else 0.0, clock=clock, sleep=sleep)
        self.rate = RateMeter(clock)
        self.step_time = Samples(window=int(2 * config.physics_rate))
        self.run_delay = RunDelay() if run_delay is None else run_delay
        self.cpu_wait_misses = 0  # deadline misses with more than a period of waiting for a CPU before them
        self._cpu_wait = [math.nan, math.nan]  # the physics thread's wait for a CPU at its start, at the last check
        self._steal = [math.nan, math.nan]  # the host's steal at the start and the end
        self.wall_start = self.cpu_start = None
        self.wall_end = self.cpu_end = None
        self.gc_pauses = GcPauses()
        self.frozen = 0  # objects of the start-up frozen out of the collector's reach
        #: the physics thread's SCHED_FIFO priority in effect (0: normal scheduler) and one line
        #: saying how it is scheduled, set by the thread when it starts
        self.priority = 0
        self.scheduling = ""

    def freeze(self) -> None:
        """Before the thread starts: the start-up's objects frozen, the collector's pauses watched."""
        self.frozen = freeze_start_up()
        self.gc_pauses.install()

    def schedule(self) -> None:
        """The calling (physics) thread's scheduling: SCHED_FIFO at config.thread_priority while
        pacing in real time (pacing.realtime_priority); as fast as possible it never sleeps, and a
        FIFO thread that never sleeps would take its CPU from everything else: normal then."""
        wanted = int(self.config.thread_priority)
        if self.rtf > 0:
            self.priority, self.scheduling = realtime_priority(wanted)
        elif getattr(self.config, "lockstep", False):
            self.scheduling = "normal scheduler (lock-step: paced by the commands, no wall deadline)"
        else:
            self.scheduling = "normal scheduler (real_time_factor 0: as fast as possible, never sleeping)"

    def begin(self, node_time: float) -> None:
        """The physics thread starts its run at `node_time`."""
        self.wall_start, self.cpu_start = self.clock(), time.process_time()
        self._cpu_wait = [self.run_delay()] * 2
        self._steal[0] = host_steal()
        self.restart(node_time)

    def restart(self, node_time: float) -> None:
        """Deadlines and the rate measured from `node_time` on (start, reset, resume)."""
        self.pacer.restart(node_time)
        self.rate.mark(node_time)

    def steps_took(self, seconds: float, n: int) -> None:
        """`n` physics steps took `seconds` together."""
        per_step = seconds / n
        for _ in range(n):
            self.step_time.add(per_step)

    def wait(self, node_time: float) -> str | None:
        """Sleep until `node_time`'s wall deadline; a line saying why the thread left SCHED_FIFO
        when it has not slept for FIFO_DEMOTE_AFTER (None otherwise)."""
        waited = self.run_delay()
        if not self.pacer.wait(node_time) and waited - self._cpu_wait[1] > self.pacer.tolerance:
            self.cpu_wait_misses += 1
        demoted = None
        if self.priority and self.clock() - self.pacer.last_sleep > FIFO_DEMOTE_AFTER:
            demoted = self._demote(node_time)
        self._cpu_wait[1] = waited
        return demoted

    def _demote(self, node_time: float) -> str:
        """Back to the normal scheduler (the thread cannot keep up: it never sleeps)."""
        normal_priority()
        self.scheduling = (f"normal scheduler since node time {node_time:.3f} s: SCHED_FIFO priority "
                           f"{self.priority} dropped, the physics thread had not slept for {FIFO_DEMOTE_AFTER:g} s "
                           f"(behind real time)")
        self.priority = 0
        return f"physics thread: {self.scheduling}"

    def end(self) -> None:
        """The physics thread ends its run."""
        if self.wall_start is not None:
            self.wall_end, self.cpu_end = self.clock(), time.process_time()
        self._cpu_wait[1] = self.run_delay()
        self._steal[1] = host_steal()
        if isinstance(self.run_delay, RunDelay):
            self.run_delay.close()

    def stop(self) -> None:
        self.gc_pauses.remove()

    @property
    def cpu_wait(self) -> float:
        """Seconds the physics thread waited, runnable, for a CPU between its start and its last check."""
        return self._cpu_wait[1] - self._cpu_wait[0]

    @property
    def steal(self) -> float:
        """The host's steal (s) between the thread's start and its end."""
        return self._steal[1] - self._steal[0]

    def wall_cpu(self) -> tuple[float, float]:
        """Wall and CPU seconds of the run so far (zeros if it never started)."""
        if self.wall_start is None:  # never started (stopped during start-up)
            return 0.0, 0.0
        return (self.wall_end or self.clock()) - self.wall_start, (self.cpu_end or time.process_time()) - self.cpu_start
