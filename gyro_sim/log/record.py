"""Recording a simulation: the publication set of one tick, and offline runs to a log.

The contract that makes a log re-simulable bit for bit (:mod:`gyro_sim.log.resim`), which the
node's recorder keeps too:

- every ``Simulator.advance`` call integrates exactly ``params["advance_dt"]`` seconds;
- the log time of everything is ``offset + time_ns(sim.time)`` (integer nanoseconds), where
  the offset is 0, or the log time of the last ``reset`` event on /gyro_sim/events;
- at a step boundary the order is: outputs published (computed with the commands that were
  in force during the step just taken), then events, then the command that takes effect
  for the next step, logged on /gyro_sim/axis_moments when it changes (and at the start);
- messages are written in that order (file order is causal order).

The run parameters (metadata ``gyro_sim``/``params``) hold the integrator and its tolerances,
``advance_dt``, the publish rate and, for offline runs, the command schedule; plus the
versions and machine that produced the numbers.
"""
from __future__ import annotations

import math
import platform
import sys
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import DEFAULT_FLUSH_PERIOD, LogWriter

#: a boundary within this fraction of the step from a publish tick counts as on it
TICK_TOLERANCE = 0.5
#: a scheduled command takes effect at the first boundary at or after its time (this close
#: counts as at: the boundaries are sums of the step, rounded to ns)
COMMAND_TOLERANCE_NS = 1


def machine_params() -> dict:
    """Where the numbers came from (bit-for-bit re-simulation needs the same)."""
    from gyro_sim import __version__

    return {"gyro_sim_version": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "machine": platform.machine(), "system": platform.system()}


def run_params(sim, *, advance_dt: float, publish_rate: float, source: str,
               duration: float | None = None, command_schedule: Sequence | None = None,
               **extra) -> dict:
    """The ``params`` of a log of `sim` (see the module docstring)."""
    integ = sim.integrator
    p = {
        "format": 1,
        "source": source,
        "integrator": sim.integrator_name,
        "rtol": float(integ.rtol),
        "atol": float(integ.atol) if np.ndim(integ.atol) == 0 else [float(a) for a in integ.atol],
        "step": float(integ.step),
        "advance_dt": float(advance_dt),
        "publish_rate": float(publish_rate),
        "axis_names": list(sim.axis_names),
        "commands_topic": M.AXIS_MOMENTS,
        "time": "simulated (log time = simulated time since start or last reset event)",
    }
    if duration is not None:
        p["duration"] = float(duration)
    if command_schedule is not None:
        p["command_schedule"] = [[float(t), [float(v) for v in vals]] for t, vals in command_schedule]
    p.update(machine_params())
    p.update(extra)
    return p


class LogRecorder:
    """Writes a Simulator's publications and commands to a :class:`LogWriter` (offline runs).

    The messages are those of :class:`gyro_sim.msgs.messages.Publication`, the node's own; the
    diagnostics come with every publication at least `diagnostics_period` simulated seconds
    after the last one (the node keeps the same rhythm).

    Parameters
    ----------
    writer : the log
    sim : the Simulator
    diagnostics_period : simulated seconds between two /diagnostics
    """

    def __init__(self, writer: LogWriter, sim, *, diagnostics_period: float = M.DIAGNOSTICS_PERIOD):
        self.writer, self.sim = writer, sim
        self.publication = M.Publication([b.name for b in sim.scene.bodies], hardware_id=sim.scene.name)
        self.channels: dict[str, int] = {}
        self.time = M.NodeTime(sim)  # the log time
        self.messages = 0
        self.period_ns = M.time_ns(diagnostics_period)
        self._next_diag_ns = 0
        sim.reference_invariants()  # the drifts' reference: the state now
        self.imu_ticks = None  # when the publications sample the IMUs (scenes with IMUs only)
        if sim.imu_names:
            from gyro_sim.dynamics.imu import ImuTicks

            self.imu_ticks = ImuTicks(sim.imu_rates)

    def _write(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        ch = self.channels.get(topic)
        if ch is None:
            ch = self.channels[topic] = self.writer.add_channel(topic, msgtype)
        self.writer.write_raw(ch, t_ns, data)
        self.messages += 1

    def publish(self, run: M.Status | None = None):
        """Every output of the simulator now, on its topic; returns the Snapshot."""
        t = self.time.ns
        diag = t >= self._next_diag_ns
        snap = self.sim.snapshot(invariants=diag)
        if diag:
            while self._next_diag_ns <= t:
                self._next_diag_ns += self.period_ns
        for topic, msgtype, data in self.publication.messages(snap, t, diagnostics_run=run if diag else False):
            self._write(topic, msgtype, t, data)
        if self.imu_ticks is not None:
            self._publish_imus(t)
        return snap

    def _publish_imus(self, t_ns: int) -> None:
        """The IMUs whose sample starts now (from the accelerations the snapshot just computed)."""
        due = self.imu_ticks.due(self.sim.time)
        if due:
            readings = self.sim.imus()
            for topic, msgtype, data in M.imu_messages([readings[j] for j in due], t_ns):
                self._write(topic, msgtype, t_ns, data)

    def command(self, values: Sequence[float]) -> None:
        """The command taking effect for the next step (log it, then call set_axis_moments)."""
        self._write(M.AXIS_MOMENTS, M.COMMAND_TYPE, self.time.ns, M.axis_moments(values))

    def event(self, text: str) -> None:
        self._write(M.EVENTS, M.STRING_TYPE, self.time.ns, M.string(text))

    def reset(self) -> None:
        """Log a reset event, reset the simulator; log time goes on from here."""
        t = self.time.ns
        self.event("reset")
        self.sim.reset()
        self.time.offset_ns = t
        self._next_diag_ns = t
        self.sim.reference_invariants()


@dataclass
class RunRecord:
    """What an offline recording did."""

    path: str
    steps: int = 0
    publications: int = 0
    messages: int = 0
    sim_time: float = 0.0
    wall_time: float = 0.0
    write_time: float = 0.0  # wall time spent building and writing messages
    interrupted: bool = False
    commands: list = field(default_factory=list)


def read_schedule(path, axis_names: Sequence[str]) -> list[tuple[float, list[float]]]:
    """A command schedule from a file: YAML (a list of ``[t, [values]]``) or a gyro_sim log
    (``.mcap``: its ~/axis_moments, /gyro_sim/axis_moments of a node in the root namespace, at
    their log times, resets not followed).
    Raises ValueError naming the problem."""
    from pathlib import Path

    p = Path(path)
    if p.suffix == ".mcap":
        from gyro_sim.log.mcap_log import LogReader

        with LogReader(p) as log:
            topic = log.topic_names().axis_moments  # a namespaced node's log too
            raw = [(t_ns * 1e-9, list(msg.data)) for _, _, t_ns, msg in log.messages([topic])]
        if not raw:
            raise ValueError(f"no {topic} in the log")
    else:
        import yaml

        raw = yaml.safe_load(p.read_text())
        if not isinstance(raw, list) or not all(isinstance(e, (list, tuple)) and len(e) == 2 for e in raw):
            raise ValueError("expected a YAML list of [t, [one value per axis]]")
    try:
        return _schedule(raw, len(axis_names))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{exc} (axes: {', '.join(axis_names)})") from None


def _schedule(schedule, n_axes: int) -> list[tuple[float, list[float]]]:
    out = []
    for t, vals in schedule or ():
        vals = [float(v) for v in np.asarray(vals, dtype=float).ravel()]
        if len(vals) != n_axes:
            raise ValueError(f"command at t = {t}: {len(vals)} values for {n_axes} axes")
        if not (math.isfinite(float(t)) and all(math.isfinite(v) for v in vals)):
            raise ValueError(f"command at t = {t}: non-finite")
        out.append((float(t), vals))
    out.sort(key=lambda c: c[0])
    return out


def record_run(sim, path, *, duration: float, chunk: float = 0.01, publish_rate: float = 100.0,
               schedule: Sequence[tuple[float, Sequence[float]]] = (), flush_period: float = DEFAULT_FLUSH_PERIOD,
               overwrite: bool = False,
               source: str = "gyro-sim run", progress: Callable[[float, float], None] | None = None,
               stop: Callable[[], bool] | None = None) -> RunRecord:
    """Simulate `duration` seconds offline and record everything to `path`.

    The step is ``duration / round(duration / min(chunk, 1 / publish_rate))`` (every advance()
    call the same; never longer than the publish period). At each boundary: publish if a
    publish tick (period 1 / publish_rate) is due within half a step, then apply and log the
    scheduled command that takes effect (the last one with time <= t), then step.

    Parameters
    ----------
    schedule : (t, values) pairs: axis moments (one per ``sim.axis_names``) from time t on.
        The command in force at t = 0 (zeros unless scheduled) is always logged.
    progress : called as progress(sim.time, duration) after every step
    stop : polled after every step; True ends the run early (the log is closed cleanly)

    Raises gyro_sim SimulationError (after closing the log) when the integration fails.
    """
    import time as _time

    if not (duration > 0 and chunk > 0 and publish_rate > 0):
        raise ValueError("duration, chunk and publish_rate must be > 0")
    if sim.imu_names:  # the IMUs are sampled at publications: at the publish rate or a divisor of it
        from gyro_sim.dynamics.imu import ImuRateError, check_rates

        problem = check_rates(sim.scene, publish_rate)
        if problem is not None:
            raise ImuRateError(problem)
        sim.set_imu_default_rate(publish_rate)
    n_axes = len(sim.axis_names)
    sched = _schedule(schedule, n_axes)
    steps = max(1, int(round(duration / min(chunk, duration, 1.0 / publish_rate))))
    dt = duration / steps
    period_ns = int(round(1e9 / publish_rate))
    tol_ns = int(TICK_TOLERANCE * dt * 1e9)
    params = run_params(sim, advance_dt=dt, publish_rate=publish_rate, source=source, duration=duration,
                        command_schedule=sched or [(0.0, [0.0] * n_axes)])
    rec = RunRecord(str(path))
    wall0 = _time.perf_counter()
    with LogWriter(path, scene=sim.scene, params=params, flush_period=flush_period, overwrite=overwrite) as w:
        r = LogRecorder(w, sim)
        next_pub = 0
        si = 0
        current = None
        for i in range(steps + 1):
            t_ns = r.time.ns
            tw = _time.perf_counter()
            if t_ns + tol_ns >= next_pub:
                elapsed = _time.perf_counter() - wall0
                r.publish(M.Status(M.RUN_STATUS, {
                    "state": "running", "backend": sim.backend, "wall_time_s": elapsed, "steps": rec.steps,
                    "real_time_factor_target": 0.0,  # offline: as fast as possible
                    **({"real_time_factor_achieved": sim.time / elapsed} if elapsed > 0 else {}),
                    "commands_applied": len(rec.commands)}, hardware_id=sim.scene.name))
                rec.publications += 1
                while next_pub <= t_ns + tol_ns:
                    next_pub += period_ns
            if i == steps:
                rec.write_time += _time.perf_counter() - tw
                break
            new = current if current is not None else [0.0] * n_axes
            while si < len(sched) and M.time_ns(sched[si][0]) <= t_ns + COMMAND_TOLERANCE_NS:
                new = sched[si][1]
                si += 1
            if new != current:
                r.command(new)
                sim.set_axis_moments(new)
                rec.commands.append((t_ns, list(new)))
                current = new
            rec.write_time += _time.perf_counter() - tw
            sim.advance(dt)
            rec.steps += 1
            if progress is not None:
                progress(sim.time, duration)
            if stop is not None and stop():
                rec.interrupted = True
                break
        rec.messages = r.messages
    rec.sim_time = sim.time
    rec.wall_time = _time.perf_counter() - wall0
    return rec


def print_record(rec: RunRecord, file=sys.stdout) -> None:
    import os

    size = os.path.getsize(rec.path)
    per_s = size / rec.sim_time if rec.sim_time > 0 else float("nan")
    print(f"log:                       {rec.path} ({rec.messages} messages, {size / 1e6:.2f} MB, "
          f"{per_s / 1e3:.1f} kB per simulated second)", file=file)
    if rec.messages:
        print(f"recording cost:            {1e6 * rec.write_time / rec.messages:.1f} us per message "
              f"({100 * rec.write_time / max(rec.wall_time, 1e-9):.0f} % of the run)", file=file)
    print(f"view it:                   gyro-sim view {rec.path}    (or: rerun {rec.path})", file=file)
