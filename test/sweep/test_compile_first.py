"""A sweep on a LocalCluster compiles its integrators' kernels in the calling process (and its
warm-up helper) before the workers start (each then loads them from the disk cache); serial
runs and remote clusters do not (the run compiles where it runs)."""
from __future__ import annotations

import pytest

from gyro_sim.sweep import execute
from gyro_sim.sweep.spec import load_sweep

#: two integrators, each on both backends: four points
GRID = {"name": "integrators", "scene": "hinge_chain",
        "grid": {"run.integrator": ["rk4", "dop853"], "run.backend": ["numpy", "numba"]},
        "run": {"horizon": 0.01, "chunk": 0.01}, "measures": ["final_state"]}


def test_the_integrators_run_on_numba_are_those_compiled():
    sweep = load_sweep(GRID)
    assert execute.integrators_of(sweep, sweep.points) == ["dop853", "rk4"]
    numpy_only = [p for p in sweep.points if p.params["run.backend"] == "numpy"]
    assert execute.integrators_of(sweep, numpy_only) == []
    fixed = load_sweep({**GRID, "grid": {"run.horizon": [0.01]}, "run": {"integrator": "radau", "horizon": 0.01}})
    assert execute.integrators_of(fixed, fixed.points) == ["radau"]


@pytest.mark.parametrize("workers, scheduler, compiles", [(2, None, True), (0, None, False),
                                                          (None, "tcp://127.0.0.1:1", False)])
def test_only_a_local_cluster_is_compiled_for_first(tmp_path, monkeypatch, workers, scheduler, compiles):
    sweep = load_sweep({**GRID, "grid": {"run.integrator": ["rk4"]}})
    events = []
    monkeypatch.setattr(execute, "compile_for_workers", lambda sw, points, stream=None: events.append(
        ("compile", execute.integrators_of(sw, points))))
    monkeypatch.setattr(execute, "_run_dask", lambda *a: events.append(("cluster", None)))
    monkeypatch.setattr(execute, "run_batch", lambda pay, b: events.append(("serial", None)) or [])
    monkeypatch.setattr(execute, "write_part", lambda out, rows: None)
    execute.run(sweep, tmp_path, workers=workers, scheduler=scheduler)
    if compiles:
        assert events == [("compile", ["rk4"]), ("cluster", None)]
    else:
        assert ("compile", ["rk4"]) not in events and events


def test_each_integrator_is_compiled_once_then_its_first_scene(monkeypatch):
    """Each integrator is asked for once, then the scene of its first point on numba."""
    import io

    from gyro_sim import warmup

    calls = []
    monkeypatch.setattr(warmup, "precompile", lambda stream, prog, integrator, helper=True: calls.append(
        (prog, integrator, helper)) or False)
    monkeypatch.setattr(execute, "prepare_scene", lambda sw, point: calls.append(
        point.params["run.integrator"]))
    sweep = load_sweep(GRID)
    execute.compile_for_workers(sweep, sweep.points, io.StringIO())
    assert calls == [("gyro-sim sweep", "dop853", True), "dop853", ("gyro-sim sweep", "rk4", True), "rk4"]


def test_a_scene_that_fails_to_prepare_is_left_to_its_point(monkeypatch):
    """What fails while preparing (here: the Simulator) is not raised: the point reports it."""
    import gyro_sim.simulator

    def broken(*a, **k):
        raise gyro_sim.simulator.SimulationError("no way")

    monkeypatch.setattr(gyro_sim.simulator, "Simulator", broken)
    sweep = load_sweep(GRID)
    execute.prepare_scene(sweep, sweep.points[0])
