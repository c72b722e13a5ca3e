"""Running a sweep's points: in batches on a Dask cluster (or serially, in this process).

- ``workers=N``: a ``distributed.LocalCluster`` of N worker processes with one thread each
  (the dynamics is single-threaded numba; threads would fight over the GIL between steps);
- ``scheduler="tcp://host:8786"``: an existing cluster (``dask scheduler`` and ``dask worker``
  on other machines, each with gyro_sim installed);
- ``workers=0``: serially, here, without Dask (the reference the parallel table must equal).

The points not yet in DIR/parts are cut into batches (contiguous point indices) that go out as
tasks; every finished batch is written as its own Parquet part at once, in whatever order the
batches finish. A worker that dies takes its running batch with it and Dask runs that batch
again elsewhere (a LocalCluster's nanny also restarts the worker); nothing already written is
lost. Ctrl-C cancels what is pending and keeps what is written.
"""
from __future__ import annotations

import dataclasses
import io
import logging
import math
import multiprocessing
import os
import time
from pathlib import Path
from typing import Any, Callable

from gyro_sim.errors import GyroSimError
from gyro_sim.safe_paths import raise_interrupt_behind
from gyro_sim.sweep.point import run_batch
from gyro_sim.sweep.results import read_parts, write_part

#: the name multiprocessing gives the worker processes of a local Dask cluster
LOCAL_WORKER_NAME = "Dask Worker process"
#: the LocalCluster this process runs a sweep on, while it runs (what `stop_local_workers` stops)
_LOCAL_CLUSTERS: list = []

#: tasks per worker when the sweep does not fix `batch`: enough for balance, few enough to keep
#: the per-task overhead (a few ms on a LocalCluster) out of the way
TASKS_PER_WORKER = 4
MAX_AUTO_BATCH = 64


class ClusterError(GyroSimError, RuntimeError):
    """The cluster could not run the sweep (no scheduler there, batches that kept failing)."""


def batch_size(sweep, n_todo: int, workers: int) -> int:
    if sweep.batch:
        return sweep.batch
    return max(1, min(MAX_AUTO_BATCH, math.ceil(n_todo / max(1, workers * TASKS_PER_WORKER))))


def batches(points: list, size: int) -> list[list]:
    return [points[i:i + size] for i in range(0, len(points), size)]


def payload(sweep) -> dict[str, Any]:
    """What every task needs: the sweep without its (possibly long) list of points."""
    return {"sweep": dataclasses.replace(sweep, points=[])}


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def first_points(sweep, points) -> dict[str, Any]:
    """The first of `points` run with each integrator on the numba backend (backend "numba" or
    "auto"), by integrator, sorted."""
    out: dict[str, Any] = {}
    for p in points:
        run = dict(sweep.run)
        run.update({k.removeprefix("run."): v for k, v in p.params.items() if k.startswith("run.")})
        if run.get("backend") != "numpy":
            out.setdefault(run["integrator"], p)
    return dict(sorted(out.items()))


def integrators_of(sweep, points) -> list[str]:
    """The integrators `points` run on the numba backend, sorted."""
    return list(first_points(sweep, points))


def compile_for_workers(sweep, points, stream=None) -> None:
    """Compile (or load) in this process, before a LocalCluster's workers start, what the first
    step of each of `points`' integrators needs on the numba backend, then what the scene of
    its first point needs besides (a Lagrange chain's integrals, the heavy-subtree path: a
    Simulator built on it, a snapshot): every worker then loads it from numba's disk cache (the
    same cache: the workers inherit this environment) instead of compiling it again, each on
    its own. The warm-up helper (gyro_sim.warmup) shares the first step's compile before the
    workers start, then goes on niced, leaving the CPU to them. A cold cache is said in one
    line on `stream` (None: nothing); what fails here is left to the points, which report it."""
    from gyro_sim.warmup import precompile

    sink = stream if stream is not None else io.StringIO()
    for integrator, point in first_points(sweep, points).items():
        precompile(sink, prog="gyro-sim sweep", integrator=integrator)
        prepare_scene(sweep, point)


def prepare_scene(sweep, point) -> None:
    """A Simulator on `point`'s scene with its run options and a snapshot (what every point
    takes first): compiles what that scene needs beyond the integrator's first step."""
    from gyro_sim.scene.load import load_scene
    from gyro_sim.simulator import Simulator

    scene_map, run = sweep.point_scene(point)
    try:
        sim = Simulator(load_scene(scene_map), integrator=run["integrator"], rtol=run["rtol"], atol=run["atol"],
                        step=run["step"], backend=run["backend"])
        sim.snapshot(bodies=False, wrenches=False)
    except Exception as exc:  # noqa: BLE001 - the point itself reports what fails here
        raise_interrupt_behind(exc)


def stop_local_workers() -> None:
    """Kill this process's local Dask workers at once (a signal handler's way to end a sweep).

    Each nanny is first told that its worker goes away for good: a nanny that saw its worker
    die would start another one, and closing the cluster then waits until that one is up (a
    new process importing gyro_sim, most of a second) before it can stop it. Busy
    workers are killed rather than closed: one takes seconds to close gracefully, and its batch
    is run again on --resume anyway.
    """
    for cluster in _LOCAL_CLUSTERS:
        for nanny in list(getattr(cluster, "workers", {}).values()):
            close_gracefully = getattr(nanny, "close_gracefully", None)
            if close_gracefully is not None:  # a Nanny (not a Worker in this process)
                close_gracefully()
    for child in multiprocessing.active_children():
        if child.name.startswith(LOCAL_WORKER_NAME):
            child.kill()


def run(sweep, out: Path, *, workers: int | None = None, scheduler: str | None = None,
        progress: Callable[[int, int, str], None] | None = None,
        on_batch: Callable[[Any, list[dict]], None] | None = None, stream=None) -> dict[str, Any]:
    """Run the points of `sweep` that DIR/parts does not hold yet.

    Returns {"ran", "skipped", "wall", "where", "interrupted"}. Raises ClusterError.
    `on_batch(client, rows)` is called after each part is written (client None when serial).
    On a LocalCluster, the kernels are compiled here first (`compile_for_workers`; a cold
    cache said on `stream`).
    """
    done = {int(r["point"]) for r in read_parts(out)}
    todo = [p for p in sweep.points if p.index not in done]
    total = len(sweep.points)
    stats = {"ran": 0, "skipped": len(done), "wall": 0.0, "interrupted": False}
    if workers is None and scheduler is None:
        workers = default_workers()
    if progress:
        progress(len(done), total, f"{len(done)}/{total} points")
    if not todo:
        stats["where"] = "nothing to run"
        return stats
    t0 = time.perf_counter()

    def finished(rows: list[dict], client=None) -> None:
        write_part(out, rows)
        stats["ran"] += len(rows)
        if on_batch:
            on_batch(client, rows)
        if progress:
            n = len(done) + stats["ran"]
            rate = stats["ran"] / max(time.perf_counter() - t0, 1e-9)
            progress(n, total, f"{n}/{total} points, {rate:.2f}/s")

    try:
        if scheduler is None and workers == 0:
            stats["where"] = "serial, in-process"
            pay = payload(sweep)
            for b in batches(todo, batch_size(sweep, len(todo), 1)):
                finished(run_batch(pay, b))
        else:
            if scheduler is None:
                compile_for_workers(sweep, todo, stream)
            _run_dask(sweep, todo, workers, scheduler, finished, stats)
    except KeyboardInterrupt:
        stats["interrupted"] = True
    stats["wall"] = time.perf_counter() - t0
    return stats


def _run_dask(sweep, todo, workers, scheduler, finished, stats) -> None:
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    try:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise ClusterError(f"no Dask scheduler at {scheduler}: {exc}".splitlines()[0]) from None
            n_workers = max(1, len(client.scheduler_info().get("workers", {})))
            stats["where"] = f"Dask scheduler {scheduler}, {n_workers} workers"
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
            _LOCAL_CLUSTERS.append(cluster)
            client = Client(cluster)
            n_workers = workers
            stats["where"] = f"LocalCluster, {workers} worker{'s' if workers != 1 else ''} x 1 thread"
    except ClusterError:
        raise
    except Exception as exc:  # noqa: BLE001  (a cluster that does not start: one line, exit 1)
        raise_interrupt_behind(exc)
        raise ClusterError(f"could not start the Dask cluster: {type(exc).__name__}: {exc}".splitlines()[0]) from None
    futures = []
    try:
        pay = client.scatter(payload(sweep), broadcast=True)
        size = batch_size(sweep, len(todo), n_workers)
        token = sweep.digest()
        futures = [client.submit(run_batch, pay, b, key=f"gyro-sweep-{token}-{b[0].index}-{len(b)}", pure=False)
                   for b in batches(todo, size)]
        for fut in as_completed(futures):
            try:
                rows = fut.result()
            except Exception as exc:  # noqa: BLE001  (KilledWorker, a worker without gyro_sim, a bug)
                raise ClusterError(f"a batch failed: {type(exc).__name__}: {exc}".splitlines()[0]) from None
            finished(rows, client)
            fut.release()
    finally:
        try:
            if futures:
                client.cancel(futures)
            client.close()
        finally:
            if cluster is not None:
                try:
                    cluster.close()
                finally:
                    _LOCAL_CLUSTERS.remove(cluster)
