"""Radau's compiled advance (gyro_sim.integrators.radau.loop) and its Python driver (both on the
arithmetic of gyro_sim.integrators.radau.kernels) against independent references: scipy's
`scipy.integrate.Radau` on the same right-hand side and tolerances, scipy's LAPACK LU, and
each other.

How close to scipy, and why:

- The Jacobian: scipy's own (num_jac) chooses its difference increments adaptively, with a
  memory of its own; the error estimate (MU_REAL/h I - J)^-1 (f + E Z / h) depends on J, so a
  different approximation gives another (equally valid) step sequence. scipy is given here a
  forward-difference Jacobian written below (increments sqrt(eps) max(|y_j|, 1), as
  represented: Numerical Recipes' `temp - x`), the textbook one Radau forms.
- The controller's memory: Gustafsson's predictive controller (HW II, eq. 8.25) divides by
  the previous accepted step (radau5.f: HACC = H after an accepted step); scipy remembers
  the size that step was first tried with (`self.h_abs_old = self.h_abs`), which differs from
  the accepted one after a rejection. scipy's `h_abs_old` is set to its last accepted step
  after each of its steps (nothing else of scipy's state is touched): without it the two
  sequences part at the step after the first rejection.
- The end: the step before t1 is stretched by up to 1 % (dop853.f) and factored afresh
  for its size; scipy neither (it reuses the LU of the previous size): the last step costs
  scipy more Newton iterations, and is otherwise the same.
- The arithmetic: the LU factors are LAPACK's getrf, scipy's bit for bit; scipy's sums and
  triangular solves are BLAS (their order and fused multiply-adds are the library's), the
  kernels add one product at a time. A Newton solve from the same start: the same
  iterations, Z to round-off. The error norm is a cancelling sum (~rtol of |Z|), so its
  relative round-off is ~1e-16 / rtol, and h_new ~ err^(-1/4) takes a quarter of it each
  step: the accepted step sequence is scipy's (as many steps, accepted and rejected, as many
  LU factorisations) with times equal to STEP_TIME_RTOL, and the states at the end (both at
  t1) to round-off as the error control amplifies it.

Reached here (scipy 1.17, OpenBLAS): on a hinge pendulum at rtol 1e-6, 508 steps (27
rejected), step times within 4.5e-9 relative, the final state within 6e-13 of max |y|; at
rtol 1e-9, 2870 steps, times within 2.8e-7 (the drift of err^(-1/4) over the run), state
within 2e-12; a stiff variant (tip 1e6 x the links) at rtol 1e-8: 443 steps, 3.5e-8, 5e-15.

The compiled loop and the Python driver run the same kernels between the same rhs
evaluations: identical bits, counters included (and so are two runs of either).
"""
import glob
import math
import os

import numpy as np
import pytest

from gyro_sim.dynamics import kernel as fast
from gyro_sim import jit
from gyro_sim.integrators.radau import loop as fast_radau
from gyro_sim.integrators.radau import kernels as rk
from gyro_sim.integrators import IntegrationError
from gyro_sim.integrators.radau import driver as R
from gyro_sim.integrators.radau.driver import Radau
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import Simulator
from test.integrators.package_paths import in_package

from test.dynamics.chains import random_chain
from test.integrators.test_dop853 import held_system, hinge_pendulum

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

EPS = np.finfo(float).eps
#: accepted step times against scipy's (the error norm's cancellation, see the docstring)
STEP_TIME_RTOL = 1e-6
#: the state at t1 against scipy's, relative to max |y|
STATE_RTOL = 1e-10
#: a Newton solve from the same start against scipy's, relative to max |Z|
NEWTON_RTOL = 1e-12
#: the shipped scenes run in every session (the others are marked slow)
FAST_SCENES = ("hinge_chain", "stiff_fast_rotor", "free_chain_rotors")
SCENES = sorted(os.path.basename(p)[:-5] for p in glob.glob(
    os.path.join(os.path.dirname(__file__), "..", "..", "config", "*.yaml")) if not p.endswith("params.yaml"))


def stiff_hinges(ratio=1e6) -> dict:
    """hinge_pendulum with its tip `ratio` times as heavy as its two links (mass and
    inertia): a fast elbow mode, stiff; no quaternion in the state."""
    sd = hinge_pendulum()
    for b in sd["bodies"][:2]:
        b["mass"] /= math.sqrt(ratio)
    tip = sd["bodies"][2]
    tip["mass"] *= math.sqrt(ratio)
    tip["inertia_com"] = (np.array(tip["inertia_com"]) * math.sqrt(ratio)).tolist()
    return sd


def forward_difference_jacobian(fun):
    """J[:, j] = (f(y + d_j e_j) - f(y)) / d_j, d_j = sqrt(eps) max(|y_j|, 1) as represented
    (the textbook forward difference; Numerical Recipes, 3rd ed., sec. 5.7)."""
    def jac(t, y):
        f = fun(t, y)
        J = np.empty((y.size, y.size))
        for j in range(y.size):
            yj = y.copy()
            yj[j] = y[j] + math.sqrt(EPS) * max(abs(y[j]), 1.0)
            J[:, j] = (fun(t, yj) - f) / (yj[j] - y[j])
        return J
    return jac


def python_driver(system, **options) -> Radau:
    """Radau stepping in Python on a system that has the compiled loop."""
    integ = Radau(system, **options)
    integ._loop = None  # the Python driver on the same system
    return integ


def counters(integ):
    return (integ.nfev, integ.nsteps, integ.nrejected, integ.njev, integ.nlu, integ.error_estimate,
            integ.last_step, integ._h_abs)


def scipy_run(system, y0, t0, t1, rtol, atol, first_step):
    """scipy's Radau stepped to t1 with the forward-difference Jacobian and radau5.f's
    controller memory (see the module docstring): the solver, accepted times and states."""
    si = pytest.importorskip("scipy.integrate")
    ref = si.Radau(system.rhs, t0, y0, t1, rtol=rtol, atol=atol, first_step=first_step,
                   jac=forward_difference_jacobian(system.rhs))
    ts, ys = [], []
    while ref.status == "running":
        assert ref.step() is None
        ref.h_abs_old = ref.t - ref.t_old  # the accepted step (radau5.f's HACC)
        ts.append(ref.t)
        ys.append(ref.y.copy())
    assert ref.status == "finished"
    return ref, np.array(ts), np.array(ys)


# ------------------------------------------------------------------ against scipy
@pytest.mark.parametrize("scene, rtol, t1", [(hinge_pendulum(), 1e-6, 3.1), (stiff_hinges(), 1e-8, 1.1)],
                         ids=["pendulum", "stiff"])
@pytest.mark.parametrize("compiled", (False, True))
@pytest.mark.slow
def test_accepted_steps_are_scipys(scene, rtol, t1, compiled):
    """From the same first step: scipy's steps (as many accepted, as many rejected, as many LU
    factorisations), at times equal to STEP_TIME_RTOL, the state at t1 equal to round-off."""
    atol, t0 = rtol * 1e-2, 0.1
    system, y0 = held_system(scene)
    assert system.quaternion_block()[1] == 0  # nothing projected: scipy's problem exactly
    integ = Radau(system, rtol=rtol, atol=atol) if compiled else python_driver(system, rtol=rtol, atol=atol)
    integ.begin(t0, y0.copy(), t1)  # the first step, here, to hand to scipy
    h0 = integ._h_abs
    integ.reset()
    ref, ts_ref, ys_ref = scipy_run(system, y0, t0, t1, rtol, atol, h0)
    if compiled:
        integ._trace = np.zeros(len(ts_ref) + 5)  # the ends of the steps
        y1 = integ.advance(t0, y0, t1)
        ts = integ._trace[:integ._flags[fast_radau.F_TRACED]]
    else:
        y1, ts, t = y0.copy(), [], t0
        integ.begin(t0, y1, t1)
        while t < t1:
            t = integ.take_step(t, y1, t1)
            ts.append(t)
        integ.end(t1, y1)
        ts = np.array(ts)
    assert integ.nsteps == len(ts) == len(ts_ref) > 100 and integ.nrejected > 5
    assert integ.nlu == ref.nlu  # the same steps factored: the same sizes tried
    np.testing.assert_allclose(ts, ts_ref, rtol=STEP_TIME_RTOL, atol=0)
    assert ts[-1] == ts_ref[-1] == t1
    assert np.abs(y1 - ys_ref[-1]).max() <= STATE_RTOL * np.abs(ys_ref).max()


def test_newton_solve_is_scipys():
    """One simplified Newton solve of the collocation system from Z0 = 0 (the kernels through
    the Python driver) against scipy's solve_collocation_system with LAPACK's LU of the same
    matrices: the same iterations, convergence and rate; Z to round-off."""
    ra = pytest.importorskip("scipy.integrate._ivp.radau")
    sl = pytest.importorskip("scipy.linalg")
    system, y = held_system(stiff_hinges(), seed=2)
    rtol, atol, t, h = 1e-8, 1e-10, 0.1, 0.004
    integ = python_driver(system, rtol=rtol, atol=atol)
    f = system.rhs(t, y)
    integ._jacobian(t, y, f)
    integ._factor(h)
    scale = atol + np.abs(y) * rtol
    integ._Z0[:] = 0.0
    converged, n_iter, rate = integ._newton(t, y, h, scale)
    J = integ.jacobian
    I = np.identity(y.size)
    LU_real = sl.lu_factor(ra.MU_REAL / h * I - J)
    LU_complex = sl.lu_factor(ra.MU_COMPLEX / h * I - J)
    ok, k, Z, rate_ref = ra.solve_collocation_system(
        system.rhs, t, y, h, np.zeros((3, y.size)), scale, integ._newton_tol,
        LU_real, LU_complex, sl.lu_solve)
    assert (converged, n_iter) == (ok, k) and converged and n_iter >= 2
    assert rate == pytest.approx(rate_ref, rel=1e-6)
    assert np.abs(integ._Z - Z).max() <= NEWTON_RTOL * np.abs(Z).max()


def _radau_matrices(n=23, h=0.01, seed=7):
    """J (n, n) with badly scaled columns and the two matrices Radau factors."""
    J = np.random.default_rng(seed).normal(size=(n, n)) * np.geomspace(1e-3, 1e3, n)
    return J, h, Radau.MU_REAL / h * np.eye(n) - J, Radau.MU_COMPLEX / h * np.eye(n) - J


def test_lu_is_lapacks():
    """rad_factor's LU of the matrices Radau factors is LAPACK's getrf (scipy.linalg.lu_factor)
    bit for bit (the same routine, column-major); the solves agree with getrs to round-off;
    real and complex."""
    sl = pytest.importorskip("scipy.linalg")
    if not rk.LAPACK_GETRF:
        pytest.skip("numba offers no LAPACK here: the textbook LU (test_textbook_lu_agrees_with_lapack)")
    J, h, M_real, M_complex = _radau_matrices()
    n = J.shape[0]
    LU_real, LU_complex = np.empty((n, n)), np.empty((n, n), dtype=complex)
    piv_real, piv_complex = np.empty(n, dtype=np.int32), np.empty(n, dtype=np.int32)
    assert rk.rad_factor(J, h, Radau.MU_REAL, Radau.MU_COMPLEX, LU_real, piv_real, LU_complex,
                         piv_complex) == 0
    rng = np.random.default_rng(8)
    for M, LU, piv in ((M_real, LU_real, piv_real), (M_complex, LU_complex, piv_complex)):
        lu_ref, piv_ref = sl.lu_factor(M)
        np.testing.assert_array_equal(LU.T, lu_ref)
        np.testing.assert_array_equal(piv - 1, piv_ref)
        b = rng.normal(size=n) + (1j * rng.normal(size=n) if M.dtype.kind == "c" else 0)
        x = b.copy()
        rk.rad_lu_solve(LU, piv, x)
        x_ref = sl.lu_solve((lu_ref, piv_ref), b)
        assert np.abs(x - x_ref).max() <= 1e-12 * np.abs(x_ref).max()


@pytest.mark.slow
def test_textbook_lu_agrees_with_lapack():
    """The fallback LU (rad_lu, where numba offers no LAPACK): LAPACK's pivots, factors and
    solutions to round-off."""
    sl = pytest.importorskip("scipy.linalg")
    for M in _radau_matrices()[2:]:
        At, piv = np.ascontiguousarray(M.T), np.empty(M.shape[0], dtype=np.int32)
        assert rk.rad_lu(At, piv) == 0
        lu_ref, piv_ref = sl.lu_factor(M)
        np.testing.assert_array_equal(piv - 1, piv_ref)
        assert np.abs(At.T - lu_ref).max() <= 1e-13 * np.abs(lu_ref).max()


@pytest.mark.parametrize("lu", ("rad_factor", "rad_lu"))
def test_singular_matrix_gives_non_finite_solutions(lu):
    """An exactly singular matrix: info > 0 (LAPACK's convention), and the solve is not
    finite, which the Newton iteration turns into a failure."""
    J = np.array([[1.0, 2.0], [2.0, 4.0]])
    piv = np.zeros(2, dtype=np.int32)
    if lu == "rad_lu":
        A = np.ascontiguousarray(J.T)
        assert rk.rad_lu(A, piv) == 2
    else:  # MU_REAL / h = 1 and the complex part 0 for a real mu: J - J = 0, singular
        A, Ac, pc = np.empty((2, 2)), np.empty((2, 2), dtype=complex), np.zeros(2, dtype=np.int32)
        assert rk.rad_factor(-J, 1.0, 0.0, 0j, A, piv, Ac, pc) > 0
    b = np.array([1.0, 1.0])
    rk.rad_lu_solve(A, piv, b)
    assert not np.isfinite(b).all()


def test_controller_is_scipys_predict_factor():
    """Gustafsson's factor bit for bit as scipy's predict_factor (the same operations)."""
    ra = pytest.importorskip("scipy.integrate._ivp.radau")
    rng = np.random.default_rng(3)
    for _ in range(50):
        h, h_old = rng.uniform(1e-4, 1e-2, 2)
        err, err_old = 10.0 ** rng.uniform(-4, 1, 2)
        assert rk.rad_predict_factor(h, h_old, err, err_old) == ra.predict_factor(h, h_old, err, err_old)
        assert rk.rad_predict_factor(h, math.nan, err, math.nan) == ra.predict_factor(h, None, err, None)
    with np.errstate(divide="ignore"):
        zero = np.float64(0.0)  # err = 0: an infinite factor (scipy: numpy's division by zero)
        assert rk.rad_predict_factor(1e-3, 2e-3, 0.0, 0.5) == ra.predict_factor(1e-3, 2e-3, zero, 0.5) == math.inf


def test_dense_output_is_scipys():
    """The collocation polynomial from the same Z: scipy's RadauDenseOutput to round-off."""
    ra = pytest.importorskip("scipy.integrate._ivp.radau")
    rng = np.random.default_rng(4)
    Z, y_old = rng.normal(size=(3, 9)), rng.normal(size=9)
    t_old, t_new = 0.37, 0.37 + 0.0123
    tq = np.sort(rng.uniform(t_old, t_new, 13))
    Qt, Y = np.empty((3, 9)), np.empty((13, 9))
    rk.rad_dense_coefficients(Z, Radau.P, Qt)
    rk.rad_dense_eval(Qt, y_old, t_old, t_new - t_old, tq, Y)
    ref = ra.RadauDenseOutput(t_old, t_new, y_old, Z.T.dot(ra.P))(tq).T
    terms = (np.abs(Qt).sum(axis=0) + np.abs(y_old)).max()  # the size of what is summed
    np.testing.assert_allclose(Y, ref, rtol=0, atol=4 * EPS * terms)
    sums = np.abs(Z).sum(axis=0).max() * np.abs(ra.P).max()
    np.testing.assert_allclose(Qt.T, Z.T.dot(ra.P), rtol=0, atol=4 * EPS * sums)


def test_method_constants_are_scipys():
    ra = pytest.importorskip("scipy.integrate._ivp.radau")
    for ours, theirs in ((Radau.T, ra.T), (Radau.TI, ra.TI), (Radau.C, ra.C), (Radau.E, ra.E), (Radau.P, ra.P)):
        np.testing.assert_allclose(ours, theirs, rtol=1e-15, atol=1e-15)
    assert Radau.MU_REAL == pytest.approx(ra.MU_REAL, rel=1e-15)
    assert Radau.MU_COMPLEX == pytest.approx(ra.MU_COMPLEX, rel=1e-15)
    from gyro_sim.integrators import base

    assert Radau.CONTROL.tolist() == [base.SAFETY, base.MIN_FACTOR, base.MAX_FACTOR, R.NEWTON_MAXITER,
                                      R.RADAU_SLOW_ITER, R.RADAU_SLOW_RATE, R.RADAU_KEEP_STEP,
                                      R.RADAU_NEWTON_FAIL_FACTOR, R.LU_REUSE_RTOL, base.MIN_STEP_RELATIVE,
                                      base.LAST_STEP_STRETCH]
    assert fast_radau.ORDER_OF_ESTIMATOR == Radau.error_estimator_order
    assert (fast_radau.NONFINITE_STAGES, fast_radau.NONFINITE_STATE, fast_radau.NONFINITE_ERROR) == (
        R.NONFINITE_STAGES, R.NONFINITE_STATE, R.NONFINITE_ERROR)


# ------------------------------------------------------------------ compiled == Python driver
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_advance_is_the_python_driver_bit_for_bit(seed, base):
    """10 ms calls with output times: the same bits, counters and memory (a scalar atol with a
    fixed base, one per component with a free one); a perturbed state between calls (no
    continuation: no predictor, the Jacobian old) and new held inputs."""
    system, y0 = held_system(random_chain(seed, base=base), seed)
    kw = dict(rtol=1e-7, atol=1e-9 if base == "fixed" else np.geomspace(1e-10, 1e-8, system.size))
    compiled, python = Radau(system, **kw), python_driver(system, **kw)
    assert compiled._loop is not None
    ya, yb = y0.copy(), y0.copy()
    for k in range(6):
        t0, t1 = 0.1 + 0.01 * k, 0.1 + 0.01 * (k + 1)
        if k == 3:
            ya[system.model.i_vel] += 1e-3
            yb[system.model.i_vel] += 1e-3
        te = np.linspace(t0, t1, 4)[1:] if k % 2 else None
        ra, rb = compiled.advance(t0, ya, t1, t_eval=te), python.advance(t0, yb, t1, t_eval=te)
        if te is not None:
            (ya, Ya), (yb, Yb) = ra, rb
            np.testing.assert_array_equal(Ya, Yb)
        else:
            ya, yb = ra, rb
        np.testing.assert_array_equal(ya, yb)
        assert counters(compiled) == counters(python)
        np.testing.assert_array_equal(compiled.jacobian, python.jacobian)
    assert not np.array_equal(ya, y0) and compiled.nsteps > 6


def _scene_runs(scene):
    states = []
    for compiled in (True, False):
        sim = Simulator(load_scene(scene), integrator="radau", rtol=1e-8, atol=1e-10, backend="numba")
        if not compiled:
            sim.integrator._loop = None
        for _ in range(50):
            sim.advance(0.01)
        states.append((sim.state.copy(), counters(sim.integrator)))
    np.testing.assert_array_equal(states[0][0], states[1][0])
    assert states[0][1] == states[1][1]


@pytest.mark.parametrize("scene", FAST_SCENES)
def test_scenes_compiled_equal_python_driver(scene):
    """Shipped scenes, 0.5 s in 10 ms calls of Simulator.advance: the same state, bit for bit
    (quaternions projected after every step, held inputs, moving bases, rotors)."""
    _scene_runs(scene)


@pytest.mark.slow
@pytest.mark.parametrize("scene", [s for s in SCENES if s not in FAST_SCENES])
def test_every_other_scene_compiled_equals_python_driver(scene):
    _scene_runs(scene)


def test_outputs_and_quaternions():
    """Outputs inside steps from the collocation polynomial, projected (unit quaternions) as the
    Python driver's; two runs identical, fresh and after a reset (logs are re-simulated)."""
    system, y0 = held_system("chain_4", seed=3)
    te = np.linspace(0.1, 0.4, 31)[::3]  # not contiguous
    runs = []
    for _ in range(2):
        integ = Radau(system, rtol=1e-8, atol=1e-10)
        runs.append(integ.advance(0.1, y0, 0.4, t_eval=te))
        integ.reset()
        runs.append(integ.advance(0.1, y0, 0.4, t_eval=te))
    runs.append(python_driver(system, rtol=1e-8, atol=1e-10).advance(0.1, y0, 0.4, t_eval=te))
    for y, Y in runs[1:]:
        np.testing.assert_array_equal(y, runs[0][0])
        np.testing.assert_array_equal(Y, runs[0][1])
    assert np.abs(np.linalg.norm(runs[0][1][:, system.model.i_quat], axis=-1) - 1).max() < 1e-15


def test_single_steps_after_compiled_calls_continue_the_same():
    """The public single step (what "auto" drives) after compiled calls picks up the memory the
    loop left (step sizes, Jacobian, LU, the collocation polynomial): the same as the Python
    driver all along."""
    system, y0 = held_system("heavy_top", seed=4)
    a, b = Radau(system, rtol=1e-8, atol=1e-10), python_driver(system, rtol=1e-8, atol=1e-10)
    ya, yb = a.advance(0.1, y0, 0.15), b.advance(0.1, y0, 0.15)
    for integ, y in ((a, ya), (b, yb)):
        integ.begin(0.15, y, 0.2)
        t = 0.15
        while t < 0.2:
            t = integ.take_step(t, y, 0.2)
        integ.end(0.2, y)
    np.testing.assert_array_equal(ya, yb)
    assert counters(a) == counters(b)


# ------------------------------------------------------------------ failures
def _failure(integ, y0, t1, h=None):
    integ._h_abs = h
    with pytest.raises(IntegrationError) as info:
        integ.advance(0.1, y0, t1)
    return str(info.value), info.value.t, info.value.h, counters(integ)


@pytest.mark.parametrize("scene, speed", [("chain_4", 1e150), ("heavy_top", 1e30)])
def test_collapse_reports_as_in_python(scene, speed):
    """A state whose stages overflow: the step keeps failing until its size collapses; the same
    error (message naming what was not finite, time, step) and counters from both drivers."""
    system, y0 = held_system(scene)
    y0[system.model.i_vel.start] = speed
    got = _failure(Radau(system, rtol=1e-6, atol=1e-8), y0, 0.2, h=1e-3)
    assert got == _failure(python_driver(system, rtol=1e-6, atol=1e-8), y0, 0.2, h=1e-3)
    assert "step size collapsed" in got[0]


def test_non_finite_initial_rhs_fails_as_in_python():
    system, y0 = held_system("chain_4")
    y0[system.model.i_vel.start] = 1e200
    got = _failure(Radau(system), y0, 0.2)
    assert got == _failure(python_driver(system), y0, 0.2)
    assert "rhs is not finite at the initial state" in got[0]


# ------------------------------------------------------------------ the loop's cache


def test_loop_cache_is_keyed_on_every_file_it_compiles_in():
    names = {in_package(p) for p in fast_radau.DEPENDENCIES}
    assert names == {"dynamics/kernel.py", "dynamics/actuators.py", "integrators/radau/kernels.py",
                     "integrators/dop853/kernels.py",
                     "integrators/adaptive_kernels.py",
                     "integrators/radau/loop.py"}
    assert jit.cache_directory(fast_radau.DEPENDENCIES).name.startswith("fast_loop-")


def test_one_compiled_loop_per_process_and_argument_types():
    a, _ = held_system("chain_4")
    b, _ = held_system("heavy_top", seed=1)
    loop = Radau(a)._loop
    assert Radau(b)._loop is loop and fast_radau.loop_for(b.kernel_arguments()) is loop


def test_matrix_free_and_system_jacobian_step_in_python(monkeypatch):
    system, _ = held_system("chain_4")
    monkeypatch.setattr(R, "DENSE_MAX", -1)
    assert Radau(system)._loop is None


def test_warm_up_compiles_and_forgets():
    """warm_up: the compiled loop (or, loop=False, the single step) runs once, then the memory
    is reset and the counters are as before; a run after it is the run of a fresh integrator."""
    system, y0 = held_system("heavy_top", seed=5)
    warm, fresh = Radau(system, rtol=1e-8, atol=1e-10), Radau(system, rtol=1e-8, atol=1e-10)
    warm.warm_up(0.1, y0)
    assert warm._loop.entry is not None  # compiled (or loaded): straight to it
    assert (warm.nfev, warm.nsteps, warm.njev, warm.nlu, warm._h_abs) == (0, 0, 0, 0, None)
    np.testing.assert_array_equal(warm.advance(0.1, y0, 0.2), fresh.advance(0.1, y0, 0.2))
    assert counters(warm) == counters(fresh)
    single = Radau(system, rtol=1e-8, atol=1e-10)
    single.warm_up(0.1, y0, loop=False)  # what "auto" needs: the single step only
    assert single.nfev == 0 and single._h_abs is None


def test_a_recorded_radau_run_resimulates_bit_for_bit(tmp_path):
    """A log recorded with radau (compiled) and commands, re-simulated: deviation 0."""
    pytest.importorskip("mcap")
    from gyro_sim.log.record import record_run
    from gyro_sim.log.resim import resimulate

    sim = Simulator(load_scene("hinge_chain"), integrator="radau", backend="numba")
    schedule = [(0.0, [0.001, 0.0, 0.0]), (0.05, [0.0, 0.02, -0.01])]
    rec = record_run(sim, tmp_path / "run.mcap", duration=0.1, chunk=0.005, publish_rate=100.0,
                     schedule=schedule)
    res = resimulate(tmp_path / "run.mcap")
    assert res.compared == rec.publications > 5 and res.max_deviation == 0.0, res.report()


@pytest.mark.slow
def test_python_driver_on_the_numpy_reference_agrees():
    """The Python driver on the numpy reference (ChainODE: another implementation of the rhs,
    equal to round-off) and the compiled loop: the same steps, the state after 0.3 s equal to
    round-off as the error control amplifies it."""
    runs = []
    for backend in ("numba", "numpy"):
        sim = Simulator(load_scene("hinge_chain"), integrator="radau", rtol=1e-8, atol=1e-10, backend=backend)
        assert (sim.integrator._loop is not None) == (backend == "numba")
        for _ in range(30):
            sim.advance(0.01)
        runs.append((sim.state.copy(), sim.integrator.nsteps, sim.integrator.nrejected, sim.integrator.njev))
    (a, *ca), (b, *cb) = runs
    assert ca == cb
    assert np.abs(a - b).max() <= 1e-10 * np.abs(a).max()


# ------------------------------------------------------------------ the detection mode ("auto")
def _detection(n, nonstiff_hrho, needed, margin=math.inf):
    """The detection arrays of radau_advance (as Auto builds them): counters, window, cost
    (dop853_kernels), handback, easy (radau_kernels), power."""
    from gyro_sim.integrators.dop853 import kernels as dk

    handback = np.array([nonstiff_hrho, margin, 12.0, 5.95, 200.0, 30.0])
    easy = np.array([math.nan, 1.0, 0.0, needed])
    return (np.zeros(dk.COUNTERS_SIZE, dtype=np.int64), np.zeros((20, 2)), np.full(dk.COST_SIZE, math.nan),
            handback, easy, np.zeros(0))


def test_detection_mode_that_never_fires_is_the_plain_loop():
    """The tests of "auto" run after every step (h rho < 0 never holds, the cost margin is
    infinite): the same steps and bits as the plain loop; rho is the final Jacobian's
    (against numpy's eigenvalues); the cost window full, radau's cost measured."""
    from gyro_sim.integrators.dop853 import kernels as dk

    system, y0 = held_system(stiff_hinges())
    plain, detecting = (Radau(system, rtol=1e-8, atol=1e-10) for _ in range(2))
    det = _detection(y0.size, 0.0, 3.0)
    y_plain, y_det = y0.copy(), y0.copy()
    for k in range(5):
        t0, t1 = 0.1 + 0.1 * k, 0.2 + 0.1 * k
        y_plain = plain.advance(t0, y_plain, t1)
        assert detecting.advance_detecting(t0, y_det, t1, None, None, det) == (t1, 0)
    np.testing.assert_array_equal(y_plain, y_det)
    assert counters(plain) == counters(detecting)
    counts, window, cost, _, easy, _ = det
    rho = np.max(np.abs(np.linalg.eigvals(detecting.jacobian)))
    assert easy[rk.EASY_RHO] == pytest.approx(rho, rel=1e-10) and easy[rk.EASY_STALE] == 0.0
    assert easy[rk.EASY_STEPS] == 0.0
    assert counts[dk.C_WINDOW] == window.shape[0] and cost[dk.COST_RADAU] > 0.0


def test_detection_mode_stops_at_the_accepted_state():
    """h rho < inf holds for every step: the 3rd accepted step asks for the hand-back, the
    call ends there (SWITCH, REASON_NONSTIFF) with the state and counters of a plain call to
    that time (but one rhs evaluation: at the new state, for a next step, as the Python loop
    of "auto" evaluates it); the next plain call continues from it as from the end of a call."""
    system, y0 = held_system(stiff_hinges())
    stopped, plain = (Radau(system, rtol=1e-8, atol=1e-10) for _ in range(2))
    stopped._trace = np.zeros(10)  # the ends of the steps
    y_s = y0.copy()
    t, code = stopped.advance_detecting(0.1, y_s, 1.0, None, None, _detection(y0.size, math.inf, 3.0))
    assert code == fast_radau.REASON_NONSTIFF and stopped.nsteps == 3
    assert t == stopped._trace[2] < 1.0
    y_p = plain.advance(0.1, y0, t)
    np.testing.assert_array_equal(y_s, y_p)
    assert counters(stopped)[1:] == counters(plain)[1:] and stopped.nfev == plain.nfev + 1
    np.testing.assert_array_equal(stopped.advance(t, y_s, 1.0), plain.advance(t, y_p, 1.0))
    assert counters(stopped)[1:] == counters(plain)[1:] and stopped.nfev == plain.nfev + 1
