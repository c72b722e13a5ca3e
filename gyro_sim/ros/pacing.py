"""Pacing a fixed-step simulation against the wall clock, and the timing statistics (no rclpy).

The loop computes ahead: the state at a chunk boundary is computed *before* the wall clock
reaches it, then the loop sleeps until the boundary's wall deadline and publishes. So a
published stamp equals the wall time (scaled by the real-time factor) up to the wake-up
latency of one `time.sleep`, and no timer callback per physics step is needed.

A boundary reached more than one physics period after its deadline is a *deadline miss*
(simulated and wall time then disagree by more than a step). A short lateness, up to
MAX_CATCH_UP of wall time (a wake-up delayed by the OS on a busy machine), is made up: the
due steps run back to back, at most MAX_CATCH_UP worth, and simulated time does not drift.
Beyond that (the CPU does not keep up) the schedule *slips*: the wall origin moves forward by
the whole lateness, which is never made up by a burst of steps. Simulated time then falls
behind wall time by exactly the accumulated slips, which the achieved real-time factor shows.
"""
from __future__ import annotations

import math
import os
import time
from collections import deque

import numpy as np

#: longest wall time between two wake-ups of the physics loop (s): the latency of a command
MAX_WAKE_PERIOD = 2e-3
#: largest wall lateness (s) made up by running due steps back to back; beyond it the schedule
#: slips. It covers the burst the "fixed" integrator's real-time budget allows
#: (gyro_sim.integrators.fixed: BURST_STEPS x EVAL_BUDGET = 60,000 evaluations; 40 ms of CPU in
#: the compiled loops, 144 ms in the rescue's Python driver at 2.4 us an evaluation, 2 cores,
#: 2026-11-29), with room for a machine half as fast: the calls of a violent command that run
#: late within that credit are made up by the cheaper calls after them, and only a CPU that does
#: not keep up on average slips
MAX_CATCH_UP = 0.3
#: whole-run statistics are kept in fixed histograms (constant memory over any run length):
#: logarithmic bins from HIST_LOW to HIST_HIGH seconds, each HIST_RATIO wide; a quantile is
#: the geometric centre of its bin (relative error below (HIST_RATIO - 1) / 2 = 0.5 %)
HIST_LOW, HIST_HIGH, HIST_RATIO = 1e-8, 1e3, 1.01


def chunk_steps(steps_per_publish: int, dt: float, rtf: float) -> int:
    """Physics steps per wake-up: the largest divisor of `steps_per_publish` (so publication
    times fall on wake-ups) whose wall duration stays within MAX_WAKE_PERIOD; all of them when
    running as fast as possible (rtf 0)."""
    if rtf <= 0:
        return steps_per_publish
    best = 1
    for k in range(1, steps_per_publish + 1):
        if steps_per_publish % k == 0 and k * dt / rtf <= MAX_WAKE_PERIOD * (1 + 1e-9):
            best = k
    return best


class Pacer:
    """Wall-clock deadlines of chunk boundaries for a real-time factor (0: no waiting).

    Parameters
    ----------
    rtf : simulated seconds per wall second (0: as fast as possible).
    tolerance : wall lateness (s) that is not a miss: one physics period of wall time.
    catch_up : wall lateness (s) made up without slipping (at least `tolerance`).
    clock, sleep : injectable for tests (time.monotonic, time.sleep).
    """

    def __init__(self, rtf: float, tolerance: float, catch_up: float = MAX_CATCH_UP, clock=time.monotonic,
                 sleep=time.sleep):
        self.rtf = float(rtf)
        self.tolerance = float(tolerance)
        self.catch_up = max(float(catch_up), self.tolerance)
        self.clock, self.sleep = clock, sleep
        self.misses = 0
        self.slipped = 0.0  # wall seconds given up in total
        self.restart(0.0)

    def restart(self, sim_time: float) -> None:
        """Make `sim_time` the simulated time of now (start, after a pause or a reset)."""
        self.origin = self.clock()
        self.sim0 = float(sim_time)
        self.last_sleep = self.origin  # clock time of the last wait that slept (or of the restart)

    def deadline(self, sim_time: float) -> float:
        """The wall time (clock units) at which `sim_time` is due."""
        return self.origin + (sim_time - self.sim0) / self.rtf

    def lag(self, sim_time: float, now: float | None = None) -> float:
        """Wall-mapped simulated time minus `sim_time` (s of simulated time): > 0 when behind."""
        if self.rtf <= 0:
            return 0.0
        now = self.clock() if now is None else now
        return (now - self.origin) * self.rtf - (sim_time - self.sim0)

    def wait(self, sim_time: float) -> bool:
        """Wait until `sim_time` is due. Returns False on a deadline miss (slipping if far behind)."""
        if self.rtf <= 0:
            return True
        deadline = self.deadline(sim_time)
        now = self.clock()
        if now < deadline:
            while now < deadline:
                self.sleep(deadline - now)
                now = self.clock()
            self.last_sleep = now
            return True
        late = now - deadline
        if late <= self.tolerance:
            return True
        self.misses += 1
        if late > self.catch_up:
            self.slipped += late
            self.origin += late
        return False


class Histogram:
    """Quantiles of non-negative durations (s) in constant memory: counts in logarithmic bins
    (module constants), plus the exact count, sum and maximum. Values below HIST_LOW count in
    the first bin, above HIST_HIGH in the last."""

    _LOG_LOW = float(np.log(HIST_LOW))
    _LOG_RATIO = float(np.log(HIST_RATIO))
    BINS = int(np.ceil(np.log(HIST_HIGH / HIST_LOW) / np.log(HIST_RATIO))) + 1

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS, dtype=np.int64)
        self.n = 0
        self.total = 0.0
        self.max = float("nan")

    def add(self, x: float) -> None:
        i = 0 if x <= HIST_LOW else min(self.BINS - 1, int((np.log(x) - self._LOG_LOW) / self._LOG_RATIO))
        self.counts[i] += 1
        self.n += 1
        self.total += x
        if not x <= self.max:  # also replaces the initial NaN
            self.max = x

    @property
    def mean(self) -> float:
        return self.total / self.n if self.n else float("nan")

    def quantiles(self, *qs: float) -> list[float]:
        """Percentiles `qs` (0..100); 100 is the exact maximum; NaN without data."""
        if not self.n:
            return [float("nan")] * len(qs)
        cum = np.cumsum(self.counts)
        out = []
        for q in qs:
            if q >= 100:
                out.append(self.max)
                continue
            i = int(np.searchsorted(cum, q / 100.0 * self.n, side="left"))
            i = min(i, self.BINS - 1)
            out.append(min(float(np.exp(self._LOG_LOW + (i + 0.5) * self._LOG_RATIO)), self.max))
        return out


class Samples:
    """Durations (s): the last `window` kept for live percentiles, the whole run in a Histogram
    (constant memory). `offset`: what is recorded is |x - offset| (a nominal interval's jitter)."""

    def __init__(self, window: int, offset: float | None = None):
        self.window: deque[float] = deque(maxlen=window)
        self.run = Histogram()
        self.offset = offset

    def add(self, x: float) -> None:
        if self.offset is not None:
            x = abs(x - self.offset)
        self.window.append(x)
        self.run.add(x)

    def window_percentiles(self, *qs) -> list[float]:
        if not len(self.window):
            return [float("nan")] * len(qs)
        return [float(v) for v in np.percentile(np.fromiter(self.window, float), qs)]

    def run_percentiles(self, *qs) -> list[float]:
        return self.run.quantiles(*qs)


class RateMeter:
    """Simulated time against wall time over a sliding window: the achieved real-time factor."""

    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self.mark(0.0)
        self.total_sim = 0.0
        self.total_wall = 0.0

    def mark(self, sim_time: float) -> None:
        self._wall0, self._sim0 = self.clock(), sim_time

    def window_rtf(self, sim_time: float) -> float:
        """Achieved factor since the last mark; marks now. NaN (not measured) when no simulated
        time passed since the mark (the start, a reset): a factor needs an interval behind it."""
        now = self.clock()
        wall, sim = now - self._wall0, sim_time - self._sim0
        self.total_sim += sim
        self.total_wall += wall
        self._wall0, self._sim0 = now, sim_time
        return sim / wall if wall > 0 and sim > 0 else float("nan")

class RunDelay:
    """Seconds the calling thread has waited so far, runnable, for a CPU (Linux's
    /proc/thread-self/schedstat, its second field): the time the OS scheduler gave the CPUs to
    other threads and processes while this one was ready to run. NaN where the system does
    not tell. The file is opened by the first call, in the thread that makes it (then one
    pread per call, ~2 us)."""

    def __init__(self, path: str = "/proc/thread-self/schedstat"):
        self.path = path
        self._fd: int | None = None
        self._failed = False

    def __call__(self) -> float:
        if self._fd is None:
            if self._failed:
                return math.nan
            try:
                self._fd = os.open(self.path, os.O_RDONLY)
            except OSError:
                self._failed = True
                return math.nan
        try:
            return int(os.pread(self._fd, 128, 0).split()[1]) * 1e-9
        except (OSError, ValueError, IndexError):
            return math.nan

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def host_steal(path: str = "/proc/stat") -> float:
    """Seconds of CPU time (summed over the CPUs) the hypervisor ran something else on this
    virtual machine's CPUs (Linux /proc/stat, "steal"; in clock ticks of 10 ms); NaN where the
    system does not tell. While it does, no thread here runs and no timer here fires on time."""
    try:
        with open(path) as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return math.nan


def normal_priority(setscheduler=None) -> None:
    """Put the calling thread back under the normal scheduler (SCHED_OTHER)."""
    setscheduler = setscheduler or getattr(os, "sched_setscheduler", None)
    if setscheduler is not None and hasattr(os, "SCHED_OTHER"):
        try:
            setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:  # pragma: no cover - lowering one's own policy is always allowed
            pass


def realtime_priority(priority: int, setscheduler=None) -> tuple[int, str]:
    """Put the calling thread under the SCHED_FIFO policy at `priority` (1-99), as ros2_control
    does with its control thread (`thread_priority`), where the system allows it (root, or an
    rtprio limit: `ulimit -r`, /etc/security/limits.conf). Returns (the FIFO priority in
    effect, 0 for the normal scheduler; one line saying so and, if refused, why and how to
    allow it).

    A FIFO thread that becomes runnable (its sleep until a deadline ends) preempts every
    normal thread on its CPU at once: under load, a normal thread waits for a CPU for up to
    a scheduler slice (a few ms), which is a deadline miss at 1 kHz. Linux keeps 5 % of
    every CPU second for normal threads (sched_rt_runtime_us), so a FIFO thread cannot
    lock a machine up. `setscheduler` is injectable for tests (os.sched_setscheduler)."""
    priority = int(priority)
    if priority <= 0:
        return 0, "normal scheduler (thread_priority 0)"
    setscheduler = setscheduler or getattr(os, "sched_setscheduler", None)
    if setscheduler is None or not hasattr(os, "SCHED_FIFO"):
        return 0, f"normal scheduler: SCHED_FIFO (thread_priority {priority}) is not available on this system"
    try:
        setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # 0: the calling thread (Linux)
    except OSError as exc:
        return 0, (f"normal scheduler: SCHED_FIFO priority {priority} refused ({exc.strerror or exc}); "
                   f"allow it with an rtprio limit (ulimit -r, /etc/security/limits.conf) or set thread_priority:=0")
    return priority, f"SCHED_FIFO priority {priority}"


class Floor:
    """The machine's own floor of deadline misses: a thread that does nothing but sleep to the
    physics loop's wake-up deadlines (every `period` s, `Pacer` with the loop's tolerance, the
    same scheduling as `realtime_priority` gives the physics thread) and counts the misses. Run
    beside the node, it meets the same host steal, timer latency and CPU contention without
    any of the node's work or its interpreter lock (a separate process): what it misses, the
    node cannot be expected to hold."""

    def __init__(self, period: float = 2e-3, tolerance: float = 1e-3, priority: int = 0, clock=time.monotonic,
                 sleep=time.sleep):
        self.period, self.priority = float(period), int(priority)
        self.pacer = Pacer(1.0, tolerance, clock=clock, sleep=sleep)
        self.wakeups = 0
        self.got_priority = 0
        self._stop = False
        self._thread = None

    def _run(self) -> None:
        self.got_priority = realtime_priority(self.priority)[0] if self.priority else 0
        self.pacer.restart(0.0)
        k = 0
        while not self._stop:
            k += 1
            self.pacer.wait(k * self.period)
            self.wakeups += 1

    def start(self) -> "Floor":
        import threading

        self._thread = threading.Thread(target=self._run, name="gyro_sim-floor", daemon=True)
        self._thread.start()
        return self

    def stop_soon(self) -> None:
        """Ask the thread to stop after its current wait (from any thread)."""
        self._stop = True

    def stop(self) -> int:
        """Stop; the misses counted."""
        self._stop = True
        if self._thread is not None:
            self._thread.join(5.0)
        return self.pacer.misses


class ShareLimit:
    """The largest share of the interpreter a thread takes on average (the node's executor, so
    that a flood of commands cannot starve the physics thread), with bursts allowed.

    The thread's CPU time is counted against an allowance of `share` times the wall time
    passed; once it is more than `burst` CPU seconds over, `after` says how long to sleep for
    the allowance to catch up. Commands at a steady 1 kHz (~0.1-0.2 ms of CPU each) stay within
    it and are never delayed; a flood is held to `share` on average.
    """

    def __init__(self, share: float, burst: float, clock=time.monotonic):
        self.share, self.burst, self.clock = float(share), float(burst), clock
        self.over = 0.0  # CPU seconds taken beyond the allowance
        self._last = clock()

    def after(self, cpu: float) -> float:
        """The thread took `cpu` CPU seconds since the last call: how long it should sleep now."""
        now = self.clock()
        self.over = max(0.0, self.over + cpu - self.share * (now - self._last))
        self._last = now
        if self.over <= self.burst:
            return 0.0
        return self.over / self.share
