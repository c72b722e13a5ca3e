"""The arithmetic of Radau IIA (3 stages, order 5), compiled with numba.

One implementation, two drivers: :class:`gyro_sim.integrators.radau.driver.Radau` calls these
between its rhs evaluations on any system (the numpy reference among them), and the compiled
loop :func:`gyro_sim.integrators.radau.loop.radau_advance` calls the same functions between calls of
the articulated-body kernel. The method is data (the class attributes of Radau: C, E, T, TI,
P, the eigenvalues MU_REAL and MU_COMPLEX of A^-1), and so are the controller's constants
(`control`, :data:`CONTROL_SIZE` values).

What each function computes, as scipy's `scipy.integrate.Radau` does (radau.py:
solve_collocation_system, predict_factor, Radau._step_impl, RadauDenseOutput), in the same
order of operations wherever scipy's order is defined (its sums are BLAS products, whose
order and fused multiply-adds are the library's: there the results agree to round-off):

    delta_j = (y_j + FD_REL max(|y_j|, FD_MIN)) - y_j      FD Jacobian steps  (rad_fd_delta)
    J[:, j] = (f(y + delta_j e_j) - f) / delta_j            its columns        (rad_fd_column)
    LU of MU_REAL/h I - J and MU_COMPLEX/h I - J             LAPACK's getrf     (rad_factor)
    W = TI Z, Z = T W                                        eigenbasis of A^-1 (rad_transform)
    f_real = sum_j TI[0, j] F_j - MU_REAL/h W_0             Newton residual    (rad_newton_residual)
    f_cplx = sum_j (TI[1, j] + i TI[2, j]) F_j - MU_COMPLEX/h (W_1 + i W_2)
    dW from the two LUs, ||dW / scale||_rms                 Newton increment   (rad_newton_increment)
    rate tests of the simplified Newton (HW II, sec. IV.8)   iteration control  (rad_newton_advance)
    err = (MU_REAL/h I - J)^-1 (f + (E Z) / h)              error estimate     (rad_error)
    Gustafsson's predictive controller                       step control       (rad_control_*)
    Q = Z^T P; y(t_old + x h) = y_old + Q (x, x^2, x^3)      dense output       (rad_dense_*)

The LU is LAPACK's getrf (scipy's LAPACK, reached from compiled code as numba's own
np.linalg reaches it: the factors are scipy.linalg.lu_factor's bit for bit), called by the
compiled loop and the Python driver alike; where numba offers no such access, the textbook LU
with partial pivoting of rad_lu (its factors agree with LAPACK's to round-off). The solves are
this module's (rad_lu_solve, as getrs does them for one right-hand side).
The sums run over j in increasing order, one product added at a time. No fastmath: IEEE
arithmetic, no contraction into fused multiply-adds. Without numba these stay plain Python
(correct, slow).

References
----------
.. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II: Stiff and
       Differential-Algebraic Problems", 2nd ed., Springer 1996, sec. IV.8 (Radau IIA: the
       simplified Newton iteration in the eigenbasis of A^-1, its stopping criterion, the
       error estimate, the predictive step-size controller).
.. [2] E. Hairer, radau5.f, http://www.unige.ch/~hairer/software.html
.. [3] scipy.integrate.Radau (scipy/integrate/_ivp/radau.py, scipy 1.17).
.. [4] G. H. Golub, C. F. Van Loan, "Matrix Computations", 4th ed., Johns Hopkins 2013,
       sec. 3.4 (Gaussian elimination with partial pivoting).
"""
from __future__ import annotations

import math

import numpy as np

from pathlib import Path

from gyro_sim import jit
from gyro_sim.integrators import adaptive_kernels
from gyro_sim.integrators.adaptive_kernels import rms_scaled
from gyro_sim.integrators.dop853 import kernels as dop853_kernels
from gyro_sim.integrators.dop853.kernels import C_WINDOW, COST_DOP853, COST_RADAU

#: the files these kernels compile in (the key of their numba cache directory): dop853's
#: constants are compiled in too
DEPENDENCIES = (Path(__file__), Path(adaptive_kernels.__file__), Path(dop853_kernels.__file__))
njit = jit.njit_with_dependencies(*DEPENDENCIES)

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

#: stages of Radau IIA (rows of Z, W, F)
N_STAGES = 3
#: the controller's constants in `control` (Radau.CONTROL): SAFETY, MIN_FACTOR, MAX_FACTOR,
#: NEWTON_MAXITER, RADAU_SLOW_ITER, RADAU_SLOW_RATE, RADAU_KEEP_STEP, RADAU_NEWTON_FAIL_FACTOR,
#: LU_REUSE_RTOL, MIN_STEP_RELATIVE, LAST_STEP_STRETCH
CONTROL_SIZE = 11
(C_SAFETY, C_MIN_FACTOR, C_MAX_FACTOR, C_NEWTON_MAXITER, C_SLOW_ITER, C_SLOW_RATE, C_KEEP_STEP,
 C_NEWTON_FAIL_FACTOR, C_LU_REUSE_RTOL, C_MIN_STEP_RELATIVE, C_LAST_STEP_STRETCH) = range(CONTROL_SIZE)
#: what rad_newton_advance returns: iterate again, converged, diverging (or too slow)
NEWTON_CONTINUE = 0
NEWTON_CONVERGED = 1
NEWTON_DIVERGING = 2


# --- vectors ---------------------------------------------------------------------------------
@njit
def rad_finite(x):
    """True if every component of x (n,) is finite."""
    for i in range(x.shape[0]):
        if not (abs(x[i]) < math.inf):
            return False
    return True


@njit
def rad_finite_rows(F, bad):
    """bad (k,) = 1 where the row of F (k, n) has a non-finite component, else 0; returns
    True if none has."""
    ok = True
    for s in range(F.shape[0]):
        bad[s] = 0
        for i in range(F.shape[1]):
            if not (abs(F[s, i]) < math.inf):
                bad[s] = 1
                ok = False
                break
    return ok


@njit
def rad_add(a, b, out):
    """out (n,) = a + b."""
    for i in range(a.shape[0]):
        out[i] = a[i] + b[i]


@njit
def rad_scale(y, y_new, rtol, atol, sc):
    """sc (n,) = atol + max(|y|, |y_new|) rtol (np.maximum: NaN propagates); y_new = y gives
    atol + |y| rtol. atol (n,)."""
    for i in range(y.shape[0]):
        a, b = abs(y[i]), abs(y_new[i])
        m = b if (b > a or b != b) else a
        sc[i] = m * rtol + atol[i]


@njit
def rad_dw_norm(dW, sc):
    """||dW / sc||_rms over all 3 n components, row after row (scipy: norm(dW / scale))."""
    k, n = dW.shape[0], dW.shape[1]
    acc = 0.0
    for s in range(k):
        for i in range(n):
            v = dW[s, i] / sc[i]
            acc += v * v
    return math.sqrt(acc / (k * n)) if n else 0.0


# --- the Jacobian by forward differences --------------------------------------------------
@njit
def rad_fd_delta(y, rel_step, min_scale, delta):
    """delta (n,): the forward-difference steps delta_j = (y_j + rel_step max(|y_j|,
    min_scale)) - y_j, as represented (the difference of two floats: exact in the quotient)."""
    for j in range(y.shape[0]):
        a = abs(y[j])
        delta[j] = (y[j] + rel_step * (a if a > min_scale else min_scale)) - y[j]


@njit
def rad_fd_column(J, j, fj, f, dj):
    """Column j of the forward-difference Jacobian: J[:, j] = (fj - f) / dj."""
    for i in range(f.shape[0]):
        J[i, j] = (fj[i] - f[i]) / dj


# --- LU with partial pivoting ----------------------------------------------------------------
# The factors are stored as LAPACK's getrf leaves them, column-major: an (n, n) C-ordered array
# holding M^T (At[j, i] = M[i, j]); pivots 1-based int32 (row k was swapped with row piv[k]).
@njit
def rad_lu(At, piv):
    """LU of M in place, At (n, n) = M^T (M column-major), with partial pivoting (Golub, Van
    Loan, sec. 3.4; LAPACK's dgetf2 / zgetf2): P M = L U, L unit lower, U upper, the pivot the
    entry of largest |Re| + |Im| (LAPACK's i?amax), the first of equals; at step k rows k and
    piv[k] - 1 are swapped, whole rows. Real or complex. Returns 0, or k + 1 for the first k
    with U[k, k] exactly 0 (that column is left uneliminated: solves give inf/nan). The
    textbook (unblocked) algorithm: the fallback of rad_factor where LAPACK is not reachable."""
    n = At.shape[0]
    info = 0
    for k in range(n):
        p = k
        big = abs(At[k, k].real) + abs(At[k, k].imag)
        for i in range(k + 1, n):
            v = abs(At[k, i].real) + abs(At[k, i].imag)
            if v > big:
                big = v
                p = i
        piv[k] = p + 1
        if p != k:
            for j in range(n):
                tmp = At[j, k]
                At[j, k] = At[j, p]
                At[j, p] = tmp
        pivot = At[k, k]
        if pivot == 0:
            if info == 0:
                info = k + 1
            continue
        for i in range(k + 1, n):
            At[k, i] = At[k, i] / pivot
        for j in range(k + 1, n):
            u = At[j, k]
            for i in range(k + 1, n):
                At[j, i] -= At[k, i] * u
    return info


#: the kernels are compiled (numba, and not NUMBA_DISABLE_JIT): LAPACK is reached as numba reaches it
_COMPILED = numba is not None and not numba.config.DISABLE_JIT
if _COMPILED:
    try:  # LAPACK's getrf as numba's np.linalg calls it (scipy's LAPACK: scipy.linalg.cython_lapack)
        from numba import types as _types
        from numba.np.linalg import _LAPACK

        _LAPACK()
        _XGETRF_REAL = _LAPACK().numba_xxgetrf(_types.float64)
        _XGETRF_COMPLEX = _LAPACK().numba_xxgetrf(_types.complex128)
    except Exception:  # noqa: BLE001 - another numba layout: the textbook LU
        _XGETRF_REAL = _XGETRF_COMPLEX = None
else:
    _XGETRF_REAL = _XGETRF_COMPLEX = None
#: the LU is LAPACK's getrf (blocked, BLAS-3; scipy's lu_factor bit for bit); else rad_lu
LAPACK_GETRF = _XGETRF_REAL is not None
_KIND_REAL, _KIND_COMPLEX = ord("d"), ord("z")

if LAPACK_GETRF:
    @njit
    def _getrf_real(At, piv):
        n = At.shape[0]
        return _XGETRF_REAL(_KIND_REAL, n, n, At.ctypes, n, piv.ctypes)

    @njit
    def _getrf_complex(At, piv):
        n = At.shape[0]
        return _XGETRF_COMPLEX(_KIND_COMPLEX, n, n, At.ctypes, n, piv.ctypes)
elif not _COMPILED:  # plain Python: LAPACK through scipy, the same routine
    def _getrf_real(At, piv):
        from scipy.linalg.lapack import get_lapack_funcs

        getrf, = get_lapack_funcs(("getrf",), dtype=At.dtype)
        lu, p, info = getrf(At.T)
        At[:] = lu.T
        piv[:] = p + 1
        return max(info, 0)

    _getrf_complex = _getrf_real
else:
    _getrf_real = _getrf_complex = rad_lu


@njit
def rad_lu_solve(At, piv, b):
    """Solves M x = b in place (b (n,) becomes x) from the factors of M in At (n, n) = the
    column-major LU (rad_factor): the row swaps, then L (unit lower) forward and U backward,
    column by column (as LAPACK's getrs with one right-hand side: x_i -= L_ij x_j for j
    increasing, then for j decreasing x_j /= U_jj and x_i -= U_ij x_j)."""
    n = At.shape[0]
    for k in range(n):
        p = piv[k] - 1
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for j in range(n):
        x = b[j]
        for i in range(j + 1, n):
            b[i] -= At[j, i] * x
    for j in range(n - 1, -1, -1):
        x = b[j] / At[j, j]
        b[j] = x
        for i in range(j):
            b[i] -= At[j, i] * x


@njit
def rad_factor(J, h, mu_real, mu_complex, LU_real, piv_real, LU_complex, piv_complex):
    """The two matrices of the simplified Newton iteration and their LU (HW II, sec. IV.8):
    MU_REAL/h I - J and MU_COMPLEX/h I - J (complex; off the diagonal -J, on it MU/h - J),
    written column-major into LU_real, LU_complex (n, n) and factored there (LAPACK's getrf,
    else rad_lu), pivots into piv_real, piv_complex (n,) int32. Returns the larger info
    (0: both regular)."""
    n = J.shape[0]
    c_real = mu_real / h
    c_complex = complex(mu_complex.real / h, mu_complex.imag / h)
    for i in range(n):
        for j in range(n):
            LU_real[j, i] = -J[i, j]
            LU_complex[j, i] = -J[i, j]
        LU_real[i, i] = c_real - J[i, i]
        LU_complex[i, i] = complex(c_complex.real - J[i, i], c_complex.imag)
    info_real = _getrf_real(LU_real, piv_real)
    info_complex = _getrf_complex(LU_complex, piv_complex)
    return max(info_real, info_complex)


# --- the collocation system -----------------------------------------------------------------
@njit
def rad_transform(M, X, out):
    """out (3, n) = M X, M (3, 3), X (3, n): W = TI Z or Z = T W."""
    n = X.shape[1]
    for r in range(M.shape[0]):
        for i in range(n):
            acc = 0.0
            for j in range(X.shape[0]):
                acc += M[r, j] * X[j, i]
            out[r, i] = acc


@njit
def rad_predict(Qt, t_old, h_old, y_old, t, h, C, y, Z0):
    """The Newton start Z0 (3, n) of a step (t, h) from the collocation polynomial of the
    previous step (Qt (3, n), from (t_old, y_old) of size h_old): Z0[s] = y_poly(t + C[s] h)
    - y (scipy: `self.sol(t + h * C).T - y`)."""
    for s in range(C.shape[0]):
        x = (t + h * C[s] - t_old) / h_old
        x2 = x * x
        x3 = x2 * x
        for i in range(y.shape[0]):
            Z0[s, i] = ((Qt[0, i] * x + Qt[1, i] * x2 + Qt[2, i] * x3) + y_old[i]) - y[i]


@njit
def rad_stage_state(y, Z, s, ys):
    """ys (n,) = y + Z[s]: the state of stage s."""
    for i in range(y.shape[0]):
        ys[i] = y[i] + Z[s, i]


@njit
def rad_newton_residual(F, W, TI, h, mu_real, mu_complex, f_real, f_complex):
    """The right-hand sides of the two linear systems of a simplified Newton iteration in the
    eigenbasis of A^-1 (scipy's solve_collocation_system):

        f_real    = sum_j TI[0, j] F_j - MU_REAL/h W_0                    (n,)
        f_complex = sum_j (TI[1, j] + i TI[2, j]) F_j - MU_COMPLEX/h (W_1 + i W_2)

    F (3, n) the rhs at the stage states, W (3, n) the stages in the eigenbasis."""
    c_real = mu_real / h
    cr, ci = mu_complex.real / h, mu_complex.imag / h
    for i in range(F.shape[1]):
        a = 0.0
        b = 0.0
        c = 0.0
        for j in range(3):
            a += TI[0, j] * F[j, i]
            b += TI[1, j] * F[j, i]
            c += TI[2, j] * F[j, i]
        f_real[i] = a - c_real * W[0, i]
        w1, w2 = W[1, i], W[2, i]
        f_complex[i] = complex(b - (cr * w1 - ci * w2), c - (cr * w2 + ci * w1))


@njit
def rad_newton_increment(LU_real, piv_real, LU_complex, piv_complex, f_real, f_complex, scale, dW):
    """dW (3, n): the Newton increment from the residuals (solved in place) through the two
    LUs (dW_0 real, dW_1 + i dW_2 complex); returns ||dW / scale||_rms."""
    rad_lu_solve(LU_real, piv_real, f_real)
    rad_lu_solve(LU_complex, piv_complex, f_complex)
    for i in range(f_real.shape[0]):
        dW[0, i] = f_real[i]
        dW[1, i] = f_complex[i].real
        dW[2, i] = f_complex[i].imag
    return rad_dw_norm(dW, scale)


@njit
def rad_newton_advance(dW_norm, dW_norm_old, k, tol, maxiter, W, dW, T, Z):
    """Iteration k (from 0) of the simplified Newton iteration after its increment dW, of norm
    dW_norm (the previous one dW_norm_old; HW II, sec. IV.8, eq. 8.10 ff.; scipy):
    rate = dW_norm / dW_norm_old (from k = 1; NaN before). Diverging (rate >= 1) or too slow
    to converge within maxiter iterations (rate^(maxiter - k) / (1 - rate) dW_norm > tol):
    NEWTON_DIVERGING, nothing updated. Else W += dW, Z = T W, and NEWTON_CONVERGED when
    dW_norm = 0 or rate / (1 - rate) dW_norm < tol, else NEWTON_CONTINUE. Returns (code, rate)."""
    rate = math.nan
    if k > 0:
        rate = dW_norm / dW_norm_old
        if rate >= 1.0 or rate ** float(maxiter - k) / (1.0 - rate) * dW_norm > tol:
            return NEWTON_DIVERGING, rate
    for s in range(W.shape[0]):
        for i in range(W.shape[1]):
            W[s, i] += dW[s, i]
    rad_transform(T, W, Z)
    if dW_norm == 0.0 or (k > 0 and rate / (1.0 - rate) * dW_norm < tol):
        return NEWTON_CONVERGED, rate
    return NEWTON_CONTINUE, rate


# --- error estimate and step control ----------------------------------------------------------
@njit
def rad_error_rhs(E, Z, h, f, ZE, b):
    """ZE (n,) = (sum_j E[j] Z[j]) / h and b = f + ZE: the right-hand side of the error
    estimate (HW II, sec. IV.8, eq. 8.19 ff.; scipy: `f + Z.T.dot(E) / h`)."""
    for i in range(f.shape[0]):
        acc = 0.0
        for j in range(3):
            acc += E[j] * Z[j, i]
        ZE[i] = acc / h
        b[i] = f[i] + ZE[i]


@njit
def rad_error(LU_real, piv_real, b, scale):
    """The error estimate err = (MU_REAL/h I - J)^-1 b in place of b (n,); returns
    ||err / scale||_rms."""
    rad_lu_solve(LU_real, piv_real, b)
    return rms_scaled(b, scale)


@njit
def rad_predict_factor(h_abs, h_abs_old, error_norm, error_norm_old):
    """Gustafsson's predictive step-size factor (HW II, sec. IV.8, eq. 8.25; scipy's
    predict_factor): min(1, h/h_old (err_old/err)^(1/4)) err^(-1/4), the first factor 1 when
    there is no previous step (h_old or err_old NaN) or err = 0 (then the factor is inf)."""
    if error_norm_old != error_norm_old or h_abs_old != h_abs_old or error_norm == 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
    return min(1.0, multiplier) * error_norm ** -0.25


@njit
def rad_safety(n_iter, control):
    """SAFETY (2 NEWTON_MAXITER + 1) / (2 NEWTON_MAXITER + n_iter): a step whose Newton
    iteration needed more iterations grows less (radau5.f, scipy)."""
    maxiter = control[C_NEWTON_MAXITER]
    return control[C_SAFETY] * (2.0 * maxiter + 1.0) / (2.0 * maxiter + n_iter)


@njit
def rad_control_rejected(h, h_abs_old, error_norm, error_norm_old, n_iter, control):
    """The trial size after a rejected step h (error_norm > 1): |h| max(MIN_FACTOR, safety
    factor), factor from rad_predict_factor with the last accepted step's memory."""
    factor = rad_predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
    return abs(h) * max(control[C_MIN_FACTOR], rad_safety(n_iter, control) * factor)


@njit
def rad_control_accepted(h, h_try, h_abs_old, error_norm, error_norm_old, n_iter, rate, control):
    """After an accepted step h (tried as h_try: h may be shorter, clipped to t1), whose Newton
    iteration took n_iter iterations at the last rate:

    - the Jacobian is renewed for the next step if Newton was slow (n_iter > RADAU_SLOW_ITER
      and rate > RADAU_SLOW_RATE);
    - factor = min(MAX_FACTOR, safety rad_predict_factor), 1 below RADAU_KEEP_STEP when the
      Jacobian is kept (the step and its LU factors are kept, as scipy and radau5.f);
    - the step-size memory |h| factor, but a step shortened only to land on t1 that went well
      does not shrink it (at least h_try).

    Returns (recompute_jac, the step-size memory)."""
    recompute = n_iter > control[C_SLOW_ITER] and rate > control[C_SLOW_RATE]
    factor = rad_predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
    factor = min(control[C_MAX_FACTOR], rad_safety(n_iter, control) * factor)
    if not recompute and factor < control[C_KEEP_STEP]:
        factor = 1.0
    h_abs = abs(h)
    h_next = h_abs * factor
    if h_abs < h_try and factor >= 1.0:
        h_next = max(h_next, h_try)
    return recompute, h_next


# --- dense output -------------------------------------------------------------------------------
@njit
def rad_dense_coefficients(Z, P, Qt):
    """Qt (3, n): the collocation polynomial of a step, Qt[c, i] = sum_j Z[j, i] P[j, c]
    (scipy: Q = Z.T.dot(P)); y(t_old + x h) = y_old + sum_c Qt[c] x^(c + 1)."""
    for c in range(P.shape[1]):
        for i in range(Z.shape[1]):
            acc = 0.0
            for j in range(Z.shape[0]):
                acc += Z[j, i] * P[j, c]
            Qt[c, i] = acc


@njit
def rad_dense_eval(Qt, y_old, t_old, h, tq, Y):
    """Y (k, n): the dense output at times tq (k,) of the step from (t_old, y_old) of size h,
    x = (t - t_old) / h, (Q0 x + Q1 x^2 + Q2 x^3) + y_old (scipy's RadauDenseOutput, the
    powers as its cumprod)."""
    for r in range(tq.shape[0]):
        x = (tq[r] - t_old) / h
        x2 = x * x
        x3 = x2 * x
        for i in range(y_old.shape[0]):
            Y[r, i] = (Qt[0, i] * x + Qt[1, i] * x2 + Qt[2, i] * x3) + y_old[i]


# --- the "auto" method's hand-back tests on radau's steps --------------------------------------
# One implementation for both drivers of the radau phase of gyro_sim.integrators.auto.Auto:
# its Python loop (Radau's public single step, on any system) and the detection mode of the
# compiled loop (fast_radau.radau_advance) call these on the same state arrays, owned by Auto,
# beside those of dop853_kernels (counters, window, cost: the cost window of dop853_kernels'
# auto_measure):
#
#     handback (HANDBACK_SIZE,) float64  the constants: NONSTIFF_HRHO, COST_MARGIN,
#                                         DOP853_EVALS, DOP853_BOUNDARY, EIG_MAX_SIZE,
#                                         POWER_ITERATIONS (auto.py)
#     easy (EASY_SIZE,) float64           rho(J) of radau's Jacobian (NaN: none yet), 1 while a
#                                         Jacobian refreshed since is waiting for its rho, the
#                                         steps in a row with h rho < NONSTIFF_HRHO, the count of
#                                         them that hands back
#     power (n,) float64                  the start of the power iterations (n > EIG_MAX_SIZE)
HB_NONSTIFF_HRHO, HB_COST_MARGIN, HB_DOP853_EVALS, HB_DOP853_BOUNDARY, HB_EIG_MAX_SIZE, \
    HB_POWER_ITERATIONS = range(6)
HANDBACK_SIZE = 6
EASY_RHO, EASY_STALE, EASY_STEPS, EASY_NEEDED = range(4)
EASY_SIZE = 4

_XGEEV_REAL = None
if _COMPILED:
    try:  # LAPACK's geev as numba's np.linalg.eigvals calls it (scipy's LAPACK)
        _XGEEV_REAL = _LAPACK().numba_ez_rgeev(_types.float64)
    except Exception:  # noqa: BLE001 - another numba layout: eigvals of the complex matrix
        _XGEEV_REAL = None
_JOB_NONE = ord("N")

if _XGEEV_REAL is not None:
    @njit
    def _geev_real(At, wr, wi, v):
        """Eigenvalues wr + i wi of M from At (n, n) = M^T (M column-major; destroyed)."""
        n = At.shape[0]
        return _XGEEV_REAL(_KIND_REAL, _JOB_NONE, _JOB_NONE, n, At.ctypes, n, wr.ctypes, wi.ctypes,
                           v.ctypes, 1, v.ctypes, 1)

    @njit
    def _eig_radius(J):
        """max |eigenvalue| of J (n, n), n > 0, by LAPACK's dgeev."""
        n = J.shape[0]
        At = np.empty((n, n))
        for i in range(n):
            for j in range(n):
                At[j, i] = J[i, j]
        wr, wi, v = np.empty(n), np.empty(n), np.empty(1)
        if _geev_real(At, wr, wi, v) != 0:  # the QR iteration did not converge: no rho, no
            return math.inf  # hand-back by it (numpy's eigvals raises here)
        rho = 0.0
        for i in range(n):
            r = math.hypot(wr[i], wi[i])
            if r > rho or r != r:
                rho = r
        return rho
elif not _COMPILED:  # plain Python: numpy's eigenvalues
    def _eig_radius(J):
        """max |eigenvalue| of J (n, n), n > 0."""
        return float(np.max(np.abs(np.linalg.eigvals(J))))
else:
    @njit
    def _eig_radius(J):
        """max |eigenvalue| of J (n, n), n > 0 (numba's eigvals of the complex matrix, whose
        eigenvalues need no change of domain)."""
        w = np.linalg.eigvals(J.astype(np.complex128))
        rho = 0.0
        for i in range(w.shape[0]):
            r = abs(w[i])
            if r > rho or r != r:
                rho = r
        return rho


@njit
def auto_spectral_radius(J, power, handback):
    """rho(J) = max |eigenvalue| of J (n, n): inf if J is not finite, 0 for n = 0; up to
    EIG_MAX_SIZE states from the eigenvalues (LAPACK's dgeev), above it |J x| after
    POWER_ITERATIONS power iterations from x = power (n,) (x <- J x / |J x|; Golub, Van Loan,
    sec. 7.3.1: an estimate, from below where the dominant eigenvalues are a complex pair)."""
    n = J.shape[0]
    for i in range(n):
        for j in range(n):
            if not (abs(J[i, j]) < math.inf):
                return math.inf
    if n == 0:
        return 0.0
    if n <= handback[HB_EIG_MAX_SIZE]:
        return _eig_radius(J)
    x = power.copy()
    y = np.empty(n)
    rho = 0.0
    for _ in range(int(handback[HB_POWER_ITERATIONS])):
        acc2 = 0.0
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += J[i, j] * x[j]
            y[i] = acc
            acc2 += acc * acc
        rho = math.sqrt(acc2)
        if rho == 0.0:
            return 0.0
        for i in range(n):
            x[i] = y[i] / rho
    return rho


@njit
def auto_nonstiffness_test(h, easy, handback):
    """An accepted radau step h, with rho(J) = easy[EASY_RHO]: h rho < NONSTIFF_HRHO (an
    explicit step of that size is well inside dop853's stability region) counts one more easy
    step in a row, else (or no rho yet) none. True when the count reaches easy[EASY_NEEDED]:
    the problem is not stiff (any more)."""
    rho = easy[EASY_RHO]
    if rho != rho or abs(h) * rho >= handback[HB_NONSTIFF_HRHO]:
        easy[EASY_STEPS] = 0.0
        return False
    easy[EASY_STEPS] += 1.0
    return easy[EASY_STEPS] >= easy[EASY_NEEDED]


@njit
def auto_dop853_cost(cost, easy, handback):
    """dop853's rhs evaluations per simulated second: measured (cost[COST_DOP853]), else
    estimated at its stability limit on the imaginary axis, DOP853_EVALS rho / DOP853_BOUNDARY
    (NaN without rho)."""
    dop = cost[COST_DOP853]
    if dop != dop:
        dop = handback[HB_DOP853_EVALS] * easy[EASY_RHO] / handback[HB_DOP853_BOUNDARY]
    return dop


@njit
def auto_cost_test(cost, counters, window, easy, handback):
    """Radau running, its cost window full: True when radau costs more than COST_MARGIN times
    what dop853 did (or would: auto_dop853_cost)."""
    radau = cost[COST_RADAU]
    if radau != radau or counters[C_WINDOW] < window.shape[0]:
        return False
    dop = auto_dop853_cost(cost, easy, handback)
    return dop == dop and radau > handback[HB_COST_MARGIN] * dop
