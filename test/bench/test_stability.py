"""`gyro-sim bench stability --quick`: verdicts and what reaches the outputs.

- the Kapitza verdicts are right: the inverted rod stays up above the classical threshold
  (a W)^2 = 2 g I / (m c) and falls below it, for every integrator that finished;
- the auto integrator switches on the stiff case (the fast rotor in regular precession);
- a diverging run (step moments 1e3 x gravity torque at the node's 1 kHz RK4) stops with
  SimulationError: state and time kept, the message clear, and no number of it in the report;
- the long-horizon runs report a drift growth.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from gyro_sim.bench import extreme as ex
from gyro_sim.bench import budget
from gyro_sim.bench import stability as st
from gyro_sim.simulator import SimulationError, Simulator

#: the tests here (most of them) read the report `gyro-sim bench stability --quick` writes once per run (a
#: session fixture of half a minute or more): outside the fast lane
pytestmark = pytest.mark.slow

VERDICTS = {"stable", "drifts", "fails", "too slow"}


def _item(data, key):
    return next(it for it in data["items"] if it["key"] == key)


def _run(data, key, integrator):
    return next(r for r in _item(data, key)["runs"] if r["integrator"] == integrator)


def test_outputs_written(stability_out):
    out, data, md = stability_out
    assert (out / "stability.png").stat().st_size > 10_000
    assert {it["key"] for it in data["items"]} == {it.key for it in st.items(quick=True)}
    for it in data["items"]:
        mujoco = [] if it["key"] in data["mujoco_skipped"] else list(st.MUJOCO_ROWS)
        assert [r["integrator"] for r in it["runs"]] == list(st.SETTINGS) + mujoco
        for r in it["runs"]:
            assert r["verdict"] in VERDICTS, r
    for heading in ("### Stability", "Kapitza", "Long horizon", "### Spin sweep", "### Heavy and light tips",
                    "The numbers behind the verdicts"):
        assert heading in md
    assert not re.search(r"\b(nan|inf)\b", md)  # as Python formats non-finite floats


@pytest.mark.parametrize("margin", [0.5, 3.77])
def test_kapitza_verdicts(stability_out, margin):
    _, data, _ = stability_out
    it = _item(data, f"kapitza_{margin:g}")
    expected = "stays up" if margin > 1 else "falls"
    assert it["predicted"] == expected
    finished = [r for r in it["runs"] if r["verdict"] in ("stable", "drifts")]
    assert {r["integrator"] for r in finished} >= {"rk4", "dop853", "auto"}
    for r in finished:
        assert st.kapitza_outcome(r["max_tilt"]) == expected, r
        assert r["verdict"] == "stable", r
    if margin > 1:
        assert all(r["max_tilt"] < 0.5 for r in finished)
    else:
        assert all(r["max_tilt"] > 2.0 for r in finished)  # it fell over, towards hanging


def test_auto_switches_on_the_fast_rotor(stability_out):
    _, data, md = stability_out
    r = _run(data, "fast_rotor", "auto")
    assert r["verdict"] == "stable"
    assert r["switches"] and r["switches"][0][1:3] == ["dop853", "radau"]
    assert "dop853 -> radau" in md
    # it pays off: fewer steps than dop853 alone at the same tolerance
    assert r["nsteps"] <= _run(data, "fast_rotor", "dop853")["nsteps"]
    # the exact solution is kept (error against the exact regular precession)
    assert r["error"] < 1e-6


def test_divergence_is_a_clean_failure(stability_out):
    _, data, md = stability_out
    r = _run(data, "abrupt", "rk4")
    assert r["verdict"] == "fails"
    assert "not finite" in r["note"] and "state kept" in r["note"]
    assert r["drift"] is None and r["error"] is None and r["energy_drift"] is None
    # the adaptive methods get through
    assert _run(data, "abrupt", "dop853")["verdict"] in ("stable", "drifts")


def test_nan_raises_simulation_error_and_keeps_the_state():
    scene, moments = ex.abrupt_commands()
    sim = Simulator(scene, integrator="rk4", step=1e-3)
    sim.advance(0.01)
    sim.set_axis_moments(moments)
    t0, y0 = sim.time, sim.state
    with np.errstate(all="ignore"), pytest.raises(SimulationError) as err:
        for _ in range(10):
            t0, y0 = sim.time, sim.state
            sim.advance(0.01)
    msg = str(err.value)
    assert "not finite" in msg and f"t = {t0:g}" in msg
    assert sim.time == t0 and np.array_equal(sim.state, y0) and np.all(np.isfinite(sim.state))
    # outputs still work from the kept state
    assert all(np.isfinite(v) for v in sim.joint_states().position)
    assert math.isfinite(sim.invariants()["energy"])


def test_long_horizon(stability_out):
    _, data, md = stability_out
    runs = data["long_horizon"]
    assert [r["integrator"] for r in runs] == ["rk4", "lie4"]
    for r in runs:
        assert r["failed"] is None and r["steps"] == 10_000
        assert r["t"][-1] == pytest.approx(10_000 * st.LONG_STEP)
        # neither method is symplectic: the energy error accumulates secularly (Hairer, Lubich,
        # Wanner, "Geometric Numerical Integration", ch. I.1), which the classifier must see
        assert r["growth"] == "linear (~ t)", (r["integrator"], r["slope"])
        assert abs(r["drift"][-1]) < 1e-6


def test_cpu_limit_stops_a_call_that_never_returns():
    import time

    with pytest.raises(budget.OverBudget):
        with budget.cpu_limit(0.05):
            while True:
                time.process_time()


@pytest.mark.parametrize("shape, label", [
    (lambda t: 1e-9 * np.sin(7.0 * t), "bounded"),
    (lambda t: 1e-9 * (1.0 + 0.3 * np.sin(t)), "bounded"),
    (lambda t: 1e-10 * np.sqrt(t), "random walk (~ t^1/2)"),
    (lambda t: 3e-11 * t, "linear (~ t)"),
    (lambda t: -3e-11 * t + 1e-12 * np.sin(50.0 * t), "linear (~ t)"),
    (lambda t: 1e-12 * np.exp(t / 50.0), "superlinear (faster than t^1.5: an instability)"),
])
def test_growth_classifier_on_known_shapes(shape, label):
    t = np.linspace(0.0, 1000.0, st.LONG_SAMPLES + 1)
    words, slope, _ = budget.growth(t, shape(t))
    assert words == label, (slope, words)


# ------------------------------------------------------------------ the cost of a step
def test_step_cost_part(stability_out):
    """The quick report times gauss4s, gauss4 and rk4 steps on the small chains: every run
    finished, the quantiles are ordered, and the Gauss methods (2 stages, a Newton iteration)
    take more evaluations than rk4 per step while their work stays within their caps."""
    from gyro_sim.bench import step_cost as sc
    from gyro_sim.integrators.gauss4 import driver as gauss

    _, data, md = stability_out
    rows = data["step_cost"]["rows"]
    assert {(r["n"], r["method"]) for r in rows} == {(n, m) for n in sc.QUICK_SIZES for m in sc.METHODS}
    for r in rows:
        assert not r["failed"] and r["steps"] == sc.QUICK_STEPS
        assert 0 < r["median_us"] <= r["p99_us"] <= r["worst_us"]
    by = {(r["n"], r["method"]): r for r in rows}
    for n in sc.QUICK_SIZES:
        for m in ("gauss4", "gauss4s"):
            g = by[n, m]
            assert 1 <= g["max_newton"] <= max(gauss.NEWTON_CAP, gauss.DENSE_NEWTON_CAP)
            assert g["max_step_rhs"] > by[n, "rk4"]["max_step_rhs"]
    assert "The cost of one physics step" in md


def test_largest_n_holding_1khz_interpolates(monkeypatch):
    """The search doubles n while the median step fits the budget and interpolates log-log
    between the last two sizes: on a synthetic cost 4 us n (linear) the budget 800 us is met
    at n = 200 exactly."""
    from gyro_sim.bench import step_cost as sc

    def fake(n, method, steps=10, backend="auto"):
        return sc.CostRow(n, 8 * n, method, steps, 4.0 * n, 5.0 * n, 6.0 * n, 4.0 * n)

    monkeypatch.setattr(sc, "measure", fake)
    rows = [fake(n, "rk4") for n in (2, 10, 20, 100)]
    best, crossing, extra = sc.largest_holding(rows, "rk4", 10)
    assert [r.n for r in extra] == [200, 400]
    assert best == 200 and crossing == pytest.approx(200.0, rel=1e-12)
    failing = [sc.CostRow(2, 16, "gauss4", 3, 1.0, 1.0, 1.0, 1.0, failed="diverged")]
    assert sc.largest_holding(failing, "gauss4", 10)[:2] == (None, None)
