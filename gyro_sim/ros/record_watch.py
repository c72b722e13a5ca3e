"""The physics loop's watch over the live recorder (gyro_sim.ros.recorder.LiveRecorder): a
failure ends the run; publications dropped from the log while the writer is behind are marked
by an event where the dropping starts and one where it stops (events are never dropped)."""
from __future__ import annotations

import time

#: wall seconds without a new publication dropped from the log after which the recorder counts
#: as caught up (an event says so)
RECORD_QUIET = 1.0


class RecordWatch:
    """Follows `recorder` from the physics thread; `out.event(t_ns, text, level)` says what it sees."""

    def __init__(self, recorder, out, clock=time.monotonic):
        self.recorder, self.out, self.clock = recorder, out, clock
        self.failure: str | None = None  # why recording failed (the run then ended)
        self._drops_seen = 0  # records dropped from the log, as last seen
        self._last_drop: float | None = None  # wall time a new drop was last seen; None: not dropping

    def check(self, t_ns: int) -> bool:
        """Look at the recorder at node time `t_ns`; True when recording failed (said once)."""
        rec = self.recorder
        if rec.failure is not None:
            self.failure = rec.failure
            self.out.event(t_ns, f"recording failed: {rec.failure}; the run stops", level="error")
            return True
        dropped = rec.dropped_records
        if dropped != self._drops_seen:
            if self._last_drop is None:
                self.out.event(t_ns, "log writer behind: the oldest publications waiting are dropped from "
                                     "the log", level="warning")
            self._drops_seen = dropped
            self._last_drop = self.clock()
        elif self._last_drop is not None and self.clock() - self._last_drop > RECORD_QUIET:
            self._last_drop = None
            self.out.event(t_ns, f"log writer caught up: {rec.dropped_records} records of "
                                 f"{rec.dropped_publications} publications dropped from the log so far")
        return False

    @property
    def failed(self) -> str | None:
        """Why recording failed, seen by `check` or not yet (None while it works)."""
        return self.failure or self.recorder.failure

    def values(self) -> dict:
        """The run status's recording figures."""
        rec, failure = self.recorder, self.failed
        return {
            "record": (f"failed: {failure}" if failure else
                       "behind: dropping the oldest publications" if self._last_drop is not None else "recording"),
            "records_dropped": rec.dropped_records,
            "publications_dropped": rec.dropped_publications,
        }
