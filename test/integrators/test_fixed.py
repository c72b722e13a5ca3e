"""The node's fixed-step method (gyro_sim.integrators.fixed): rk4 where it is stable at
the step, gauss4s (gauss4 on a system that is not a chain) where the scene is stiff, and the
choice checked against a 1 s run."""
import math

import numpy as np
import pytest

from gyro_sim.bench.extreme import load_dict
from gyro_sim.integrators.fixed import spectral_radius_estimate, fixed_step_method
from gyro_sim.simulator import SimulationError, Simulator

STEP = 1e-3  # the node's physics step
CALL = 0.01  # the node's advance calls
FAST_SPIN = 1e4  # rad/s, the fast heavy top


def fast_heavy_top(spin=FAST_SPIN):
    """config/heavy_top.yaml spun about its axis at `spin` rad/s."""
    sd = load_dict("heavy_top")
    sd["bodies"][0]["initial"]["euler_rates"] = [0.0, 0.0, spin]
    return sd


def survives(scene, name, seconds=1.0):
    sim = Simulator(scene, integrator=name, step=STEP)
    try:
        for _ in range(round(seconds / CALL)):
            sim.advance(CALL)
    except SimulationError:
        return False
    return True


def test_spectral_radius_exact_on_a_small_matrix():
    J = np.array([[0.0, 50.0, 0.0], [-50.0, 0.0, 0.0], [0.0, 0.0, -3.0]])  # +-50 i, -3
    rho = spectral_radius_estimate(lambda t, y: J @ y, 0.0, np.array([1.0, 2.0, 3.0]))
    assert rho == pytest.approx(50.0, rel=1e-6)


@pytest.mark.parametrize("scene", ["hinge_chain", "stiff_fast_rotor"])
def test_rk4_where_stable_and_it_survives(scene):
    name, why = fixed_step_method(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert name == "rk4" and why.startswith("rk4: h |lambda| = "), why
    assert survives(scene, "rk4")


def axis_error(sim, exact) -> float:
    """The largest angle (rad) between the bodies' symmetry axes and those of the exact motion."""
    from gyro_sim.bench.peers import frames_of_state

    a = frames_of_state(sim.model, sim.time, sim.state).R[:, :, 2]
    e = frames_of_state(sim.model, sim.time, exact(sim.time)).R[:, :, 2]
    return float(np.max(np.arctan2(np.linalg.norm(np.cross(a, e), axis=1), np.sum(a * e, axis=1))))


def test_substeps_resolve_the_fast_heavy_top_where_rk4_fails():
    """At 1e4 rad/s the top turns 10 rad in a 1 ms step: rk4 at the step goes non-finite; the
    choice steps rk4 in 40 substeps (0.25 rad each) and follows the exact slow regular
    precession (eq 88, docs/theory.md sec. 4) to 1e-4 rad over 1 s."""
    from gyro_sim.bench.accuracy import precession_exact
    from gyro_sim.bench.spin_sweep import heavy_top
    from gyro_sim.integrators.fixed import SPIN_RESOLVE, fixed_step_choice
    from gyro_sim.dynamics.model import compile_model
    from gyro_sim.scene.load import load_scene

    scene = load_scene(heavy_top(FAST_SPIN))
    c = fixed_step_choice(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert (c.method, c.substeps) == ("rk4", round(STEP * FAST_SPIN / SPIN_RESOLVE)), c
    assert "x40 substeps" in c.reason and c.h_lambda < 0.5, c.reason
    assert not survives(scene, "rk4")  # the choice matters
    sim = Simulator(scene, integrator="fixed", step=STEP)
    exact = precession_exact(scene, compile_model(scene))
    for _ in range(100):
        sim.advance(CALL)
    assert sim.integrator.switches == [] and sim.integrator.substeps == 40
    assert axis_error(sim, exact) < 1e-4


def test_substeps_for_keeps_its_count_within_a_factor_two():
    from gyro_sim.integrators.fixed import MAX_SUBSTEPS, substeps_for

    assert substeps_for(1e-3, 0.0) == 1 and substeps_for(1e-3, 100.0) == 1
    assert substeps_for(1e-3, 1e3) == 4 and substeps_for(1e-3, 1e6) == MAX_SUBSTEPS
    assert substeps_for(1e-3, 600.0, now=4) == 4  # 3 needed, 4 kept
    assert substeps_for(1e-3, 400.0, now=4) == 4  # 2 needed: 4 is at most twice that, kept
    assert substeps_for(1e-3, 200.0, now=4) == 1  # 1 needed: 4 is more than twice that
    assert substeps_for(1e-3, 2e3, now=4) == 8  # not enough
    assert substeps_for(1e-3, math.inf) == MAX_SUBSTEPS


@pytest.mark.parametrize("scene", ["hinge_chain", "free_chain_rotors", "chain_4"])
def test_body_rate_bound_bounds_every_body_rate(scene):
    """Against the angular velocities of the compiled outputs (eq 34 there), at states with
    random joint rates: the bound holds and is reached on a chain turning as one body."""
    from gyro_sim.integrators.fixed import body_rate_bound

    sim = Simulator(scene, integrator="rk4", step=STEP, backend="numba")
    m, rng = sim.model, np.random.default_rng(1)
    for _ in range(5):
        y = sim.state.copy()
        y[m.i_vel] = rng.normal(scale=10.0, size=m.N)
        w = sim.system.outputs(0.0, y)["w"]
        assert np.linalg.norm(w, axis=1).max() <= body_rate_bound(m, y) * (1 + 1e-12)
    if not m.is_hinge.any() and not m.free:
        y = sim.state.copy()
        y[m.i_vel] = 0.0
        y[m.col_sph[0] + m.i_vel.start] = [0.0, 0.0, 7.0]  # the first joint only: all turn at 7 rad/s
        w = sim.system.outputs(0.0, y)["w"]
        assert np.linalg.norm(w, axis=1).max() == pytest.approx(body_rate_bound(m, y), rel=1e-12)


@pytest.mark.parametrize("n", [2, 50, 1000])
@pytest.mark.slow
def test_body_rate_bound_is_exact_on_a_spherical_chain_of_any_length(n):
    """On a spherical chain the bound is the largest |w^k| of the compiled outputs (eq 34), to
    round-off, at random joint rates: it does not grow with the chain's length (the sum of
    the joints' rates did: 404 rad/s for 1000 links turning at 3 rad/s)."""
    from gyro_sim.bench.scenes import spherical_chain
    from gyro_sim.integrators.fixed import body_rate_bound

    sim = Simulator(spherical_chain(n, rotors=True), integrator="rk4", step=STEP, backend="numba")
    m, rng = sim.model, np.random.default_rng(n)
    y = sim.state.copy()
    y[m.i_vel] = rng.normal(scale=3.0 / math.sqrt(n), size=m.N)  # a random walk of rates along the chain
    w = np.linalg.norm(sim.system.outputs(0.0, y)["w"], axis=1).max()
    assert body_rate_bound(m, y) == pytest.approx(w, rel=1e-12)


# --- "fixed": the choice made at the start and again as the motion changes -------------------

class Rotation:
    """y' = w J y in the plane (eigenvalues +-i w): rk4 is unstable for h w > 2 sqrt 2, Gauss
    collocation keeps |y| exactly (a quadratic invariant)."""

    def __init__(self, w):
        self.w, self.size, self.quat_index, self.nfev = w, 2, np.zeros((0, 4), dtype=int), 0

    def rhs(self, t, y):
        self.nfev += 1
        with np.errstate(over="ignore", invalid="ignore"):  # rk4 past its limit overflows, by design here
            return self.w * np.array([-y[1], y[0]])

    def project(self, y):
        pass


def test_fixed_is_rk4_bit_for_bit_on_a_soft_scene():
    a = Simulator("hinge_chain", integrator="fixed", step=STEP)
    b = Simulator("hinge_chain", integrator="rk4", step=STEP)
    for _ in range(30):
        a.advance(CALL)
        b.advance(CALL)
    assert a.integrator.current == "rk4" and a.integrator.switches == []
    assert np.array_equal(a.state, b.state)


def test_fixed_switches_when_a_command_stiffens_the_scene_and_back():
    """A rotation whose rate is the command: soft, then past rk4's limit, then soft again."""
    from gyro_sim.integrators.fixed import SceneFixedStep

    sys_ = Rotation(100.0)
    sys_.inputs_version = 0
    integ = SceneFixedStep(sys_, step=STEP)
    y = np.array([1.0, 0.0])
    t = 0.0
    for w, expect in ((100.0, "rk4"), (5000.0, "gauss4"), (100.0, "rk4")):
        sys_.w = w
        sys_.inputs_version += 1  # as ChainODE.hold does when the commanded values change
        for _ in range(50):
            y = integ.advance(t, y, t + CALL)
            t += CALL
        assert integ.current == expect, (w, integ.reason)
    assert [s[1:3] for s in integ.switches] == [("rk4", "gauss4"), ("gauss4", "rk4")]
    assert np.hypot(*y) == pytest.approx(1.0, abs=1e-5)  # neither let it grow (rk4 damps ~7e-9 a step)


def test_fixed_takes_a_call_again_with_gauss4_when_rk4_blows_up(monkeypatch):
    """The estimate said rk4 (forced here), rk4 overflowed within the call: the call is taken
    again from its start with gauss4, which keeps |y| = 1 to round-off (h w = 5)."""
    from gyro_sim.integrators import fixed as choose

    monkeypatch.setattr(choose, "_choice", lambda *a, **k: choose.Choice("rk4", 1, "forced", 0.0))
    integ = choose.SceneFixedStep(Rotation(5000.0), step=STEP)
    y = integ.advance(0.0, np.array([1.0, 0.0]), 1.0)  # 1000 steps: rk4 grows ~21x a step
    assert integ.current == "gauss4" and "non-finite" in integ.reason
    assert len(integ.switches) == 1 and integ.switches[0][0] == 0.0
    assert np.hypot(*y) == pytest.approx(1.0, abs=1e-12)
def test_fixed_takes_gauss4s_where_rotors_stiffen_the_scene():
    """A stiffness no substep count addresses (a fast rotor's nutation, no body turning fast):
    gauss4s (a chain's implicit rung) at the step, past rk4's limit (h = 2.5 ms: h |lambda| ~
    2.8)."""
    sim = Simulator("stiff_fast_rotor", integrator="fixed", step=2.5e-3)
    sim.advance(CALL)
    assert sim.integrator.implicit == "gauss4s"
    assert sim.integrator.current == "gauss4s" and sim.integrator.substeps == 1
    assert "stiff for rk4" in sim.integrator.reason, sim.integrator.reason


def test_the_implicit_rung_by_chain_length():
    """gauss4s on a chain up to IMPLICIT_MAX_BODIES (where it holds 1 kHz), gauss4 on a longer
    one and on a system that is not a chain; the start's choice names the same method."""
    from gyro_sim.bench.scenes import spherical_chain
    from gyro_sim.integrators import fixed as choose

    for n, expect in ((choose.IMPLICIT_MAX_BODIES, "gauss4s"), (choose.IMPLICIT_MAX_BODIES + 1, "gauss4")):
        sim = Simulator(spherical_chain(n), integrator="fixed", step=STEP)
        assert sim.integrator.implicit == expect
        assert expect in sim.integrator.methods
        c = choose._choice(sim.system.rhs, 0.0, sim.state, 1.0, "rk4", implicit=choose.implicit_for(sim.model))
        assert c.method == expect  # h = 1 s: stiff for rk4 on any chain
    assert choose.SceneFixedStep(Rotation(1.0), step=STEP).implicit == "gauss4"


class Watched(Rotation):
    """Rotation with the watchdog of |y|^2, the invariant of the exact flow (rk4 at h w = 1
    loses 0.6 % of |y| a step; gauss4 keeps it to round-off)."""

    def monitor(self, t0, y0, t1, y1):
        return (y1 @ y1 - y0 @ y0) / (y0 @ y0)


def test_fixed_retakes_a_call_that_breaks_the_energy_balance_with_gauss4():
    from gyro_sim.integrators.fixed import SceneFixedStep

    sys_ = Watched(1000.0)  # h |lambda| = 1: rk4 is stable here, not accurate
    integ = SceneFixedStep(sys_, step=STEP)
    integ.monitor = sys_.monitor
    y = integ.advance(0.0, np.array([1.0, 0.0]), CALL)
    assert integ.current == "gauss4" and "energy watchdog" in integ.reason, integ.reason
    assert integ.switches[0][1:3] == ("rk4", "gauss4")
    assert y == pytest.approx([math.cos(10.0), math.sin(10.0)], abs=2e-2)  # 10 rad turned (gauss4's phase error)
    assert np.hypot(*y) == pytest.approx(1.0, abs=1e-13)


def test_fixed_rescues_a_call_both_fixed_step_methods_fail_with_dop853(monkeypatch):
    from gyro_sim.integrators.base import IntegrationError
    from gyro_sim.integrators.fixed import RESCUE, SceneFixedStep

    integ = SceneFixedStep(Rotation(100.0), step=STEP)

    def fails(t0, y, t1):
        raise IntegrationError("gauss4", "Newton iteration failed", t0, STEP)

    monkeypatch.setattr(integ.methods["gauss4"], "march", fails)
    monkeypatch.setattr(integ.methods["rk4"], "march", fails)
    y = integ.advance(0.0, np.array([1.0, 0.0]), 0.5)
    assert integ.current == RESCUE and [s[2] for s in integ.switches] == ["gauss4", RESCUE]
    assert y == pytest.approx([math.cos(50.0), math.sin(50.0)], abs=1e-8)  # dop853 at RESCUE_RTOL 1e-10


@pytest.mark.slow
def test_fixed_carries_the_heavy_tip_through_its_whips():
    """Mass ratio 1e6 (gyro_sim.bench.extreme): the light links whip when the chain straightens
    (accelerations ~1e9 rad/s^2 for microseconds near t = 0.0874 s). rk4 fails at any step down
    to 16 us; the implicit rung gets through by halving its step, but its energy jumps there
    (gauss4: 0.35 of the kinetic energy): "fixed"'s watchdog takes those calls to dop853, which
    keeps the energy to 1e-3 of the kinetic energy."""
    from gyro_sim.bench.extreme import mass_ratio_chain

    scene = mass_ratio_chain(1e6)
    assert not survives(scene, "rk4", 0.1)
    sim = Simulator(scene, integrator="fixed", step=STEP)
    e0 = sim.invariants()["energy"]
    for _ in range(30):
        sim.advance(CALL)
    inv = sim.invariants()
    assert any(s[2] == "dop853" for s in sim.integrator.switches)
    assert abs(inv["energy"] - e0) < 1e-3 * inv["kinetic"]


@pytest.mark.parametrize("scene", ["free_chain_rotors", "heavy_top"])
def test_watchdog_on_the_numpy_backend_measures_what_the_compiled_one_does(scene):
    """The numpy backend arms "fixed"'s energy watchdog too (without it a heavy tip drifted
    5e-3 of its energy unseen), and its energy balance of a call, from the numpy invariants,
    equals the compiled outputs' on the same call to round-off: two formulations of eq 33
    and the potential."""
    sims = {b: Simulator(load_dict(scene), integrator="fixed", step=STEP, backend=b) for b in ("numpy", "numba")}
    assert all(s.integrator.monitor is not None for s in sims.values())
    rng = np.random.default_rng(1)
    ref = sims["numba"]
    y0 = ref.state.copy()
    y1 = y0 + 1e-3 * rng.standard_normal(y0.size)  # a call that breaks the balance a little
    ref.system.project(y1)
    errs = {b: s._energy_error(0.0, y0, CALL, y1) for b, s in sims.items()}
    assert abs(errs["numba"]) > 1e-6
    assert errs["numpy"] == pytest.approx(errs["numba"], rel=1e-9, abs=1e-13)


def test_fixed_re_simulates_bit_for_bit_with_its_switches():
    """Two runs with the same commands: the same switches and the same states."""
    def run():
        sim = Simulator(fast_heavy_top(3e3), integrator="fixed", step=STEP)
        out = []
        for _ in range(20):
            sim.advance(CALL)
            out.append(sim.state.copy())
        return out, list(sim.integrator.switches), sim.integrator.current
    a, b = run(), run()
    assert a[1:] == b[1:] and all(np.array_equal(x, y) for x, y in zip(a[0], b[0]))


def test_warm_up_runs_both_methods_and_leaves_no_trace():
    """The node calls it before real time starts: gauss4s's path is compiled (or loaded) then,
    not at the first switch; state, counters and the choice are as before."""
    sim = Simulator("hinge_chain", integrator="fixed", step=STEP)
    integ, y0 = sim.integrator, sim.state
    calls = []
    for name, m in integ.methods.items():
        attr = "advance" if m.adaptive else "march"
        call = getattr(m, attr)
        setattr(m, attr, lambda t0, y, t1, call=call, name=name: (calls.append(name), call(t0, y, t1))[1])
    integ.warm_up(sim.time, y0)
    assert sorted(calls) == ["dop853", "gauss4s", "rk4", "rosenbrock1"]  # the budget's rung: numpy, run all the same
    assert all(m.nsteps == m.nfev == m.nrejected == 0 for m in integ.methods.values())
    assert np.array_equal(sim.state, y0) and integ.current == "" and integ.switches == []


def test_diagnostics_say_the_method_and_its_substeps():
    from gyro_sim.bench.spin_sweep import heavy_top
    from gyro_sim.msgs.messages import dynamics_values

    sim = Simulator(heavy_top(1e3), integrator="fixed", step=STEP)
    sim.advance(CALL)
    values = dynamics_values(sim.snapshot(bodies=False, wrenches=False, invariants=False))
    assert values["integrator_now"] == "rk4" and values["integrator_substeps"] == 4.0
    assert values["integrator_reason"].startswith("rk4 x4 substeps"), values["integrator_reason"]
