"""The physics loop's publications: a state's messages prepared right after the chunk that
computed it and sent at its deadline, the diagnostics with every publication at least
gyro_sim.msgs.messages.DIAGNOSTICS_PERIOD simulated seconds apart (once per
IDLE_DIAGNOSTICS_PERIOD of wall time while paused or stopped), and their timing."""
from __future__ import annotations

import math
import time

from gyro_sim.msgs import messages as M
from gyro_sim.ros.pacing import Samples

#: wall seconds between diagnostics while paused or stopped (running, they go with every
#: publication at least gyro_sim.msgs.messages.DIAGNOSTICS_PERIOD simulated seconds apart)
IDLE_DIAGNOSTICS_PERIOD = 1.0


class Publications:
    """What the loop hands to `out` (gyro_sim.ros.outputs.Outputs or the same methods).

    Parameters
    ----------
    out : prepare_state(t_ns, sim, diagnostics_run) -> batch, send(t_ns, batch),
        publish_diagnostics(t_ns, sim, run_status)
    config : gyro_sim.ros.params.NodeConfig (publish_rate, real_time_factor)
    clock : the wall clock (injectable for tests)
    """

    def __init__(self, out, config, clock=time.monotonic):
        self.out, self.clock = out, clock
        rate, rtf = config.publish_rate, config.real_time_factor
        self.nominal_interval = float("nan") if rtf <= 0 else 1.0 / (rate * rtf)
        window = int(2 * rate) + 1
        self.interval = Samples(window=window)
        # |interval - nominal| between publications (none when running as fast as possible)
        self.jitter = Samples(window=window, offset=self.nominal_interval) if rtf > 0 else None
        self.lag = Samples(window=window)
        self.output_time = Samples(window=window)
        self.published = 0
        # diagnostics go with every diag_every-th publication (simulated time, as offline logs)
        self.diag_every = max(1, round(M.DIAGNOSTICS_PERIOD * rate))
        self._count = 0  # publications prepared since the start or the last reset
        self._last_wall: float | None = None
        self._next_idle_diag = 0.0

    def restart(self, reset: bool = False) -> None:
        """After a reset (`reset`: the diagnostics' count starts again) or a resume: no interval
        measured across the gap."""
        if reset:
            self._count = 0
        else:
            self._last_wall = None

    def prepare(self, t_ns: int, sim, report) -> list:
        """The messages of `sim`'s state at node time `t_ns`, with `report()`'s diagnostics when due;
        raises the Simulator's SimulationError when the state cannot be published."""
        t0 = time.perf_counter()
        with_diag = self._count % self.diag_every == 0
        batch = self.out.prepare_state(t_ns, sim, report() if with_diag else False)
        self._count += 1
        self.output_time.add(time.perf_counter() - t0)
        return batch

    def send(self, t_ns: int, batch: list, lag_at) -> None:
        """Send `batch` now; `lag_at(now)`: how late (wall s) it is at wall time `now`."""
        now = self.clock()
        if self._last_wall is not None:
            self.interval.add(now - self._last_wall)
            if self.jitter is not None:
                self.jitter.add(now - self._last_wall)
        self._last_wall = now
        self.lag.add(lag_at(now))
        self.out.send(t_ns, batch)
        self.published += 1

    def idle_diagnostics(self, t_ns: int, sim, report, force: bool = False) -> None:
        """Diagnostics alone, once per IDLE_DIAGNOSTICS_PERIOD of wall time (paused, stopped)."""
        if force or self.clock() >= self._next_idle_diag:
            self._next_idle_diag = self.clock() + IDLE_DIAGNOSTICS_PERIOD
            self.out.publish_diagnostics(t_ns, sim, report())

    def idle_from_now(self) -> None:
        """The first idle diagnostics are due at once."""
        self._next_idle_diag = self.clock()

    def jitter_percentiles(self, *qs, run: bool = False) -> list[float]:
        if self.jitter is None:
            return [math.nan] * len(qs)
        return self.jitter.run_percentiles(*qs) if run else self.jitter.window_percentiles(*qs)
