"""gauss4 (dense simplified Newton or Newton-Krylov, compiled): order 4 against a tight dop853
on both paths, |q| and the quadratic invariants of a rigid body kept to round-off, angular
momentum of a free chain, bounded energy over a long horizon, Newton failures reported with
their reason, the compiled and Python drivers step for step (retakes included), and O(n)
memory on a long chain. The stiff cases (stability function, heavy tip, step moments, fast
double gyroscope) are in test_gauss4_stiff.py."""
import tracemalloc
from fractions import Fraction

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gyro_sim.bench.extreme import load_dict, mass_ratio_chain
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.bench.stability import long_horizon
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.gauss4 import kernels as gk
from gyro_sim.integrators import INTEGRATORS, IntegrationError, make_integrator
from gyro_sim.integrators.gauss4 import driver as gauss
from gyro_sim.integrators.gauss4.driver import DENSE_NEWTON_CAP, GMRES_CAP, Gauss4
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import SimulationError, Simulator
from gyro_sim.dynamics.system import FastChainODE, make_system

from test.dynamics.chains import random_chain

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")


def _system(seed=3, n=3, backend="auto", **kw):
    model = compile_model(load_scene(random_chain(seed, n=n, commands=False, **kw)))
    return model, make_system(model, backend)


def _python(integ):
    """The Python driver on the same system (the compiled march off)."""
    integ.use_compiled = False
    return integ


def _no_retake(integ):
    """The step fails at its first failing Newton iteration (no retake in halves)."""
    integ._params[gk.PAR_DEPTH] = 0
    return integ


def fast_heavy_top(spin):
    """config/heavy_top.yaml spun about its axis at `spin` rad/s (as test_fixed)."""
    sd = load_dict("heavy_top")
    sd["bodies"][0]["initial"]["euler_rates"] = [0.0, 0.0, spin]
    return sd


def test_registered():
    assert INTEGRATORS["gauss4"].order == 4


def test_predictor_extrapolates_the_collocation_polynomial():
    """Z_new = P Z_old is exact for a quadratic u: u(x) = a x + b x^2 (u(0) = 0) gives
    Z_i = u(c_i), and the next step's increments u(1 + r c_s) - u(1)."""
    g = Gauss4(Oscillator1())
    a, b = 0.7, -0.3
    u = lambda x: a * x + b * x * x  # noqa: E731
    Z = np.array([[u(c)] for c in g.C])
    for r in (1.0, 0.5, 2.0):
        want = np.array([[u(1 + r * c) - u(1)] for c in g.C])
        np.testing.assert_allclose(g.predictor(r) @ Z, want, rtol=1e-14, atol=1e-15)


def _symplectic_defect(hA, h):
    """max |h b_i hA_ij + h b_j hA_ji - h^2 b_i b_j| in exact rational arithmetic (b = 1/2)."""
    hb = Fraction(h) / 2
    return max(abs(hb * Fraction(hA[i, j]) + hb * Fraction(hA[j, i]) - hb * hb) for i in range(2) for j in range(2))


def test_step_coefficients_keep_the_symplecticity_condition_exactly():
    """gauss_scaled's h A satisfies b_i a_ij + b_j a_ji = b_i b_j with no rounding at all, for
    any h, and is h A to an ulp (the same method). Rounding the four products h a_ij on their
    own does not: that is the bias that drifted the energy linearly (and this test sees it)."""
    rng = np.random.default_rng(5)
    steps = [1e-3, 2.5e-4, 1e-2, 0.1, 1.0 / 3.0] + list(10.0 ** rng.uniform(-6, 0, 200))
    s3 = np.sqrt(3.0) / 6
    tableau = np.array([[0.25, 0.25 - s3], [0.25 + s3, 0.25]])  # HW IV.5, Table 5.1
    naive_defects = []
    for h in steps:
        hA = np.empty((2, 2))
        gk.gauss_scaled(Gauss4.A, h, hA)
        assert _symplectic_defect(hA, h) == 0, h
        np.testing.assert_allclose(hA, h * tableau, rtol=0, atol=2 * np.finfo(float).eps * h)
        naive_defects.append(_symplectic_defect(Gauss4.A * h, h))
    assert sum(d != 0 for d in naive_defects) > len(steps) // 4


def test_update_is_the_collocation_polynomial_at_the_step_end():
    """gauss_update: y + h b . F + D . (Z - h A F) is y + D . Z (the collocation polynomial at
    t + h), whatever Z; with Z the exact stage increments of x' = L x it is the Gauss step,
    the (2, 2) Pade approximant of exp(h L)."""
    rng = np.random.default_rng(2)
    n, h = 4, 0.05
    L = rng.normal(size=(n, n))
    y0 = rng.normal(size=n)
    hA = np.empty((2, 2))
    gk.gauss_scaled(Gauss4.A, h, hA)
    for Z in (rng.normal(size=(2, n)) * h, None):
        if Z is None:  # the exact collocation: (I - hA (x) L) Z = hA (x) L y0
            K = np.eye(2 * n) - np.kron(hA, L)
            Z = np.linalg.solve(K, np.kron(hA, L) @ np.concatenate([y0, y0])).reshape(2, n)
        F = np.array([L @ (y0 + Z[s]) for s in range(2)])
        y = y0.copy()
        gk.gauss_update(y, Z, F, hA, h, Gauss4.D)
        np.testing.assert_allclose(y, y0 + Gauss4.D @ Z, rtol=1e-13, atol=1e-14)
    I = np.eye(n)
    hL = h * L
    pade = np.linalg.solve(I - hL / 2 + hL @ hL / 12, I + hL / 2 + hL @ hL / 12)
    np.testing.assert_allclose(y, pade @ y0, rtol=1e-13, atol=1e-14)


class Oscillator1:
    """x' = -x (one state): for the tiny unit tests."""

    size = 1
    quat_index = np.zeros((0, 4), dtype=int)

    def rhs(self, t, y):
        return -y

    def project(self, y):
        pass


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_convergence_order_4_on_a_chain(backend, dense):
    """Error vs h against scipy's DOP853 at rtol = atol = 1e-13 (an independent reference):
    slope ~4 (both drivers: numpy is the Python driver on the numpy reference; both Newton
    paths)."""
    model, system = _system(backend=backend)
    y0, T = initial_state(model), 0.1
    sol = solve_ivp(lambda t, y: np.array(system.rhs(t, y)), (0.0, T), y0, method="DOP853",
                    rtol=1e-13, atol=1e-13)
    assert sol.success
    ref = sol.y[:, -1]
    errs = []
    hs = (0.02, 0.01, 0.005)
    for h in hs:
        y = Gauss4(system, step=h, dense=dense).advance(0.0, y0, T)
        errs.append(np.abs(y - ref).max())
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 3.7) & (orders < 4.4)), (errs, orders)


@pytest.mark.parametrize("dense", [True, False])
def test_quaternion_norms_kept_without_projection(dense):
    """The Python driver with `project` a no-op: |q| = 1 is a quadratic invariant, kept to
    round-off by the method alone (the Newton iteration converged to round-off; the dense
    path's simplified iteration too: DENSE_KAPPA)."""
    model, system = _system()
    g = _python(Gauss4(system, step=1e-3, dense=dense))
    g._project = lambda y: None  # no renormalisation: the method keeps |q| itself
    y = g.advance(0.0, initial_state(model), 0.5)
    q = y[model.i_quat]
    assert np.abs(np.linalg.norm(q, axis=1) - 1.0).max() < 1e-13


# ------------------------------------------------------------------ the two drivers
@needs_numba
@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_march_equals_the_python_driver_bit_for_bit(seed, base, dense):
    """The same kernels (gauss_kernels) between the same rhs evaluations, from compiled code or
    from Python, with held inputs and over two calls (the predictor and the dense path's
    matrix carried across): identical bits, rhs evaluations and every count."""
    model = compile_model(load_scene(random_chain(seed, base=base)))
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    runs = []
    for compiled in (True, False):
        system = FastChainODE(model)
        rng = np.random.default_rng(seed)
        g = Gauss4(system, step=1e-3, dense=dense)
        g.use_compiled = compiled
        y = initial_state(model)
        for t0, t1 in ((0.1, 0.115), (0.115, 0.13)):  # new inputs held at each call
            system.hold(t0, rng.uniform(-50, 50, nt) if nt else None,
                        rng.normal(size=nh) if nh else None, rng.normal(size=nt) * 1e-2 if nt else None)
            y = g.advance(t0, y, t1)
        runs.append((y, g.nfev, system.nfev, g.counts.copy(), g.nsteps))
    (yc, nc, sc, cc, kc), (yp, npy, sp, cp, kp) = runs
    assert np.array_equal(yc, yp)
    assert nc == npy == sc == sp == cc[gk.COUNT_RHS] and np.array_equal(cc, cp) and kc == kp == 30


@needs_numba
def test_non_finite_state_stops_the_compiled_march():
    """A state that overflows: the march stops at the failing step with the reason (a
    non-finite rhs at the stages, or a non-finite state after the step), never silently."""
    model, system = _system()
    g = make_integrator("gauss4", system, step=1e-3)
    y0 = initial_state(model)
    y0[model.i_vel.start] = 1e200
    with pytest.raises(IntegrationError, match="not finite"):
        g.advance(0.0, y0, 0.01)


# ------------------------------------------------------------------ failures
@pytest.mark.parametrize("dense, good, why", [
    (True, 0, "rhs not finite at the stages"),
    (True, 2, "iteration matrix singular or not finite"),
    (False, 0, "rhs not finite at the stages"),
    (False, 2, "the linear solve gave a non-finite update at iteration 0")])
def test_newton_failure_is_reported(dense, good, why):
    """A rhs that turns non-finite inside the iteration (Python driver, no retake), at a stage,
    in the finite-difference Jacobian or in a Jacobian-vector product: IntegrationError with
    the reason."""
    model, system = _system()
    g = _no_retake(_python(Gauss4(system, step=1e-3, dense=dense)))
    rhs = system.rhs
    calls = {"n": 0}

    def bad(t, y):
        calls["n"] += 1
        out = rhs(t, y)
        return out * np.nan if calls["n"] > good else out

    g._rhs = bad
    with pytest.raises(IntegrationError, match=f"Newton iteration failed.*{why}"):
        g.advance(0.0, initial_state(model), 0.01)


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.parametrize("compiled", [True, False])
def test_newton_cap_reached_is_reported(compiled, dense):
    """Cap 1 (one Newton iteration cannot pass the stop test from Z = 0), no retake: the step
    fails with its reason, time and step, on either driver and path, and y0 is not touched."""
    model, system = _system()
    g = _no_retake(Gauss4(system, step=1e-3, dense=dense))
    g.use_compiled = compiled
    g._params[gk.PAR_DENSE_CAP if dense else gk.PAR_NEWTON_CAP] = 1
    y0 = initial_state(model)
    keep = y0.copy()
    with pytest.raises(IntegrationError, match=r"Newton iteration failed.*not converged in 1 iter") as info:
        g.advance(0.0, y0, 0.01)
    assert info.value.t == 0.0 and info.value.h == pytest.approx(1e-3)
    assert np.array_equal(y0, keep)


@pytest.mark.parametrize("compiled", [True, False])
def test_failure_after_the_bounded_retake_is_reported(compiled):
    """A step that cannot be taken even in halves (cap 1: no substep can converge): the retake
    halves the piece down to h / 2^RETAKE_DEPTH and gives up, on either driver, with the
    reason and how far it halved; y0 is not touched and the attempts are counted."""
    model, system = _system()
    g = Gauss4(system, step=1e-3)
    g.use_compiled = compiled
    g._params[gk.PAR_DENSE_CAP] = 1
    y0 = initial_state(model)
    keep = y0.copy()
    why = r"not converged in 1 iter.*retaken in halves down to h / 2\^"
    with pytest.raises(IntegrationError, match=why) as info:
        g.advance(0.0, y0, 0.01)
    assert info.value.t == 0.0 and np.array_equal(y0, keep)
    depth = int(g._params[gk.PAR_DEPTH])
    assert f"h / 2^{depth}," in str(info.value)
    assert g.counts[gk.COUNT_RETAKEN] == depth + 1 and g.counts[gk.COUNT_STEPS_RETAKEN] == 1
    assert g.counts[gk.COUNT_MAX_STEP_RHS] <= g.worst_step_rhs


def test_bounded_retake_stops_the_simulator_with_the_reason():
    """The heavy tip (mass ratio 1e6) whips at t = 0.0874 s (accelerations of 4e9 rad/s^2 for
    microseconds, the two light links passing through alignment); with a retake budget of 4
    attempts the step cannot be taken: the Simulator reports the integrator's reason and keeps
    its state (the default budget gets through: test_gauss4_stiff.py)."""
    sim = Simulator(mass_ratio_chain(1e6), integrator="gauss4", step=1e-3)
    sim.integrator._params[gk.PAR_BUDGET] = 4
    with pytest.raises(SimulationError, match="gauss4: Newton iteration failed.*retaken in halves"):
        for _ in range(10):
            sim.advance(0.01)
    assert np.isfinite(sim.state).all() and abs(sim.time - 0.08) < 1e-12


# ------------------------------------------------------------------ invariants
@pytest.mark.slow
def test_angular_momentum_of_a_free_chain():
    """Free-floating chain with rotors, gravity removed: 1e4 steps of 1 ms. World angular
    momentum is not a quadratic invariant of this state (quaternions times body rates: cubic),
    so gauss4 keeps it to its truncation error, not to round-off: the drift falls as h^4 (the
    same 10 s at h = 0.5 ms: 16x smaller; measured 5.3e-12 and 3.3e-13 relative, rk4 5.2e-11
    and 2.9e-12), it does not grow over the run (the last quarter's worst is no larger than
    twice the first quarter's), and it is well below rk4's at the same step."""
    sd = load_dict("free_chain_rotors")
    sd.pop("gravity", None)
    drift = {}
    for name, h in (("gauss4", 1e-3), ("gauss4", 5e-4), ("rk4", 1e-3)):
        sim = Simulator(sd, integrator=name, step=h)
        L0 = sim.invariants()["angular_momentum"]
        d = []
        for _ in range(100):
            sim.advance(0.1)
            d.append(float(np.abs(sim.invariants()["angular_momentum"] - L0).max()))
        drift[name, h] = np.array(d) / np.linalg.norm(L0)
    g = drift["gauss4", 1e-3]
    assert g.max() < 2e-11, g.max()
    assert g.max() < drift["rk4", 1e-3].max() / 4, (g.max(), drift["rk4", 1e-3].max())
    assert g[75:].max() <= 2 * g[:25].max() + 1e-15, (g[:25].max(), g[75:].max())
    ratio = g.max() / drift["gauss4", 5e-4].max()
    assert 8 < ratio < 32, ratio  # order 4: 2^4 = 16


class EulerBody:
    """Euler's equations of a free rigid body, I w' = (I w) x w (body-frame w, principal I)."""

    size = 3
    quat_index = np.zeros((0, 4), dtype=int)
    I = np.array([1.0, 2.0, 3.0])

    def rhs(self, t, w):
        Iw = self.I * w
        return np.array([Iw[1] * w[2] - Iw[2] * w[1], Iw[2] * w[0] - Iw[0] * w[2],
                         Iw[0] * w[1] - Iw[1] * w[0]]) / self.I

    def project(self, y):
        pass


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.slow
def test_quadratic_invariants_of_a_free_rigid_body_to_round_off(dense):
    """Euler's equations keep 2T = w . I w and |L|^2 = |I w|^2, both quadratic: gauss4 keeps
    them to round-off, 1e4 steps of h = 10 ms (measured: relative drift <= 4.4e-15 at every
    1000th step on the Krylov path, 3.1e-15 on the dense one, no growth), where rk4 loses
    ~1e-11. Python driver."""
    body = EulerBody()
    y0 = np.array([0.4, -1.1, 0.7])

    def invariants(y):
        Iw = body.I * y
        return np.array([y @ Iw, Iw @ Iw])

    drift = {}
    for name in ("gauss4", "rk4"):
        g = (Gauss4(body, step=1e-2, dense=dense) if name == "gauss4"
             else make_integrator(name, body, step=1e-2))
        y, k0, d = y0, invariants(y0), []
        for k in range(10):
            y = g.advance(k * 10.0, y, (k + 1) * 10.0)
            d.append(np.abs(invariants(y) / k0 - 1.0).max())
        assert g.nsteps == 10000
        drift[name] = np.array(d)
    assert drift["gauss4"].max() < 2e-14, drift["gauss4"]
    assert drift["rk4"].max() > 100 * drift["gauss4"].max(), drift


def test_energy_bounded_on_a_nutating_top():
    """5000 steps of 1 ms on the nutating top: gauss4's energy error stays bounded (log-log
    slope of its running maximum ~0.1), rk4's grows linearly (slope ~1.2)."""
    runs = {r.integrator: r for r in long_horizon(5000, integrators=("gauss4", "rk4"))}
    assert runs["gauss4"].failed is None and runs["rk4"].failed is None
    assert runs["gauss4"].growth == "bounded", runs["gauss4"].slope
    assert runs["rk4"].growth == "linear (~ t)", runs["rk4"].slope


@pytest.mark.parametrize("spin", [1e2, 1e3, 1e4])
def test_fast_heavy_top_converges(spin):
    """The heavy top spun at 1e2, 1e3 and 1e4 rad/s (0.1, 1, 10 rad a step) at h = 1 ms: 0.1 s
    within the Newton cap (dense path: new stage Jacobians as the body turns), and |q| kept."""
    sim = Simulator(fast_heavy_top(spin), integrator="gauss4", step=1e-3)
    for _ in range(10):
        sim.advance(0.01)
    g = sim.integrator
    assert g.dense and g.nsteps == 100 and g.counts[gk.COUNT_MAX_NEWTON] <= DENSE_NEWTON_CAP
    q = sim.state[sim.model.i_quat]
    assert abs(np.linalg.norm(q) - 1.0) < 1e-14


@needs_numba
def test_a_stiff_motion_is_stepped_in_equal_pieces_and_coarser_ones_are_probed():
    """gauss4s on the heavy top at 1e4 rad/s (10 rad a 1 ms step): no whole step converges.
    The steps' level is kept: once most steps need a retake, the next start a level deeper
    (pieces that converge) instead of failing whole first (which retook every step, at 1.65x
    the evaluations), and after LEVEL_PATIENCE calm steps a coarser level is tried once (and
    fails here: taken back at once, the next probe waits twice as long). With level_max = 0
    (gauss4's default) every step is retaken. The compiled and the Python driver agree bit
    for bit, counts included."""
    from gyro_sim.bench.spin_sweep import heavy_top

    scene = load_scene(heavy_top(1e4))
    out = []
    for compiled, level_max in ((True, gauss.LEVEL_MAX), (False, gauss.LEVEL_MAX), (True, 0)):
        sim = Simulator(scene, integrator="gauss4s", step=1e-3)
        g = sim.integrator.inner
        g.use_compiled = compiled
        g._params[gk.PAR_PATIENCE] = 40
        g._params[gk.PAR_LEVEL_MAX] = level_max
        sim.advance(0.15)  # 150 steps: the level found, then probes after 40 and 80 calm steps
        out.append((sim.state.copy(), g.counts.copy()))
    (y_c, counts), (y_p, counts_p), (_, every) = out
    assert np.array_equal(y_c, y_p) and np.array_equal(counts, counts_p)
    # the climb (~6 steps a level, two levels) and one probe per 40 steps, of 150
    assert counts[gk.COUNT_STEPS_RETAKEN] <= 20, counts
    assert every[gk.COUNT_STEPS_RETAKEN] == 150, every
    assert counts[gk.COUNT_RHS] < 0.8 * every[gk.COUNT_RHS], (counts, every)


@needs_numba
def test_round_off_floor_is_accepted_counted_and_the_same_on_both_drivers(monkeypatch):
    """The top at 1e4 rad/s, Krylov path with GMRES at 1e-8, and a Newton stop that cannot be
    met (kappa = 0, first_tol = 0): every iteration runs down to the round-off of the rhs,
    where its updates stop contracting, whatever the processor's floating-point path. That
    floor is accepted (counted as stalled), bit for bit on both drivers; without the floor
    (NEWTON_STALL = 0, no retake) the same iteration reports divergence."""
    monkeypatch.setattr(gauss, "DENSE_MAX_SIZE", 0)
    results = []
    for stall, compiled in ((gauss.NEWTON_STALL, True), (gauss.NEWTON_STALL, False), (0.0, True)):
        sim = Simulator(fast_heavy_top(1e4), integrator="gauss4", step=1e-3)
        g = sim.integrator
        assert not g.dense
        g.use_compiled = compiled
        if stall == 0.0:
            _no_retake(g)
        g._params[gk.PAR_GMRES_RTOL] = 1e-8
        g._params[gk.PAR_KAPPA] = 0.0
        g._params[gk.PAR_FIRST_TOL] = 0.0
        g._params[gk.PAR_STALL] = stall
        try:
            for _ in range(30):
                sim.advance(0.01)
            results.append((sim.state.copy(), g.counts.copy()))
        except SimulationError as e:
            results.append(str(e))
    assert not isinstance(results[0], str), results[0]
    (yc, cc), (yp, cp), failed = results
    assert cc[gk.COUNT_STALLED] > 0 and np.array_equal(cc, cp) and np.array_equal(yc, yp)
    assert isinstance(failed, str) and "Newton iteration failed" in failed and "diverging" in failed, failed


# ------------------------------------------------------------------ memory
@needs_numba
def test_memory_is_linear_in_the_chain_length():
    """n = 2000 bodies (size 14000, above DENSE_MAX_SIZE: the Krylov path): the integrator's
    arrays are (GMRES_CAP + 11) rows of 2 size floats, and a step of the Python driver
    allocates nothing O(n^2) (tracemalloc peak below 10 MB; a single (size, size) matrix
    would be 1.6 GB)."""
    model = compile_model(load_scene(spherical_chain(2000)))
    system = make_system(model, "numba")
    g = _python(make_integrator("gauss4", system, step=1e-3))
    size = model.size
    assert not g.dense and g.workspace_bytes <= (GMRES_CAP + 11) * 2 * size * 8
    y0 = initial_state(model)
    tracemalloc.start()
    try:
        g.advance(0.0, y0, 1e-3)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert g.nsteps == 1
    assert peak < 10e6, peak
