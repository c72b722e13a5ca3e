"""`gyro-sim bench stability --quick`, the parts beside the verdicts:

- MuJoCo rows (implicitfast, RK4 at the node's 1 ms) for every case MuJoCo can express, none
  (and the reason in the report) for the others; the abrupt case's step moments reach MuJoCo
  as they reach gyro_sim;
- the spin sweep: a row per scene, spin and method, each finished or with its failure;
  its scenes start in the exact regular precession of eq 88;
- the heavy-tip table: heavy and light tips at every mass ratio.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim.bench import extreme as ex
from gyro_sim.bench import heavy_tips as ht
from gyro_sim.bench import spin_sweep as ss
from gyro_sim.bench import stability as st
from gyro_sim.scene.load import load_scene

#: the tests here (most of them) read the report `gyro-sim bench stability --quick` writes once per run (a
#: session fixture of half a minute or more): outside the fast lane
pytestmark = pytest.mark.slow

mujoco = pytest.importorskip("mujoco")


def test_mujoco_rows_where_expressible_and_the_reason_where_not(stability_out):
    _, data, md = stability_out
    skipped = data["mujoco_skipped"]
    by_key = {it.key: it for it in st.items(quick=True)}
    expressible = 0
    for it in data["items"]:
        reason = st.mujoco_skip(load_scene(by_key[it["key"]].build()))
        rows = [r for r in it["runs"] if r["integrator"] in st.MUJOCO_ROWS]
        if reason is None:
            expressible += 1
            assert it["key"] not in skipped
            assert [r["integrator"] for r in rows] == ["mujoco implicitfast", "mujoco RK4"]
            for r in rows:
                assert r["verdict"] in ("stable", "drifts", "fails", "too slow"), r
                if r["verdict"] == "fails":
                    assert r["note"].startswith("MuJoCo ") and r["drift"] is None
        else:
            assert rows == [] and skipped[it["key"]] == reason
            assert f"skipped: {reason}" in md
    assert expressible >= 5 and any(k.startswith("kapitza") for k in skipped)  # both branches seen
    assert "| mujoco RK4 |" in md and "mujoco implicitfast" in md.splitlines()[4]  # the overview's header
    # MuJoCo RK4 at 1 ms keeps the smooth cases as gyro_sim's rk4 does
    for key in ("light_tip", "looping_top"):
        it = next(i for i in data["items"] if i["key"] == key)
        assert next(r for r in it["runs"] if r["integrator"] == "mujoco RK4")["verdict"] == "stable"


def test_step_moments_reach_mujoco_as_they_reach_gyro_sim():
    """The abrupt case at a step both resolve (1 x gravity torque from t = 0.01 s, 0.05 s):
    MuJoCo RK4's final state is as close to the dop853 reference as gyro_sim's rk4 at the
    same step; without the moments it is off by O(1)."""
    from gyro_sim.bench.accuracy import chain_length, state_error
    from gyro_sim.bench.peers import frames_of_state
    from gyro_sim.dynamics.model import compile_model
    from gyro_sim.simulator import Simulator

    scene, moments = ex.abrupt_commands(1.0)
    item = st.Item("abrupt_small", "", lambda: scene, 0.05, 10.0, moments=tuple(moments), moments_at=0.01)
    res = st.run_item(item, integrators=("rk4",))
    runs = {r.integrator: r for r in res.runs}
    assert res.reference.startswith("dop853")
    rk4, mj = runs["rk4"], runs["mujoco RK4"]
    assert mj.error < 1e-4 and mj.error < 3 * rk4.error, (mj, rk4)
    free = st.Item("abrupt_none", "", lambda: scene, 0.05, 10.0)
    _, chain = st.simulate_mujoco(free, load_scene(scene), "mujoco RK4", 10.0)
    sim = Simulator(scene, integrator="dop853", rtol=1e-10, atol=1e-12)
    sim.advance(0.01)
    sim.set_axis_moments(moments)
    sim.advance(0.04)
    model = compile_model(load_scene(scene))
    ref = frames_of_state(model, sim.time, sim.state)
    assert state_error(chain.frames(), ref, chain_length(model), False) > 0.1


def test_spin_sweep_quick_has_a_row_per_scene_spin_and_method(stability_out):
    _, data, md = stability_out
    runs = data["spin_sweep"]["runs"]
    assert data["spin_sweep"]["steps"] == 10_000
    keys = [(r["scene"], r["spin"], r["method"]) for r in runs]
    assert keys == [(s, w, m) for s in ss.SCENES for w in ss.SPINS for m in ss.METHODS]
    for r in runs:
        if r["failed"]:  # a SimulationError or MuJoCo's warning stopped it: before the end, saying why
            assert isinstance(r["failed"], str) and r["failed"].strip() and not r["too_slow"], r
            assert r["t"][-1] < 10_000 * ss.STEP * (1 - 1e-12), r  # the chunk that failed left no sample
            assert len(r["t"]) == len(r["energy"]) == len(r["axis_error"]) + 1, r
            continue
        assert r["too_slow"] or r["steps_done"] == 10_000, r
        assert len(r["t"]) == len(r["energy"]) == len(r["momentum"]) == len(r["axis_error"]) + 1
        assert r["energy_growth"] in ("bounded", "random walk (~ t^1/2)", "linear (~ t)",
                                      "superlinear (faster than t^1.5: an instability)"), r["method"]
        assert all(math.isfinite(x) for x in r["axis_error"] + r["precession_error"])
    ok = {(r["scene"], r["spin"], r["method"]) for r in runs if not r["failed"] and not r["too_slow"]}
    # the soft end: every gyro_sim method gets through the heavy top at 1e2 rad/s, close to eq 88
    for m in ss.GYRO_METHODS:
        assert ("heavy_top", 1e2, m) in ok
        r = next(x for x in runs if x["scene"] == "heavy_top" and x["spin"] == 1e2 and x["method"] == m)
        assert max(r["axis_error"]) < 1e-3
    # the stiff end: rk4 at 1 ms cannot hold the top at 1e4 rad/s (h w = 10 > 2 sqrt 2)
    assert ("heavy_top", 1e4, "rk4") not in ok
    for line in ("### Spin sweep", "| heavy_top | 1e+04 | -0.02452 | rk4 | fails: "):
        assert line in md


@pytest.mark.parametrize("build, n", [(ss.heavy_top, 1), (ss.double_gyro, 2)])
def test_spin_sweep_scenes_start_in_the_exact_regular_precession(build, n):
    """phi_1' is the spin asked for, psi' = kappa the slow root (|kappa| ~ m c g / (A spin)),
    and a tight dop853 run stays on the exact solution (eq 88)."""
    from gyro_sim.dynamics.model import compile_model
    from gyro_sim.simulator import Simulator
    from gyro_sim.bench.peers import frames_of_state

    sd = build(1e3)
    rates = [b["initial"]["euler_rates"] for b in sd["bodies"]]
    assert len(rates) == n and rates[0][2] == pytest.approx(1e3, rel=1e-12)
    assert -1.0 < rates[0][0] < 0.0 and all(r[0] == rates[0][0] and r[1] == 0.0 for r in rates)
    scene = load_scene(sd)
    model = compile_model(scene)
    exact = ss._Exact(scene, model)
    sim = Simulator(scene, integrator="dop853", rtol=1e-11, atol=1e-13)
    sim.advance(0.05)
    axis, prec = exact.errors(sim.time, frames_of_state(model, sim.time, sim.state).R)
    assert axis < 1e-9 and prec < 1e-9


def test_heavy_tip_table_has_both_directions_and_every_ratio(stability_out):
    _, data, md = stability_out
    rows = data["heavy_tips"]
    assert sorted(r["ratio"] for r in rows) == sorted([*ht.RATIOS, *(1 / r for r in ht.RATIOS)])
    assert {r["kind"] for r in rows if r["ratio"] > 1} == {"heavy"}
    assert {r["kind"] for r in rows if r["ratio"] < 1} == {"light"}
    for r in rows:
        assert 0.0 <= r["numpy_oracle"] < 1e-3
        if r["numba_oracle"] is not None:  # the compiled path is exact to round-off (test_heavy_tip.py)
            assert r["numba_oracle"] < 1e-10, r
    for ratio in ht.RATIOS:
        assert f"| heavy | {ratio:.0e} |" in md and f"| light | {1 / ratio:.0e} |" in md


def test_oracle_is_the_float_kernel_to_round_off_on_a_soft_chain():
    """The 80-digit oracle and the compiled kernel agree where nothing is ill-conditioned."""
    from gyro_sim.dynamics import kernel as fast
    from gyro_sim.dynamics.model import compile_model, initial_state
    from gyro_sim.dynamics.system import ChainODE

    exact = ht.oracle([1.0])[1.0]
    model = compile_model(load_scene(ex.mass_ratio_chain(1.0)))
    u = ChainODE(model).rhs(0.0, initial_state(model))[model.i_vel]
    assert np.abs(u - exact).max() <= 1e-12 * np.abs(exact).max()
    assert fast is not None


def test_the_mujoco_peer_says_it_cannot_take_a_massless_body():
    """MuJoCo gives every moving body a mass: a scene with a massless frame (docs/scene-format.md)
    is no case for it, said by name."""
    from gyro_sim.bench.peers import mujoco_unsupported
    from gyro_sim.scene.load import load_scene
    from test.dynamics.test_massless import universal_pendulum

    assert "massless body ux" in mujoco_unsupported(load_scene(universal_pendulum()))
