"""Radau IIA with 3 stages (radau): order 5, implicit, L-stable, for stiff systems."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg.lapack import get_lapack_funcs

from .base import (
    EPS,
    MAX_FACTOR,
    MIN_FACTOR,
    SAFETY,
    AdaptiveIntegrator,
    describe_nonfinite,
    rms,
)

if TYPE_CHECKING:
    from ..system import OdeSystem

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


class Radau(AdaptiveIntegrator):
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

    Above DENSE_MAX states (a chain of some 300 bodies) nothing of size n^2 is formed: the
    "Jacobian" is its point (t, y, rhs(t, y)), kept and renewed by the same rules, and the two
    linear systems are solved by restarted GMRES (scipy.sparse.linalg.gmres) on products
    J v = (rhs(t, y + e v) - rhs(t, y)) / e, one rhs evaluation a product (two for the complex
    system), to KRYLOV_RTOL: an inexact simplified Newton (Kelley, "Iterative Methods for
    Linear and Nonlinear Equations", SIAM 1995, ch. 6), O(n) memory.
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

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        n = self.n
        jac = getattr(system, "jacobian", None)
        self._jac_fn = jac if callable(jac) else None
        self._newton_tol = max(10 * EPS / self.rtol, min(0.03, self.rtol ** 0.5))
        #: solve without forming the Jacobian (large systems, see DENSE_MAX)
        self.matrix_free = n > DENSE_MAX and self._jac_fn is None
        self._I = None if self.matrix_free else np.identity(n)
        self._F = np.empty((3, n))
        self._ys = np.empty(n)
        self._TI_complex = self.TI[1] + 1j * self.TI[2]
        self._y_end = np.empty(n)
        self._sol_y = np.empty(n)  # y_old of the collocation polynomial
        # LAPACK directly: scipy.linalg.lu_solve's checks cost more than the solve at n ~ 60
        self._getrf_real, self._getrs_real = get_lapack_funcs(("getrf", "getrs"), dtype=np.float64)
        self._getrf_complex, self._getrs_complex = get_lapack_funcs(("getrf", "getrs"),
                                                                    dtype=np.complex128)
        self._reset_memory()

    def _reset_memory(self) -> None:
        self._h_abs_old: float | None = None
        self._error_norm_old: float | None = None
        self._J: np.ndarray | None = None
        self._current_jac = False
        self._recompute_jac = False
        self._LU_real = self._LU_complex = None
        self._lu_h = None
        self._sol_Q: np.ndarray | None = None  # (n, 3); None: no predictor
        self._sol_t = self._sol_h = 0.0
        self._t_end: float | None = None

    def reset(self) -> None:
        super().reset()
        self._reset_memory()

    @property
    def jacobian(self) -> np.ndarray | None:
        """The Jacobian (n, n) the steps are using (refreshed when `njev` counts up), or None
        before the first step and in matrix-free mode (see `jacobian_point`)."""
        return None if self.matrix_free else self._J

    @property
    def jacobian_point(self) -> tuple[float, np.ndarray] | None:
        """(t, y) where the Jacobian in use is taken (matrix-free mode), else None."""
        return (self._J[0], self._J[1]) if self.matrix_free and self._J is not None else None

    def _jvp(self, v: np.ndarray) -> np.ndarray:
        """J v by a forward difference at the Jacobian's point (matrix-free mode)."""
        t, y, f = self._J
        norm = float(np.linalg.norm(v))
        if norm == 0.0:
            return np.zeros(self.n)
        e = FD_REL_STEP * max(FD_MIN_SCALE, float(np.linalg.norm(y))) / norm
        return (self._fun(t, y + e * v) - f) / e

    def _krylov(self, mu: complex, b: np.ndarray) -> np.ndarray:
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

    # --- linear algebra ---------------------------------------------------------------------
    def _jacobian(self, t: float, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """d rhs / dy (n, n): the system's, or forward differences around f = rhs(t, y); in
        matrix-free mode only its point (t, y, f), copied."""
        self.njev += 1
        if self.matrix_free:
            return (t, y.copy(), f.copy())
        if self._jac_fn is not None:
            J = np.asarray(self._jac_fn(t, y), dtype=float)
            if J.shape != (self.n, self.n):
                raise ValueError(f"jacobian must have shape {(self.n, self.n)}, got {J.shape}")
            return J
        delta = (y + FD_REL_STEP * np.maximum(np.abs(y), FD_MIN_SCALE)) - y
        J = np.empty((self.n, self.n))
        yj = self._ys
        yj[:] = y
        for j in range(self.n):
            yj[j] = y[j] + delta[j]
            J[:, j] = self._fun(t, yj)
            yj[j] = y[j]
        J -= f[:, None]
        J /= delta
        return J

    def _factor(self, h: float) -> None:
        """LU of MU_REAL/h I - J and MU_COMPLEX/h I - J (LAPACK getrf); matrix-free: only h."""
        if self.matrix_free:
            self._LU_real = self._LU_complex = ("krylov", h)
            self._lu_h = h
            return
        self._LU_real = self._lu(self._getrf_real, self.MU_REAL / h * self._I - self._J)
        self._LU_complex = self._lu(self._getrf_complex, self.MU_COMPLEX / h * self._I - self._J)
        self._lu_h = h
        self.nlu += 2

    @staticmethod
    def _lu(getrf, M: np.ndarray) -> tuple:
        lu, piv, info = getrf(M, overwrite_a=True)
        if info < 0:
            raise ValueError(f"getrf: illegal argument {-info}")
        # info > 0: exactly singular; the solves give inf/nan and the step is rejected
        return lu, piv

    def _solve(self, getrs, LU: tuple, b: np.ndarray) -> np.ndarray:
        if self.matrix_free:
            h = LU[1]
            return self._krylov(self.MU_REAL / h if getrs is self._getrs_real else self.MU_COMPLEX / h, b)
        x, info = getrs(LU[0], LU[1], b)
        return x

    def _solve_real(self, b: np.ndarray) -> np.ndarray:
        return self._solve(self._getrs_real, self._LU_real, b)

    # --- the step -------------------------------------------------------------------------------
    def _newton(self, t, y, h, Z0, scale):
        """Simplified Newton iteration for the collocation system (scipy's
        solve_collocation_system). Returns (converged, n_iter, Z (3, n), rate)."""
        F, ys = self._F, self._ys
        M_real, M_complex = self.MU_REAL / h, self.MU_COMPLEX / h
        W = self.TI @ Z0
        Z = Z0
        dW = np.empty_like(W)
        ch = h * self.C
        dW_norm_old = rate = None
        converged = False
        tol = self._newton_tol
        k = 0
        for k in range(NEWTON_MAXITER):
            for i in range(3):
                np.add(y, Z[i], out=ys)
                F[i] = self._fun(t + ch[i], ys)
            if not np.isfinite(F).all():
                self._nonfinite = describe_nonfinite(F)
                break
            f_real = self.TI[0] @ F - M_real * W[0]
            f_complex = self._TI_complex @ F - M_complex * (W[1] + 1j * W[2])
            dW[0] = self._solve(self._getrs_real, self._LU_real, f_real)
            dW_complex = self._solve(self._getrs_complex, self._LU_complex, f_complex)
            dW[1] = dW_complex.real
            dW[2] = dW_complex.imag
            dW_norm = rms((dW / scale).ravel())
            if dW_norm_old is not None:
                rate = dW_norm / dW_norm_old
            if rate is not None and (
                rate >= 1 or rate ** (NEWTON_MAXITER - k) / (1 - rate) * dW_norm > tol
            ):
                break  # diverges, or will not converge within NEWTON_MAXITER
            W += dW
            Z = self.T @ W
            if dW_norm == 0 or (rate is not None and rate / (1 - rate) * dW_norm < tol):
                converged = True
                break
            dW_norm_old = dW_norm
        return converged, k + 1, Z, rate

    @staticmethod
    def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old) -> float:
        """Gustafsson's predictive step-size factor (Hairer, Wanner II, sec. IV.8)."""
        if error_norm_old is None or h_abs_old is None or error_norm == 0:
            multiplier = 1.0
        else:
            multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
        with np.errstate(divide="ignore"):
            return min(1.0, multiplier) * np.float64(error_norm) ** -0.25

    def begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        super().begin(t0, y, t1)
        if self._t_end != t0 or not np.array_equal(y, self._y_end):
            # not a continuation of the previous call: no predictor, the Jacobian is old
            self._sol_Q = None
            self._current_jac = False

    def end(self, t1: float, y: np.ndarray) -> None:
        """A call ends at (t1, y): the next call continues if it starts there."""
        self._t_end = t1
        self._y_end[:] = y

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        f = self._f
        min_step = self._min_step(t, t1)
        if self._h_abs > self.max_step:
            h_abs, h_abs_old, error_norm_old = self.max_step, None, None
        else:
            h_abs, h_abs_old, error_norm_old = self._h_abs, self._h_abs_old, self._error_norm_old
        if self._J is None or self._recompute_jac:
            self._J = self._jacobian(t, y, f)
            self._current_jac, self._recompute_jac = True, False
            self._LU_real = None
        self._nonfinite = ""
        rejected = False
        while True:
            if h_abs < min_step:
                raise self._collapse(t, h_abs, self._nonfinite)
            h, t_new = self._clip(t, h_abs, t1)
            if self._sol_Q is None:
                Z0 = np.zeros((3, self.n))
            else:
                x = (t + h * self.C - self._sol_t) / self._sol_h
                Z0 = (self._sol_Q @ np.array([x, x * x, x * x * x])).T + (self._sol_y - y)
            scale = self._scale(y)
            converged = False
            while not converged:
                if self._LU_real is None or abs(h - self._lu_h) > LU_REUSE_RTOL * h:
                    self._factor(h)
                converged, n_iter, Z, rate = self._newton(t, y, h, Z0, scale)
                if not converged:
                    if self._current_jac:
                        break
                    self._J = self._jacobian(t, y, f)
                    self._current_jac = True
                    self._LU_real = None
            if not converged:
                h_abs = abs(h) * RADAU_NEWTON_FAIL_FACTOR
                self._LU_real = None
                self.nrejected += 1
                continue
            y_new = self._y_new
            np.add(y, Z[-1], out=y_new)
            ZE = (self.E @ Z) / h
            error = self._solve_real(f + ZE)
            scale = self._scale(y, y_new)
            error_norm = rms(error / scale)
            safety = SAFETY * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
            if rejected and error_norm > 1:
                error = self._solve_real(self._fun(t, y + error) + ZE)
                error_norm = rms(error / scale)
            if not (math.isfinite(error_norm) and np.isfinite(y_new).all()):
                self._nonfinite = describe_nonfinite(y_new) if not np.isfinite(y_new).all() else \
                    "a non-finite error estimate"
                h_abs = abs(h) * MIN_FACTOR
                rejected = True
                self.nrejected += 1
                continue
            if error_norm > 1:
                factor = self._predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
                h_abs = abs(h) * max(MIN_FACTOR, safety * factor)
                rejected = True
                self.nrejected += 1
                continue
            break
        self._recompute_jac = n_iter > RADAU_SLOW_ITER and rate > RADAU_SLOW_RATE
        factor = self._predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
        factor = min(MAX_FACTOR, safety * factor)
        if not self._recompute_jac and factor < RADAU_KEEP_STEP:
            factor = 1.0
        # from now on J belongs to an older state (a slow Newton renews it next step)
        self._current_jac = False
        self._h_abs_old = abs(h)
        self._error_norm_old = error_norm
        self._h_abs = self._next_h(abs(h), h_abs, factor)
        self._Z = Z
        self.error_estimate = error_norm
        self.last_step = h
        return t_new

    def _accept(self, t, y, t_new, y_new) -> None:
        # the collocation polynomial of this step: dense output and next Newton start
        self._sol_Q = self._Z.T @ self.P
        self._sol_t, self._sol_h = t, t_new - t
        self._sol_y[:] = y

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        x = (tq - t) / (t_new - t)
        return y + np.column_stack([x, x * x, x * x * x]) @ self._sol_Q.T
