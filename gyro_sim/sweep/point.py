"""One point of a sweep: build the scene, simulate, measure. Runs on the Dask workers.

A row is a flat dict (the Parquet columns). Always: ``point``, ``seed``, the varied parameters
(named by their key paths), ``ok`` (no SimulationError), ``error`` ("" or the error's text),
``t_reached``; then, by measure:

- ``final_state``: ``final.<joint>.position`` / ``.velocity`` (sim.joint_states() at the end);
- ``max_tilt``: ``max_tilt_rad``, the largest angle between body 1's axis and the upward
  vertical (-gravity), sampled after every chunk (the Kapitza and sleeping-top verdicts);
- ``max_deviation``: ``max_deviation_rad``, the largest angle any body's axis turned away from
  its start direction, sampled after every chunk;
- ``exact_error``: ``exact_error_rad``, the largest difference of the Euler angles from the
  regular precession started by the scene (psi, theta, phi linear in time: eq 88; meaningful
  for scenes that start in one, such as heavy_top and double_gyro_*);
- ``drift``: ``drift.<invariant>`` (relative drift of each integral this scene conserves, as
  Simulator.snapshot reports it) and ``max_drift`` (their largest magnitude), at the end;
- ``cpu_time``: ``cpu_s`` (CPU time of the simulation; the one column that varies between runs);
- ``eigenvalues``: ``max_real_eig``, the largest real part of the eigenvalues of the linear
  model at the point's initial state and zero commands (``Simulator.linearize`` in the body
  chart, where a steady spin is an equilibrium: docs/linearization.md), NaN where that state
  is not an equilibrium (no verdict there); ``eig_tolerance``, the model's own zero tolerance.
  A sweep whose measures are only ``eigenvalues`` (and ``cpu_time``) simulates nothing.

Verdicts add ``verdict.<name>`` (ok and the measure below the threshold), a theory adds
``theory_margin`` and ``theory.<verdict>`` (margin > 1).
"""
from __future__ import annotations

import math
import os
import time
import warnings
from typing import Any

# as in gyro_sim.cli: one BLAS thread per worker process (workers are processes, one thread each)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

#: the column that depends on the machine's load, left out of the bit-for-bit comparisons
TIMING_COLUMNS = ("cpu_s",)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _axes(sim) -> np.ndarray:
    """(n, 3) every body's z-axis in the world frame."""
    return np.array([b.rotation[:, 2] for b in sim.body_states()])


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0))


def run_point(scene_map: dict[str, Any], run: dict[str, Any], measures: tuple[str, ...]) -> dict[str, Any]:
    """Simulate one point; the measure columns (module docstring). Deterministic: the row
    depends only on the arguments (cpu_s aside)."""
    from gyro_sim.scene.load import load_scene
    from gyro_sim.simulator import SimulationError, Simulator

    scene = load_scene(scene_map)
    sim = Simulator(scene, integrator=run["integrator"], rtol=run["rtol"], atol=run["atol"], step=run["step"],
                    backend=run["backend"])
    n = max(1, int(round(run["horizon"] / run["chunk"])))
    dt = run["horizon"] / n
    up = None
    if scene.gravity is not None:
        up = -np.asarray(scene.gravity, dtype=float) / np.linalg.norm(scene.gravity)
    else:
        up = np.array([0.0, 0.0, 1.0])
    want = set(measures)
    from gyro_sim.sweep.spec import simulates

    if not simulates(want):
        n = 0  # only the initial state is measured
    row_eig = _eigen_columns(sim) if "eigenvalues" in want else {}
    axes0 = _axes(sim) if want & {"max_tilt", "max_deviation"} else None
    max_tilt = float(_angle(axes0[0], up)) if "max_tilt" in want else None
    max_dev = 0.0
    exact = None
    if "exact_error" in want:
        js = sim.joint_states()
        names = [nm for nm in js.name if nm.endswith(("_psi", "_theta", "_phi"))]
        sel = [js.name.index(nm) for nm in names]
        exact = (sel, np.array(js.position)[sel], np.array(js.velocity)[sel], 0.0)
    row: dict[str, Any] = {"ok": True, "error": ""}
    cpu0 = time.process_time()
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(n):
            try:
                sim.advance(dt)
            except SimulationError as exc:
                row["ok"], row["error"] = False, str(exc).splitlines()[0][:300] or type(exc).__name__
                break
            if axes0 is not None:
                ax = _axes(sim)
                if max_tilt is not None:
                    max_tilt = max(max_tilt, float(_angle(ax[0], up)))
                if "max_deviation" in want:
                    max_dev = max(max_dev, float(np.max(_angle(ax, axes0))))
            if exact is not None:
                sel, q0, v0, worst = exact
                q = np.array(sim.joint_states().position)[sel]
                exact = (sel, q0, v0, max(worst, float(np.max(np.abs(_wrap(q - (q0 + v0 * sim.time)))))))
    cpu = time.process_time() - cpu0
    row["t_reached"] = float(sim.time)
    nan = math.nan
    if "final_state" in want:
        js = sim.joint_states()
        for name, q, v in zip(js.name, js.position, js.velocity):
            row[f"final.{name}.position"] = float(q) if row["ok"] else nan
            row[f"final.{name}.velocity"] = float(v) if row["ok"] else nan
    if "max_tilt" in want:
        row["max_tilt_rad"] = max_tilt if row["ok"] else nan
    if "max_deviation" in want:
        row["max_deviation_rad"] = max_dev if row["ok"] else nan
    if "exact_error" in want:
        row["exact_error_rad"] = exact[3] if row["ok"] else nan
    if "drift" in want:
        drift = {}
        if row["ok"]:
            with np.errstate(all="ignore"):
                drift = sim.snapshot(bodies=False, wrenches=False).drift or {}
        for name, value in sorted(drift.items()):
            row[f"drift.{name}"] = float(value)
        row["max_drift"] = max((abs(float(v)) for v in drift.values()), default=0.0) if row["ok"] else nan
    row.update(row_eig)
    if "cpu_time" in want:
        row["cpu_s"] = cpu
    return row


def _eigen_columns(sim) -> dict[str, Any]:
    """max_real_eig and eig_tolerance of the linear model at the simulator's state (body chart)."""
    lin = sim.linearize(chart="body")
    ev = lin.eigenvalues()
    top = float(ev.real.max()) if len(ev) else 0.0
    return {"max_real_eig": top if lin.is_equilibrium else math.nan, "eig_tolerance": lin.tolerance}


def evaluate(sweep_payload: dict[str, Any], point) -> dict[str, Any]:
    """The full row of one point: parameters, seed, measures, verdicts, theory."""
    from gyro_sim.scene.load import load_scene
    from gyro_sim.sweep.spec import Sweep

    sweep: Sweep = sweep_payload["sweep"]
    scene_map, run = sweep.point_scene(point)
    row: dict[str, Any] = {"point": point.index, "seed": point.seed}
    for key, value in point.params.items():
        row[key] = value
    row.update(run_point(scene_map, run, sweep.measures))
    for v in sweep.verdicts:
        value = row.get(v["measure"], math.nan)
        row[f"verdict.{v['name']}"] = bool(row["ok"] and value < v["below"])
    if sweep.theory is not None:
        from gyro_sim.sweep.theory import FORMULAS

        margin = float(FORMULAS[sweep.theory["formula"]](load_scene(scene_map), run))
        row["theory_margin"] = margin
        row[f"theory.{sweep.theory['verdict']}"] = bool(margin > 1.0)
    if "cpu_s" in row:  # last, so that the deterministic columns come first
        row["cpu_s"] = row.pop("cpu_s")
    return row


def run_batch(sweep_payload: dict[str, Any], points: list) -> list[dict[str, Any]]:
    """Rows of a batch of points (one Dask task), in the given order."""
    return [evaluate(sweep_payload, p) for p in points]
