"""DOP853's whole `advance` compiled with numba: every step of a call in one compiled call.

:func:`dop853_advance` is what :meth:`gyro_sim.integrators.dop853.driver.DOP853.advance` does
in Python (`AdaptiveIntegrator._integrate`: `begin`, then `take_step` and `dense` until t1):
the steps with error control, accepted and rejected, the fresh rhs at the start, the FSAL
stage, the dense output at the requested times, the renormalisation of the quaternions of
every accepted state and output, the finite checks. It calls the articulated-body kernel
:func:`gyro_sim.dynamics.kernel.rhs_kernel` (through its compiled C function, `fast.rhs_call`) and the
arithmetic of
:mod:`gyro_sim.integrators.dop853.kernels`, the very functions the Python driver calls between its
rhs evaluations on other systems: the two drivers give the same bits.

Its detection mode runs the "auto" method's dop853 phase
(:class:`gyro_sim.integrators.auto.Auto`): dop853.f's h |lambda| for every accepted step
and Auto's tests on it (stiffness, rejections, cost: dop853_kernels.auto_*), returning at
the accepted state where one asks for a switch; the Python loop Auto runs on other systems
calls the same kernels on the same state.

DOP853 dispatches to it when its system offers `kernel_arguments` and `quaternion_block`
(the compiled :class:`gyro_sim.dynamics.system.FastChainODE`), through :func:`loop_for`: one
:class:`gyro_sim.jit.Direct` per process and types of the kernel's arguments, so a
new integrator (a new Simulator) pays numba's type dispatch only once per process.

Caching: the loop inlines fast.py and dop853_kernels.py, so it is cached in a directory keyed
on all three files (:func:`gyro_sim.jit.njit_with_dependencies`).

References
----------
.. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
       Nonstiff Problems", 2nd ed., Springer 1993: sec. II.4 (step control), II.6 (dense
       output), II.10 (DOP853).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np


from gyro_sim.integrators.adaptive_kernels import (  # what the loop returns in status[S_STATUS] (its reasons)
    ACCEPTED_RHS_NONFINITE, COLLAPSED, DONE, INITIAL_RHS_NONFINITE, REASON_REJECTED, REASON_STIFF, SWITCH,
    clip_step,
)
from gyro_sim.integrators.dop853 import kernels as dop853_kernels
from gyro_sim.dynamics import kernel as fast
from gyro_sim import jit
from gyro_sim.integrators.dop853.kernels import (
    C_STIFF, COST_DOP853, COST_RADAU, N_EXTENDED, N_STAGES, NO_HLAMB, auto_clear_attempts,
    auto_costlier, auto_measure, auto_rejection_test, auto_stiffness_test, dop_control,
    dop_dense_coefficients, dop_dense_eval, dop_error_norm, dop_finite, dop_hlamb,
    dop_initial_probe, dop_initial_step, dop_stage_state, dop_update,
)

#: the files the loop compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, *dop853_kernels.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)

#: the order of DOP853's error estimator (the starting step's exponent)
ORDER_OF_ESTIMATOR = 7

#: layout of the loop's outputs: floats (`real`) and integers (`status`)
REAL_SIZE = 6
R_T, R_H, R_H_ABS, R_ERROR, R_LAST_STEP, R_T_OLD = range(REAL_SIZE)
STATUS_SIZE = 9
(S_STATUS, S_NFEV, S_ACCEPTED, S_REJECTED, S_OUTPUTS, S_F_NEW, S_NONFINITE, S_TRACED,
 S_REASON) = range(STATUS_SIZE)
#: layout of `held_at`, with `held` the step whose h |lambda| waits for f(y1) (detection mode):
#: its end (nan: none) and size
H_T, H_H = range(2)
HELD_AT_SIZE = 2
#: rows of `held`: y1, Y12, f(Y12)
H_Y1, H_Y12, H_F12 = range(3)


class Outputs(NamedTuple):
    """The states asked of a call: Y (m, size) at te (m,), sorted within [t0, t1]."""

    te: np.ndarray
    Y: np.ndarray


class Options(NamedTuple):
    """A call's step-size memory h_mem, its options, and where the state's quaternions are."""

    h_mem: float
    max_step: float
    rtol: float
    #: (size,)
    atol: np.ndarray
    i_q0: int
    nq: int


class Method(NamedTuple):
    """DOP853's constants (the class attributes of gyro_sim.integrators.dop853.driver.DOP853)."""

    #: (16, 16), (16,): the extended tableau
    A: np.ndarray
    C: np.ndarray
    #: (12,)
    E5: np.ndarray
    E3: np.ndarray
    #: (4, 16)
    D: np.ndarray
    #: dop853_kernels' CONTROL_SIZE, INITIAL_SIZE
    control: np.ndarray
    initial: np.ndarray


class State(NamedTuple):
    """What the loop keeps and returns between calls, and its scratch (see dop853_advance)."""

    f: np.ndarray
    K: np.ndarray
    ys: np.ndarray
    y_new: np.ndarray
    y_old: np.ndarray
    F: np.ndarray
    bad: np.ndarray
    trace: np.ndarray
    real: np.ndarray
    status: np.ndarray
    held: np.ndarray
    held_at: np.ndarray


class Detection(NamedTuple):
    """The stiffness detection's state (dop853_kernels), carried from call to call; `detect`
    empty: off."""

    detect: np.ndarray
    counters: np.ndarray
    attempts: np.ndarray
    window: np.ndarray
    cost: np.ndarray


@_njit
def dop853_advance(t0, t1, y, outputs, options, method, state, detection, model, data, inputs):
    """DOP853 from (t0, y) to exactly t1 > t0, y (size,) in place; outputs.Y (m, size) the
    states at outputs.te (m,), sorted within [t0, t1]. The records: Outputs, Options, Method,
    State, Detection (their fields are named below as in the loop).

    The call starts with a fresh f = rhs(t0, y) (inputs may have changed since the last call).
    h_mem: the step-size memory of the last call; 0 on the first call after a reset: the
    starting step is selected here (dop853_kernels.dop_initial_*, one more rhs evaluation).
    A (16, 16), C (16,): the extended tableau (row 12 the weights B, rows 13..15 the extra
    stages of the dense output); E5, E3 (12,); D (4, 16); control, initial: the constants of
    dop853_kernels (CONTROL_SIZE, INITIAL_SIZE). Quaternions y[i_q0 + 4 j : +4], j < nq.
    Scratch, left as the Python driver leaves its own: K (16, size) the stages of the last
    step, ys (size,) its last stage state, y_new the accepted state, y_old the one before, F
    (7, size), bad (12,) the non-finite stages of the last non-finite trial. trace (k,): the
    ends of the first k accepted steps (k may be 0).

    Outputs: real (REAL_SIZE,) t reached (or of the failure), h of the failure, the step-size
    memory, the error norm and size of the last accepted step, its start; status
    (STATUS_SIZE,) the status (DONE, COLLAPSED, ...), rhs evaluations, accepted and rejected
    steps, outputs filled, whether f = rhs(y_new) is known, whether the last failing step had
    a non-finite trial, the steps traced, the reason of a SWITCH. model, data, inputs:
    fast.rhs_kernel's records.

    Detection mode (detect not empty), the "auto" method's dop853 phase
    (gyro_sim.integrators.auto.Auto, whose Python loop over DOP853's public single step
    does the same on other systems): every accepted step also gets dop853.f's h |lambda|
    (dop853_kernels.dop_hlamb) once f(y1) is known, and after it, as in that loop, the
    stiffness test (if h |lambda| is known), the rejection test, the cost window and, if a
    test fired, `auto_costlier` (radau measured costlier: the detection starts over); a
    switch asked for before t1 ends the call there (SWITCH). The tests' state: detect,
    counters, attempts, window, cost (dop853_kernels), carried from call to call. The last
    step of a call has no f(y1) unless the dense output needed it: it is `held` (3, size) and
    `held_at` (HELD_AT_SIZE,), and tested at the start of the next call if that call continues
    from its end (then a switch may end the call before its first step). Off, these are not
    read (empty or not).
    """
    te, Y = outputs
    h_mem, max_step, rtol, atol, i_q0, nq = options
    A, C, E5, E3, D, control, initial = method
    f, K, ys, y_new, y_old, F, bad, trace, real, status, held, held_at = state
    detect, counters, attempts, window, cost = detection
    detecting = detect.shape[0] > 0
    m = te.shape[0]
    nfev = 0
    nfev_measured = 0  # nfev at the end of the last step measured (detection mode)
    naccepted = 0
    nrejected = 0
    j = 0
    while j < m and te[j] <= t0:
        Y[j, :] = y
        j += 1
    status[S_F_NEW] = 0
    status[S_NONFINITE] = 0
    status[S_STATUS] = DONE
    status[S_REASON] = 0
    fast.rhs_call(t0, y, f, model, data, inputs)
    nfev += 1
    if not dop_finite(f):
        status[S_STATUS] = INITIAL_RHS_NONFINITE
        real[R_T] = t0
    elif h_mem <= 0.0:  # the starting step (AdaptiveIntegrator.begin), F[0] and F[1] as scratch
        sc, f1 = F[0], F[1]
        h0, d1 = dop_initial_probe(y, f, rtol, atol, t1 - t0, initial, sc, ys)
        fast.rhs_call(t0 + h0, ys, f1, model, data, inputs)
        nfev += 1
        h_mem = dop_initial_step(f, f1, sc, h0, d1, t1 - t0, max_step, ORDER_OF_ESTIMATOR, initial)
    if detecting and status[S_STATUS] == DONE:  # the last call's last step, if this continues it
        if held_at[H_T] == t0 and _equal(held[H_Y1], y):
            hlamb = dop_hlamb(held_at[H_H], held[H_Y12], held[H_F12], y, f)
            if hlamb != NO_HLAMB and auto_stiffness_test(hlamb, counters, detect):
                status[S_STATUS] = SWITCH
                status[S_REASON] = REASON_STIFF
                real[R_T] = t0
        held_at[H_T] = math.nan
    t = t0
    t_old = t0
    error = real[R_ERROR]
    last_step = real[R_LAST_STEP]
    min_step_relative, stretch = control[4], control[5]
    while status[S_STATUS] == DONE and t < t1:
        # --- one accepted step (DOP853._step_impl)
        rejected_before = nrejected
        hlamb = NO_HLAMB
        h_abs = min(h_mem, max_step)
        min_step = min_step_relative * max(abs(t), abs(t1))
        rejected = False
        status[S_NONFINITE] = 0
        t_new = t
        while True:
            if h_abs < min_step:
                status[S_STATUS] = COLLAPSED
                real[R_T] = t
                real[R_H] = h_abs
                break
            h, t_new = clip_step(t, h_abs, t1, stretch)
            K[0, :] = f
            for st in range(1, N_STAGES):
                dop_stage_state(y, K, A, st, h, ys)
                fast.rhs_call(t + C[st] * h, ys, K[st], model, data, inputs)
                nfev += 1
            dop_update(y, K, A[N_STAGES, :N_STAGES], h, y_new)
            err = dop_error_norm(K, E5, E3, h, y, y_new, rtol, atol)
            finite = dop_finite(y_new)
            accepted, h_next = dop_control(err, finite, h, h_abs, rejected, control)
            if accepted:
                h_mem = h_next
                error = err
                last_step = h
                break
            if not (finite and math.isfinite(err)):
                status[S_NONFINITE] = 1
                for st in range(N_STAGES):
                    bad[st] = 0 if dop_finite(K[st]) else 1
            h_abs = h_next
            rejected = True
            nrejected += 1
        if status[S_STATUS] != DONE:
            break
        # --- accept it (AdaptiveIntegrator.take_step)
        fast.normalize_quaternions(y_new, i_q0, nq)
        status[S_F_NEW] = 0
        if t_new < t1:
            fast.rhs_call(t_new, y_new, f, model, data, inputs)
            nfev += 1
            if not dop_finite(f):
                status[S_STATUS] = ACCEPTED_RHS_NONFINITE
                real[R_T] = t_new
                real[R_H] = last_step
                break
            status[S_F_NEW] = 1
            K[N_STAGES, :] = f
            if detecting:  # ys and K[11]: the last stage
                hlamb = dop_hlamb(last_step, ys, K[N_STAGES - 1], y_new, f)
        elif detecting:  # f(y1) waits for the dense output or the next call
            held[H_Y1, :] = y_new
            held[H_Y12, :] = ys
            held[H_F12, :] = K[N_STAGES - 1]
            held_at[H_T] = t_new
            held_at[H_H] = last_step
        t_old = t
        y_old[:] = y
        y[:] = y_new
        t = t_new
        if naccepted < trace.shape[0]:
            trace[naccepted] = t
        naccepted += 1
        # --- the dense output at the times inside the step (AdaptiveIntegrator.dense)
        k = j
        while k < m and te[k] < t:
            k += 1
        if k > j:
            if status[S_F_NEW] == 0:
                fast.rhs_call(t, y_new, f, model, data, inputs)
                nfev += 1
                if not dop_finite(f):
                    status[S_STATUS] = ACCEPTED_RHS_NONFINITE
                    real[R_T] = t
                    real[R_H] = last_step
                    break
                status[S_F_NEW] = 1
                K[N_STAGES, :] = f
                if detecting:
                    hlamb = dop_hlamb(last_step, ys, K[N_STAGES - 1], y_new, f)
                    held_at[H_T] = math.nan
            for st in range(N_STAGES + 1, N_EXTENDED):
                dop_stage_state(y_old, K, A, st, last_step, ys)
                fast.rhs_call(t_old + C[st] * last_step, ys, K[st], model, data, inputs)
                nfev += 1
            dop_dense_coefficients(y_old, y_new, K, D, last_step, F)
            dop_dense_eval(F, y_old, t_old, last_step, te[j:k], Y[j:k])
            for r in range(j, k):
                fast.normalize_quaternions(Y[r], i_q0, nq)
            j = k
        while j < m and te[j] <= t:
            Y[j, :] = y
            j += 1
        if detecting:  # the tests of the step (Auto._run)
            reason = 0
            if hlamb != NO_HLAMB and auto_stiffness_test(hlamb, counters, detect):
                reason = REASON_STIFF
            if auto_rejection_test(nrejected - rejected_before, counters, attempts, detect):
                reason = REASON_REJECTED
            auto_measure(t - t_old, nfev - nfev_measured, counters, window, cost, COST_DOP853)
            nfev_measured = nfev
            if reason != 0 and auto_costlier(cost, COST_RADAU, COST_DOP853, 1.0):
                counters[C_STIFF] = 0  # radau was measured slower here: keep going
                auto_clear_attempts(counters)
                reason = 0
            if reason != 0 and t < t1:
                status[S_STATUS] = SWITCH
                status[S_REASON] = reason
                real[R_T] = t
    if status[S_STATUS] == DONE:
        real[R_T] = t
    real[R_H_ABS] = h_mem
    real[R_ERROR] = error
    real[R_LAST_STEP] = last_step
    real[R_T_OLD] = t_old
    status[S_NFEV] = nfev
    status[S_ACCEPTED] = naccepted
    status[S_REJECTED] = nrejected
    status[S_OUTPUTS] = j
    status[S_TRACED] = min(naccepted, trace.shape[0])


@_njit
def _equal(a, b):
    """a == b elementwise for every element (numpy.array_equal of two (n,) arrays)."""
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


_LOOPS: dict[tuple, jit.Direct] = {}


def loop_for(kernel_arguments: tuple) -> jit.Direct:
    """:func:`dop853_advance` called through its compiled entry point, for a system whose
    kernel arguments (`FastChainODE.kernel_arguments()`) have the types of these: one per
    process and combination of types (the first call dispatches, the later ones go straight
    to the entry point). The caller passes the other arguments with fixed types: float64
    C-contiguous arrays of fixed dimensions, Python floats and ints."""
    key = jit.type_key(kernel_arguments)
    loop = _LOOPS.get(key)
    if loop is None:
        loop = _LOOPS[key] = jit.Direct(dop853_advance)
    return loop
