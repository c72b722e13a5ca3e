"""`gyro-sim bench accuracy --quick`: structure and sanity of what it writes.

- every reference scene has a reference whose error is shown, and on the exact scenes the
  estimated error of the tight reference bounds its true error;
- errors fall as the tolerance tightens (gyro_sim's dop853, every scene);
- on the regular precessions (exact solution) the error is at the level the tolerance
  promises;
- the peers are in the same run: scipy everywhere, MuJoCo except where it cannot represent
  the scene (said so);
- the live error estimate table compares estimate and true error;
- nothing non-finite reaches an output.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from gyro_sim.bench import accuracy as acc
from gyro_sim.bench import peers
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import Simulator

#: the tests here (most of them) read the report `gyro-sim bench accuracy --quick` writes once per run (a
#: session fixture of half a minute or more): outside the fast lane
pytestmark = pytest.mark.slow

EXACT = ("heavy_top", "double_gyro_plus", "double_gyro_minus")
#: dop853's global error at the horizon, against rtol: at most this factor (quick horizons)
PROMISE = 100.0


def _points(data, scene, label):
    return [p for p in data["points"] if p["scene"] == scene
            and (p["method"] if p["engine"] == "gyro_sim" else f"{p['engine']} {p['method']}") == label]


def test_outputs_written(accuracy_out):
    out, data, md = accuracy_out
    assert (out / "accuracy.png").stat().st_size > 10_000
    assert data["quick"] is True
    keys = {c.key for c in acc.cases(quick=True)}
    assert set(data["references"]) == keys
    assert {(r["scene"], r["target"]) for r in data["summary"]} == {(k, t) for k in keys for t in acc.TARGETS}
    for heading in ("### Accuracy", "Cheapest method", "References", "live error estimate", "### Every run"):
        assert heading in md
    assert not re.search(r"\b(nan|inf)\b", md)  # as Python formats non-finite floats


def test_references(accuracy_out):
    _, data, _ = accuracy_out
    for key, ref in data["references"].items():
        assert 0.0 < ref["est_error"] < 1e-9, (key, ref)
        if key in EXACT:
            assert ref["kind"].startswith("exact")
            # the reference pair's difference bounds the tight run's true error
            assert ref["true_error"] <= ref["est_error"], (key, ref)
        else:
            assert ref["true_error"] is None


@pytest.mark.parametrize("case", [c.key for c in acc.cases(quick=True)])
def test_error_falls_with_tolerance(accuracy_out, case):
    _, data, _ = accuracy_out
    pts = sorted(_points(data, case, "dop853"), key=lambda p: -p["setting"])  # loose -> tight
    assert len(pts) >= 3
    errors = [p["error"] for p in pts]
    assert all(e is not None and math.isfinite(e) for e in errors)
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-2 * errors[0], errors  # 1e-5 -> 1e-9: at least 100x


@pytest.mark.parametrize("case", EXACT)
def test_exact_error_at_promised_level(accuracy_out, case):
    _, data, _ = accuracy_out
    for label in ("dop853", "scipy DOP853", "auto"):
        for p in _points(data, case, label):
            assert p["error"] <= PROMISE * p["setting"], (label, p)
            assert p["inv_error"] <= PROMISE * p["setting"], (label, p)


def test_peers_present(accuracy_out):
    _, data, md = accuracy_out
    for case in acc.cases(quick=True):
        engines = {p["engine"] for p in data["points"] if p["scene"] == case.key}
        assert {"gyro_sim", "scipy"} <= engines
        if case.key == "free_chain_rotors":
            assert "MuJoCo" not in engines
        else:
            assert "MuJoCo" in engines
    assert "skipped: speed rotor" in md
    # MuJoCo's RK4 converges at order 4 on the exact scenes (the MJCF mapping is right)
    for case in EXACT:
        pts = sorted(_points(data, case, "MuJoCo RK4"), key=lambda p: -p["setting"])
        e = [p["error"] for p in pts]
        h = [p["setting"] for p in pts]
        order = math.log(e[0] / e[-1]) / math.log(h[0] / h[-1])
        assert 3.5 < order < 4.5, (case, e)


def test_error_estimate_table(accuracy_out):
    _, data, md = accuracy_out
    rows = data["estimates"]
    assert {(r["scene"], r["method"]) for r in rows} == {(s, m) for s in EXACT for m in ("dop853", "radau")}
    for r in rows:
        assert r["local_ratios"], r
        assert all(x > 0 and math.isfinite(x) for x in r["local_ratios"])
        assert r["estimates"] and all(0.0 <= e for e in r["estimates"])
        assert math.isfinite(r["global_error"])
        if r["method"] == "dop853":
            # dop853's estimate is of the size of the true local error (measured: 0.2 - 1.6)
            assert 0.05 < float(np.median(r["local_ratios"])) < 10.0, r


def test_cost_at_interpolates():
    P = acc.Point
    pts = [P("s", "gyro_sim", "m", 1e-3, 1.0, 1e-3, None, 0, 0), P("s", "gyro_sim", "m", 1e-6, 10.0, 1e-7, None, 0, 0)]
    assert acc.cost_at(pts, 1e-5) == pytest.approx(10 ** 0.5)
    assert acc.cost_at(pts, 1e-3) == 1.0
    assert acc.cost_at(pts, 1e-9) is None


def test_precession_exact_matches_simulation():
    """The exact final state of a regular precession equals a tight run (a check of
    `precession_exact` itself, independent of the report)."""
    scene = load_scene(acc.load_dict("double_gyro_minus"))
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    sim.advance(0.7)
    exact = acc.precession_exact(scene, sim.model)(0.7)
    F = peers.frames_of_state(sim.model, 0.7, sim.state)
    G = peers.frames_of_state(sim.model, 0.7, exact)
    assert acc.state_error(F, G, 1.0, False) < 1e-10
    # rotor angle: a quadrature at the constant relative rate
    assert abs(sim.state[sim.model.i_kappa][0] - exact[sim.model.i_kappa][0]) < 1e-8


def test_mujoco_mapping_free_base():
    """A free-floating chain with torque rotors only (MuJoCo can): same motion as gyro_sim."""
    sd = acc.load_dict("free_chain_rotors")
    sd["bodies"][1]["rotors"][0]["mode"] = "torque"  # speed rotors are not representable
    scene = load_scene(sd)
    assert peers.mujoco_unsupported(scene) is None
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    sim.advance(0.3)
    ref = peers.frames_of_state(sim.model, 0.3, sim.state)
    run = peers.run_mujoco(scene, "RK4", 1e-4, 0.3)
    assert run.failed is None
    assert acc.state_error(run.frames, ref, 0.6, True) < 1e-8


def test_peer_ratio_at_1e8_interpolates_both_engines():
    """dop853 reaches 1e-8 halfway (log-log) between 1 ms (1e-6) and 10 ms (1e-10): sqrt(10)
    ms; MuJoCo RK4 between 10 and 100 ms: 10 sqrt(10) ms; the ratio is 0.1 exactly."""
    P = acc.Point
    pts = [P("s", "gyro_sim", "dop853", 1e-6, 1e-3, 1e-6, None, 1, 1),
           P("s", "gyro_sim", "dop853", 1e-10, 1e-2, 1e-10, None, 1, 1),
           P("s", "MuJoCo", "RK4", 1e-3, 1e-2, 1e-6, None, 1, 1),
           P("s", "MuJoCo", "RK4", 1e-4, 1e-1, 1e-10, None, 1, 1)]
    table = acc.peer_ratio_table(pts)
    assert "| s | 3.16 | 31.6 | 0.100x |" in table, table
