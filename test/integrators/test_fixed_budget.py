""""fixed" (gyro_sim.integrators.fixed): the stiffness estimate against the dense Jacobian, the
real-time budget (a bound on what a call costs, the drift it lets through reported), the
linearly implicit Euler step of that budget, and the simulator seen through its interface."""
import math

import numpy as np
import pytest

from gyro_sim.bench.extreme import abrupt_commands
from gyro_sim.integrators import fixed
from gyro_sim.integrators.base import IntegrationError
from gyro_sim.simulator import Simulator

STEP = 1e-3  # the node's physics step
CALL = 0.01  # the node's advance calls


class Rotation:
    """y' = w J y in the plane (eigenvalues +-i w), |y|^2 its invariant; rk4 at h w = 1 loses
    ~0.3 % of |y|^2 a step (|R(i)|^2 = 1 - 1/72 + 1/576)."""

    def __init__(self, w):
        self.w, self.size, self.quat_index = w, 2, np.zeros((0, 4), dtype=int)

    def rhs(self, t, y):
        with np.errstate(over="ignore", invalid="ignore"):
            return self.w * np.array([-y[1], y[0]])

    def project(self, y):
        pass

    def monitor(self, t0, y0, t1, y1):
        return (y1 @ y1 - y0 @ y0) / (y0 @ y0)


def dense_spectral_radius(rhs, t, y):
    """The largest |eigenvalue| of a dense forward-difference Jacobian, each column by its own
    component's perturbation (1e-7 of its size): the estimate's oracle, formed whole."""
    f0 = np.array(rhs(t, y))
    J = np.empty((y.size, y.size))
    for j in range(y.size):
        d = 1e-7 * max(1.0, abs(y[j]))
        yp = y.copy()
        yp[j] += d
        J[:, j] = (np.array(rhs(t, yp)) - f0) / d
    return float(np.abs(np.linalg.eigvals(J)).max())


def test_the_estimate_follows_the_dense_jacobian_after_a_violent_command():
    """0.12 s into the violent step (bodies at ~3e4 rad/s, a wheel's angle of ~1e5 rad in the
    state): the Krylov estimate agrees with the dense Jacobian's eigenvalues, where one
    perturbation for the whole state, scaled by |y|, overestimates 40-fold."""
    scene, moments = abrupt_commands()
    sim = Simulator(scene, integrator="dop853", rtol=1e-8, atol=1e-10)
    sim.advance(CALL)
    sim.set_axis_moments(moments)
    for _ in range(12):
        sim.advance(CALL)
    rhs, y = sim.held_rhs(), sim.state
    assert np.linalg.norm(y) > 1e4  # the regime of the overestimate
    rho = dense_spectral_radius(rhs, sim.time, y)
    assert fixed.spectral_radius_estimate(rhs, sim.time, y) == pytest.approx(rho, rel=1e-3)
    assert fixed.spectral_radius_estimate(rhs, sim.time, y, fixed.RECHECK_DIM) == pytest.approx(rho, rel=0.05)


def test_linearly_implicit_euler_is_l_stable_and_of_order_one():
    """y' = lambda y: one step is exactly 1 / (1 - h lambda) (its stability function, to the
    differences' round-off): 1e-4 for h lambda = -1e4; on y' = -y its error at t = 1 halves
    with the step (order 1) against exp(-1)."""

    class Linear:
        size, quat_index = 1, np.zeros((0, 4), dtype=int)

        def __init__(self, lam):
            self.lam = lam

        def rhs(self, t, y):
            return self.lam * y

        def project(self, y):
            pass

    for lam in (-1e7, -1.0, 500.0):
        g = fixed.LinearlyImplicitEuler(Linear(lam), step=STEP)
        y = g.advance(0.0, np.array([1.0]), STEP)
        assert y[0] == pytest.approx(1.0 / (1.0 - STEP * lam), rel=1e-6)
    errors = []
    for h in (0.02, 0.01):
        y = fixed.LinearlyImplicitEuler(Linear(-1.0), step=h).advance(0.0, np.array([1.0]), 1.0)
        errors.append(abs(y[0] - math.exp(-1.0)))
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.05)


def over_budget(integ):
    integ.credit, integ.over_budget = -1.0, True


def test_over_budget_the_watchdog_reports_instead_of_retaking():
    """rk4 at h w = 0.5 loses ~2.2e-3 of |y|^2 in a 10 ms call (the watchdog's limit: 1e-5):
    under budget the call is retaken (gauss4); over budget it is kept, counted, and the error
    counted is the monitor's own."""
    sys_ = Rotation(500.0)
    y0 = np.array([1.0, 0.0])
    under = fixed.SceneFixedStep(sys_, step=STEP)
    under.monitor = sys_.monitor
    under.advance(0.0, y0, CALL)
    assert under.current == "gauss4" and under.budget_calls == 0
    over = fixed.SceneFixedStep(sys_, step=STEP)
    over.monitor = sys_.monitor
    over_budget(over)
    y = over.advance(0.0, y0, CALL)
    expect = sys_.monitor(0.0, y0, CALL, y)
    assert over.current == "rk4" and over.switches == [] and "over the real-time budget" in over.reason
    assert over.budget_calls == 1 and over.budget_energy_error == expect
    assert fixed.ENERGY_WATCH * CALL < abs(expect) < fixed.OVER_BUDGET_WATCH * CALL


def test_over_budget_a_stiff_call_takes_rk4_in_the_substeps_that_make_it_stable():
    """h w = 5: stiff for rk4 at the step (the choice says gauss4). Over budget the call goes to
    rk4 in ceil(5 / (BUDGET_RK4_SAFETY x RK4_IMAG_LIMIT)) = 2 substeps (h w = 2.5 each, inside
    rk4's region, |h w| <= 2 sqrt 2), 8 evaluations a step: within the budget, where gauss4's
    cost has no bound. Its result is rk4's on the rotation: |y| = |R(2.5 i)|^20, R rk4's
    stability polynomial."""
    sys_ = Rotation(5000.0)
    integ = fixed.SceneFixedStep(sys_, step=STEP)
    over_budget(integ)
    y = integ.advance(0.0, np.array([1.0, 0.0]), CALL)
    assert (integ.current, integ.substeps) == ("rk4", 2) and "in place of gauss4" in integ.reason
    assert integ.methods["rk4"].nfev == 10 * 2 * 4 and integ.methods["gauss4"].nfev == 0
    z = 2.5j
    assert np.hypot(*y) == pytest.approx(abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** 20, rel=1e-9)


def test_over_budget_a_call_beyond_rk4s_substeps_takes_the_fixed_cost_rung():
    """h w = 500: rk4 would need 354 substeps (more than MAX_SUBSTEPS). Over budget the call goes
    to the linearly implicit Euler step at one step a physics step (size + 1 = 3 evaluations
    each), which damps |y| (L-stable) rather than let it grow."""
    sys_ = Rotation(5e5)
    integ = fixed.SceneFixedStep(sys_, step=STEP)
    over_budget(integ)
    y = integ.advance(0.0, np.array([1.0, 0.0]), CALL)
    assert integ.current == fixed.BUDGET_RUNG and "in place of gauss4" in integ.reason
    assert integ.methods[fixed.BUDGET_RUNG].nfev == 10 * 3
    assert np.hypot(*y) < 1.0


def test_the_budget_rungs_call_is_kept_and_its_error_reported_never_retaken():
    """Over budget, a call of the budget's rung that breaks the energy balance (by 5 % here, past
    OVER_BUDGET_WATCH) is kept and its error counted: no rescue is run (its
    cost would have no bound)."""
    sys_ = Rotation(5e5)
    integ = fixed.SceneFixedStep(sys_, step=STEP)
    integ.monitor = lambda t0, y0, t1, y1: 0.05
    over_budget(integ)
    y = integ.advance(0.0, np.array([1.0, 0.0]), CALL)
    assert integ.current == fixed.BUDGET_RUNG and integ.methods[fixed.RESCUE].nfev == 0
    assert integ.budget_calls == 1 and integ.budget_energy_error == 0.05
    assert np.isfinite(y).all()


@pytest.mark.parametrize("error, calls", [(0.5, 14), (0.999, 2), (1.0, 1), (math.nan, 1)])
def test_calls_kept_past_the_growth_limit_end_the_run(error, calls):
    """Calls kept over budget whose energy gains (relative to the kinetic energy: x2 a call at
    0.5, x1000 at 0.999) compound past KEEP_GROWTH end the run: BudgetOutrun, a simulation error,
    with the state of the failing call's start; an energy that is not finite at once."""
    sys_ = Rotation(5e5)
    integ = fixed.SceneFixedStep(sys_, step=STEP)
    integ.monitor = lambda t0, y0, t1, y1: error
    y = np.array([1.0, 0.0])
    for k in range(calls):
        over_budget(integ)
        start = y.copy()
        if k < calls - 1:
            integ._march(k * CALL, y, (k + 1) * CALL)
            continue
        with pytest.raises(fixed.BudgetOutrun, match="outran the real-time budget"):
            integ._march(k * CALL, y, (k + 1) * CALL)
        assert np.array_equal(y, start) and integ.budget_calls == calls - 1


def test_a_kept_gain_paid_back_by_a_loss_goes_on():
    """x100 then / 100, again and again: the L-stable rung damping back what it overshot."""
    integ = fixed.SceneFixedStep(Rotation(5e5), step=STEP)
    for k in range(20):
        integ._keep(0.99 if k % 2 == 0 else -0.99, k * CALL)
    assert integ.budget_calls == 20
    with pytest.raises(fixed.BudgetOutrun):
        for k in range(3):
            integ._keep(0.99, k * CALL)


def test_the_rescue_is_bounded_and_the_fixed_cost_result_kept(monkeypatch):
    """Under budget, rk4 blows up (h w = 1e4), gauss4 breaks the energy balance (every call by
    half here) and the rescue is taken: it may spend one burst of evaluations, past which the call
    is taken by the budget's rung, kept, and its error reported. What a call costs has a bound:
    dop853 would need ~1e6 evaluations for the 1e5 rad the call turns."""
    monkeypatch.setattr(fixed, "_choice", lambda *a, **k: fixed.Choice("rk4", 1, "forced", 0.0))
    sys_ = Rotation(1e7)
    integ = fixed.SceneFixedStep(sys_, step=STEP)
    integ.monitor = lambda t0, y0, t1, y1: 0.05
    y = integ.advance(0.0, np.array([1.0, 0.0]), CALL)
    assert [s[2] for s in integ.switches] == ["gauss4", fixed.RESCUE, fixed.BUDGET_RUNG]
    assert integ._plain.count == fixed.BURST_STEPS * fixed.EVAL_BUDGET + 1  # the evaluation that stopped it
    assert integ.current == fixed.BUDGET_RUNG and "rescue overspent" in integ.reason
    assert integ.budget_calls == 1 and integ.budget_energy_error == 0.05
    assert np.isfinite(y).all()


def test_a_watchdog_trip_is_told_by_its_type():
    err = fixed.WatchdogTrip("rk4", 0.25, 1.0, STEP, CALL)
    assert isinstance(err, IntegrationError) and err.error == 0.25 and "energy watchdog" in err.reason


def test_budget_credit_comes_back_and_ends_the_over_budget_state():
    """The credit: EVAL_BUDGET a physics step comes in, a call's evaluations go out, up to the
    burst; over budget from below zero until it is whole again."""
    integ = fixed.SceneFixedStep(Rotation(1.0), step=STEP)
    full = fixed.BURST_STEPS * fixed.EVAL_BUDGET
    integ._spend(0.0, CALL, full + 10 * fixed.EVAL_BUDGET + 1)
    assert integ.credit == -1 and integ.over_budget
    integ._spend(0.0, CALL, 0)
    assert integ.over_budget  # not before the credit is whole
    while integ.credit < full:
        integ._spend(0.0, CALL, 0)
    assert integ.credit == full and not integ.over_budget


def test_the_choice_asks_the_simulator_through_its_interface():
    """fixed_step_choice needs only the Simulator's time, state, model and held_rhs: no
    `system` to mutate."""
    sim = Simulator("hinge_chain", integrator="rk4", step=STEP)

    class Facade:
        time, state, model = sim.time, sim.state, sim.model
        held_rhs = staticmethod(sim.held_rhs)

    assert fixed.fixed_step_choice(Facade(), STEP) == fixed.fixed_step_choice(sim, STEP)


def test_diagnostics_carry_the_drift_let_through_over_budget():
    from gyro_sim.msgs.messages import BUDGET_CALLS_KEY, BUDGET_ERROR_KEY, dynamics_values

    sim = Simulator("hinge_chain", integrator="fixed", step=STEP)
    sim.advance(CALL)
    values = dynamics_values(sim.snapshot(bodies=False, wrenches=False, invariants=False))
    assert values[BUDGET_CALLS_KEY] == 0.0 and values[BUDGET_ERROR_KEY] == 0.0
    sim.integrator.budget_calls, sim.integrator.budget_energy_error = 3, -2e-4
    values = dynamics_values(sim.snapshot(bodies=False, wrenches=False, invariants=False))
    assert values[BUDGET_CALLS_KEY] == 3.0 and values[BUDGET_ERROR_KEY] == -2e-4


# --- the guard: the physics thread compiles nothing ----------------------------------------------
def test_warm_up_enters_every_rung_in_the_manifest(monkeypatch):
    monkeypatch.setattr(fixed, "WARM", set())
    sim = Simulator("hinge_chain", integrator="fixed", step=STEP)
    assert not fixed.WARM
    sim.integrator.warm_up(sim.time, sim.state)
    assert fixed.WARM == set(sim.integrator.methods) >= {"rk4", "gauss4s", fixed.RESCUE, fixed.BUDGET_RUNG}


def test_guarded_fixed_takes_no_rung_this_process_has_not_run(monkeypatch):
    """Guarded, with nothing in the manifest: the heavy tip's first whip (rk4 blows up near
    t = 0.087 s) is retaken by the budget's rung (numpy on the compiled rhs), each rung held back
    said once; unguarded the same run takes gauss4s and dop853."""
    from gyro_sim.bench.extreme import mass_ratio_chain

    scene = mass_ratio_chain(1e6)
    runs = {}
    for guard in (True, False):
        monkeypatch.setattr(fixed, "WARM", set())
        sim = Simulator(scene, integrator="fixed", step=STEP)
        sim.integrator.guard = guard
        for _ in range(10):
            sim.advance(CALL)
        assert np.isfinite(sim.state).all()
        runs[guard] = sim.integrator
    used = {s[2].split()[0] for s in runs[True].switches}
    assert used <= {"rk4", fixed.BUDGET_RUNG} and fixed.BUDGET_RUNG in used
    assert len(runs[True].notes) == len(set(runs[True].notes)) >= 1
    assert all("not compiled yet" in n for n in runs[True].notes)
    assert {"gauss4s", fixed.RESCUE} <= {s[2].split()[0] for s in runs[False].switches}


COLD_RUN = r'''
import json, sys, threading
import numpy as np
from numba.core import event
from gyro_sim.bench.extreme import mass_ratio_chain
from gyro_sim.simulator import Simulator

compiles = []


class Listener(event.Listener):
    def on_start(self, ev):
        compiles.append(threading.current_thread().name)

    def on_end(self, ev):
        pass


sim = Simulator(mass_ratio_chain(1e6), integrator="fixed", step=1e-3)  # the start: its first step compiled
sim.snapshot()
sim.advance(0.01)
sim.integrator.guard = True  # as the node sets it
event.register("numba:compile", Listener())
before = len(compiles)


def physics():
    for _ in range(29):  # through the first whip (t = 0.087 s)
        sim.advance(0.01)


thread = threading.Thread(target=physics, name="physics")
thread.start()
thread.join()
json.dump({"physics": compiles[before:].count("physics"), "switches": [s[2] for s in sim.integrator.switches],
           "finite": bool(np.isfinite(sim.state).all())}, sys.stdout)
'''


@pytest.mark.slow
def test_no_compile_on_the_physics_thread_through_a_whip_on_an_empty_cache(tmp_path):
    """A process of its own on an empty, private numba cache: the start compiles the first
    step's kernels; then a thread steps the heavy tip through its first whip, and numba's
    compile-event listener sees no compile from that thread (on an empty cache every first call
    compiles: a kernel that thread called first would show): the rungs it has not run (gauss4s,
    dop853) are held back, the budget's rung steps in their place. Unguarded, the same run takes
    both (test_guarded_fixed_takes_no_rung_this_process_has_not_run)."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), GYRO_SIM_BACKGROUND_FILL="0")
    out = subprocess.run([sys.executable, "-c", COLD_RUN], env=env, capture_output=True, text=True, timeout=900,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout)
    assert got["physics"] == 0 and got["finite"]
    assert fixed.BUDGET_RUNG in got["switches"] and not {"gauss4s", fixed.RESCUE} & set(got["switches"])
