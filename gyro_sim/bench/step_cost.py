"""The cost of one physics step at the node's rate, gauss4s and gauss4 beside rk4: median, tail
and worst.

The node advances its Simulator one physics step (1 ms) per call (`ros/loop.py`), so that is
what is timed here: `Simulator.advance(STEP)` called STEPS times on the spherical chain of n
links with a torque rotor on every body and gravity (`scenes.spherical_chain`, the chain of the
scaling report; under gravity it swings and whips), after a warm-up call (compilation and the
first Jacobian are not counted). Each call's CPU time on the calling thread (thread_time: the
method's own cost, not the time other processes of a shared machine take from it) gives the
median, the 99th percentile and the worst step; the wall time of the whole run gives the mean
the deadline sees (`mean_wall_us`). For the Gauss methods the report adds their own worst case in
work: the most Newton iterations and right-hand-side evaluations any one step took (their
`counts`), against the bound their caps set (gauss.py: Newton iterations, retakes).

"Holds 1 kHz" means the median step fits in the physics period with a margin for the
publication (HOLD_FRACTION of the period); the largest n that does is found by measuring
doubling sizes past the listed ones until one does not, then interpolating log-log between
the last two.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

#: the node's physics step (s)
STEP = 1e-3
#: chain lengths of the table and the quick run's
SIZES = (2, 10, 20, 100)
QUICK_SIZES = (2, 10)
#: timed steps per run (quick)
STEPS, QUICK_STEPS = 2000, 200
#: the methods side by side
METHODS = ("gauss4s", "gauss4", "rk4")
#: the explicit method the others are compared with
BASELINE = "rk4"
#: a step "holds 1 kHz" when its median is within this share of the period (the rest: publication)
HOLD_FRACTION = 0.8
#: the search for the largest n holding 1 kHz stops here
SEARCH_MAX_N = 3200


@dataclass
class CostRow:
    n: int
    states: int
    method: str
    steps: int
    median_us: float
    p99_us: float
    worst_us: float
    mean_wall_us: float
    max_newton: int = 0  # Gauss methods: most Newton iterations of one (sub)step
    max_step_rhs: int = 0  # Gauss methods: most rhs evaluations of one step
    retaken: int = 0  # Gauss methods: steps retaken in pieces
    failed: str = ""  # a SimulationError's message: the run stopped there


def measure(n: int, method: str, steps: int = STEPS, backend: str = "auto") -> CostRow:
    """Time `steps` calls of advance(STEP) with `method` on the n-link chain."""
    from gyro_sim.simulator import SimulationError, Simulator
    from gyro_sim.bench.scenes import spherical_chain

    sim = Simulator(spherical_chain(n, rotors=True), integrator=method, step=STEP, backend=backend)
    sim.advance(STEP)  # compile / load the kernels, the first Jacobian
    counts0 = _counts(sim)
    times = np.empty(steps)
    failed = ""
    wall0 = time.perf_counter()
    done = 0
    for k in range(steps):
        t0 = time.thread_time_ns()
        try:
            sim.advance(STEP)
        except SimulationError as exc:
            failed = str(exc)
            break
        times[k] = time.thread_time_ns() - t0
        done += 1
    wall = time.perf_counter() - wall0
    t = times[:done] * 1e-3
    row = CostRow(n, sim.state.size, method, done, float(np.median(t)) if done else math.nan,
                  float(np.percentile(t, 99)) if done else math.nan, float(t.max()) if done else math.nan,
                  wall / max(done, 1) * 1e6, failed=failed)
    counts = _counts(sim)
    if counts is not None:
        from gyro_sim.integrators.gauss4 import kernels as gk

        row.max_newton = int(counts[gk.COUNT_MAX_NEWTON])
        row.max_step_rhs = int(counts[gk.COUNT_MAX_STEP_RHS])
        row.retaken = int(counts[gk.COUNT_STEPS_RETAKEN] - counts0[gk.COUNT_STEPS_RETAKEN])
    return row


def _counts(sim):
    counts = getattr(sim.integrator, "counts", None)
    return None if counts is None else np.array(counts)


def holds(row: CostRow) -> bool:
    return not row.failed and row.median_us <= HOLD_FRACTION * STEP * 1e6


def largest_holding(rows: list[CostRow], method: str, steps: int, backend: str = "auto",
                    progress=None) -> tuple[int | None, float | None, list[CostRow]]:
    """(largest measured n whose step holds 1 kHz, the interpolated n where the median meets
    the budget, the extra rows measured on the way) for `method`: doubling n past the largest
    of `rows` while it still holds."""
    mine = sorted((r for r in rows if r.method == method), key=lambda r: r.n)
    extra = []
    while mine and holds(mine[-1]) and mine[-1].n * 2 <= SEARCH_MAX_N:
        row = measure(mine[-1].n * 2, method, steps, backend)
        extra.append(row)
        mine.append(row)
        if progress:
            progress(row)
    held = [r for r in mine if holds(r)]
    if not held:
        return None, None, extra
    best = held[-1]
    above = [r for r in mine if r.n > best.n and not r.failed]
    if not above:
        return best.n, None, extra
    nxt = above[0]
    budget = HOLD_FRACTION * STEP * 1e6
    slope = math.log(nxt.median_us / best.median_us) / math.log(nxt.n / best.n)
    crossing = best.n * (budget / best.median_us) ** (1.0 / slope) if slope > 0 else None
    return best.n, crossing, extra


def table(rows: list[CostRow]) -> str:
    """One line per chain and method: median, p99, worst, the work of the worst step (Gauss
    methods) and the median against BASELINE's on the same chain."""
    by = {(r.n, r.method): r for r in rows}
    methods = [m for m in METHODS if any(r.method == m for r in rows)]
    out = ["| n (states) | method | median (us) | p99 (us) | worst (us) | most Newton iterations / rhs "
           f"evaluations in a step | median / {BASELINE}'s |",
           "|---:|---|---:|---:|---:|---:|---:|"]
    for n in sorted({r.n for r in rows}):
        base = by.get((n, BASELINE))
        for m in methods:
            x = by.get((n, m))
            if x is None:
                continue
            if x.failed:
                cells = [f"fails after {x.steps} steps", "n/a", "n/a", "n/a", "n/a"]
            else:
                work = f"{x.max_newton} / {x.max_step_rhs}" if x.max_step_rhs else "n/a"
                ratio = (f"{x.median_us / base.median_us:.1f}x" if base is not None and not base.failed
                         else "n/a")
                cells = [f"{x.median_us:.1f}", f"{x.p99_us:.1f}", f"{x.worst_us:.1f}", work, ratio]
            out.append(f"| {n} ({x.states}) | {m} | " + " | ".join(cells) + " |")
    return "\n".join(out)
