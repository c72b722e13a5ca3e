"""The "auto" integrator (gyro_sim.integrators.Auto): dop853 while not stiff, radau while
stiff, detected and reported."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from gyro_sim.bench import accuracy as acc
from gyro_sim.bench import extreme as ex
from gyro_sim.integrators import INTEGRATORS, IntegrationError, StiffnessWarning, make_integrator
from gyro_sim.simulator import Simulator


def _run(scene, rtol, horizon, chunk=None):
    sim = Simulator(scene, integrator="auto", rtol=rtol, atol=rtol * 1e-2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        n = 1 if chunk is None else round(horizon / chunk)
        for _ in range(n):
            sim.advance(horizon / n)
    return sim, [w for w in caught if issubclass(w.category, StiffnessWarning)]


def test_registered():
    assert INTEGRATORS["auto"].name == "auto"
    assert make_integrator("auto", Simulator(acc.load_dict("heavy_top")).system).method == "dop853"


@pytest.mark.parametrize("chunk", [None, 0.01])
def test_switches_to_radau_when_stiff(chunk):
    """The fast rotor in regular precession: dop853 sits on its stability boundary
    (h |lambda| ~ 5.9, the imaginary-axis limit); auto hands over to radau, keeps the exact
    solution, and needs fewer rhs evaluations (in 10 ms chunks, as the node calls it, each
    chunk costs radau at least one step: the gain is smaller)."""
    scene = ex.fast_rotor_precession(1e4)
    sim, caught = _run(scene, 1e-8, 1.0, chunk)
    integ = sim.integrator
    assert integ.method == "radau"
    assert [s[1:3] for s in integ.switches] == [("dop853", "radau")]
    assert integ.switches[0][3].startswith("stiff")
    assert caught and "dop853 -> radau" in str(caught[0].message)
    dop = Simulator(scene, integrator="dop853", rtol=1e-8, atol=1e-10)
    n = 1 if chunk is None else round(1.0 / chunk)
    for _ in range(n):
        dop.advance(1.0 / n)
    assert integ.nfev < 0.7 * dop.integrator.nfev
    loaded = acc.load_scene(scene)
    exact = acc.precession_exact(loaded, sim.model)(1.0)
    err = acc.state_error(acc.frames_of_state(sim.model, 1.0, sim.state),
                          acc.frames_of_state(sim.model, 1.0, exact), 1.0, False)
    assert err < 1e-7


def test_stays_explicit_when_not_stiff():
    sim, caught = _run(acc.load_dict("chain_4"), 1e-8, 1.0)
    assert sim.integrator.method == "dop853" and not sim.integrator.switches and not caught
    dop = Simulator(acc.load_dict("chain_4"), integrator="dop853", rtol=1e-8, atol=1e-10)
    dop.advance(1.0)
    assert np.array_equal(sim.state, dop.state)  # the very same steps


def test_goes_back_when_radau_costs_more():
    """At rtol 1e-10 radau (order 5) needs more work than dop853 at its stability limit:
    auto measures both and returns to dop853."""
    sim, _ = _run(ex.fast_rotor_precession(1e4), 1e-10, 1.0)
    integ = sim.integrator
    assert [s[1:3] for s in integ.switches] == [("dop853", "radau"), ("radau", "dop853")]
    assert "costs" in integ.switches[1][3]
    assert integ.method == "dop853"


def test_reset_and_counters():
    sim, _ = _run(ex.fast_rotor_precession(1e4), 1e-8, 0.5)
    integ = sim.integrator
    assert integ.nfev == integ.explicit.nfev + integ.implicit.nfev > 0
    assert integ.nsteps == integ.explicit.nsteps + integ.implicit.nsteps
    assert integ.error_estimate is not None and integ.order == 5
    sim.reset()
    assert integ.method == "dop853" and integ.switches == [] and integ.order == 8


def test_dense_output_across_a_switch():
    sim = Simulator(ex.fast_rotor_precession(1e4), integrator="auto", rtol=1e-8, atol=1e-10)
    integ = sim.integrator
    times = np.linspace(0.0, 1.0, 41)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffnessWarning)
        y1, Y = integ.advance(0.0, sim.state, 1.0, t_eval=times)
    assert integ.switches
    exact = acc.precession_exact(acc.load_scene(ex.fast_rotor_precession(1e4)), sim.model)
    for t, y in zip(times, Y):
        F = acc.frames_of_state(sim.model, t, y)
        G = acc.frames_of_state(sim.model, t, exact(t))
        assert acc.state_error(F, G, 1.0, False) < 1e-6, t
    assert np.array_equal(Y[-1], y1)


class _NanAfter:
    """y' = -y until t = 0.5, then NaN."""

    size = 2
    quat_index = np.zeros((0, 4), dtype=int)

    def rhs(self, t, y):
        return np.full(2, np.nan) if t > 0.5 else -y

    def project(self, y):
        pass


def test_failure_is_reported_as_auto():
    integ = make_integrator("auto", _NanAfter(), rtol=1e-6, atol=1e-8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffnessWarning)
        with pytest.raises(IntegrationError) as err:
            integ.advance(0.0, np.ones(2), 1.0)
    assert err.value.method == "auto" and 0.4 < err.value.t <= 0.5
    assert "radau running" in str(err.value)  # dop853 collapsed first, radau tried
    assert integ.switches and integ.switches[0][1:3] == ("dop853", "radau")


def test_one_compiled_call_per_advance_in_radau():
    """On the numba backend radau's phase runs in its compiled loop: one call of it per
    `advance` from the switch on (the call that switches: dop853's loop, then radau's), and the
    loop is there before the first switch (loaded with the integrator)."""
    pytest.importorskip("numba")
    sim = Simulator(ex.fast_rotor_precession(1e4), integrator="auto", rtol=1e-8, atol=1e-10,
                    backend="numba")
    integ = sim.integrator
    assert integ.explicit.compiled and integ.implicit.compiled
    assert integ.implicit._loop.entry is not None  # loaded: straight to it
    loop, calls = integ.implicit._loop, []

    def counted(*args):
        calls.append(sim.time)
        return loop(*args)

    integ.implicit._loop = counted
    ends = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffnessWarning)
        for _ in range(50):
            sim.advance(0.01)
            ends.append(sim.time)
    (t_switch, *_), = integ.switches
    assert len(calls) == sum(1 for t in ends if t > t_switch) > 30


def test_a_recorded_auto_run_resimulates_bit_for_bit(tmp_path):
    """A log recorded with auto through a switch to radau (both phases compiled), with
    commands, re-simulated: deviation 0."""
    pytest.importorskip("mcap")
    pytest.importorskip("numba")
    from gyro_sim.log.record import record_run
    from gyro_sim.log.resim import resimulate

    scene = ex.fast_rotor_precession(1e4)
    scene["bodies"][0]["rotors"][0]["actuated"] = True  # a command: the rotor's torque
    sim = Simulator(scene, integrator="auto", rtol=1e-8, atol=1e-10, backend="numba")
    assert len(sim.axis_names) == 1
    schedule = [(0.0, [0.0]), (0.2, [1e-4])]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffnessWarning)
        rec = record_run(sim, tmp_path / "run.mcap", duration=0.4, chunk=0.01, publish_rate=100.0,
                         schedule=schedule)
        res = resimulate(tmp_path / "run.mcap")
    assert [s[1:3] for s in sim.integrator.switches][:1] == [("dop853", "radau")]
    assert res.compared == rec.publications > 20 and res.max_deviation == 0.0, res.report()
