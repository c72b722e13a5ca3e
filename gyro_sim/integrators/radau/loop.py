"""Radau IIA's whole `advance` compiled with numba: every step of a call in one compiled call.

:func:`radau_advance` is what :meth:`gyro_sim.integrators.radau.driver.Radau.advance` does in
Python in its dense mode (`AdaptiveIntegrator._integrate`: `begin`, then `take_step` and
`dense` until t1, then `end`): the fresh rhs at the start and the starting step, the
forward-difference Jacobian and the two LU factorisations with their reuse rules, the
simplified Newton iteration, the error estimate and step control (accepted and rejected
steps), the collocation polynomial as dense output at the requested times and as the next
Newton start, the renormalisation of the quaternions of every accepted state and output,
the finite checks. It calls the articulated-body kernel :func:`gyro_sim.dynamics.kernel.rhs_kernel`
(through its compiled C function, `fast.rhs_call`) and the arithmetic of :mod:`gyro_sim.integrators.radau.kernels`
(the starting step that of :mod:`gyro_sim.integrators.dop853.kernels`), the very functions the Python driver calls
between its rhs evaluations on other systems: the two drivers give the same bits.

Its detection mode runs the "auto" method's radau phase
(:class:`gyro_sim.integrators.auto.Auto`): rho(J) whenever the Jacobian is refreshed,
and after every accepted step Auto's tests on h rho and on the cost (radau_kernels.auto_*,
dop853_kernels.auto_measure), returning at the accepted state where one asks for the
hand-back to dop853; the Python loop Auto runs on other systems calls the same kernels on the
same state.

Radau dispatches to it when its system offers `kernel_arguments` and `quaternion_block` (the
compiled :class:`gyro_sim.dynamics.system.FastChainODE`), has no `jacobian`, and is at most
DENSE_MAX states (the matrix-free mode steps in Python), through :func:`loop_for`: one
:class:`gyro_sim.jit.Direct` per process and types of the kernel's arguments.

The integrator's memory between calls (step sizes, the Jacobian and its LU factors, the
collocation polynomial, where the last call ended) lives in the arrays passed in: `mem`
(MEM_SIZE floats, the M_* slots) and `flags` (FLAGS_SIZE integers, the F_* slots, which also
return the counts and the status of the call).

Caching: the loop inlines fast.py, radau_kernels.py and dop853_kernels.py, so it is cached in a
directory keyed on all four files (:func:`gyro_sim.jit.njit_with_dependencies`).

References
----------
.. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II: Stiff and
       Differential-Algebraic Problems", 2nd ed., Springer 1996, sec. IV.8.
.. [2] scipy.integrate.Radau (scipy/integrate/_ivp/radau.py, scipy 1.17).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np


from gyro_sim.integrators.adaptive_kernels import (  # what the loop returns in flags[F_STATUS] (its reasons)
    ACCEPTED_RHS_NONFINITE, COLLAPSED, DONE, INITIAL_RHS_NONFINITE, NO_STARTING_STEP, REASON_COSTLY,
    REASON_NONSTIFF, SWITCH, clip_step,
)
from gyro_sim.dynamics import kernel as fast
from gyro_sim import jit
from gyro_sim.integrators.radau import kernels as radau_kernels
from gyro_sim.integrators.dop853.kernels import (
    COST_RADAU, auto_measure, dop_initial_probe, dop_initial_step,
)
from gyro_sim.integrators.radau.kernels import (
    C_LAST_STEP_STRETCH, C_LU_REUSE_RTOL, C_MIN_FACTOR, C_MIN_STEP_RELATIVE, C_NEWTON_FAIL_FACTOR,
    C_NEWTON_MAXITER, EASY_RHO, EASY_STALE, NEWTON_CONVERGED, NEWTON_DIVERGING, auto_cost_test,
    auto_nonstiffness_test, auto_spectral_radius, rad_add, rad_control_accepted,
    rad_control_rejected, rad_dense_coefficients, rad_dense_eval, rad_error, rad_error_rhs,
    rad_factor, rad_fd_column, rad_fd_delta, rad_finite, rad_finite_rows, rad_newton_advance,
    rad_newton_increment, rad_newton_residual, rad_predict, rad_scale, rad_stage_state,
    rad_transform,
)

#: the files the loop compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, *radau_kernels.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)

#: the order of Radau's error estimator (the starting step's exponent)
ORDER_OF_ESTIMATOR = 3
#: non-finite trials, as Radau names them (radau.NONFINITE_*): stages, the state, the error
NONFINITE_STAGES, NONFINITE_STATE, NONFINITE_ERROR = 1, 2, 3

#: layout of `mem`: the step-size memory (0: select the starting step), the last accepted step
#: and its error norm (NaN: none), the step of the LU factors (NaN: none), the collocation
#: polynomial's start and size, where the last call ended (NaN: none), error norm and size of
#: the last accepted step (NaN: none); outputs: the time reached (or of a failure), the step of
#: a failure, the start of the last step
MEM_SIZE = 12
(M_H_ABS, M_H_ABS_OLD, M_ERROR_OLD, M_LU_H, M_SOL_T, M_SOL_H, M_T_END, M_ERROR, M_LAST_STEP,
 M_T, M_H, M_T_OLD) = range(MEM_SIZE)
#: layout of `flags`: a Jacobian is there, taken at the current state, to be renewed; LU factors
#: are there; a collocation polynomial is there (all 0/1, in and out); outputs: the status,
#: rhs evaluations, Jacobians, LU factorisations, accepted and rejected steps, outputs filled,
#: whether f = rhs(y_new) is known, the non-finite trial of a failing step, the steps traced,
#: the reason of a SWITCH
FLAGS_SIZE = 16
(F_HAS_J, F_CURRENT_JAC, F_RECOMPUTE_JAC, F_HAS_LU, F_HAS_SOL, F_STATUS, F_NFEV, F_NJEV, F_NLU,
 F_ACCEPTED, F_REJECTED, F_OUTPUTS, F_F_NEW, F_NONFINITE, F_TRACED, F_REASON) = range(FLAGS_SIZE)


@_njit
def _fd_jacobian(t, y, f, J, fd_rel_step, fd_min_scale, delta, ys, fj,
                 model, data, inputs):
    """J (size, size) = d rhs / dy at (t, y) by forward differences around f = rhs(t, y)
    (Radau._jacobian: rad_fd_delta, one rhs evaluation and rad_fd_column a column); delta, ys,
    fj (size,) scratch. Returns the rhs evaluations (size)."""
    n = y.shape[0]
    rad_fd_delta(y, fd_rel_step, fd_min_scale, delta)
    ys[:] = y
    for c in range(n):
        ys[c] = y[c] + delta[c]
        fast.rhs_call(t, ys, fj, model, data, inputs)
        rad_fd_column(J, c, fj, f, delta[c])
        ys[c] = y[c]
    return n


class Outputs(NamedTuple):
    """The states asked of a call: Y (m, size) at te (m,), sorted within [t0, t1]."""

    te: np.ndarray
    Y: np.ndarray


class Options(NamedTuple):
    """A call's options, the forward-difference Jacobian's, and where the state's quaternions are."""

    max_step: float
    rtol: float
    atol: np.ndarray
    newton_tol: float
    fd_rel_step: float
    fd_min_scale: float
    i_q0: int
    nq: int


class Method(NamedTuple):
    """Radau IIA's constants (the class attributes of gyro_sim.integrators.radau.driver.Radau) and the controller's."""

    C: np.ndarray
    E: np.ndarray
    T: np.ndarray
    TI: np.ndarray
    P: np.ndarray
    mu_real: np.ndarray
    mu_complex: np.ndarray
    control: np.ndarray
    initial: np.ndarray


class State(NamedTuple):
    """What the loop keeps between calls (J, its LU factors, the collocation polynomial, mem, flags), and its scratch
    (see radau_advance)."""

    f: np.ndarray
    J: np.ndarray
    LU_real: np.ndarray
    piv_real: np.ndarray
    LU_complex: np.ndarray
    piv_complex: np.ndarray
    Z0: np.ndarray
    Z: np.ndarray
    W: np.ndarray
    dW: np.ndarray
    F: np.ndarray
    ys: np.ndarray
    f_real: np.ndarray
    f_complex: np.ndarray
    scale: np.ndarray
    delta: np.ndarray
    ZE: np.ndarray
    err: np.ndarray
    fe: np.ndarray
    y_new: np.ndarray
    y_old: np.ndarray
    y_bad: np.ndarray
    bad: np.ndarray
    Qt: np.ndarray
    sol_y: np.ndarray
    y_end: np.ndarray
    trace: np.ndarray
    mem: np.ndarray
    flags: np.ndarray


class Detection(NamedTuple):
    """The detection mode's state (dop853_kernels, radau_kernels), carried from call to call; `handback` empty: off."""

    counters: np.ndarray
    window: np.ndarray
    cost: np.ndarray
    handback: np.ndarray
    easy: np.ndarray
    power: np.ndarray


@_njit
def radau_advance(t0, t1, y, outputs, options, method, state, detection, model, data, inputs):
    """Radau IIA from (t0, y) to exactly t1 > t0, y (size,) in place; outputs.Y (m, size) the
    states at outputs.te (m,), sorted within [t0, t1]. The records: Outputs, Options, Method,
    State, Detection (their fields are named below as in the loop).

    The call starts with a fresh f = rhs(t0, y) (inputs may have changed since the last call);
    with mem[M_H_ABS] = 0 (the first call after a reset) the starting step is selected here
    (one more rhs evaluation). C, E (3,), T, TI, P (3, 3), mu_real, mu_complex: the method
    (Radau's class attributes); control, initial: the constants of radau_kernels
    (CONTROL_SIZE) and dop853_kernels (INITIAL_SIZE); fd_rel_step, fd_min_scale: the
    forward-difference Jacobian's. Quaternions y[i_q0 + 4 j : +4], j < nq.
    The memory between calls: J (size, size), its LU factors LU_real, piv_real, LU_complex
    (complex), piv_complex; Qt (3, size) and sol_y (size,): the collocation polynomial of the
    last step; y_end (size,): where the last call ended; mem, flags (see the M_* and F_*
    slots). Scratch, left as the Python driver leaves its own: Z0, Z, W, dW, F (3, size),
    ys, scale, delta, ZE, err, fe, y_new, y_old (size,), f_real (size,), f_complex (size,
    complex); y_bad (size,) and bad (3,): the state or stages of the last non-finite trial.
    trace (k,): the ends of the first k accepted steps (k may be 0). model, data, inputs:
    fast.rhs_kernel's records.

    Detection mode (handback not empty), the "auto" method's radau phase
    (gyro_sim.integrators.auto.Auto, whose Python loop over Radau's public single step
    does the same on other systems): after every accepted step, as in that loop, rho(J) of
    the Jacobian in use if it was refreshed since the last rho (radau_kernels.
    auto_spectral_radius; `power` (size,) the start of its power iterations), the
    non-stiffness test on h rho, the cost window (dop853_kernels.auto_measure) and, if the
    first did not fire, the cost test (radau_kernels.auto_*); a hand-back asked for before t1
    ends the call there (SWITCH, as a call that ended there: the next continues from it). The
    tests' state: counters, window, cost (dop853_kernels), handback, easy (radau_kernels),
    carried from call to call. Off, these are not read (empty or not).
    """
    te, Y = outputs
    max_step, rtol, atol, newton_tol, fd_rel_step, fd_min_scale, i_q0, nq = options
    C, E, T, TI, P, mu_real, mu_complex, control, initial = method
    (f, J, LU_real, piv_real, LU_complex, piv_complex, Z0, Z, W, dW, F, ys, f_real, f_complex, scale, delta,
     ZE, err, fe, y_new, y_old, y_bad, bad, Qt, sol_y, y_end, trace, mem, flags) = state
    counters, window, cost, handback, easy, power = detection
    detecting = handback.shape[0] > 0
    m = te.shape[0]
    nfev = 0
    nfev_measured = 0  # nfev at the end of the last step measured (detection mode)
    njev = 0
    nlu = 0
    naccepted = 0
    nrejected = 0
    maxiter = int(control[C_NEWTON_MAXITER])
    h_mem = mem[M_H_ABS]
    h_abs_old_mem = mem[M_H_ABS_OLD]
    error_old_mem = mem[M_ERROR_OLD]
    lu_h = mem[M_LU_H]
    sol_t = mem[M_SOL_T]
    sol_h = mem[M_SOL_H]
    error = mem[M_ERROR]
    last_step = mem[M_LAST_STEP]
    has_J = flags[F_HAS_J] != 0
    current_jac = flags[F_CURRENT_JAC] != 0
    recompute_jac = flags[F_RECOMPUTE_JAC] != 0
    has_lu = flags[F_HAS_LU] != 0
    has_sol = flags[F_HAS_SOL] != 0
    status = DONE
    nonfinite = 0
    f_new = False
    t_fail = t0
    h_fail = 0.0
    reason = 0
    j = 0
    while j < m and te[j] <= t0:
        Y[j, :] = y
        j += 1
    # --- begin: a fresh rhs, the starting step, is this call a continuation?
    fast.rhs_call(t0, y, f, model, data, inputs)
    nfev += 1
    if not rad_finite(f):
        status = INITIAL_RHS_NONFINITE
        t_fail = t0
    else:
        if h_mem <= 0.0:  # F[0] and F[1] as scratch
            sc, f1 = F[0], F[1]
            h0, d1 = dop_initial_probe(y, f, rtol, atol, t1 - t0, initial, sc, ys)
            if h0 > 0.0:
                fast.rhs_call(t0 + h0, ys, f1, model, data, inputs)
                nfev += 1
                h_mem = dop_initial_step(f, f1, sc, h0, d1, t1 - t0, max_step, ORDER_OF_ESTIMATOR,
                                         initial)
            else:
                status = NO_STARTING_STEP
                t_fail = t0
                h_fail = d1
    if status == DONE:
        continuation = mem[M_T_END] == t0
        if continuation:
            for i in range(y.shape[0]):
                if y[i] != y_end[i]:
                    continuation = False
                    break
        if not continuation:
            has_sol = False
            current_jac = False
    t = t0
    t_old = t0
    min_step_relative, stretch = control[C_MIN_STEP_RELATIVE], control[C_LAST_STEP_STRETCH]
    while status == DONE and t < t1:
        # --- one accepted step (Radau._step_impl)
        min_step = min_step_relative * max(abs(t), abs(t1))
        if h_mem > max_step:
            h_abs, h_abs_old, error_old = max_step, math.nan, math.nan
        else:
            h_abs, h_abs_old, error_old = h_mem, h_abs_old_mem, error_old_mem
        nonfinite = 0
        rejected = False
        h = 0.0
        t_new = t
        n_iter = 0
        rate = math.nan
        error_norm = math.nan
        if not has_J or recompute_jac:  # the Jacobian at (t, y) (Radau._jacobian)
            nfev += _fd_jacobian(t, y, f, J, fd_rel_step, fd_min_scale, delta, ys, fe, model, data, inputs)
            njev += 1
            has_J = True
            has_lu = False
            current_jac = True
            recompute_jac = False
            if detecting:
                easy[EASY_STALE] = 1.0
        while True:
            if h_abs < min_step:
                status = COLLAPSED
                t_fail = t
                h_fail = h_abs
                break
            h, t_new = clip_step(t, h_abs, t1, stretch)
            if has_sol:
                rad_predict(Qt, sol_t, sol_h, sol_y, t, h, C, y, Z0)
            else:
                Z0[:, :] = 0.0
            rad_scale(y, y, rtol, atol, scale)
            converged = False
            while True:
                if not has_lu or abs(h - lu_h) > control[C_LU_REUSE_RTOL] * h:
                    rad_factor(J, h, mu_real, mu_complex, LU_real, piv_real, LU_complex, piv_complex)
                    nlu += 2
                    lu_h = h
                    has_lu = True
                # the simplified Newton iteration (Radau._newton)
                rad_transform(TI, Z0, W)
                Z[:, :] = Z0
                dW_norm_old = math.nan
                rate = math.nan
                for k in range(maxiter):
                    n_iter = k + 1
                    for st in range(3):
                        rad_stage_state(y, Z, st, ys)
                        fast.rhs_call(t + h * C[st], ys, F[st], model, data, inputs)
                        nfev += 1
                    if not rad_finite_rows(F, bad):
                        nonfinite = NONFINITE_STAGES
                        break
                    rad_newton_residual(F, W, TI, h, mu_real, mu_complex, f_real, f_complex)
                    dW_norm = rad_newton_increment(LU_real, piv_real, LU_complex, piv_complex,
                                                   f_real, f_complex, scale, dW)
                    code, rate = rad_newton_advance(dW_norm, dW_norm_old, k, newton_tol, maxiter,
                                                    W, dW, T, Z)
                    if code == NEWTON_DIVERGING:
                        break
                    if code == NEWTON_CONVERGED:
                        converged = True
                        break
                    dW_norm_old = dW_norm
                if converged or current_jac:
                    break
                # failed with an old Jacobian: a new one at (t, y), the same step again
                nfev += _fd_jacobian(t, y, f, J, fd_rel_step, fd_min_scale, delta, ys, fe, model, data, inputs)
                njev += 1
                has_lu = False
                current_jac = True
                if detecting:
                    easy[EASY_STALE] = 1.0
            if not converged:
                h_abs = abs(h) * control[C_NEWTON_FAIL_FACTOR]
                has_lu = False
                nrejected += 1
                continue
            rad_add(y, Z[2], y_new)
            rad_scale(y, y_new, rtol, atol, scale)
            rad_error_rhs(E, Z, h, f, ZE, err)
            error_norm = rad_error(LU_real, piv_real, err, scale)
            if rejected and error_norm > 1.0:
                rad_add(y, err, ys)
                fast.rhs_call(t, ys, fe, model, data, inputs)
                nfev += 1
                rad_add(fe, ZE, err)
                error_norm = rad_error(LU_real, piv_real, err, scale)
            finite = rad_finite(y_new)
            if not (math.isfinite(error_norm) and finite):
                if finite:
                    nonfinite = NONFINITE_ERROR
                else:
                    nonfinite = NONFINITE_STATE
                    y_bad[:] = y_new
                h_abs = abs(h) * control[C_MIN_FACTOR]
                rejected = True
                nrejected += 1
                continue
            if error_norm > 1.0:
                h_abs = rad_control_rejected(h, h_abs_old, error_norm, error_old, n_iter, control)
                rejected = True
                nrejected += 1
                continue
            break
        if status != DONE:
            break
        recompute_jac, h_mem = rad_control_accepted(h, h_abs, h_abs_old, error_norm, error_old,
                                                     n_iter, rate, control)
        current_jac = False
        h_abs_old_mem = abs(h)
        error_old_mem = error_norm
        error = error_norm
        last_step = h
        # --- accept it (AdaptiveIntegrator.take_step, Radau._accept)
        fast.normalize_quaternions(y_new, i_q0, nq)
        rad_dense_coefficients(Z, P, Qt)
        sol_t = t
        sol_h = t_new - t
        sol_y[:] = y
        has_sol = True
        f_new = False
        if t_new < t1:
            fast.rhs_call(t_new, y_new, f, model, data, inputs)
            nfev += 1
            if not rad_finite(f):
                status = ACCEPTED_RHS_NONFINITE
                t_fail = t_new
                h_fail = last_step
                break
            f_new = True
        t_old = t
        y_old[:] = y
        y[:] = y_new
        t = t_new
        if naccepted < trace.shape[0]:
            trace[naccepted] = t
        naccepted += 1
        # --- the dense output at the times inside the step (Radau.dense)
        k = j
        while k < m and te[k] < t:
            k += 1
        if k > j:
            rad_dense_eval(Qt, sol_y, sol_t, sol_h, te[j:k], Y[j:k])
            for r in range(j, k):
                fast.normalize_quaternions(Y[r], i_q0, nq)
            j = k
        while j < m and te[j] <= t:
            Y[j, :] = y
            j += 1
        if detecting:  # the tests of the step (Auto._run)
            if easy[EASY_STALE] != 0.0:  # rho of the Jacobian refreshed since the last one
                easy[EASY_RHO] = auto_spectral_radius(J, power, handback)
                easy[EASY_STALE] = 0.0
            reason = REASON_NONSTIFF if auto_nonstiffness_test(t - t_old, easy, handback) else 0
            auto_measure(t - t_old, nfev - nfev_measured, counters, window, cost, COST_RADAU)
            nfev_measured = nfev
            if reason == 0 and auto_cost_test(cost, counters, window, easy, handback):
                reason = REASON_COSTLY
            if reason != 0 and t < t1:
                status = SWITCH
                break
            reason = 0
    if status == DONE or status == SWITCH:  # end: the next call continues if it starts here
        mem[M_T_END] = t1 if status == DONE else t
        y_end[:] = y
        mem[M_T] = t
    else:
        mem[M_T] = t_fail
        mem[M_H] = h_fail
    mem[M_H_ABS] = h_mem
    mem[M_H_ABS_OLD] = h_abs_old_mem
    mem[M_ERROR_OLD] = error_old_mem
    mem[M_LU_H] = lu_h
    mem[M_SOL_T] = sol_t
    mem[M_SOL_H] = sol_h
    mem[M_ERROR] = error
    mem[M_LAST_STEP] = last_step
    mem[M_T_OLD] = t_old
    flags[F_HAS_J] = has_J
    flags[F_CURRENT_JAC] = current_jac
    flags[F_RECOMPUTE_JAC] = recompute_jac
    flags[F_HAS_LU] = has_lu
    flags[F_HAS_SOL] = has_sol
    flags[F_STATUS] = status
    flags[F_NFEV] = nfev
    flags[F_NJEV] = njev
    flags[F_NLU] = nlu
    flags[F_ACCEPTED] = naccepted
    flags[F_REJECTED] = nrejected
    flags[F_OUTPUTS] = j
    flags[F_F_NEW] = f_new
    flags[F_NONFINITE] = nonfinite
    flags[F_TRACED] = min(naccepted, trace.shape[0])
    flags[F_REASON] = reason


_LOOPS: dict[tuple, jit.Direct] = {}


def loop_for(kernel_arguments: tuple) -> jit.Direct:
    """:func:`radau_advance` called through its compiled entry point, for a system whose kernel
    arguments (`FastChainODE.kernel_arguments()`) have the types of these: one per process and
    combination of types (the first call dispatches, the later ones go straight to the entry
    point). The caller passes the other arguments with fixed types: float64 (complex128 for
    the complex LU and residual) C-contiguous arrays of fixed dimensions, int64 pivots and
    flags, Python floats, a complex and ints."""
    key = jit.type_key(kernel_arguments)
    loop = _LOOPS.get(key)
    if loop is None:
        loop = _LOOPS[key] = jit.Direct(radau_advance)
    return loop
