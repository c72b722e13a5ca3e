"""Radau IIA with 3 stages (radau): order 5, implicit, L-stable, for stiff systems."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.adaptive_kernels import clip_step, rms_scaled
from gyro_sim.integrators.radau import loop as fast_radau
from gyro_sim.integrators.dop853.kernels import dop_initial_probe, dop_initial_step
from gyro_sim.integrators.radau.kernels import (
    CONTROL_SIZE, NEWTON_CONVERGED, NEWTON_DIVERGING, rad_add, rad_control_accepted,
    rad_control_rejected, rad_dense_coefficients, rad_dense_eval, rad_dw_norm, rad_error,
    rad_error_rhs, rad_factor, rad_fd_column, rad_fd_delta, rad_finite, rad_finite_rows,
    rad_newton_advance, rad_newton_increment, rad_newton_residual, rad_predict,
    rad_scale, rad_stage_state, rad_transform,
)
from gyro_sim.integrators.base import (
    H0_DEFAULT, H0_FRACTION, H0_GROWTH, H0_NEGLIGIBLE, H0_TINY_DERIVATIVES, H0_TINY_FRACTION,
    H0_TINY_STEP, EPS, LAST_STEP_STRETCH, MAX_FACTOR, MIN_FACTOR, MIN_STEP_RELATIVE, SAFETY,
    AdaptiveIntegrator, IntegrationError, WholeAdvanceLoop, describe_nonfinite,
)

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

# --- Radau IIA (Hairer, Wanner II, sec. IV.8; scipy radau.py) --------------------------------
#: maximum number of simplified Newton iterations per step
NEWTON_MAXITER = 6
#: a Newton iteration that took more iterations than this, and converged more slowly than
#: RADAU_SLOW_RATE, asks for a new Jacobian
RADAU_SLOW_ITER = 2
RADAU_SLOW_RATE = 1e-3
#: after an accepted step, factors below this keep the step and its LU factors (as scipy;
#: radau5.f keeps it for factors in [QUOT1, QUOT2] = [1, 1.2])
RADAU_KEEP_STEP = 1.2
#: the step is halved after a Newton failure
RADAU_NEWTON_FAIL_FACTOR = 0.5
#: LU factors are reused if the step differs from theirs by less than this (relative)
LU_REUSE_RTOL = 1e-6
#: forward-difference Jacobian: step sqrt(eps) * max(|y_j|, FD_MIN_SCALE)
FD_REL_STEP = math.sqrt(EPS)
FD_MIN_SCALE = 1.0
#: above this size the Jacobian is never formed: the linear systems are solved by GMRES on
#: Jacobian-vector products (forward differences of the rhs at the Jacobian's point), O(n)
#: memory; at or below it, the dense Jacobian and LU (faster for small systems)
DENSE_MAX = 2000
#: `warm_up` advances this far (s, relative to max(1, |t0|)): a step or two, to compile
WARM_UP_SPAN = 1e-6
#: GMRES (matrix-free mode): relative residual, restart length, restarts
KRYLOV_RTOL = 1e-8
KRYLOV_RESTART = 30
KRYLOV_RESTARTS = 4


# --- Radau IIA coefficients (scipy radau.py; Hairer, Wanner II, sec. IV.8) -----------------
_S6 = math.sqrt(6.0)
#: A is not used by the iteration (it works in the eigenbasis of A^-1); kept as data.
_RADAU_A = np.array([
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
])
_RADAU_C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1.0])
_RADAU_E = np.array([-13 - 7 * _S6, -13 + 7 * _S6, -1.0]) / 3
# eigenvalues of A^-1: one real, a complex pair; A^-1 = T diag(MU_REAL, block(MU_COMPLEX)) TI
_MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
_MU_COMPLEX = 3 + 0.5 * (3 ** (1 / 3) - 3 ** (2 / 3)) - 0.5j * (3 ** (5 / 6) + 3 ** (7 / 6))
_RADAU_T = np.array([
    [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
    [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
    [1.0, 1.0, 0.0],
])
_RADAU_TI = np.array([
    [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
    [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
    [0.50287263494578682, -2.57192694985560522, 0.59603920482822492],
])
# dense output: y(t_old + x h) = y_old + Z^T P (x, x^2, x^3)
_RADAU_P = np.array([
    [13 / 3 + 7 * _S6 / 3, -23 / 3 - 22 * _S6 / 3, 10 / 3 + 5 * _S6],
    [13 / 3 - 7 * _S6 / 3, -23 / 3 + 22 * _S6 / 3, 10 / 3 - 5 * _S6],
    [1 / 3, -8 / 3, 10 / 3],
])


#: what a non-finite trial left for the collapse message (the compiled loop's codes too)
NONFINITE_NONE, NONFINITE_STAGES, NONFINITE_STATE, NONFINITE_ERROR = range(4)


class Radau(WholeAdvanceLoop, AdaptiveIntegrator):
    """Implicit Runge-Kutta method Radau IIA, 3 stages, order 5, for stiff systems.

    The algorithm of Hairer and Wanner's radau5 as ported in scipy's Radau [3]: the
    collocation system is solved by a simplified Newton iteration in the eigenbasis of A^-1,
    which splits it into one real and one complex linear system of size n (LU-factored once
    per step size and Jacobian); the error is estimated with an embedded formula of order 3
    filtered through the real LU (again with rhs(t, y + err) after a rejection); step control
    is Gustafsson's predictive controller. The Jacobian is `system.jacobian` if the system
    has one, else forward differences (n rhs evaluations, counted in nfev); it is reused
    across steps and recomputed only when Newton converged slowly (more than
    RADAU_SLOW_ITER iterations at a rate above RADAU_SLOW_RATE) or failed with an old one.

    One implementation, two drivers: the arithmetic (the forward-difference Jacobian, the two
    LU factorisations and their solves, the Newton residual and increment and its rate tests,
    the error estimate, the controller, the dense output) is :mod:`gyro_sim.integrators.radau.kernels`.
    On a system that offers `kernel_arguments` and `quaternion_block` (the compiled
    :class:`gyro_sim.dynamics.system.FastChainODE`) and no `jacobian`, in the dense mode, a whole
    `advance` runs in one compiled call, :func:`gyro_sim.integrators.radau.loop.radau_advance`
    (compiled, or loaded from numba's cache, by the first `advance`, by `warm_up` or by
    `load_loop`: ~20 s of CPU once per version of its files, then ~0.1 s), in the "auto"
    method's radau phase too (`advance_detecting`, its tests inside the loop); on any other
    system, in the matrix-free mode, and for the public single step (`begin` / `take_step` /
    `dense`, which "auto" drives where there is no compiled loop) this class steps in Python, calling the same
    arithmetic between its rhs evaluations. The two give the same bits, counters included;
    against scipy's Radau on the same rhs, Jacobian and tolerances they take the same steps
    (test/integrators/test_radau.py). The LU is the kernels' own (partial pivoting, as
    LAPACK's getrf): the same bits in and out of compiled code.

    The controller divides by the last accepted step (radau5.f's HACC); scipy's Radau keeps
    the size that step was first tried with (`h_abs_old = h_abs`), which differs after a
    rejection: the only difference of the step sequences besides round-off and the last step
    before t1 (stretched by up to LAST_STEP_STRETCH here, and factored for its own size).

    Above DENSE_MAX states (a chain of some 300 bodies) nothing of size n^2 is formed: the
    "Jacobian" is its point (t, y, rhs(t, y)), kept and renewed by the same rules, and the two
    linear systems are solved by restarted GMRES (scipy.sparse.linalg.gmres) on products
    J v = (rhs(t, y + e v) - rhs(t, y)) / e, one rhs evaluation a product (two for the complex
    system), to KRYLOV_RTOL: an inexact simplified Newton (Kelley, "Iterative Methods for
    Linear and Nonlinear Equations", SIAM 1995, ch. 6), O(n) memory. This mode steps in
    Python (the Newton iteration around GMRES, on the same kernels otherwise).
    Dense output: the collocation polynomial (order 3 between the nodes), which also predicts
    the next step's Newton start when the state continues from the previous call.

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II: Stiff and
           Differential-Algebraic Problems", 2nd ed., Springer 1996, sec. IV.8.
    .. [2] E. Hairer, radau5.f, http://www.unige.ch/~hairer/software.html
    .. [3] scipy.integrate.Radau (scipy/integrate/_ivp/radau.py), ported here.
    """

    name = "radau"
    order = 5
    error_estimator_order = 3
    dense_output = True
    A = _RADAU_A
    B = _RADAU_A[-1]
    C = _RADAU_C
    E = _RADAU_E
    MU_REAL = _MU_REAL
    MU_COMPLEX = _MU_COMPLEX
    T = _RADAU_T
    TI = _RADAU_TI
    P = _RADAU_P
    #: the controller's constants (radau_kernels.CONTROL_SIZE, in the order of its C_* indices)
    CONTROL = np.array([SAFETY, MIN_FACTOR, MAX_FACTOR, NEWTON_MAXITER, RADAU_SLOW_ITER,
                        RADAU_SLOW_RATE, RADAU_KEEP_STEP, RADAU_NEWTON_FAIL_FACTOR, LU_REUSE_RTOL,
                        MIN_STEP_RELATIVE, LAST_STEP_STRETCH])
    #: the starting step's constants (dop853_kernels.dop_initial_probe, dop_initial_step), base's
    INITIAL = np.array([H0_NEGLIGIBLE, H0_DEFAULT, H0_FRACTION, H0_GROWTH, H0_TINY_DERIVATIVES,
                        H0_TINY_STEP, H0_TINY_FRACTION])
    assert CONTROL.size == CONTROL_SIZE

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        n = self.n
        jac = getattr(system, "jacobian", None)
        self._jac_fn = jac if callable(jac) else None
        self._newton_tol = max(10 * EPS / self.rtol, min(0.03, self.rtol ** 0.5))
        #: solve without forming the Jacobian (large systems, see DENSE_MAX)
        self.matrix_free = n > DENSE_MAX and self._jac_fn is None
        self._atol_v = np.ascontiguousarray(np.broadcast_to(np.asarray(self.atol, dtype=float), (n,)))
        # the Jacobian and the LU factors of MU_REAL/h I - J and MU_COMPLEX/h I - J (dense mode;
        # (n, n) from the first Jacobian on: "auto" builds a Radau it may never run)
        self._J, self._LU_real = np.zeros((0, 0)), np.zeros((0, 0))
        self._LU_complex = np.zeros((0, 0), dtype=complex)
        self._piv_real = np.zeros(n, dtype=np.int32)  # LAPACK's pivots (1-based)
        self._piv_complex = np.zeros(n, dtype=np.int32)
        # the stages: Z (3, n) in y, W in the eigenbasis of A^-1, F the rhs there
        self._Z0, self._Z, self._W, self._dW, self._F = (np.zeros((3, n)) for _ in range(5))
        self._ys, self._scale_v, self._delta, self._ZE, self._err, self._fe, self._y_bad = (
            np.zeros(n) for _ in range(7))
        self._f_real = np.zeros(n)
        self._f_complex = np.zeros(n, dtype=complex)
        self._bad = np.zeros(3, dtype=np.int64)
        self._y_end = np.zeros(n)
        self._Qt = np.zeros((3, n))  # the collocation polynomial of the last step
        self._sol_y = np.zeros(n)  # its y_old
        self._reset_memory()
        # the compiled loop (fast_radau), when the system offers the kernel
        self._loop = None
        offers_kernel = callable(getattr(system, "kernel_arguments", None)) and callable(
            getattr(system, "quaternion_block", None))
        if n and not self.matrix_free and self._jac_fn is None and offers_kernel:
            self._loop = fast_radau.loop_for(system.kernel_arguments())
            self._i_q0, self._nq = (int(v) for v in system.quaternion_block())
            self._mem = np.zeros(fast_radau.MEM_SIZE)
            self._flags = np.zeros(fast_radau.FLAGS_SIZE, dtype=np.int64)
            self._no_te, self._no_Y = np.zeros(0), np.zeros((0, n))
            #: the ends of the first len(_trace) accepted steps of the last compiled call (tests)
            self._trace = np.zeros(0)
            #: outputs filled by the last compiled call (also when it raised)
            self.outputs_filled = 0
            # the loop is compiled (or loaded) by the first advance, by `warm_up` or by
            # `load_loop`, not here: "auto" builds a Radau it may never run

    def warm_up(self, t0: float, y: np.ndarray, *, loop: bool = True) -> None:
        """A short advance from (t0, y) the way this integrator will step, then forgotten (the
        memory reset, the counters kept), so that its code is compiled, or loaded from numba's
        cache, now rather than in the middle of a real-time run: the compiled loop if the
        system has one and `loop`, else the public single step (the Python driver's kernels;
        loop=False: what "auto" drives where the loop is not compiled). A failure to step is ignored: the code is
        compiled all the same."""
        counts = (self.nfev, self.nsteps, self.nrejected, self.njev, self.nlu)
        system_nfev = getattr(self.system, "nfev", None)
        span = WARM_UP_SPAN * max(1.0, abs(t0))
        try:
            if loop and self._loop is not None:
                self.advance(t0, y, t0 + span, t_eval=[t0 + 0.5 * span])
            else:
                yc = np.array(y, dtype=float)
                self.begin(t0, yc, t0 + span)
                self.take_step(t0, yc, t0 + span)
                self.dense(np.array([t0]))
        except IntegrationError:
            pass
        finally:
            self.reset()
            self.nfev, self.nsteps, self.nrejected, self.njev, self.nlu = counts
            if system_nfev is not None:
                self.system.nfev = system_nfev

    def load_loop(self) -> None:
        """Compile the loop, or load it from numba's cache, now (the "auto" method, which may
        switch to radau in the middle of a real-time run): a call of no step from a valid state
        (unit quaternions), then forgotten. Nothing without the compiled loop."""
        if self._loop is None:
            return
        n = self.n
        y = np.zeros(n)
        y[self._i_q0:self._i_q0 + 4 * self._nq:4] = 1.0
        self._allocate()
        self._pack()
        self._call_loop(0.0, y, 0.0, self._no_te, self._no_Y, _NO_DETECTION)
        self._reset_memory()
        self._f[:] = 0.0

    def _reset_memory(self) -> None:
        self._h_abs_old = math.nan  # the last accepted step (NaN: none)
        self._error_norm_old = math.nan  # its error norm
        self._has_J = False  # a Jacobian (or its point, matrix-free) is there
        self._J_point = None  # matrix-free: (t, y, rhs(t, y)) of the Jacobian
        self._current_jac = False  # ... and taken at the current state
        self._recompute_jac = False  # renew it at the next step
        self._has_lu = False
        self._lu_h = math.nan  # the step the LU factors are for
        self._has_sol = False  # a collocation polynomial to predict the Newton start from
        self._sol_t = self._sol_h = 0.0
        self._t_end = math.nan  # where the last call ended (with _y_end)
        self._nonfinite = NONFINITE_NONE

    def reset(self) -> None:
        super().reset()
        self._reset_memory()

    @property
    def jacobian(self) -> np.ndarray | None:
        """The Jacobian (n, n) the steps are using (refreshed in place when `njev` counts up),
        or None before the first step and in matrix-free mode (see `jacobian_point`)."""
        return self._J if self._has_J and not self.matrix_free else None

    @property
    def jacobian_point(self) -> tuple[float, np.ndarray] | None:
        """(t, y) where the Jacobian in use is taken (matrix-free mode), else None."""
        return (self._J_point[0], self._J_point[1]) if self.matrix_free and self._J_point is not None else None

    # --- matrix-free linear algebra ------------------------------------------------------------
    def _jvp(self, v: np.ndarray) -> np.ndarray:
        """J v by a forward difference at the Jacobian's point (matrix-free mode)."""
        t, y, f = self._J_point
        norm = float(np.linalg.norm(v))
        if norm == 0.0:
            return np.zeros(self.n)
        e = FD_REL_STEP * max(FD_MIN_SCALE, float(np.linalg.norm(y))) / norm
        return (self._fun(t, y + e * v) - f) / e

    def _krylov(self, mu: complex | float, b: np.ndarray) -> np.ndarray:
        """(mu I - J) x = b by restarted GMRES on Jacobian-vector products."""
        from scipy.sparse.linalg import LinearOperator, gmres

        if isinstance(mu, complex):
            def mv(v):
                v = np.asarray(v).ravel()
                return mu * v - (self._jvp(v.real) + 1j * self._jvp(v.imag))
            dtype = np.complex128
        else:
            def mv(v):
                v = np.asarray(v).ravel()
                return mu * v - self._jvp(v)
            dtype = np.float64
        op = LinearOperator((self.n, self.n), matvec=mv, dtype=dtype)
        x, _ = gmres(op, b, rtol=KRYLOV_RTOL, atol=0.0, restart=KRYLOV_RESTART, maxiter=KRYLOV_RESTARTS)
        return x  # not converged: an inexact solve; Newton's rate test judges the result

    # --- the Python driver ---------------------------------------------------------------------
    def _initial_step(self, t0, y0, f0, t1, order) -> float:
        """The starting step (HNW I, sec. II.4; scipy's select_initial_step) by the kernels the
        compiled loop calls (dop853_kernels): `AdaptiveIntegrator._initial_step` in the same
        arithmetic."""
        if self.n == 0:
            return super()._initial_step(t0, y0, f0, t1, order)
        span = t1 - t0
        sc, y1 = np.empty(self.n), np.empty(self.n)
        h0, d1 = dop_initial_probe(y0, f0, self.rtol, self._atol_v, span, self.INITIAL, sc, y1)
        if not h0 > 0.0:  # |f0| so large against |y0| that no step is representable
            raise self._no_starting_step(t0, d1)
        f1 = self._fun(t0 + h0, y1)
        return dop_initial_step(f0, f1, sc, h0, d1, span, self.max_step, order, self.INITIAL)

    def _allocate(self) -> None:
        """The (n, n) Jacobian and LU factors of the dense mode, once."""
        if self._J.shape[0] != self.n:
            n = self.n
            self._J, self._LU_real = np.zeros((n, n)), np.zeros((n, n))
            self._LU_complex = np.zeros((n, n), dtype=complex)

    def _no_starting_step(self, t0: float, d1: float) -> IntegrationError:
        return IntegrationError(self.name, f"no starting step: the rhs is too large (weighted norm {d1:.3g})",
                                t0, None)

    def _jacobian(self, t: float, y: np.ndarray, f: np.ndarray) -> None:
        """The Jacobian d rhs / dy at (t, y), f = rhs(t, y), into _J: the system's, or forward
        differences (rad_fd_delta, rad_fd_column); in matrix-free mode only its point (t, y, f),
        copied. Counts njev; the LU factors are stale after it."""
        self.njev += 1
        self._has_J = True
        self._has_lu = False
        if self.matrix_free:
            self._J_point = (t, y.copy(), f.copy())
            return
        self._allocate()
        if self._jac_fn is not None:
            J = np.asarray(self._jac_fn(t, y), dtype=float)
            if J.shape != (self.n, self.n):
                raise ValueError(f"jacobian must have shape {(self.n, self.n)}, got {J.shape}")
            self._J[:] = J
            return
        delta, yj = self._delta, self._ys
        rad_fd_delta(y, FD_REL_STEP, FD_MIN_SCALE, delta)
        yj[:] = y
        for j in range(self.n):
            yj[j] = y[j] + delta[j]
            rad_fd_column(self._J, j, self._fun(t, yj), f, delta[j])
            yj[j] = y[j]

    def _factor(self, h: float) -> None:
        """LU of MU_REAL/h I - J and MU_COMPLEX/h I - J (rad_factor); matrix-free: only h."""
        if not self.matrix_free:
            rad_factor(self._J, h, self.MU_REAL, self.MU_COMPLEX, self._LU_real, self._piv_real,
                       self._LU_complex, self._piv_complex)
            self.nlu += 2
        self._lu_h = h
        self._has_lu = True

    def _newton(self, t: float, y: np.ndarray, h: float, scale: np.ndarray) -> tuple[bool, int, float]:
        """The simplified Newton iteration for the collocation system from Z0 (scipy's
        solve_collocation_system) into _Z. Returns (converged, n_iter, rate)."""
        F, ys, W, dW, Z = self._F, self._ys, self._W, self._dW, self._Z
        f_real, f_complex = self._f_real, self._f_complex
        rad_transform(self.TI, self._Z0, W)
        Z[:] = self._Z0
        dW_norm_old = rate = math.nan
        k = 0
        for k in range(NEWTON_MAXITER):
            for i in range(3):
                rad_stage_state(y, Z, i, ys)
                F[i] = self._fun(t + h * self.C[i], ys)
            if not rad_finite_rows(F, self._bad):
                self._nonfinite = NONFINITE_STAGES
                return False, k + 1, rate
            rad_newton_residual(F, W, self.TI, h, self.MU_REAL, self.MU_COMPLEX, f_real, f_complex)
            if self.matrix_free:
                dW[0] = self._krylov(self.MU_REAL / h, f_real)
                x = self._krylov(self.MU_COMPLEX / h, f_complex)
                dW[1], dW[2] = x.real, x.imag
                dW_norm = rad_dw_norm(dW, scale)
            else:
                dW_norm = rad_newton_increment(self._LU_real, self._piv_real, self._LU_complex,
                                               self._piv_complex, f_real, f_complex, scale, dW)
            code, rate = rad_newton_advance(dW_norm, dW_norm_old, k, self._newton_tol,
                                            NEWTON_MAXITER, W, dW, self.T, Z)
            if code == NEWTON_DIVERGING:
                return False, k + 1, rate
            if code == NEWTON_CONVERGED:
                return True, k + 1, rate
            dW_norm_old = dW_norm
        return False, k + 1, rate

    def _error_solve(self, b: np.ndarray, scale: np.ndarray) -> float:
        """b (n,) becomes (MU_REAL/h I - J)^-1 b; returns its norm in scale."""
        if self.matrix_free:
            b[:] = self._krylov(self.MU_REAL / self._lu_h, b)
            return rms_scaled(b, scale)
        return rad_error(self._LU_real, self._piv_real, b, scale)

    def begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        super().begin(t0, y, t1)
        if not (self._t_end == t0 and np.array_equal(y, self._y_end)):
            # not a continuation of the previous call: no predictor, the Jacobian is old
            self._has_sol = False
            self._current_jac = False

    def end(self, t1: float, y: np.ndarray) -> None:
        """A call ends at (t1, y): the next call continues if it starts there."""
        self._t_end = t1
        self._y_end[:] = y

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        f, scale, Z, err = self._f, self._scale_v, self._Z, self._err
        min_step = self._min_step(t, t1)
        if self._h_abs > self.max_step:
            h_abs, h_abs_old, error_norm_old = self.max_step, math.nan, math.nan
        else:
            h_abs, h_abs_old, error_norm_old = self._h_abs, self._h_abs_old, self._error_norm_old
        if not self._has_J or self._recompute_jac:
            self._jacobian(t, y, f)
            self._current_jac, self._recompute_jac = True, False
        self._nonfinite = NONFINITE_NONE
        rejected = False
        while True:
            if h_abs < min_step:
                raise self._collapse(t, h_abs, self._describe_nonfinite())
            h, t_new = clip_step(t, h_abs, t1, LAST_STEP_STRETCH)
            if self._has_sol:
                rad_predict(self._Qt, self._sol_t, self._sol_h, self._sol_y, t, h, self.C, y, self._Z0)
            else:
                self._Z0[:] = 0.0
            rad_scale(y, y, self.rtol, self._atol_v, scale)
            converged = False
            while not converged:
                if not self._has_lu or abs(h - self._lu_h) > LU_REUSE_RTOL * h:
                    self._factor(h)
                converged, n_iter, rate = self._newton(t, y, h, scale)
                if not converged:
                    if self._current_jac:
                        break
                    self._jacobian(t, y, f)
                    self._current_jac = True
            if not converged:
                h_abs = abs(h) * RADAU_NEWTON_FAIL_FACTOR
                self._has_lu = False
                self.nrejected += 1
                continue
            y_new = self._y_new
            rad_add(y, Z[2], y_new)
            rad_scale(y, y_new, self.rtol, self._atol_v, scale)
            rad_error_rhs(self.E, Z, h, f, self._ZE, err)
            error_norm = self._error_solve(err, scale)
            if rejected and error_norm > 1:
                rad_add(y, err, self._ys)
                rad_add(self._fun(t, self._ys), self._ZE, err)
                error_norm = self._error_solve(err, scale)
            if not (math.isfinite(error_norm) and rad_finite(y_new)):
                if rad_finite(y_new):
                    self._nonfinite = NONFINITE_ERROR
                else:
                    self._nonfinite = NONFINITE_STATE
                    self._y_bad[:] = y_new
                h_abs = abs(h) * MIN_FACTOR
                rejected = True
                self.nrejected += 1
                continue
            if error_norm > 1:
                h_abs = rad_control_rejected(h, h_abs_old, error_norm, error_norm_old, n_iter, self.CONTROL)
                rejected = True
                self.nrejected += 1
                continue
            break
        self._recompute_jac, self._h_abs = rad_control_accepted(
            h, h_abs, h_abs_old, error_norm, error_norm_old, n_iter, rate, self.CONTROL)
        # from now on J belongs to an older state (a slow Newton renews it next step)
        self._current_jac = False
        self._h_abs_old = abs(h)
        self._error_norm_old = error_norm
        self.error_estimate = error_norm
        self.last_step = h
        return t_new

    def _describe_nonfinite(self) -> str:
        """What the last non-finite trial of the step had (for the collapse message)."""
        if self._nonfinite == NONFINITE_STAGES:
            return describe_nonfinite(np.where(self._bad[:, None] != 0, np.nan, 0.0))
        if self._nonfinite == NONFINITE_STATE:
            return describe_nonfinite(self._y_bad)
        if self._nonfinite == NONFINITE_ERROR:
            return "a non-finite error estimate"
        return ""

    def _accept(self, t, y, t_new, y_new) -> None:
        # the collocation polynomial of this step: dense output and next Newton start
        rad_dense_coefficients(self._Z, self.P, self._Qt)
        self._sol_t, self._sol_h = t, t_new - t
        self._sol_y[:] = y
        self._has_sol = True

    def dense(self, tq: np.ndarray) -> np.ndarray:
        """States (k, size), projected, at times tq (k,) inside the step `take_step` just took:
        the collocation polynomial (it needs no rhs at the step's end)."""
        tq = np.ascontiguousarray(tq, dtype=float)
        Y = np.empty((tq.size, self.n))
        rad_dense_eval(self._Qt, self._sol_y, self._sol_t, self._sol_h, tq, Y)
        for row in Y:
            self._project(row)
        return Y

    # --- the compiled loop -------------------------------------------------------------------
    def _integrate(self, t0, y, t1, te, Y) -> None:
        if self._loop is None or t1 == t0:
            super()._integrate(t0, y, t1, te, Y)
        else:
            self._integrate_compiled(t0, y, t1, te, Y)

    def _pack(self) -> None:
        """The step-size and Jacobian memory into the loop's `mem` and `flags`."""
        fr = fast_radau
        mem, flags = self._mem, self._flags
        mem[fr.M_H_ABS] = 0.0 if self._h_abs is None else self._h_abs  # 0: select the first step
        mem[fr.M_H_ABS_OLD] = self._h_abs_old
        mem[fr.M_ERROR_OLD] = self._error_norm_old
        mem[fr.M_LU_H] = self._lu_h
        mem[fr.M_SOL_T] = self._sol_t
        mem[fr.M_SOL_H] = self._sol_h
        mem[fr.M_T_END] = self._t_end
        mem[fr.M_ERROR] = math.nan if self.error_estimate is None else self.error_estimate
        mem[fr.M_LAST_STEP] = math.nan if self.last_step is None else self.last_step
        flags[:] = 0
        flags[fr.F_HAS_J] = self._has_J
        flags[fr.F_CURRENT_JAC] = self._current_jac
        flags[fr.F_RECOMPUTE_JAC] = self._recompute_jac
        flags[fr.F_HAS_LU] = self._has_lu
        flags[fr.F_HAS_SOL] = self._has_sol

    def _unpack(self) -> None:
        """The loop's memory and counts back into this integrator."""
        fr = fast_radau
        m, st = self._mem.tolist(), self._flags.tolist()
        self._h_abs = m[fr.M_H_ABS] if m[fr.M_H_ABS] > 0.0 else None
        self._h_abs_old, self._error_norm_old = m[fr.M_H_ABS_OLD], m[fr.M_ERROR_OLD]
        self._lu_h, self._sol_t, self._sol_h, self._t_end = (m[fr.M_LU_H], m[fr.M_SOL_T], m[fr.M_SOL_H],
                                                             m[fr.M_T_END])
        if not math.isnan(m[fr.M_ERROR]):
            self.error_estimate, self.last_step = m[fr.M_ERROR], m[fr.M_LAST_STEP]
        self._has_J, self._current_jac, self._recompute_jac, self._has_lu, self._has_sol = (
            bool(st[i]) for i in (fr.F_HAS_J, fr.F_CURRENT_JAC, fr.F_RECOMPUTE_JAC, fr.F_HAS_LU,
                                  fr.F_HAS_SOL))
        self._nonfinite = st[fr.F_NONFINITE]
        nfev = st[fr.F_NFEV]
        self.nfev += nfev
        self.system.nfev += nfev
        self.njev += st[fr.F_NJEV]
        self.nlu += st[fr.F_NLU]
        self.nsteps += st[fr.F_ACCEPTED]
        self.nrejected += st[fr.F_REJECTED]
        self._f_new = st[fr.F_F_NEW] != 0

    def _integrate_compiled(self, t0: float, y: np.ndarray, t1: float, te, Y,
                            detection: tuple | None = None) -> tuple[float, int]:
        """`_integrate` (the loop of `begin`, `take_step`, `dense`, `end`) in one compiled call.

        With `detection`, the arrays (counters, window, cost, handback, easy, power) of the
        "auto" method's tests on radau's steps (dop853_kernels, radau_kernels), the loop runs
        in its detection mode (fast_radau.radau_advance) and may stop at an accepted state
        before t1, as a call that ended there: returns (the time reached, the reason of a
        hand-back asked for there, fast_radau.REASON_*, or 0). `outputs_filled`: the rows of
        Y filled, also when the call raises.
        """
        fr = fast_radau
        if te is None:
            te, Y = self._no_te, self._no_Y
        elif not (te.flags.c_contiguous and te.flags.writeable):
            te = te.copy()
        self._allocate()
        self._pack()
        self._call_loop(t0, y, t1, te, Y, _NO_DETECTION if detection is None else detection)
        self._unpack()
        m, st = self._mem.tolist(), self._flags.tolist()
        self.outputs_filled = st[fr.F_OUTPUTS]
        code = st[fr.F_STATUS]
        if code == fr.DONE or code == fr.SWITCH:
            if st[fr.F_ACCEPTED]:
                self._t_old, self._t_new = m[fr.M_T_OLD], m[fr.M_T]
            return m[fr.M_T], st[fr.F_REASON]
        if code == fr.INITIAL_RHS_NONFINITE:
            raise IntegrationError(self.name, "rhs is not finite at the initial state", t0, None,
                                   describe_nonfinite(self._f))
        elif code == fr.NO_STARTING_STEP:
            raise self._no_starting_step(t0, m[fr.M_H])
        elif code == fr.COLLAPSED:
            raise self._collapse(m[fr.M_T], m[fr.M_H], self._describe_nonfinite())
        else:  # ACCEPTED_RHS_NONFINITE
            raise IntegrationError(self.name, "rhs is not finite at the accepted state", m[fr.M_T],
                                   m[fr.M_H], describe_nonfinite(self._f))

    def _call_loop(self, t0: float, y: np.ndarray, t1: float, te, Y, detection: tuple) -> None:
        """fast_radau.radau_advance with this integrator's method, options, memory, scratch."""
        fr = fast_radau
        self._loop(float(t0), float(t1), y, fr.Outputs(te, Y),
                   fr.Options(float(self.max_step), float(self.rtol), self._atol_v, float(self._newton_tol),
                              float(FD_REL_STEP), float(FD_MIN_SCALE), self._i_q0, self._nq),
                   fr.Method(self.C, self.E, self.T, self.TI, self.P, self.MU_REAL, self.MU_COMPLEX,
                             self.CONTROL, self.INITIAL),
                   fr.State(self._f, self._J, self._LU_real, self._piv_real, self._LU_complex,
                            self._piv_complex, self._Z0, self._Z, self._W, self._dW, self._F, self._ys,
                            self._f_real, self._f_complex, self._scale_v, self._delta, self._ZE, self._err,
                            self._fe, self._y_new, self._y_old, self._y_bad, self._bad, self._Qt,
                            self._sol_y, self._y_end, self._trace, self._mem, self._flags),
                   fr.Detection(*detection), *self.system.kernel_arguments())


#: the detection arrays of a plain call (fast_radau.radau_advance: handback empty, the others
#: not read), of the types of Auto's: counters, window, cost, handback, easy, power
_NO_DETECTION = (np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0),
                 np.zeros(0))
