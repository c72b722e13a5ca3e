"""The gauss4 march compiled with numba: `nsteps` steps of the 2-stage Gauss method in one call.

:func:`gauss_march` is the Python driver :meth:`gyro_sim.core.integrators.gauss.Gauss4._newton`
(with `_step` and the base's projection and finiteness check) statement for statement, calling
the articulated-body kernel :func:`gyro_sim.core.fast.rhs_kernel` directly and the arithmetic
of :mod:`gyro_sim.core.gauss_kernels` (the very functions the Python driver calls): no Python
between two evaluations, and the same steps bit for bit (test/core/test_gauss.py).
:class:`GaussMarch` binds it to a :class:`gyro_sim.core.system.FastChainODE` through the
system's public `kernel_arguments()` and `quaternion_block()`; `Gauss4` uses it when its
system offers them.

Caching as :mod:`gyro_sim.core.fast_loop`: the march inlines fast.py and gauss_kernels.py, so
its numba cache lives in a directory keyed on all the files it compiles in
(`fast_loop.njit_with_dependencies`): an edit of any of them starts an empty one.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import fast, fast_loop
from . import gauss_kernels as gk
from .gauss_kernels import (
    COUNT_KRYLOV,
    COUNT_MAX_KRYLOV,
    COUNT_MAX_NEWTON,
    COUNT_NEWTON,
    COUNT_RHS,
    COUNT_STALLED,
    NEWTON_CONVERGED,
    NEWTON_DIVERGING,
    NEWTON_NOT_FINITE,
    NEWTON_STALLED,
    PAR_DIVERGE,
    PAR_FD_EPS,
    PAR_FIRST_TOL,
    PAR_GMRES_ATOL,
    PAR_GMRES_RTOL,
    PAR_KAPPA,
    PAR_NEWTON_CAP,
    PAR_STALL,
    PAR_STALL_RATE,
    PAR_TOL,
    STEP_DIVERGED,
    STEP_LINEAR,
    STEP_NONFINITE,
    STEP_NOT_CONVERGED,
    STEP_OK,
    STEP_RHS_NONFINITE,
)

#: the files the march compiles in (the key of its cache directory)
DEPENDENCIES = (Path(fast.__file__), Path(gk.__file__), Path(fast_loop.__file__), Path(__file__))
_njit = fast_loop.njit_with_dependencies(*DEPENDENCIES)


@_njit
def gauss_march(t0, h, nsteps, y, A, C, D, P0, use_p0, P1, use_p1, params, Zp, Z, Ys, F, Fp, Yp,
                w, V, H, cs, sn, g, coef, info, counts, i_q0, nq,
                work, is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment,
                inertia, lam_speed, torque_body, torque_axis, torque_A, flags, base,
                ht0, p0, pdot, L_rotor, tau):
    """`nsteps` gauss4 steps of size h from (t0, y), y (size,) in place; step k starts at
    t0 + k h. The first step starts Newton from P0 Zp (use_p0) or 0, the others from P1 Zp
    (use_p1) or 0; Zp (2, size) ends as the last step's stage increments. After each step the
    quaternions y[i_q0 + 4 j : +4], j < nq, are renormalised and the state checked finite.
    The Newton iteration of a step is Gauss4._newton statement for statement (written out
    here, not called: one function less for numba and LLVM to compile).

    Returns (steps done, status): (nsteps, STEP_OK), or (k, status) when step k failed: y is
    then its start (Newton failure) or its non-finite result (STEP_NONFINITE). info (3,) holds
    the last Newton iteration, rate, update norm; counts (6,) is incremented. The arguments
    from `work` on are those of fast.rhs_kernel (`ht0` its `t0`, the start of the hold);
    params as gauss_kernels.PAR_*; the rest scratch of Gauss4's shapes.
    """
    n = y.shape[0]
    m = H.shape[1]
    tol, kappa, first_tol, diverge = params[PAR_TOL], params[PAR_KAPPA], params[PAR_FIRST_TOL], \
        params[PAR_DIVERGE]
    grtol, gatol, eps = params[PAR_GMRES_RTOL], params[PAR_GMRES_ATOL], params[PAR_FD_EPS]
    newton_cap = int(params[PAR_NEWTON_CAP])
    stall, stall_rate = params[PAR_STALL], params[PAR_STALL_RATE]
    inv_eps = 1.0 / eps
    hA = A * h
    for k in range(nsteps):
        t = t0 + k * h
        tc = (t + C[0] * h, t + C[1] * h)
        gk.gauss_weights(y, tol, w)
        if k == 0 and use_p0:
            gk.gauss_predict(Zp, P0, Z)
        elif k > 0 and use_p1:
            gk.gauss_predict(Zp, P1, Z)
        else:
            Z[:, :] = 0.0
        status = STEP_NOT_CONVERGED
        norm_prev = 0.0
        for it in range(newton_cap):
            counts[COUNT_NEWTON] += 1
            counts[COUNT_MAX_NEWTON] = max(counts[COUNT_MAX_NEWTON], it + 1)
            for st in range(2):
                gk.gauss_stage_state(y, Z, st, Ys[st])
                fast.rhs_kernel(tc[st], Ys[st], F[st], work, is_hinge, qrow, own_col, col_start,
                                hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
                                torque_axis, torque_A, flags, base, ht0, p0, pdot, L_rotor, tau)
                counts[COUNT_RHS] += 1
            if not gk.all_finite(F):
                status = STEP_RHS_NONFINITE
                break
            beta = gk.gmres_start(Z, F, hA, w, V, g)
            if beta == 0.0:
                status = STEP_OK
                break
            goal = gk.gmres_goal(beta, grtol, gatol, n)
            j = 0
            while j < m:
                for st in range(2):
                    gk.gauss_perturbed(Ys[st], w, V[j], st, eps, Yp)
                    fast.rhs_kernel(tc[st], Yp, Fp[st], work, is_hinge, qrow, own_col, col_start,
                                    hinge_axis, s, mass, first_moment, inertia, lam_speed,
                                    torque_body, torque_axis, torque_A, flags, base, ht0, p0, pdot,
                                    L_rotor, tau)
                    counts[COUNT_RHS] += 1
                gk.gauss_operator(V[j], Fp, F, hA, w, inv_eps, V[j + 1])
                res = gk.gmres_arnoldi(V, H, cs, sn, g, j)
                j += 1
                if res <= goal:
                    break
            counts[COUNT_KRYLOV] += j
            counts[COUNT_MAX_KRYLOV] = max(counts[COUNT_MAX_KRYLOV], j)
            norm = gk.gmres_update(V, H, g, j, w, Z, coef)
            code, theta = gk.newton_test(norm, norm_prev, it, kappa, first_tol, diverge, stall,
                                         stall_rate)
            info[0], info[1], info[2] = it, theta, norm
            if code == NEWTON_CONVERGED:
                status = STEP_OK
                break
            if code == NEWTON_STALLED:
                counts[COUNT_STALLED] += 1
                status = STEP_OK
                break
            if code == NEWTON_DIVERGING:
                status = STEP_DIVERGED
                break
            if code == NEWTON_NOT_FINITE:
                status = STEP_LINEAR
                break
            norm_prev = norm
        if status != STEP_OK:
            return k, status
        gk.gauss_update(y, Z, D)
        Zp[:, :] = Z
        fast.normalize_quaternions(y, i_q0, nq)
        if not _all_finite_1d(y):
            return k, STEP_NONFINITE
    return nsteps, STEP_OK


@_njit
def _all_finite_1d(y):
    """True when every entry of y (size,) is finite."""
    for i in range(y.shape[0]):
        if not (abs(y[i]) < np.inf):
            return False
    return True


class GaussMarch:
    """:func:`gauss_march` bound to a FastChainODE `system` (its kernel arguments read at every
    call: they change with `hold`); called through `fast_loop.Direct` (the types stay the
    same). Counts the rhs evaluations in `system.nfev`, as `march_explicit_rk` does."""

    def __init__(self, system):
        self.system = system
        self._march = fast_loop.Direct(gauss_march)

    def __call__(self, t0, y, h, nsteps, A, C, D, P0, P1, params, Zp, Z, Ys, F, Fp, Yp, w, V, H,
                 cs, sn, g, coef, info, counts) -> tuple[int, int, int]:
        """(steps done, status, rhs evaluations) of `nsteps` steps (see gauss_march); P0 or P1
        None: Newton starts from Z = 0 there."""
        if y.shape != (self.system.size,) or y.dtype != np.float64 or not y.flags.c_contiguous:
            raise ValueError(f"y must be a contiguous float64 array of shape ({self.system.size},)")
        i_q0, nq = self.system.quaternion_block()
        before = int(counts[COUNT_RHS])
        done, status = self._march(
            float(t0), float(h), int(nsteps), y, A, C, D,
            P0 if P0 is not None else P1 if P1 is not None else np.zeros((2, 2)), int(P0 is not None),
            P1 if P1 is not None else np.zeros((2, 2)), int(P1 is not None), params, Zp, Z, Ys, F,
            Fp, Yp, w, V, H, cs, sn, g, coef, info, counts, int(i_q0), int(nq),
            *self.system.kernel_arguments())
        calls = int(counts[COUNT_RHS]) - before
        self.system.nfev += calls
        return int(done), int(status), calls
