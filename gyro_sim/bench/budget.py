"""What the reports share: a CPU budget per run, and how a drift series grows.

Used by the stability report and its spin sweep (:mod:`gyro_sim.bench.stability`,
:mod:`gyro_sim.bench.spin_sweep`).
"""
from __future__ import annotations

import contextlib
import math
import signal

import numpy as np


class OverBudget(BaseException):
    """The CPU budget of a run is spent (raised from a SIGPROF handler, inside `advance`).

    A BaseException, as KeyboardInterrupt: raised asynchronously, it can land inside library
    code whose `except Exception` would turn it into something else (numpy's `norm` turns it
    into a TypeError)."""


@contextlib.contextmanager
def cpu_limit(seconds: float):
    """Raise OverBudget in this (main) thread once `seconds` of process CPU time have passed.

    A timer on CPU time (setitimer ITIMER_PROF), so that a single `advance` call that never
    returns (an integrator grinding at a tiny step) is stopped too. Where there is no such
    timer (Windows, other threads), nothing is armed and the caller's checks between calls
    remain.
    """
    def handler(signum, frame):
        raise OverBudget()

    try:
        old = signal.signal(signal.SIGPROF, handler)
        signal.setitimer(signal.ITIMER_PROF, max(seconds, 1e-3))
    except (AttributeError, ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0.0)
        signal.signal(signal.SIGPROF, old)


def growth(t, drift) -> tuple[str, float, float]:
    """How a drift series grows: (words, log-log slope of its running maximum over the last two
    decades of time, fitted d(drift)/dt per second). The first sample (t = 0) is left out of the
    slope; fewer than four samples give ("", nan, nan)."""
    t_all, d_all = np.asarray(t, float), np.asarray(drift, float)
    tt, d = t_all[1:], np.abs(d_all[1:])
    if tt.size < 4:
        return "", math.nan, math.nan
    running = np.maximum.accumulate(d)
    sel = tt >= tt[-1] / 100.0  # the last two decades
    slope = math.nan
    if sel.sum() >= 3 and np.all(running[sel] > 0):
        slope = float(np.polyfit(np.log(tt[sel]), np.log(running[sel]), 1)[0])
    rate = float(np.polyfit(t_all, d_all, 1)[0])
    if math.isnan(slope):
        words = "n/a"
    elif slope < 0.25:
        words = "bounded"
    elif slope < 0.75:
        words = "random walk (~ t^1/2)"
    elif slope < 1.5:
        words = "linear (~ t)"
    else:
        words = "superlinear (faster than t^1.5: an instability)"
    return words, slope, rate
