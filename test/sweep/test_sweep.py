"""gyro-sim sweep: validation, bit-for-bit parallel = serial, a killed worker,
--resume, Ctrl-C, and the two theory maps within one grid cell of their formulas.

One LocalCluster of 2 single-threaded worker processes serves the whole module (as the
issue asks); the sweeps are small (a sleeping top over a few tenths of a second)."""
from __future__ import annotations

import copy
import os
import signal

import pyarrow.parquet as pq
import pytest

pytest.importorskip("distributed")

from gyro_sim.cli import main
from gyro_sim.sweep import execute, results
from gyro_sim.sweep.commands import find_sweep
from gyro_sim.sweep.point import TIMING_COLUMNS
from gyro_sim.sweep.spec import SweepError, load_sweep

#: a small grid: the sleeping top of config/sweeps/sleeping_top.yaml, 3 x 4 points, 0.3 s each
SMALL = {
    "name": "small sleeping-top grid",
    "scene": "heavy_top",
    "set": {"bodies[0].initial": {"quaternion": [0.9996875162757026, 0.024997395914712332, 0.0, 0.0],
                                  "angular_velocity": [0.0, 0.0, 40.0]}},
    "grid": {"bodies[0].com[2]": {"linspace": [0.02, 0.1, 3]},
             "bodies[0].initial.angular_velocity[2]": [10.0, 30.0, 50.0, 70.0]},
    "run": {"integrator": "dop853", "rtol": 1e-9, "atol": 1e-11, "horizon": 0.3, "chunk": 0.01},
    "measures": ["final_state", "max_tilt", "max_deviation", "drift", "cpu_time"],
    "verdicts": [{"name": "stays_up", "measure": "max_tilt_rad", "below": 0.5}],
    "theory": {"formula": "maievski", "verdict": "stays_up"},
    "batch": 1,
}


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    c = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    yield c
    c.close()


def table(out):
    return pq.read_table(out / results.RESULTS).drop(list(TIMING_COLUMNS))


def serial(sweep, out):
    stats = execute.run(sweep, out, workers=0)
    results.finish(sweep, out, results.read_parts(out), stats)
    return table(out)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small grid run serially, in this process: what every other run must equal."""
    out = tmp_path_factory.mktemp("serial")
    return serial(load_sweep(SMALL), out)


# ------------------------------------------------------------------------------ validation
@pytest.mark.parametrize("edit, key", [
    (lambda d: d["grid"].update({"bodies[3].com[2]": [0.1]}), "grid[bodies[3].com[2]]: bodies[3]: index out of range"),
    (lambda d: d["grid"].update({"bodies[0].comm[2]": [0.1]}), "grid[bodies[0].comm[2]]: bodies[0].comm: no such key"),
    (lambda d: d["run"].update({"integrator": "rk5"}), "run.integrator: 'rk5'"),
    (lambda d: d["run"].update({"horizon": -1.0}), "run.horizon"),
    (lambda d: d["grid"].update({"base.position[0]": {"logspace": [0.0, 1.0, 3]}}), "grid[base.position[0]].logspace"),
    (lambda d: d["verdicts"][0].update({"measure": "max_tilt"}), "verdicts[0].measure"),
    (lambda d: d.update({"theory": {"formula": "kapitza", "verdict": "falls"}}), "theory.verdict"),
    (lambda d: d.update({"grdi": {}}), "grdi: unknown key"),
    (lambda d: d["grid"].update({"bodies[0].mass": [1.0, -2.0]}), "bodies[0].mass"),
    (lambda d: d.update({"scene": "no_such_scene"}), "scene: scene 'no_such_scene' not found"),
])
def test_bad_sweep_names_the_key(edit, key):
    d = copy.deepcopy(SMALL)
    edit(d)
    with pytest.raises(SweepError) as err:
        load_sweep(d)
    assert key in str(err.value)


def test_bad_sweep_file_exit_2_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: heavy_top\ngrid:\n  bodies[0].initial.euler[7]: [1.0]\n")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bodies[0].initial.euler[7]: index out of range" in err[0]
    assert not (tmp_path / "o").exists()  # refused before anything runs or is written
    bad.write_text("scene: heavy_top\ngrid: {bodies[0].com[2]: [1.0]}\n")  # YAML: [ ] in a flow mapping
    assert main(["sweep", str(bad), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and 'quote key paths' in err


def test_points_deterministic_seeds():
    d = {"scene": "heavy_top", "random": {"draws": 6, "seed": 7, "parameters": {
        "bodies[0].com[2]": {"uniform": [0.05, 0.1]}, "run.integrator": {"choice": ["rk4", "dop853"]}}},
        "run": {"horizon": 0.1}}
    a, b = load_sweep(d), load_sweep({**d, "random": {**d["random"], "draws": 9}})
    assert [p.params for p in a.points] == [p.params for p in b.points[:6]]  # point i: seed and i only
    assert len({p.seed for p in b.points}) == 9


# ------------------------------------------------------------------------- on the cluster
@pytest.mark.slow
def test_parallel_equals_serial_bit_for_bit(cluster, reference, tmp_path):
    sweep = load_sweep(SMALL)
    out = tmp_path / "par"
    stats = execute.run(sweep, out, scheduler=cluster.scheduler_address)
    assert stats["ran"] == 12 and not stats["interrupted"]
    assert len(list((out / results.PARTS).glob("*.parquet"))) == 12  # one part per batch
    results.finish(sweep, out, results.read_parts(out), stats)
    assert table(out).equals(reference)


@pytest.mark.slow
def test_killed_worker_loses_nothing(cluster, reference, tmp_path):
    sweep = load_sweep(SMALL)
    out = tmp_path / "killed"
    killed, kept = [], {}

    def kill_one(client, rows):
        if not killed:  # after the first finished batch: SIGKILL a worker in the middle of its batch
            pids = client.run(os.getpid)
            victim = sorted(pids.values())[0]
            os.kill(victim, signal.SIGKILL)
            killed.append(victim)
            kept.update({p.name: p.read_bytes() for p in (out / results.PARTS).glob("*.parquet")})

    stats = execute.run(sweep, out, scheduler=cluster.scheduler_address, on_batch=kill_one)
    assert killed and not stats["interrupted"]
    for name, data in kept.items():  # parts written before the kill are untouched
        assert (out / results.PARTS / name).read_bytes() == data
    results.finish(sweep, out, results.read_parts(out), stats)
    assert table(out).equals(reference)
    cluster.wait_for_workers(2, timeout=60)  # the nanny restarted it (the next tests use both)


@pytest.mark.slow
def test_interrupt_then_resume(cluster, reference, tmp_path, capsys):
    sweep = load_sweep(SMALL)
    out = tmp_path / "res"
    seen = []

    def ctrl_c(client, rows):
        seen.append(rows[0]["point"])
        if len(seen) == 4:
            raise KeyboardInterrupt  # as Ctrl-C in the driver: pending batches cancelled, parts kept

    stats = execute.run(sweep, out, scheduler=cluster.scheduler_address, on_batch=ctrl_c)
    assert stats["interrupted"]
    done = {r["point"] for r in results.read_parts(out)}
    assert len(done) >= 4 and len(done) < 12
    results.write_manifest(out, sweep)
    import yaml

    f = tmp_path / "small.yaml"
    f.write_text(yaml.safe_dump(SMALL))
    # same sweep from a file: the manifest's digest is the same
    assert load_sweep(f).digest() == sweep.digest()
    capsys.readouterr()
    assert main(["sweep", str(f), "--out", str(out), "--scheduler", cluster.scheduler_address]) == 2
    assert "--resume" in capsys.readouterr().err  # no silent overwrite, no silent mixing
    assert main(["sweep", str(f), "--out", str(out), "--resume", "--scheduler", cluster.scheduler_address]) == 0
    assert f"{len(done)} done before, skipped" in (out / results.SUMMARY).read_text()
    assert table(out).equals(reference)
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump({**SMALL, "run": {**SMALL["run"], "horizon": 0.2}}))
    assert main(["sweep", str(other), "--out", str(out), "--resume", "--workers", "0"]) == 2
    assert "holds another sweep" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["kapitza", "sleeping_top"])
@pytest.mark.slow
def test_theory_map_within_one_cell(cluster, tmp_path, name):
    """The shipped maps (--quick): the computed stability boundary within one grid cell of
    Kapitza's (a W)^2 = 2 g I / (m c), of Maievski's (A p)^2 = 4 B m g c."""
    sweep = load_sweep(find_sweep(name), quick=True)
    out = tmp_path / name
    stats = execute.run(sweep, out, scheduler=cluster.scheduler_address)
    rows = results.read_parts(out)
    assert len(rows) == len(sweep.points) and all(r["ok"] for r in rows)
    check = results.finish(sweep, out, rows, stats)["check"]
    assert check["within_one_cell"], check
    verdicts = {bool(r["verdict." + check["verdict"]]) for r in rows}
    assert verdicts == {True, False}  # the map crosses the boundary
    assert (out / results.MAP).stat().st_size > 10_000


@pytest.mark.slow
def test_fixed_step_map_rk4(tmp_path):
    """The largest stable rk4 step against rotor spin: where 2 sqrt(2) / w_n says, to one cell."""
    d = load_sweep(find_sweep("fixed_step"), quick=True)
    d.axes["run.integrator"] = ["rk4"]
    from gyro_sim.sweep.spec import make_points

    d.points = make_points(d)
    execute.run(d, tmp_path, workers=0)
    done = results.finish(d, tmp_path, results.read_parts(tmp_path), {})
    assert done["check"]["within_one_cell"], done["check"]
    for r in done["largest"]:
        assert 0.5 < r["largest"] / r["theory_bound"] <= 1.0


def test_a_model_file_is_a_sweep_scene(tmp_path):
    """An MJCF model names the scene of a sweep as a YAML scene does (its first keyframe), and
    a grid over its masses runs: each point a valid scene, its mass the grid's."""
    sweep = load_sweep({"scene": "arm_flywheel.xml", "grid": {"bodies[0].mass": [1.0, 2.0]},
                        "run": {"integrator": "rk4", "step": 1e-3, "horizon": 0.01, "chunk": 0.01},
                        "measures": ["drift"]})
    assert sweep.scene_path.endswith("arm_flywheel.xml") and len(sweep.points) == 2
    stats = execute.run(sweep, tmp_path, workers=0)
    rows = results.read_parts(tmp_path)
    assert stats is not None and len(rows) == 2 and all(r["ok"] for r in rows), rows
    bad = copy.deepcopy({"scene": "no_such_model.xml", "run": {"horizon": 0.1}})
    with pytest.raises(SweepError, match="no_such_model.xml"):
        load_sweep(bad)
