"""The "auto" integrator's two drivers of its dop853 and radau phases give the same bits.

On a system with the compiled kernel (FastChainODE), Auto runs DOP853's compiled loop in its
detection mode (gyro_sim.integrators.dop853.loop.dop853_advance): h |lambda| of every accepted step,
the stiffness and rejection tests and the cost window inside compiled code, returning where a
test asks for a switch; and likewise Radau's (gyro_sim.integrators.radau.loop.radau_advance): rho(J)
when the Jacobian is refreshed, the non-stiffness and cost tests, the cost window. On other
systems it steps either method by its public single step and calls the same tests after each
step: that Python loop is the reference here (the loop Auto ran on every system before the
compiled ones), on the same system with the compiled loops switched off. States, outputs at
t_eval, switch times and reasons, counters: identical.
"""
import warnings

import numpy as np
import pytest

from gyro_sim.bench import accuracy as acc
from gyro_sim.bench import extreme as ex
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators import StiffnessWarning, make_integrator
from gyro_sim.integrators import auto as auto_module
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.dynamics.system import FastChainODE, make_system

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

ROTOR = ex.fast_rotor_precession(1e4)  # auto switches to radau near t = 0.1 s


def chain_4() -> dict:
    return acc.load_dict("chain_4")


def drivers(scene: dict, rtol: float):
    """Two "auto" integrators on one FastChainODE of `scene`: the compiled driver and the
    Python one; and the initial state."""
    model = compile_model(load_scene(scene))
    system = FastChainODE(model)
    compiled = make_integrator("auto", system, rtol=rtol, atol=rtol * 1e-2)
    python = make_integrator("auto", system, rtol=rtol, atol=rtol * 1e-2)
    python.explicit._loop = None  # the Python loops on the same system
    python.implicit._loop = None
    assert compiled.explicit.compiled and compiled.implicit.compiled
    assert not (python.explicit.compiled or python.implicit.compiled)
    return compiled, python, initial_state(model)


def run(integ, y0, horizon: float, chunk: float, t_eval=None):
    """`integ` from (0, y0) to `horizon` in calls of `chunk` (as the node calls it), the
    outputs of each call at the times of t_eval inside it; the state after each call and the
    outputs."""
    y, ends, rows = y0.copy(), [], []
    n = round(horizon / chunk)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StiffnessWarning)
        for k in range(n):
            t0, t1 = k * chunk, (k + 1) * chunk
            if t_eval is None:
                y = integ.advance(t0, y, t1)
            else:
                y, Y = integ.advance(t0, y, t1, t_eval=t_eval[(t_eval >= t0) & (t_eval <= t1)])
                rows.append(Y)
            ends.append(y.copy())
    return np.array(ends), rows


def assert_same(a, b, ra, rb):
    """Identical runs of the two drivers a, b: states ra[0], rb[0], outputs ra[1], rb[1]."""
    np.testing.assert_array_equal(ra[0], rb[0])
    assert len(ra[1]) == len(rb[1])
    for p, q in zip(ra[1], rb[1]):
        np.testing.assert_array_equal(p, q)
    assert a.switches == b.switches
    assert (a.nfev, a.nsteps, a.nrejected, a.njev, a.nlu, a.method) == \
        (b.nfev, b.nsteps, b.nrejected, b.njev, b.nlu, b.method)
    assert (a.error_estimate, a.last_step) == (b.error_estimate, b.last_step)
    np.testing.assert_array_equal(a._counters, b._counters)
    np.testing.assert_array_equal(a._cost, b._cost)
    np.testing.assert_array_equal(a._easy, b._easy)
    np.testing.assert_array_equal(a._window, b._window)


def test_not_stiff_chain():
    a, b, y0 = drivers(chain_4(), 1e-8)
    ra, rb = run(a, y0, 0.3, 0.01), run(b, y0, 0.3, 0.01)
    assert not a.switches and a.method == "dop853"
    assert_same(a, b, ra, rb)


@pytest.mark.parametrize("chunk", [0.01, 0.3])
def test_switch_to_radau(chunk):
    a, b, y0 = drivers(ROTOR, 1e-8)
    ra, rb = run(a, y0, 0.3, chunk), run(b, y0, 0.3, chunk)
    assert [s[1:3] for s in a.switches] == [("dop853", "radau")]
    assert_same(a, b, ra, rb)


def test_switch_at_the_start_of_a_call():
    """Calls of about one step each: the h |lambda| of a call's last step waits for f(y1), the
    next call's first rhs; the 15th stiff step is tested there, and auto switches before that
    call's first step."""
    chunk = 0.006  # just above dop853's step on its stability limit here (~5.5e-3)
    a, b, y0 = drivers(ROTOR, 1e-8)
    ra, rb = run(a, y0, 0.15, chunk), run(b, y0, 0.15, chunk)
    assert [s[1:3] for s in a.switches] == [("dop853", "radau")]
    assert any(a.switches[0][0] == k * chunk for k in range(round(0.15 / chunk)))
    assert_same(a, b, ra, rb)


@pytest.mark.parametrize("scene", ["chain_4", "rotor"])
def test_dense_output(scene):
    a, b, y0 = drivers(chain_4() if scene == "chain_4" else ROTOR, 1e-8)
    t_eval = np.linspace(0.0, 0.3, 47)
    ra, rb = run(a, y0, 0.3, 0.05, t_eval), run(b, y0, 0.3, 0.05, t_eval)
    assert sum(len(r) for r in ra[1]) >= t_eval.size  # the ends of calls twice
    assert bool(a.switches) == (scene == "rotor")
    assert_same(a, b, ra, rb)


def test_back_to_dop853_when_radau_costs_more():
    """At rtol 1e-10 auto measures radau costlier and returns to dop853, whose later stiff
    steps then only restart the detection (auto_costlier)."""
    a, b, y0 = drivers(ROTOR, 1e-10)
    ra, rb = run(a, y0, 0.5, 0.01), run(b, y0, 0.5, 0.01)
    assert [s[1:3] for s in a.switches] == [("dop853", "radau"), ("radau", "dop853")]
    assert_same(a, b, ra, rb)


@pytest.mark.parametrize("chunk", [0.01, 0.25])
def test_hand_back_when_not_stiff(monkeypatch, chunk):
    """The non-stiffness test made easy to pass (h rho < 1e4: every step of radau here, whose
    steps are ~10 ms against rho = 1080): radau hands back after NONSTIFF_STEPS steps, dop853
    finds the stiffness again, radau waits twice as long the next time; the same bits from
    both drivers, outputs at t_eval included, through every switch."""
    monkeypatch.setattr(auto_module, "NONSTIFF_HRHO", 1e4)
    monkeypatch.setattr(auto_module, "NONSTIFF_STEPS", 5)
    a, b, y0 = drivers(ROTOR, 1e-8)
    t_eval = np.linspace(0.0, 1.0, 61)
    ra, rb = run(a, y0, 1.0, chunk, t_eval), run(b, y0, 1.0, chunk, t_eval)
    kinds = [s[1:3] for s in a.switches]
    assert kinds[:3] == [("dop853", "radau"), ("radau", "dop853"), ("dop853", "radau")]
    backs = [s[3] for s in a.switches if s[2] == "dop853"]
    assert backs == [f"not stiff: h rho(J) < 10000 in {5 * 2 ** k} steps" for k in range(len(backs))]
    assert len(backs) >= (3 if chunk == 0.01 else 1)  # 5, 10, 20 steps: doubled each time
    assert_same(a, b, ra, rb)


def test_power_iterations(monkeypatch):
    """rho(J) by power iterations (the rule above EIG_MAX_SIZE states, here lowered below the
    rotor's 8): the same bits from both drivers; an estimate of the nutation's 1080 rad/s."""
    monkeypatch.setattr(auto_module, "EIG_MAX_SIZE", 4)
    a, b, y0 = drivers(ROTOR, 1e-8)
    ra, rb = run(a, y0, 0.5, 0.01), run(b, y0, 0.5, 0.01)
    assert [s[1:3] for s in a.switches][:1] == [("dop853", "radau")]
    rho = a._easy[0]
    w_n, _ = ex.fast_rotor_frequencies(ex.fast_rotor_spin(1e4))
    assert rho == pytest.approx(w_n, rel=1e-2)
    assert_same(a, b, ra, rb)


def test_rejection_test(monkeypatch):
    """The rejection test (the stiffness test off, a short window) switches in both drivers
    at the same step, with the same counts in the reason."""
    monkeypatch.setattr(auto_module, "STIFF_HLAMB", np.inf)
    monkeypatch.setattr(auto_module, "REJECT_WINDOW", 10)
    monkeypatch.setattr(auto_module, "REJECT_FRACTION", 0.2)
    a, b, y0 = drivers(chain_4(), 1e-8)
    ra, rb = run(a, y0, 0.3, 0.01), run(b, y0, 0.3, 0.01)
    assert a.switches and "step attempts rejected" in a.switches[0][3]
    assert_same(a, b, ra, rb)


def test_reset_forgets_the_held_step():
    """After a reset both drivers start afresh (the step held for the next call included)."""
    a, b, y0 = drivers(ROTOR, 1e-8)
    run(a, y0, 0.05, 0.01), run(b, y0, 0.05, 0.01)
    a.reset(), b.reset()
    assert_same(a, b, run(a, y0, 0.3, 0.01), run(b, y0, 0.3, 0.01))


def test_numpy_backend_steps_in_python():
    """Without the compiled kernel (the numpy reference backend) auto steps dop853 and radau in
    Python and detects the same stiffness."""
    model = compile_model(load_scene(ROTOR))
    integ = make_integrator("auto", make_system(model, "numpy"), rtol=1e-8, atol=1e-10)
    assert not (integ.explicit.compiled or integ.implicit.compiled)
    run(integ, initial_state(model), 0.2, 0.01)
    assert [s[1:3] for s in integ.switches] == [("dop853", "radau")]


# ------------------------------------------------------------------ the tests' kernels
def test_window_kernels_are_the_list_windows():
    """The ring buffers of dop853_kernels against the lists Auto kept before: the last
    REJECT_WINDOW attempts, the last COST_WINDOW (dt, nfev), their sums oldest first."""
    from gyro_sim.integrators.dop853 import kernels as dk

    rng = np.random.default_rng(1)
    counters = np.zeros(dk.COUNTERS_SIZE, dtype=np.int64)
    attempts = np.zeros(7, dtype=np.int64)
    window = np.zeros((5, 2))
    cost = np.full(dk.COST_SIZE, np.nan)
    detect = np.array([5.0, 15, 6, 0.3])
    att_list, win_list, cost_ref = [], [], float("nan")
    for k in range(200):
        if k == 120:  # the detection starts over
            dk.auto_clear_attempts(counters)
            att_list.clear()
        rejected = int(rng.integers(0, 3))
        fired = dk.auto_rejection_test(rejected, counters, attempts, detect)
        att_list = (att_list + [rejected])[-attempts.size:]
        n_rej = sum(att_list)
        n_all = n_rej + len(att_list)
        assert fired == (n_all >= attempts.size and n_rej >= 0.3 * n_all)
        assert dk.auto_rejections(counters, attempts) == (n_rej, n_all)
        dt, nfev = float(rng.uniform(1e-4, 1e-2)), int(rng.integers(12, 40))
        dk.auto_measure(dt, nfev, counters, window, cost, dk.COST_RADAU)
        win_list = (win_list + [(dt, nfev)])[-window.shape[0]:]
        if len(win_list) == window.shape[0]:
            span = 0.0
            for x in win_list:
                span += x[0]
            cost_ref = sum(x[1] for x in win_list) / span
        assert np.array_equal(cost[dk.COST_RADAU], cost_ref, equal_nan=True)
    assert np.isnan(cost[dk.COST_DOP853])  # the other method's slot untouched


def test_stiffness_test_is_dop853f():
    """dop853.f's counting (IASTI, NONSTI): stiff after STIFF_STEPS stiff steps, unless
    NONSTIFF_RESET non-stiff steps in a row came between."""
    from gyro_sim.integrators.dop853 import kernels as dk

    counters = np.zeros(dk.COUNTERS_SIZE, dtype=np.int64)
    detect = np.array([5.0, 4, 2, 0.5])
    stiff, calm = 6.0, 1.0
    # 3 stiff, 1 calm (not a reset), 1 stiff: the 4th stiff step fires
    assert [dk.auto_stiffness_test(h, counters, detect) for h in (stiff, stiff, stiff, calm, stiff)] \
        == [False, False, False, False, True]
    counters[:] = 0
    # 3 stiff, 2 calm (a reset), 3 stiff: not yet
    assert not any(dk.auto_stiffness_test(h, counters, detect)
                   for h in (stiff, stiff, stiff, calm, calm, stiff, stiff, stiff))


def test_hlamb_is_the_norm_ratio():
    """dop_hlamb = |h| ||f1 - f12|| / ||y1 - Y12|| (to round-off: numpy's norms sum otherwise);
    no estimate when y1 = Y12."""
    from gyro_sim.integrators.dop853 import kernels as dk

    rng = np.random.default_rng(2)
    y1, Y12, f1, f12 = rng.normal(size=(4, 9))
    h = -3e-3
    ref = abs(h) * np.linalg.norm(f1 - f12) / np.linalg.norm(y1 - Y12)
    assert dk.dop_hlamb(h, Y12, f12, y1, f1) == pytest.approx(ref, rel=1e-14)
    assert dk.dop_hlamb(h, y1, f12, y1, f1) == dk.NO_HLAMB


def test_spectral_radius_kernel():
    """auto_spectral_radius against numpy's eigenvalues (to round-off: another LAPACK build
    may order its operations otherwise): a random matrix, a rotation-like one (+-i w, the
    gyroscopic case), a non-finite one; above EIG_MAX_SIZE the power iterations converge to
    a dominant real eigenvalue."""
    from gyro_sim.integrators.radau import kernels as rk

    handback = np.array([2.0, 1.5, 12.0, 5.95, 50.0, 200.0])
    rng = np.random.default_rng(3)
    J = rng.normal(size=(9, 9))
    power = np.zeros(0)
    assert rk.auto_spectral_radius(J, power, handback) == pytest.approx(
        np.max(np.abs(np.linalg.eigvals(J))), rel=1e-12)
    w = 1080.0
    R = np.array([[0.0, w, 0.0], [-w, 0.0, 0.0], [0.0, 0.0, -3.0]])
    assert rk.auto_spectral_radius(R, power, handback) == pytest.approx(w, rel=1e-13)
    assert rk.auto_spectral_radius(np.zeros((0, 0)), power, handback) == 0.0
    bad = J.copy()
    bad[2, 3] = np.nan
    assert rk.auto_spectral_radius(bad, power, handback) == np.inf
    # 60 states > EIG_MAX_SIZE = 50: power iterations, eigenvalues 1..59 and -100 (dominant)
    Q, _ = np.linalg.qr(rng.normal(size=(60, 60)))
    D = np.diag(np.r_[np.arange(1.0, 60.0), -100.0])
    big = Q @ D @ Q.T
    est = rk.auto_spectral_radius(big, rng.normal(size=60), handback)
    assert est == pytest.approx(100.0, rel=1e-6)


def test_hand_back_tests_are_the_rules():
    """auto_nonstiffness_test and auto_cost_test against the rules in auto.py, written out:
    NEEDED steps in a row with h rho < NONSTIFF_HRHO; radau's measured cost above
    COST_MARGIN x dop853's (measured, else 12 rho / 5.95), once its window is full."""
    from gyro_sim.integrators.dop853 import kernels as dk
    from gyro_sim.integrators.radau import kernels as rk

    handback = np.array([2.0, 1.5, 12.0, 5.95, 200.0, 30.0])
    easy = np.array([np.nan, 0.0, 0.0, 3.0])
    assert not rk.auto_nonstiffness_test(1e-3, easy, handback)  # no rho yet
    easy[rk.EASY_RHO] = 1000.0
    steps = [1e-3, 1e-3, 3e-3, 1e-3, 1e-3, 1e-3]  # h rho = 1, 1, 3 (breaks the row), 1, 1, 1
    assert [rk.auto_nonstiffness_test(h, easy, handback) for h in steps] == \
        [False, False, False, False, False, True]
    counters = np.zeros(dk.COUNTERS_SIZE, dtype=np.int64)
    window = np.zeros((4, 2))
    cost = np.full(dk.COST_SIZE, np.nan)
    cost[dk.COST_RADAU] = 3000.0
    assert not rk.auto_cost_test(cost, counters, window, easy, handback)  # window not full
    counters[dk.C_WINDOW] = 4
    # dop853 never measured: 12 x 1000 / 5.95 = 2017 per s; 3000 < 1.5 x 2017
    assert not rk.auto_cost_test(cost, counters, window, easy, handback)
    assert rk.auto_dop853_cost(cost, easy, handback) == pytest.approx(12 * 1000 / 5.95)
    cost[dk.COST_DOP853] = 1900.0  # measured: 3000 > 1.5 x 1900
    assert rk.auto_cost_test(cost, counters, window, easy, handback)
