"""The gauss4 march compiled with numba: `nsteps` steps of the 2-stage Gauss method in one call.

:func:`gauss_march` is the Python driver of :class:`gyro_sim.integrators.gauss4.driver.Gauss4`
(`_step`, `_substep`, `_newton_dense`, `_newton_krylov`, with the base's projection and
finiteness check) statement for statement, calling the articulated-body kernel
:func:`gyro_sim.dynamics.kernel.rhs_kernel` (through its compiled C function, `fast.rhs_call`; the
canonical field through `fast_canonical.canonical_call`) and the arithmetic of
:mod:`gyro_sim.integrators.gauss4.kernels` (the very functions the Python driver calls): no Python
between two evaluations, and the same steps bit for bit (test/core/test_gauss.py).
:class:`GaussMarch` binds it to a :class:`gyro_sim.dynamics.system.FastChainODE` through the
system's public `kernel_arguments()` and `quaternion_block()`; `Gauss4` uses it when its
system offers them.

The workspace `ws` is the tuple `Gauss4.workspace` builds (its order: :data:`WS_FIELDS`), and
the kernel's arguments `kargs` the tuple `kernel_arguments()` returns: one argument each.

Caching: the march inlines fast.py and gauss_kernels.py, so its numba cache lives in a directory
keyed on all the files it compiles in (:func:`gyro_sim.jit.njit_with_dependencies`): an edit of
any of them starts an empty one.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from gyro_sim.dynamics import kernel as fast, canonical_kernel as fast_canonical
from gyro_sim import jit
from gyro_sim.integrators.rk4 import loop as fast_loop
from gyro_sim.integrators.gauss4 import kernels as gk
from gyro_sim.integrators.gauss4.kernels import (
    COUNT_JACOBIAN, COUNT_KRYLOV, COUNT_LU, COUNT_MAX_KRYLOV, COUNT_MAX_NEWTON, COUNT_MAX_DEPTH,
    COUNT_MAX_STEP_RHS, COUNT_STEPS_RETAKEN, COUNT_NEWTON, COUNT_RETAKEN, COUNT_RHS, COUNT_STALLED,
    DST_FLOOR, DST_H, DST_HPRED, DST_REFRESH, H_REUSE, NEWTON_CONVERGED, NEWTON_DIVERGING,
    NEWTON_NOT_FINITE, NEWTON_STALLED, PAR_BUDGET, PAR_DENSE, PAR_DENSE_CAP, PAR_DENSE_KAPPA,
    PAR_DEPTH, PAR_DIV_REFRESH, PAR_DIVERGE, PAR_FD_EPS, PAR_FIRST_TOL, PAR_FLOOR_FACTOR,
    PAR_GMRES_ATOL, PAR_GMRES_RTOL, PAR_KAPPA, PAR_LEVEL_MAX, PAR_PATIENCE, PAR_NEWTON_CAP,
    PAR_REFRESH_CAP, PAR_REFRESH_KAPPA, PAR_REFRESH_RATE, PAR_STALL, PAR_STALL_RATE, PAR_TOL,
    STEP_BUDGET, STEP_DIVERGED, STEP_LINEAR, STEP_NONFINITE, STEP_NOT_CONVERGED, STEP_OK,
    STEP_RHS_NONFINITE, STEP_SINGULAR,
)

#: the files the march compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(gk.__file__), Path(fast_loop.__file__),
                Path(fast_canonical.__file__), Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)

#: the arrays of the workspace tuple, in order (shapes: n the size, m GMRES_CAP or 0 on the
#: dense path, nd the size on the dense path or 0): stage increments Z, the predictor's Zp,
#: Zp saved at a substep's start, Z before the last update, y at a substep's and at a step's
#: start (n,), stage states
#: Ys, rhs F and Fp (2, n); Yp, w (n,); the Krylov basis V (m + 1, 2, n), H (m + 1, m), cs, sn,
#: coef (m,), g (m + 1,); stage Jacobians J (2, nd, nd), iteration matrix M (2 nd, 2 nd), its
#: pivots piv (2 nd,) int64, the dense residual r (2 nd,); the predictor matrix P (2, 2); the
#: step's coefficients h A (2, 2) (gauss_kernels.gauss_scaled)
WS_FIELDS = ("Z", "Zp", "Zs", "Zb", "ys", "y0", "Ys", "F", "Fp", "Yp", "w", "V", "H", "cs", "sn", "coef", "g",
             "J", "M", "piv", "r", "P", "hA")


def _field(t, y, out, kargs):
    """out = f(t, y): the chain's kernel (fast.rhs_kernel) for a FastChainODE's arguments, the
    canonical one (fast_canonical.canonical_kernel: gauss4s) for a FastCanonicalChain's, which
    are longer; chosen when the march is compiled for the arguments' types."""
    if len(kargs) == fast_canonical.CHAIN_RECORDS:
        fast.rhs_call(t, y, out, *kargs)
    else:
        fast_canonical.canonical_call(t, y, out, *kargs)


if jit.available():
    from numba.extending import overload

    @overload(_field, inline="always")
    def _field_typed(t, y, out, kargs):
        if len(kargs) == fast_canonical.CHAIN_RECORDS:
            return lambda t, y, out, kargs: fast.rhs_call(t, y, out, *kargs)
        return lambda t, y, out, kargs: fast_canonical.canonical_call(t, y, out, *kargs)


@_njit
def _rhs(t, y, out, counts, kargs):
    """out = f(t, y) by the articulated-body kernel (or the canonical one: `_field`), counted."""
    _field(t, y, out, kargs)
    counts[COUNT_RHS] += 1


@_njit
def newton_dense(t, y, h, C, params, dstate, ws, info, counts, kargs):
    """The dense Newton iteration of one (sub)step from the start guess in Z, with the step's
    coefficients in ws's hA (`substep` sets them): Gauss4._newton_dense statement for
    statement. Returns a STEP_ status; Z (2, size) the solution on STEP_OK."""
    Z, Zp, Zs, Zb, ys, y0, Ys, F, Fp, Yp, w, V, H, cs, sn, coef, g, J, M, piv, r, P, hA = ws
    n = y.shape[0]
    tol, kappa, first_tol, diverge = params[PAR_TOL], params[PAR_DENSE_KAPPA], params[PAR_FIRST_TOL], \
        params[PAR_DIVERGE]
    cap, rate, rcap = int(params[PAR_DENSE_CAP]), params[PAR_REFRESH_RATE], int(params[PAR_REFRESH_CAP])
    stall, stall_rate, floor_factor = params[PAR_STALL], params[PAR_STALL_RATE], params[PAR_FLOOR_FACTOR]
    tc = (t + C[0] * h, t + C[1] * h)
    gk.gauss_weights(y, tol, w)
    if abs(dstate[DST_H] - h) > H_REUSE * h:
        dstate[DST_REFRESH] = 1.0
    refreshes = 0
    norm_prev = 0.0
    k = 0
    for it in range(cap):
        counts[COUNT_NEWTON] += 1
        counts[COUNT_MAX_NEWTON] = max(counts[COUNT_MAX_NEWTON], it + 1)
        for st in range(2):
            gk.gauss_stage_state(y, Z, st, Ys[st])
            _rhs(tc[st], Ys[st], F[st], counts, kargs)
        if not gk.all_finite(F):
            return STEP_RHS_NONFINITE
        if dstate[DST_REFRESH] != 0.0:
            for st in range(2):
                for j in range(n):
                    d = gk.jac_perturb(Ys[st], j, Yp)
                    _rhs(tc[st], Yp, Fp[st], counts, kargs)
                    gk.jac_column(Fp[st], F[st], d, J[st], j)
            counts[COUNT_JACOBIAN] += 1
            for st in range(2):
                gk.noise_perturb(Ys[st], Yp)
                _rhs(tc[st], Yp, Fp[st], counts, kargs)
            gk.newton_matrix(J, hA, M)
            counts[COUNT_LU] += 1
            if gk.lu_factor(M, piv) != 0:
                dstate[DST_H] = 0.0
                return STEP_SINGULAR
            gk.noise_residual(Fp, F, hA, r)
            gk.lu_solve(M, piv, r)
            dstate[DST_FLOOR] = gk.noise_floor(gk.scaled_rms(r, w), floor_factor, stall)
            dstate[DST_H] = h
            dstate[DST_REFRESH] = 0.0
            refreshes += 1
            norm_prev = 0.0
            k = 0
        Zb[:, :] = Z
        gk.dense_residual(Z, F, hA, r)
        gk.lu_solve(M, piv, r)
        norm = gk.dense_update(r, w, Z)
        code, theta = gk.newton_test(norm, norm_prev, k, kappa, first_tol, diverge, dstate[DST_FLOOR],
                                     stall_rate)
        info[0], info[1], info[2] = it, theta, norm
        if code == NEWTON_CONVERGED:
            return STEP_OK
        if code == NEWTON_STALLED:
            counts[COUNT_STALLED] += 1
            return STEP_OK
        if code == NEWTON_DIVERGING or code == NEWTON_NOT_FINITE:
            if refreshes >= min(rcap, int(params[PAR_DIV_REFRESH])):
                return STEP_DIVERGED if code == NEWTON_DIVERGING else STEP_LINEAR
            Z[:, :] = Zb  # back to the last iterate, and a Jacobian there
            dstate[DST_REFRESH] = 1.0
            norm_prev = 0.0
            k = 0
            continue
        if k > 0 and refreshes < rcap and gk.refresh_wanted(theta, norm, cap - 1 - it,
                                                            params[PAR_REFRESH_KAPPA], rate):
            dstate[DST_REFRESH] = 1.0
        norm_prev = norm
        k += 1
    return STEP_NOT_CONVERGED


@_njit
def newton_krylov(t, y, h, C, params, ws, info, counts, kargs):
    """The Newton-Krylov iteration of one (sub)step from the start guess in Z, with ws's hA:
    Gauss4._newton_krylov statement for statement. Returns a STEP_ status."""
    Z, Zp, Zs, Zb, ys, y0, Ys, F, Fp, Yp, w, V, H, cs, sn, coef, g, J, M, piv, r, P, hA = ws
    n = y.shape[0]
    m = H.shape[1]
    tol, kappa, first_tol, diverge = params[PAR_TOL], params[PAR_KAPPA], params[PAR_FIRST_TOL], \
        params[PAR_DIVERGE]
    grtol, gatol, eps = params[PAR_GMRES_RTOL], params[PAR_GMRES_ATOL], params[PAR_FD_EPS]
    newton_cap = int(params[PAR_NEWTON_CAP])
    stall, stall_rate = params[PAR_STALL], params[PAR_STALL_RATE]
    inv_eps = 1.0 / eps
    tc = (t + C[0] * h, t + C[1] * h)
    gk.gauss_weights(y, tol, w)
    norm_prev = 0.0
    for it in range(newton_cap):
        counts[COUNT_NEWTON] += 1
        counts[COUNT_MAX_NEWTON] = max(counts[COUNT_MAX_NEWTON], it + 1)
        for st in range(2):
            gk.gauss_stage_state(y, Z, st, Ys[st])
            _rhs(tc[st], Ys[st], F[st], counts, kargs)
        if not gk.all_finite(F):
            return STEP_RHS_NONFINITE
        beta = gk.gmres_start(Z, F, hA, w, V, g)
        if beta == 0.0:
            return STEP_OK
        goal = gk.gmres_goal(beta, grtol, gatol, n)
        j = 0
        while j < m:
            for st in range(2):
                gk.gauss_perturbed(Ys[st], w, V[j], st, eps, Yp)
                _rhs(tc[st], Yp, Fp[st], counts, kargs)
            gk.gauss_operator(V[j], Fp, F, hA, w, inv_eps, V[j + 1])
            res = gk.gmres_arnoldi(V, H, cs, sn, g, j)
            j += 1
            if res <= goal:
                break
        counts[COUNT_KRYLOV] += j
        counts[COUNT_MAX_KRYLOV] = max(counts[COUNT_MAX_KRYLOV], j)
        norm = gk.gmres_update(V, H, g, j, w, Z, coef)
        code, theta = gk.newton_test(norm, norm_prev, it, kappa, first_tol, diverge, stall, stall_rate)
        info[0], info[1], info[2] = it, theta, norm
        if code == NEWTON_CONVERGED:
            return STEP_OK
        if code == NEWTON_STALLED:
            counts[COUNT_STALLED] += 1
            return STEP_OK
        if code == NEWTON_DIVERGING:
            return STEP_DIVERGED
        if code == NEWTON_NOT_FINITE:
            return STEP_LINEAR
        norm_prev = norm
    return STEP_NOT_CONVERGED


class Method(NamedTuple):
    """Gauss4's coefficients (gyro_sim.integrators.gauss4.driver.Gauss4): A, C, D."""

    A: np.ndarray
    C: np.ndarray
    D: np.ndarray


class State(NamedTuple):
    """What a march keeps across calls and reports: dstate (gauss_kernels.DST_*), info (3,),
    counts (COUNT_*)."""

    dstate: np.ndarray
    info: np.ndarray
    counts: np.ndarray


@_njit
def substep(t, y, h, method, params, state, ws, i_q0, nq, kargs):
    """One (sub)step of size h from (t, y): Gauss4._substep statement for statement. Sets ws's
    hA (gauss_kernels.gauss_scaled), starts Newton from the previous (sub)step's collocation
    polynomial extrapolated (its step in dstate[DST_HPRED], 0: from Z = 0); on success
    y += D . Z (gauss_kernels.gauss_update), its quaternions renormalised, and Z kept as the
    next predictor's. method (Method), state (State)."""
    A, C, D = method
    dstate, info, counts = state
    Z, Zp, Zs, Zb, ys, y0, Ys, F, Fp, Yp, w, V, H, cs, sn, coef, g, J, M, piv, r, P, hA = ws
    hp = dstate[DST_HPRED]
    if hp > 0.0:
        gk.predictor_matrix(C, h / hp, P)
        gk.gauss_predict(Zp, P, Z)
    else:
        Z[:, :] = 0.0
    gk.gauss_scaled(A, h, hA)
    if params[PAR_DENSE] != 0.0:
        status = newton_dense(t, y, h, C, params, dstate, ws, info, counts, kargs)
    else:
        status = newton_krylov(t, y, h, C, params, ws, info, counts, kargs)
    if status != STEP_OK:
        return status
    gk.gauss_update(y, Z, F, hA, h, D)
    Zp[:, :] = Z
    dstate[DST_HPRED] = h
    fast.normalize_quaternions(y, i_q0, nq)
    return STEP_OK


@_njit
def gauss_march(t0, h, nsteps, y, method, params, state, ws, i_q0, nq, kargs):
    """`nsteps` gauss4 steps of size h from (t0, y), y (size,) in place; step k starts at
    t0 + k h: Gauss4._step statement for statement. A (sub)step whose Newton iteration fails is
    taken again as two halves, down to h / 2^depth (depth = params[PAR_DEPTH]), and the pieces
    coarsen again after it (gauss_kernels.retake_next), at most params[PAR_BUDGET] (sub)step
    attempts a step; a step starts in pieces of h / 2^level, the level kept across steps and
    calls (gauss_kernels.level_start, level_next); the quaternions y[i_q0 + 4 j : +4], j < nq,
    are renormalised after each (sub)step and the state checked finite after each step.

    Returns (steps done, status): (nsteps, STEP_OK), or (k, status) when step k failed: y is
    then its start (Newton failure) or its non-finite result (STEP_NONFINITE). info (3,) holds
    the last Newton iteration, rate, update norm; counts is incremented; dstate
    (gauss_kernels.DST_*) carries the dense path's matrix and the predictor across calls;
    params as gauss_kernels.PAR_*; ws the workspace (WS_FIELDS); kargs the arguments of
    fast.rhs_kernel after (t, y, out). method (Method): A, C, D; state (State): dstate, info,
    counts.
    """
    dstate, info, counts = state
    Z, Zp, Zs, Zb, ys, y0, Ys, F, Fp, Yp, w, V, H, cs, sn, coef, g, J, M, piv, r, P, hA = ws
    max_depth = int(params[PAR_DEPTH])
    budget = int(params[PAR_BUDGET])
    end = 1 << max_depth
    unit = h / end
    level_max, patience = int(params[PAR_LEVEL_MAX]), params[PAR_PATIENCE]
    for k in range(nsteps):
        t = t0 + k * h
        before = counts[COUNT_RHS]
        y0[:] = y
        pos = 0
        level = gk.level_start(h, dstate, max_depth)
        depth = level
        attempts = 0
        retaken = False
        status = STEP_OK
        while pos < end:
            ys[:] = y
            Zs[:, :] = Zp
            hs = dstate[DST_HPRED]
            status = substep(t + pos * unit, y, h / (1 << depth), method, params, state, ws, i_q0, nq, kargs)
            attempts += 1
            if status != STEP_OK:
                y[:] = ys
                Zp[:, :] = Zs
                dstate[DST_HPRED] = hs
                counts[COUNT_RETAKEN] += 1
                if not retaken:
                    counts[COUNT_STEPS_RETAKEN] += 1
                retaken = True
            pos, depth = gk.retake_next(status == STEP_OK, pos, depth, max_depth, level)
            if depth > max_depth:
                break
            counts[COUNT_MAX_DEPTH] = max(counts[COUNT_MAX_DEPTH], depth)
            if attempts >= budget and pos < end:
                if status == STEP_OK:
                    status = STEP_BUDGET
                break
        counts[COUNT_MAX_STEP_RHS] = max(counts[COUNT_MAX_STEP_RHS], counts[COUNT_RHS] - before)
        if status != STEP_OK:
            y[:] = y0
            dstate[DST_HPRED] = 0.0
            dstate[DST_H] = 0.0
            return k, status
        gk.level_next(level, retaken, dstate, level_max, patience)
        if not fast_loop.finite(y):
            return k, STEP_NONFINITE
    return nsteps, STEP_OK


class GaussMarch:
    """:func:`gauss_march` bound to a FastChainODE `system` (its kernel arguments read at every
    call: they change with `hold`); called through `jit.Direct` (the types stay the
    same). Counts the rhs evaluations in `system.nfev`, as `gyro_sim.integrators.rk4.loop.ErkMarch` does."""

    def __init__(self, system):
        self.system = system
        self._march = jit.Direct(gauss_march)

    def __call__(self, t0, y, h, nsteps, A, C, D, params, dstate, ws, info, counts) -> tuple[int, int, int]:
        """(steps done, status, rhs evaluations) of `nsteps` steps (see gauss_march)."""
        if y.shape != (self.system.size,) or y.dtype != np.float64 or not y.flags.c_contiguous:
            raise ValueError(f"y must be a contiguous float64 array of shape ({self.system.size},)")
        i_q0, nq = self.system.quaternion_block()
        before = int(counts[COUNT_RHS])
        done, status = self._march(float(t0), float(h), int(nsteps), y, Method(A, C, D), params,
                                   State(dstate, info, counts), ws, int(i_q0), int(nq),
                                   self.system.kernel_arguments())
        calls = int(counts[COUNT_RHS]) - before
        self.system.nfev += calls
        return int(done), int(status), calls
