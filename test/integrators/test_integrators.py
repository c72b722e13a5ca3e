"""The integrators (gyro_sim.integrators): tableau properties, measured convergence
orders, the rigid-body invariants, stiffness, dense output and the `advance` contract.

Test systems are defined here: a linear, time-dependent ODE with an exact solution; a
torque-free rigid body (a quaternion and the body angular velocity in the state) whose
energy, |L| and world angular momentum are exact invariants, with the closed-form solution
of the symmetric top; the stiff linear ODE y' = -lam (y - cos t); Van der Pol.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim import integrators as integ
from gyro_sim.integrators import (
    DOP853, INTEGRATORS, RK4, IntegrationError, Lie4, Radau, make_integrator,
)
from gyro_sim.dynamics.rotations import quat_exp, quat_mul, quat_to_matrix

NAMES = ("rk4", "dop853", "radau", "lie4", "gauss4")
FIXED = ("rk4", "lie4", "gauss4")
ADAPTIVE = ("dop853", "radau")
NO_QUAT = np.zeros((0, 4), dtype=int)


# ------------------------------------------------------------------ test systems
class Oscillator:
    """x' = v, v' = -x, z' = cos(t) z: x = cos t, v = -sin t, z = exp(sin t)."""

    size = 3
    quat_index = NO_QUAT

    def rhs(self, t, y):
        return np.array([y[1], -y[0], math.cos(t) * y[2]])

    def jacobian(self, t, y):
        return np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, math.cos(t)]])

    def project(self, y):
        pass

    @staticmethod
    def exact(t):
        t = np.asarray(t, dtype=float)
        return np.stack([np.cos(t), -np.sin(t), np.exp(np.sin(t))], axis=-1)


class RigidBody:
    """Torque-free rigid body, y = (q (world from body), omega_body); principal inertia I.

    q' = 1/2 (0, omega_world) (x) q, I omega' = (I omega) x omega (Euler).
    """

    size = 7
    quat_index = np.arange(4).reshape(1, 4)

    def __init__(self, inertia, normalise=True):
        self.I = np.asarray(inertia, dtype=float)
        self.normalise = normalise

    def rhs(self, t, y):
        q, w = y[:4], y[4:]
        w_dot = np.cross(self.I * w, w) / self.I
        w_world = quat_to_matrix(q) @ w
        return np.concatenate([0.5 * quat_mul(np.concatenate([[0.0], w_world]), q), w_dot])

    def project(self, y):
        if self.normalise:
            y[:4] /= np.linalg.norm(y[:4])

    def invariants(self, y):
        """(kinetic energy, |L|, L in world axes (3,))."""
        q, w = y[:4], y[4:]
        L_world = quat_to_matrix(q) @ (self.I * w)
        return 0.5 * w @ (self.I * w), np.linalg.norm(L_world), L_world

    def symmetric_top(self, y0, t):
        """Exact state at t for I = (A, A, C): q = exp(t L/A) (x) q0 (x) exp(t mu e3)."""
        A, A2, C = self.I
        assert A == A2
        q0, w0 = y0[:4], y0[4:]
        L_world = quat_to_matrix(q0) @ (self.I * w0)
        mu = w0[2] * (1.0 - C / A)  # body-frame precession rate of omega
        spin = quat_exp(np.array([0.0, 0.0, t * mu]))
        q = quat_mul(quat_mul(quat_exp(t * L_world / A), q0), spin)
        c, s = math.cos(mu * t), math.sin(mu * t)
        w = np.array([c * w0[0] + s * w0[1], -s * w0[0] + c * w0[1], w0[2]])
        return np.concatenate([q, w])


class StiffLinear:
    """y' = -lam (y - cos t), y(0) = 1 (stiff for large lam)."""

    size = 1
    quat_index = NO_QUAT

    def __init__(self, lam):
        self.lam = lam

    def rhs(self, t, y):
        return -self.lam * (y - math.cos(t))

    def project(self, y):
        pass

    def exact(self, t):
        lam = self.lam
        y = lam * lam * math.cos(t) + lam * math.sin(t) + math.exp(-lam * t)
        return np.array([y / (lam * lam + 1)])


class VanDerPol:
    size = 2
    quat_index = NO_QUAT

    def __init__(self, mu):
        self.mu = mu

    def rhs(self, t, y):
        return np.array([y[1], self.mu * (1.0 - y[0] ** 2) * y[1] - y[0]])

    def project(self, y):
        pass


class NanAfter(Oscillator):
    """The oscillator, but rhs is NaN for t > t_bad."""

    def __init__(self, t_bad):
        self.t_bad = t_bad

    def rhs(self, t, y):
        return super().rhs(t, y) if t <= self.t_bad else np.full(3, np.nan)


class Workspace:
    """Wraps a system: rhs returns its own buffer, overwritten by every call."""

    def __init__(self, system):
        self.inner = system
        self.size = system.size
        self.quat_index = system.quat_index
        self.project = system.project
        self._out = np.empty(system.size)

    def rhs(self, t, y):
        self._out[:] = self.inner.rhs(t, y)
        return self._out


class Counting:
    """Wraps a system and counts the calls of rhs and jacobian."""

    def __init__(self, system):
        self.inner = system
        self.size = system.size
        self.quat_index = system.quat_index
        self.project = system.project
        self.calls = self.njac = 0
        if callable(getattr(system, "jacobian", None)):
            self.jacobian = self._jacobian

    def rhs(self, t, y):
        self.calls += 1
        return self.inner.rhs(t, y)

    def _jacobian(self, t, y):
        self.njac += 1
        return self.inner.jacobian(t, y)


def _body_state(w=(0.4, 1.5, -0.7)):
    return np.concatenate([quat_exp(np.array([0.3, -0.2, 0.5])), w])


def _slope(x, err):
    return np.polyfit(np.log(x), np.log(err), 1)[0]


def _qerr(y, ref):
    """Max error of a body state, the quaternion up to sign."""
    e = np.abs(y - ref).max()
    flipped = ref.copy()
    flipped[:4] *= -1
    return min(e, np.abs(y - flipped).max())


def _quat_err(y, ref):
    """Error of the quaternion alone (up to sign): the rotation, the Lie-group part."""
    return min(np.abs(y[:4] - ref[:4]).max(), np.abs(y[:4] + ref[:4]).max())


# ------------------------------------------------------------------ registry
def test_registry_and_documentation():
    # the named methods, plus "auto" (dop853 that switches to radau on stiffness) and "fixed"
    # (rk4 that switches to gauss4: test_fixed.py), and "gauss4s" (gauss4 on the chain's
    # canonical equations: chains only, test_gauss4s.py)
    assert set(INTEGRATORS) == set(NAMES) | {"auto", "fixed", "gauss4s"}
    for name, cls in INTEGRATORS.items():
        assert cls.name == name
        assert isinstance(cls.order, int)
        assert "order" in cls.__doc__.lower() and "References" in cls.__doc__
    assert {INTEGRATORS[n].order for n in NAMES} == {4, 8, 5}


def test_unknown_name_lists_valid_names():
    with pytest.raises(ValueError) as err:
        make_integrator("euler", Oscillator())
    for name in NAMES:
        assert name in str(err.value)


def test_bad_options_rejected():
    with pytest.raises(ValueError):
        make_integrator("rk4", Oscillator(), step=0.0)
    with pytest.raises(ValueError):
        make_integrator("dop853", Oscillator(), atol=-1.0)
    with pytest.raises(ValueError):
        make_integrator("dop853", Oscillator(), atol=np.ones(2))
    it = make_integrator("rk4", Oscillator())
    with pytest.raises(ValueError):
        it.advance(1.0, Oscillator.exact(0.0), 0.0)
    with pytest.raises(ValueError):
        it.advance(0.0, np.zeros(2), 1.0)
    with pytest.raises(ValueError):
        it.advance(0.0, Oscillator.exact(0.0), 1.0, t_eval=[0.5, 0.2])
    with pytest.raises(ValueError):
        it.advance(0.0, Oscillator.exact(0.0), 1.0, t_eval=[0.5, 1.5])


# ------------------------------------------------------------------ tableaus
@pytest.mark.parametrize("cls", [RK4, DOP853])
def test_explicit_tableau(cls):
    A, B, C = cls.A, cls.B, cls.C
    assert A.shape == (cls.n_stages, cls.n_stages) and B.shape == C.shape == (cls.n_stages,)
    assert np.allclose(np.triu(A), 0.0)  # explicit
    assert math.isclose(B.sum(), 1.0, abs_tol=1e-14)
    np.testing.assert_allclose(A.sum(axis=1), C, atol=1e-14)
    if cls is DOP853:
        assert abs(cls.E3.sum()) < 1e-14 and abs(cls.E5.sum()) < 1e-14
        np.testing.assert_allclose(cls.A_EXTRA.sum(axis=1), cls.C_EXTRA, atol=1e-14)
        assert cls.order == 8 and cls.error_estimator_order == 7


def test_dop853_coefficients_are_scipys():
    """The copied coefficients equal scipy's (the source cited), digit for digit."""
    dop = pytest.importorskip("scipy.integrate._ivp.dop853_coefficients")
    n = dop.N_STAGES
    np.testing.assert_array_equal(DOP853.A, dop.A[:n, :n])
    np.testing.assert_array_equal(DOP853.B, dop.B)
    np.testing.assert_array_equal(DOP853.C, dop.C[:n])
    np.testing.assert_array_equal(DOP853.E3, dop.E3[:n])
    np.testing.assert_array_equal(DOP853.E5, dop.E5[:n])
    np.testing.assert_array_equal(DOP853.A_EXTRA, dop.A[n + 1:])
    np.testing.assert_array_equal(DOP853.D, dop.D)


def test_radau_tableau():
    A, C = Radau.A, Radau.C
    np.testing.assert_allclose(A.sum(axis=1), C, atol=1e-15)
    np.testing.assert_array_equal(Radau.B, A[-1])  # stiffly accurate
    assert math.isclose(Radau.B.sum(), 1.0, abs_tol=1e-15)
    # Radau IIA of order 5: B . C^(k-1) = 1/k for k <= 5
    for k in range(1, 6):
        assert math.isclose(Radau.B @ C ** (k - 1), 1.0 / k, abs_tol=1e-14)
    # T, TI: A^-1 = T diag(MU_REAL, [[a, -b], [b, a]]) TI with MU_COMPLEX = a + i b
    np.testing.assert_allclose(Radau.T @ Radau.TI, np.eye(3), atol=1e-14)
    Lam = Radau.TI @ np.linalg.inv(A) @ Radau.T
    a, b = Radau.MU_COMPLEX.real, Radau.MU_COMPLEX.imag
    np.testing.assert_allclose(Lam, [[Radau.MU_REAL, 0, 0], [0, a, -b], [0, b, a]], atol=1e-12)
    # the collocation polynomial passes through the nodes: P (c, c^2, c^3) = identity
    X = np.array([C, C**2, C**3])
    np.testing.assert_allclose(Radau.P @ X, np.eye(3), atol=1e-13)


def test_lie4_coefficients():
    np.testing.assert_allclose(Lie4.BETA1 + Lie4.BETA2, RK4.B, atol=1e-16)
    np.testing.assert_allclose(Lie4.ALPHA.sum(axis=1) + [0, 0, 0, 0.5], Lie4.C)  # Y4 from Y2


# ------------------------------------------------------------------ convergence orders
@pytest.mark.parametrize("name", FIXED)
def test_fixed_step_order_linear(name):
    T, ns = 2.0, np.array([20, 40, 80, 160])
    err = []
    for n in ns:
        y = make_integrator(name, Oscillator(), step=T / n).advance(0.0, Oscillator.exact(0.0), T)
        err.append(np.abs(y - Oscillator.exact(T)).max())
    assert 3.7 <= _slope(T / ns, err) <= 4.3


@pytest.mark.parametrize("name", FIXED)
@pytest.mark.slow
def test_fixed_step_order_symmetric_top(name):
    """Global error against the closed-form symmetric top: of the quaternion alone (where
    lie4 differs from rk4) and of the whole state."""
    body = RigidBody([1.0, 1.0, 2.5], normalise=False)
    y0, T, ns = _body_state((0.6, -0.3, 2.0)), 5.0, np.array([50, 100, 200, 400])
    ref = body.symmetric_top(y0, T)
    ys = [make_integrator(name, body, step=T / n).advance(0.0, y0, T) for n in ns]
    assert 3.7 <= _slope(T / ns, [_quat_err(y, ref) for y in ys]) <= 4.3
    assert 3.7 <= _slope(T / ns, [_qerr(y, ref) for y in ys]) <= 4.3


def test_lie4_output_exponentials_in_the_right_order():
    """The check of the scheme's statement "the right exponential acts first": swapped,
    the method drops to order 2 on the symmetric top."""
    class Swapped(Lie4):
        BETA1, BETA2 = Lie4.BETA2, Lie4.BETA1

    body = RigidBody([1.0, 1.0, 2.5], normalise=False)
    y0, T, ns = _body_state((0.6, -0.3, 2.0)), 5.0, np.array([50, 100, 200, 400])
    ref = body.symmetric_top(y0, T)
    err = [_quat_err(Swapped(body, step=T / n).advance(0.0, y0, T), ref) for n in ns]
    assert 1.7 <= _slope(T / ns, err) <= 2.3


def test_lie4_invariants_converge_at_order_4_and_q_stays_unit():
    """Asymmetric body, no projection: |q| = 1 to round-off; the largest deviation of each
    invariant over the run (energy, |L|, the world vector L) converges at order 4."""
    body = RigidBody([1.0, 2.0, 3.0], normalise=False)
    y0, T, ns = _body_state(), 5.0, np.array([50, 100, 200, 400])
    E0, L0, Lw0 = body.invariants(y0)
    dE, dL, dLw = [], [], []
    for n in ns:
        it = make_integrator("lie4", body, step=T / n)
        _, Y = it.advance(0.0, y0, T, t_eval=np.linspace(0.0, T, 51)[1:])
        assert np.abs(np.linalg.norm(Y[:, :4], axis=1) - 1.0).max() < 1e-14
        inv = [body.invariants(y) for y in Y]
        dE.append(max(abs(E - E0) for E, _, _ in inv))
        dL.append(max(abs(L - L0) for _, L, _ in inv))
        dLw.append(max(np.abs(Lw - Lw0).max() for _, _, Lw in inv))
    for d in (dE, dL, dLw):
        assert 3.7 <= _slope(T / ns, d) <= 4.3, d


def test_lie4_long_run_keeps_unit_quaternion():
    body = RigidBody([1.0, 2.0, 3.0], normalise=False)
    y = make_integrator("lie4", body, step=0.01).advance(0.0, _body_state(), 20.0)
    assert abs(np.linalg.norm(y[:4]) - 1.0) < 1e-14


def test_rk4_without_projection_drifts_off_unit():
    """The contrast to lie4: rk4 does not keep |q| = 1 by itself."""
    body = RigidBody([1.0, 2.0, 3.0], normalise=False)
    y = make_integrator("rk4", body, step=0.05).advance(0.0, _body_state(), 20.0)
    assert abs(np.linalg.norm(y[:4]) - 1.0) > 1e-9


def test_dop853_order_at_fixed_step():
    """With the error control out of play (huge tolerance) the step is max_step: order 8."""
    T, ns = 10.0, np.array([14, 20, 28, 40])
    err = []
    for n in ns:
        it = make_integrator("dop853", Oscillator(), rtol=1e3, atol=1e3, max_step=T / n)
        y = it.advance(0.0, Oscillator.exact(0.0), T)
        assert it.nrejected == 0 and it.nsteps <= n + 1
        err.append(np.abs(y - Oscillator.exact(T)).max())
    assert 7.5 <= _slope(T / ns, err) <= 9.0


@pytest.mark.parametrize("name, band", [("dop853", (6.5, 11.0)), ("radau", (3.5, 6.5))])
def test_adaptive_work_precision(name, band):
    """Error against rhs evaluations over a sweep of tolerances: slope about -order (radau's
    steps follow its order-3 estimator, h ~ tol^(1/4) while its error ~ tol: between 4 and
    5); the error falls monotonically with the tolerance and stays within a modest
    multiple of it."""
    T, tols = 10.0, np.array([1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11])
    err, nfev = [], []
    for tol in tols:
        it = make_integrator(name, Oscillator(), rtol=tol, atol=tol)
        y = it.advance(0.0, Oscillator.exact(0.0), T)
        err.append(np.abs(y - Oscillator.exact(T)).max())
        nfev.append(it.nfev)
    assert np.all(np.diff(err) < 0) and np.all(np.diff(nfev) > 0)
    assert band[0] <= -_slope(nfev, err) <= band[1]
    assert np.all(np.asarray(err) < 100 * tols)


@pytest.mark.parametrize("name, steps", [("dop853", (0.2, 0.4, 0.8)), ("radau", (0.05, 0.1, 0.2))])
def test_error_estimate_against_true_local_error(name, steps):
    """One step from the exact state. Radau's estimate (of its embedded order-3 formula)
    bounds the true weighted error; DOP853's blended 5th/3rd-order estimate is built to
    behave like the error of the order-8 result (dop853.f): it tracks it within
    a small factor but is not a strict bound."""
    tol = 1e-3
    y0 = Oscillator.exact(0.0)
    for h in steps:
        it = make_integrator(name, Oscillator(), rtol=tol, atol=tol, max_step=h)
        it._h_abs = h  # skip the initial-step selection: exactly one step of h
        y1 = it.advance(0.0, y0, h)
        assert it.nsteps == 1 and it.nrejected == 0 and it.last_step == h
        scale = tol + tol * np.maximum(np.abs(y0), np.abs(y1))
        true = np.sqrt(np.mean(((y1 - Oscillator.exact(h)) / scale) ** 2))
        assert 0 < it.error_estimate <= 1.0
        if name == "radau":
            assert true <= it.error_estimate
        else:
            assert 0.1 <= true / it.error_estimate <= 2.0


@pytest.mark.parametrize("name", ADAPTIVE)
@pytest.mark.slow
def test_adaptive_on_rigid_body(name):
    """Tight tolerance on the symmetric top; project keeps |q| = 1; invariants hold."""
    body = RigidBody([1.0, 1.0, 2.5])
    y0, T = _body_state((0.6, -0.3, 2.0)), 5.0
    it = make_integrator(name, body, rtol=1e-10, atol=1e-12)
    y = it.advance(0.0, y0, T)
    assert _qerr(y, body.symmetric_top(y0, T)) < 1e-8
    assert abs(np.linalg.norm(y[:4]) - 1.0) < 1e-15
    E0, L0, Lw0 = body.invariants(y0)
    E, L, Lw = body.invariants(y)
    assert abs(E - E0) < 1e-8 and np.abs(Lw - Lw0).max() < 1e-8


# ------------------------------------------------------------------ dense output, t_eval
@pytest.mark.parametrize("name, tol, bound", [("dop853", 1e-10, 200), ("radau", 1e-7, 10)])
def test_dense_output(name, tol, bound):
    """Interpolated values are within a small multiple of the tolerance (dop853's
    interpolant is of order 7 against its order-8 steps, radau's is the collocation
    polynomial), and asking for them does not change the steps."""
    y0, T = Oscillator.exact(0.0), 10.0
    t_eval = np.linspace(0.0, T, 1001)
    y_plain = make_integrator(name, Oscillator(), rtol=tol, atol=tol).advance(0.0, y0, T)
    it = make_integrator(name, Oscillator(), rtol=tol, atol=tol)
    y1, Y = it.advance(0.0, y0, T, t_eval=t_eval)
    assert Y.shape == (1001, 3)
    np.testing.assert_array_equal(y1, y_plain)
    np.testing.assert_array_equal(Y[0], y0)
    np.testing.assert_array_equal(Y[-1], y1)
    assert it.nsteps < 300  # so most points are interpolated
    assert np.abs(Y - Oscillator.exact(t_eval)).max() < bound * tol


@pytest.mark.parametrize("name", NAMES)
def test_t_eval_consistent(name):
    y0, T = Oscillator.exact(0.0), 2.0
    t_eval = np.array([0.0, 0.25, 0.25, 1.0, 1.7, 2.0])
    it = make_integrator(name, Oscillator(), rtol=1e-10, atol=1e-10, step=0.01)
    y1, Y = it.advance(0.0, y0, T, t_eval=t_eval)
    np.testing.assert_array_equal(Y[0], y0)
    np.testing.assert_array_equal(Y[1], Y[2])
    np.testing.assert_array_equal(Y[-1], y1)
    assert np.abs(Y - Oscillator.exact(t_eval)).max() < 1e-7
    if name in FIXED:  # stepping exactly to each time: the same as stopping there
        y_mid = make_integrator(name, Oscillator(), step=0.01).advance(0.0, y0, 1.0)
        np.testing.assert_allclose(Y[3], y_mid, rtol=0, atol=1e-12)
    _, Y_empty = it.advance(0.0, y0, T, t_eval=[])
    assert Y_empty.shape == (0, 3)


# ------------------------------------------------------------------ the advance contract
@pytest.mark.parametrize("name", NAMES)
def test_advance_returns_new_array_and_keeps_y0(name):
    y0 = _body_state()
    keep = y0.copy()
    it = make_integrator(name, RigidBody([1.0, 2.0, 3.0]))
    y1 = it.advance(0.0, y0, 0.1)
    np.testing.assert_array_equal(y0, keep)
    assert y1 is not y0 and not np.shares_memory(y1, y0)
    np.testing.assert_array_equal(it.advance(0.3, y0, 0.3), y0)  # empty interval


@pytest.mark.parametrize("name", NAMES)
def test_rhs_may_return_its_workspace(name):
    """rhs returning one buffer, overwritten by each call, gives the same result bitwise."""
    body = RigidBody([1.0, 2.0, 3.0])
    y0 = _body_state()
    kw = dict(rtol=1e-8, atol=1e-10, step=0.01)
    a, A = make_integrator(name, body, **kw).advance(0.0, y0, 1.0, t_eval=[0.33, 0.5])
    b, B = make_integrator(name, Workspace(body), **kw).advance(0.0, y0, 1.0, t_eval=[0.33, 0.5])
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(A, B)


@pytest.mark.parametrize("t0, t1, step", [
    (0.0, 0.01, 1e-3), (0.1, 0.11, 1e-3), (0.2, 0.3, 0.01), (0.1, 1.1, 0.1),
    (1000.0, 1000.001, 1e-4), (0.0, 0.0105, 1e-3),
])
def test_fixed_step_count(t0, t1, step):
    it = make_integrator("rk4", Oscillator(), step=step)
    it.advance(t0, Oscillator.exact(t0), t1)
    n = math.ceil((t1 - t0) / step - 1e-6)
    assert it.nsteps == n and it.nfev == 4 * n
    assert math.isclose(it.last_step, (t1 - t0) / n)
    assert it.error_estimate is None


@pytest.mark.parametrize("name", FIXED)
def test_short_calls_equal_one_long_call_bitwise(name):
    """Dyadic times: the substeps of 64 short calls line up with those of one long call."""
    body = RigidBody([1.0, 2.0, 3.0])
    step, calls, per_call = 2.0**-8, 64, 2
    y0 = _body_state()
    y_long = make_integrator(name, body, step=step).advance(0.0, y0, calls * per_call * step)
    it = make_integrator(name, body, step=step)
    y = y0
    for k in range(calls):
        y = it.advance(k * per_call * step, y, (k + 1) * per_call * step)
    np.testing.assert_array_equal(y, y_long)
    assert it.nsteps == calls * per_call


@pytest.mark.parametrize("name", ADAPTIVE)
def test_short_calls_adaptive(name):
    """A real-time loop of 1 ms calls: close to one long call; the step-size memory is kept
    (one step per call), each call starts with one fresh rhs and wastes none at its end."""
    tol, calls, dt = 1e-10, 500, 1e-3
    y0 = Oscillator.exact(0.0)
    y_long = make_integrator(name, Oscillator(), rtol=tol, atol=tol).advance(0.0, y0, calls * dt)
    it = make_integrator(name, Oscillator(), rtol=tol, atol=tol)
    y = y0
    for k in range(calls):
        y = it.advance(k * dt, y, (k + 1) * dt)
    np.testing.assert_allclose(y, y_long, rtol=0, atol=1e-9)
    np.testing.assert_allclose(y, Oscillator.exact(calls * dt), rtol=0, atol=1e-9)
    assert it.nsteps == calls and it.nrejected == 0
    if name == "dop853":
        # per call: 1 fresh rhs + 11 stages; plus 1 for the initial step selection, once
        assert it.nfev == 12 * calls + 1
    else:
        assert it.nlu <= 4  # the step is the same every call: the LU factors are reused


@pytest.mark.parametrize("name", ADAPTIVE)
def test_step_memory_and_reset(name):
    y0 = Oscillator.exact(0.0)
    it = make_integrator(name, Oscillator(), rtol=1e-8, atol=1e-8)
    y = it.advance(0.0, y0, 1.0)
    h = it._h_abs
    assert h is not None and it.error_estimate <= 1.0 and it.last_step > 0
    it.reset()
    assert it._h_abs is None and it.error_estimate is None
    y2 = make_integrator(name, Oscillator(), rtol=1e-8, atol=1e-8).advance(0.0, y0, 1.0)
    it.advance(0.0, y0, 1.0)
    assert it._h_abs == h  # after reset, exactly as a fresh integrator
    np.testing.assert_array_equal(y, y2)


def test_last_step_not_shrunk_by_landing_on_t1():
    """A step shortened only to land on t1 does not shrink the step-size memory."""
    it = make_integrator("dop853", Oscillator(), rtol=1e-6, atol=1e-6)
    y = it.advance(0.0, Oscillator.exact(0.0), 1.0)
    h = it._h_abs
    assert h > 0.2
    y = it.advance(1.0, y, 1.0 + 1e-9)  # one tiny step
    assert it._h_abs >= h


# ------------------------------------------------------------------ the public single step
@pytest.mark.parametrize("name", ADAPTIVE)
def test_take_step_loop_is_advance(name):
    """begin / take_step / dense / end driven from outside give what `advance` gives, bit for
    bit (the "auto" method drives its inner methods this way), counters included."""
    body = RigidBody([1.0, 1.4, 2.5])
    y0, T = _body_state((0.6, -0.3, 2.0)), 3.0
    t_eval = np.linspace(0.05, 2.95, 17)
    ref = make_integrator(name, body, rtol=1e-9, atol=1e-11)
    y_ref, Y_ref = ref.advance(0.0, y0, T, t_eval=t_eval)
    it = make_integrator(name, body, rtol=1e-9, atol=1e-11)
    y, t, rows = y0.copy(), 0.0, []
    it.begin(0.0, y, T)
    while t < T:
        t_old = t
        t = it.take_step(t, y, T)
        assert t_old < t <= T and it.last_step == pytest.approx(t - t_old, rel=1e-12)
        inside = t_eval[(t_eval > t_old) & (t_eval < t)]
        if inside.size:
            rows.append(it.dense(inside))
    it.end(T, y)
    assert len(rows) > 1  # several steps interpolated
    np.testing.assert_array_equal(y, y_ref)
    np.testing.assert_array_equal(np.concatenate(rows), Y_ref)
    assert (it.nfev, it.nsteps, it.nrejected, it.njev, it.nlu) == \
        (ref.nfev, ref.nsteps, ref.nrejected, ref.njev, ref.nlu)


def test_dop853_hlamb_is_h_lambda_on_a_linear_problem():
    """dop853.f's stiffness estimate: on y' = -lam (y - cos t), f(y1) - f(Y12) = -lam (y1 - Y12)
    (Y12 is at t + h), so h |lambda| comes out as h lam; it is ready once f(y1) is known."""
    lam, rel = 50.0, 1e-6  # rel: round-off of f over |y1 - Y12| ~ the local error
    it = DOP853(StiffLinear(lam), stiffness_estimate=True, rtol=1e-6, atol=1e-9)
    y = np.array([2.0])  # off the slow solution y ~ cos t: a fast transient
    it.begin(0.0, y, 1.0)
    assert it.hlamb is None
    t = 0.0
    for _ in range(5):
        t = it.take_step(t, y, 1.0)
        assert t < 1.0 and it.hlamb == pytest.approx(lam * it.last_step, rel=rel)
    # the last step of a call: f(y1) is the next call's first rhs, if it continues from there
    t1 = t + 0.9 * it.last_step
    assert it.take_step(t, y, t1) == t1
    h_last = it.last_step
    assert it.hlamb is None
    y_end = y.copy()
    it.begin(t1, y, 1.0)
    assert it.hlamb == pytest.approx(lam * h_last, rel=rel)
    t2 = t1 + 0.9 * it.last_step
    assert it.take_step(t1, y, t2) == t2  # again a last step, but the next call starts elsewhere
    it.begin(t1, y_end, 1.0)
    assert it.hlamb is None
    plain = DOP853(StiffLinear(lam), rtol=1e-6, atol=1e-9)  # off unless asked for
    y = np.array([2.0])
    plain.begin(0.0, y, 1.0)
    plain.take_step(0.0, y, 1.0)
    assert plain.hlamb is None


# ------------------------------------------------------------------ stiffness
def test_radau_stiff_linear():
    stiff = StiffLinear(1e6)
    it = make_integrator("radau", stiff, rtol=1e-6, atol=1e-9)
    y = it.advance(0.0, stiff.exact(0.0), 1.0)
    assert it.nsteps < 30
    assert abs(y[0] - stiff.exact(1.0)[0]) < 1e-6
    assert it.njev >= 1 and it.nlu >= 2


def test_radau_few_steps_where_dop853_needs_many():
    stiff = StiffLinear(1e4)
    y0 = stiff.exact(0.0)
    steps = {}
    for name in ADAPTIVE:
        it = make_integrator(name, stiff, rtol=1e-6, atol=1e-9)
        y = it.advance(0.0, y0, 1.0)
        assert abs(y[0] - stiff.exact(1.0)[0]) < 1e-5
        steps[name] = it.nsteps
    assert steps["radau"] < 30 and steps["dop853"] > 1000


def test_radau_van_der_pol():
    """Van der Pol, mu = 1000, over most of a relaxation period, against a tight run."""
    vdp = VanDerPol(1000.0)
    y0, T = np.array([2.0, 0.0]), 1500.0
    it = make_integrator("radau", vdp, rtol=1e-6, atol=1e-6)
    y = it.advance(0.0, y0, T)
    ref = make_integrator("radau", vdp, rtol=1e-10, atol=1e-10).advance(0.0, y0, T)
    assert it.nsteps < 1000
    np.testing.assert_allclose(y, ref, rtol=1e-4, atol=1e-5)


def test_radau_jacobian_system_or_differences():
    """system.jacobian is used when present; else forward differences (n rhs calls each)."""
    class NoJac(Oscillator):
        jacobian = None

    kw = dict(rtol=1e-8, atol=1e-8)
    a = make_integrator("radau", Counting(Oscillator()), **kw)
    b = make_integrator("radau", Counting(NoJac()), **kw)
    ya = a.advance(0.0, Oscillator.exact(0.0), 5.0)
    yb = b.advance(0.0, Oscillator.exact(0.0), 5.0)
    assert a.njev >= 1 and b.njev >= 1
    assert a.system.njac == a.njev and b.system.njac == 0
    assert b.nfev == b.system.calls  # the differences are counted
    np.testing.assert_allclose(ya, yb, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ya, Oscillator.exact(5.0), rtol=0, atol=1e-7)


@pytest.mark.parametrize("name", NAMES)
def test_nfev_counts_every_rhs_call(name):
    for system in (Oscillator(), RigidBody([1.0, 2.0, 3.0])):
        it = make_integrator(name, Counting(system), rtol=1e-9, atol=1e-9, step=0.01)
        y0 = Oscillator.exact(0.0) if system.size == 3 else _body_state()
        y = it.advance(0.0, y0, 0.5)
        it.advance(0.5, y, 1.0, t_eval=[0.6, 0.77, 1.0])
        assert it.nfev == it.system.calls > 0


# ------------------------------------------------------------------ failures
@pytest.mark.parametrize("name", NAMES)
def test_nan_rhs_raises(name):
    it = make_integrator(name, NanAfter(-1.0))
    with pytest.raises(IntegrationError, match="not finite"):
        it.advance(0.0, Oscillator.exact(0.0), 1.0)


@pytest.mark.parametrize("name", NAMES)
def test_nan_later_raises_with_time_and_step(name):
    it = make_integrator(name, NanAfter(0.5), step=0.01)
    with pytest.raises(IntegrationError) as err:
        it.advance(0.0, Oscillator.exact(0.0), 1.0)
    e = err.value
    assert e.method == name and 0.4 < e.t <= 0.5 + 1e-9 and e.h is not None
    assert "t = " in str(e) and "h = " in str(e) and "non-finite" in str(e)
    if name in ADAPTIVE:
        assert "collapsed" in str(e)


@pytest.mark.parametrize("name", NAMES)
def test_nonfinite_initial_state_raises(name):
    y0 = Oscillator.exact(0.0)
    y0[1] = np.inf
    with pytest.raises(IntegrationError, match=r"components \[1\]"):
        make_integrator(name, Oscillator()).advance(0.0, y0, 1.0)


def test_min_step_constant_is_about_ulps():
    """The collapse threshold is tens of ulps of t (the brief's ~1e-14 |t|)."""
    t = 1234.5
    assert 10 * np.spacing(t) < integ.MIN_STEP_RELATIVE * t < 100 * np.spacing(t)


def test_no_starting_step_is_an_integration_error_not_a_division_by_zero():
    class Huge:
        size, quat_index = 2, NO_QUAT

        def rhs(self, t, y):
            return np.array([1e300, 1e300])  # finite, but |f| / tolerance overflows: h0 = 0

        def project(self, y):
            pass

    with np.errstate(over="ignore"):
        with pytest.raises(IntegrationError, match="no starting step"):
            integ.make_integrator("radau", Huge()).advance(0.0, np.array([1.0, 1.0]), 1.0)
