"""The arithmetic of DOP853 (Dormand-Prince 8(5,3)), compiled with numba.

One implementation, two drivers: :class:`gyro_sim.integrators.dop853.driver.DOP853` calls these
between its rhs evaluations on any system (the numpy reference among them), and the compiled
loop :func:`gyro_sim.integrators.dop853.loop.dop853_advance` calls the same functions between calls
of the articulated-body kernel. The tableau is data (the class attributes of DOP853: the
extended A (16, 16) and C (16,), B, E5, E3 (12,), D (4, 16)), and so are the controller's
constants (`control`, :data:`CONTROL_SIZE` values, see :func:`dop_control`).

What each function computes, as scipy's `scipy.integrate.DOP853` does (rk.py: rk_step,
_estimate_error_norm, _dense_output_impl, Dop853DenseOutput) and in the same order of
operations wherever scipy's order is defined (its sums are BLAS dot products, whose order
and fused multiply-adds are the library's: there the results agree to round-off):

    ys  = y + (sum_{j<s} A[s, j] K[j]) h                   stage state       (dop_stage_state)
    y1  = y + h sum_{j<12} B[j] K[j]                        the 8th-order step (dop_update)
    err = |h| |e5|^2 / sqrt(n (|e5|^2 + 0.01 |e3|^2)),      error norm        (dop_error_norm)
          e5, e3 = sum_j E5[j] K[j], sum_j E3[j] K[j] divided by atol + rtol max(|y|, |y1|)
    h_new from err: HNW I, sec. II.4 (eq. 4.13)              step control      (dop_control)
    h0 from ||y0||, ||f0||, ||f1 - f0||: HNW I, sec. II.4    starting step     (dop_initial_*)
    F (7, n): the dense output of order 7, HNW I, sec. II.6  coefficients      (dop_dense_coefficients)
    y(t_old + x h) = y_old + F0 x + F1 x(1-x) + F2 x^2(1-x) + ...   evaluation (dop_dense_eval)

The sums run over j in increasing order, one product added at a time. No fastmath: IEEE
arithmetic, no contraction into fused multiply-adds. Without numba these stay plain Python
(correct, slow).

References
----------
.. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
       Nonstiff Problems", 2nd ed., Springer 1993: sec. II.4 (automatic step size control,
       eq. 4.13), sec. II.6 (dense output), sec. II.10 (DOP853: the 8(5,3) pair, its error
       estimator and its dense output of order 7).
.. [2] E. Hairer, dop853.f, http://www.unige.ch/~hairer/software.html
.. [3] scipy.integrate.DOP853 (scipy/integrate/_ivp/rk.py, scipy 1.17).
"""
from __future__ import annotations

import math

from pathlib import Path

from gyro_sim import jit
from gyro_sim.integrators import adaptive_kernels
from gyro_sim.integrators.adaptive_kernels import rms_scaled

#: the files these kernels compile in (the key of their numba cache directory)
DEPENDENCIES = (Path(__file__), Path(adaptive_kernels.__file__))
njit = jit.njit_with_dependencies(*DEPENDENCIES)

#: stages of a step (the 13th, FSAL, is f at the new state, row N_STAGES of K)
N_STAGES = 12
#: rows of K with the three extra stages of the dense output
N_EXTENDED = 16
#: rows of the dense-output coefficients F
N_DENSE = 7
#: the controller's constants in `control`: SAFETY, MIN_FACTOR, MAX_FACTOR, the exponent
#: -1/(q+1) (q = 7, the order of the error estimator), MIN_STEP_RELATIVE, LAST_STEP_STRETCH
CONTROL_SIZE = 6
#: the starting step's constants in `initial` (base.py's H0_*): NEGLIGIBLE, DEFAULT, FRACTION,
#: GROWTH, TINY_DERIVATIVES, TINY_STEP, TINY_FRACTION
INITIAL_SIZE = 7


@njit
def dop_stage_state(y, K, A, s, h, ys):
    """ys (n,) = y + (sum_{j<s} A[s, j] K[j]) h: the state of stage s (scipy's rk_step and
    _dense_output_impl: `y + np.dot(K[:s].T, a[:s]) * h`). y (n,), K (>= s, n), A (>s, >=s)."""
    n = y.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(s):
            acc += A[s, j] * K[j, i]
        ys[i] = y[i] + acc * h


@njit
def dop_update(y, K, B, h, y_new):
    """y_new (n,) = y + h sum_j B[j] K[j], j < len(B): the step of order 8."""
    n = y.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(B.shape[0]):
            acc += B[j] * K[j, i]
        y_new[i] = y[i] + h * acc


@njit
def dop_error_norm(K, E5, E3, h, y, y_new, rtol, atol):
    """DOP853's error norm of the step y -> y_new (HNW I, sec. II.10; scipy's
    DOP853._estimate_error_norm): the 5th-order estimate e5 damped by the 3rd-order one e3,

        err = |h| |e5|^2 / sqrt(n (|e5|^2 + 0.01 |e3|^2)),

    e5_i = sum_j E5[j] K[j, i] / sc_i (likewise e3), sc_i = atol_i + max(|y_i|, |y_new_i|) rtol.
    1 is the tolerance; 0 when both estimates vanish. atol (n,)."""
    n = y.shape[0]
    stages = E5.shape[0]
    n5 = 0.0
    n3 = 0.0
    for i in range(n):
        a5 = 0.0
        a3 = 0.0
        for j in range(stages):
            a5 += E5[j] * K[j, i]
            a3 += E3[j] * K[j, i]
        ay, an = abs(y[i]), abs(y_new[i])
        sc = atol[i] + (ay if ay >= an else an) * rtol
        e5 = a5 / sc
        e3 = a3 / sc
        n5 += e5 * e5
        n3 += e3 * e3
    if n5 == 0.0 and n3 == 0.0:
        return 0.0
    return abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * n)


@njit
def dop_finite(y):
    """True if every component of y (n,) is finite."""
    for i in range(y.shape[0]):
        if not (abs(y[i]) < math.inf):
            return False
    return True


@njit
def dop_control(err, finite, h, h_abs, rejected, control):
    """The step-size controller (HNW I, sec. II.4, eq. 4.13, with scipy's constants): given the
    error norm `err` of a trial step h (`finite`: its new state is finite), whose trial size
    was h_abs (h may be shorter: clipped to t1), after `rejected` earlier failures of this step:

    - accepted (err < 1): factor = min(MAX_FACTOR, SAFETY err^(-1/8)) (MAX_FACTOR if err = 0),
      at most 1 after a rejection; the next step h factor, but a step shortened only to land
      on t1 that went well (h < h_abs, factor >= 1) does not shrink the memory: at least h_abs;
    - rejected (err >= 1): |h| max(MIN_FACTOR, SAFETY err^(-1/8));
    - not finite (err or the state): |h| MIN_FACTOR.

    control: SAFETY, MIN_FACTOR, MAX_FACTOR, exponent (-1/8), ... (CONTROL_SIZE values).
    Returns (accepted, the step size to try or remember)."""
    safety, min_factor, max_factor, exponent = control[0], control[1], control[2], control[3]
    if not (finite and math.isfinite(err)):
        return False, abs(h) * min_factor
    if err < 1.0:
        if err == 0.0:
            factor = max_factor
        else:
            factor = min(max_factor, safety * err ** exponent)
        if rejected:
            factor = min(1.0, factor)
        h_next = h * factor
        if h < h_abs and factor >= 1.0:
            h_next = max(h_next, h_abs)
        return True, h_next
    return False, abs(h) * max(min_factor, safety * err ** exponent)


@njit
def dop_initial_probe(y0, f0, rtol, atol, span, initial, sc, y1):
    """The starting step size, first half (HNW I, sec. II.4, "starting step size"; scipy's
    select_initial_step): sc = atol + |y0| rtol, d0 = ||y0||, d1 = ||f0|| (RMS norms in sc),
    h0 = FRACTION d0 / d1 (DEFAULT if either is below NEGLIGIBLE), at most span; y1 = y0 + h0
    f0, where f1 = f(t0 + h0, y1) is to be evaluated for :func:`dop_initial_step`.
    initial: the INITIAL_SIZE constants. Returns (h0, d1)."""
    negligible, default, fraction = initial[0], initial[1], initial[2]
    n = y0.shape[0]
    for i in range(n):
        sc[i] = atol[i] + abs(y0[i]) * rtol
    d0 = rms_scaled(y0, sc)
    d1 = rms_scaled(f0, sc)
    h0 = default if d0 < negligible or d1 < negligible else fraction * d0 / d1
    h0 = min(h0, span)
    for i in range(n):
        y1[i] = y0[i] + h0 * f0[i]
    return h0, d1


@njit
def dop_initial_step(f0, f1, sc, h0, d1, span, max_step, order, initial):
    """The starting step size, second half: d2 = ||f1 - f0|| / h0 (an estimate of ||y''||, 0 if
    not finite), h1 = (FRACTION / max(d1, d2))^(1 / (order + 1)) (max(TINY_STEP, TINY_FRACTION
    h0) if both are below TINY_DERIVATIVES); h = min(GROWTH h0, h1, span, max_step). order: the
    error estimator's (7)."""
    fraction, growth = initial[2], initial[3]
    tiny_derivatives, tiny_step, tiny_fraction = initial[4], initial[5], initial[6]
    n = f0.shape[0]
    acc = 0.0
    for i in range(n):
        v = (f1[i] - f0[i]) / sc[i]
        acc += v * v
    d2 = (math.sqrt(acc / n) if n else 0.0) / h0
    if not math.isfinite(d2):
        d2 = 0.0
    if d1 <= tiny_derivatives and d2 <= tiny_derivatives:
        h1 = max(tiny_step, h0 * tiny_fraction)
    else:
        h1 = (fraction / max(d1, d2)) ** (1.0 / (order + 1))
    return min(growth * h0, h1, span, max_step)


@njit
def dop_dense_coefficients(y_old, y_new, K, D, h, F):
    """The coefficients F (7, n) of DOP853's dense output of order 7 over the step
    y_old -> y_new of size h (HNW I, sec. II.6 and II.10; scipy's _dense_output_impl):

        F0 = y_new - y_old,  F1 = h K0 - F0,  F2 = 2 F0 - h (K12 + K0),  F3..6 = h (D K)

    K (16, n): the step's stages, K12 = f(y_new) (the FSAL stage) and the three extra stages."""
    n = y_old.shape[0]
    rows, cols = D.shape[0], D.shape[1]
    for i in range(n):
        dy = y_new[i] - y_old[i]
        F[0, i] = dy
        F[1, i] = h * K[0, i] - dy
        F[2, i] = 2.0 * dy - h * (K[N_STAGES, i] + K[0, i])
        for r in range(rows):
            acc = 0.0
            for j in range(cols):
                acc += D[r, j] * K[j, i]
            F[3 + r, i] = h * acc


@njit
def dop_dense_eval(F, y_old, t_old, h, tq, Y):
    """Y (k, n): the dense output at times tq (k,) of the step from (t_old, y_old) of size h,
    x = (t - t_old) / h, by Horner's scheme in x and (1 - x) alternately from the last
    coefficient (scipy's Dop853DenseOutput, the same operations)."""
    n = y_old.shape[0]
    p = F.shape[0]
    for r in range(tq.shape[0]):
        x = (tq[r] - t_old) / h
        for i in range(n):
            acc = 0.0
            for q in range(p):
                acc += F[p - 1 - q, i]
                if q % 2 == 0:
                    acc *= x
                else:
                    acc *= 1.0 - x
            Y[r, i] = acc + y_old[i]


# --- stiffness detection: dop853.f's h |lambda| and the "auto" method's tests --------------
# One implementation for both drivers of gyro_sim.integrators.auto.Auto: its Python loop
# (DOP853's public single step, on any system) and the detection mode of the compiled loop
# (fast_dop853.dop853_advance) call these on the same state arrays, owned by Auto:
#
#     counters (COUNTERS_SIZE,) int64   the counts below
#     attempts (REJECT_WINDOW,) int64   rejected attempts before each accepted step (a ring)
#     window (COST_WINDOW, 2) float64   (dt, rhs evaluations) of each accepted step (a ring)
#     cost (COST_SIZE,) float64         rhs evaluations per simulated second, by method (nan:
#                                       not measured yet)
#     detect (DETECT_SIZE,) float64     the constants: STIFF_HLAMB, STIFF_STEPS, NONSTIFF_RESET,
#                                       REJECT_FRACTION (auto.py)
#
# The windows are as long as their arrays. Sums run oldest first, one term at a time: the
# values of Python's `sum` over the lists the tests kept before (CPython 3.11 adds floats
# left to right).

#: counters: dop853.f's IASTI and NONSTI, then the entries of `attempts` and the slot of the
#: next one, then those of `window`
C_STIFF, C_NONSTIFF, C_ATTEMPTS, C_ATTEMPT_NEXT, C_WINDOW, C_WINDOW_NEXT = range(6)
COUNTERS_SIZE = 6
#: cost: the slots of the two methods of "auto"
COST_DOP853, COST_RADAU = range(2)
COST_SIZE = 2
#: detect: the constants of the tests
D_STIFF_HLAMB, D_STIFF_STEPS, D_NONSTIFF_RESET, D_REJECT_FRACTION = range(4)
DETECT_SIZE = 4
#: what dop_hlamb returns when y1 = Y12 (no estimate)
NO_HLAMB = -1.0


@njit
def dop_hlamb(h, Y12, f12, y1, f1):
    """dop853.f's stiffness estimate (HLAMB) of an accepted step h: h |lambda| ~
    |h| sqrt(||f1 - f12||^2 / ||y1 - Y12||^2), Y12 (n,) the last stage's state (at t + h),
    f12 = f(Y12), y1 (n,) the new state, f1 = f(y1); NO_HLAMB if y1 = Y12."""
    num = 0.0
    den = 0.0
    for i in range(y1.shape[0]):
        dy = y1[i] - Y12[i]
        den += dy * dy
    if den <= 0.0:
        return NO_HLAMB
    for i in range(y1.shape[0]):
        df = f1[i] - f12[i]
        num += df * df
    return abs(h) * math.sqrt(num / den)


@njit
def auto_stiffness_test(hlamb, counters, detect):
    """dop853.f's test on one accepted step of h |lambda| = hlamb: above STIFF_HLAMB a stiff
    step (IASTI + 1, NONSTI = 0), else a non-stiff one (NONSTI + 1; NONSTIFF_RESET of them in a
    row set IASTI = 0). True when IASTI reaches STIFF_STEPS: the problem is stiff."""
    if hlamb > detect[D_STIFF_HLAMB]:
        counters[C_NONSTIFF] = 0
        counters[C_STIFF] += 1
        return counters[C_STIFF] >= detect[D_STIFF_STEPS]
    counters[C_NONSTIFF] += 1
    if counters[C_NONSTIFF] >= detect[D_NONSTIFF_RESET]:
        counters[C_STIFF] = 0
    return False


@njit
def auto_rejections(counters, attempts):
    """(rejected, all) step attempts in the window: the rejected ones and every attempt."""
    count = counters[C_ATTEMPTS]
    rejected = 0
    for i in range(count):
        rejected += attempts[i]
    return rejected, rejected + count


@njit
def auto_rejection_test(rejected, counters, attempts, detect):
    """Enters the `rejected` attempts before an accepted step in the window of the last
    len(attempts) accepted steps. True when the window holds at least len(attempts) attempts
    and at least REJECT_FRACTION of them were rejected: the problem is stiff."""
    size = attempts.shape[0]
    attempts[counters[C_ATTEMPT_NEXT]] = rejected
    counters[C_ATTEMPT_NEXT] = (counters[C_ATTEMPT_NEXT] + 1) % size
    if counters[C_ATTEMPTS] < size:
        counters[C_ATTEMPTS] += 1
    n_rej, n_all = auto_rejections(counters, attempts)
    return n_all >= size and n_rej >= detect[D_REJECT_FRACTION] * n_all


@njit
def auto_clear_attempts(counters):
    """Empties the window of attempts."""
    counters[C_ATTEMPTS] = 0
    counters[C_ATTEMPT_NEXT] = 0


@njit
def auto_measure(dt, nfev, counters, window, cost, method):
    """Enters an accepted step of dt that cost nfev rhs evaluations in the window of the last
    len(window) steps; once full, cost[method] = its evaluations / its span (if > 0)."""
    size = window.shape[0]
    slot = counters[C_WINDOW_NEXT]
    window[slot, 0] = dt
    window[slot, 1] = nfev
    counters[C_WINDOW_NEXT] = (slot + 1) % size
    if counters[C_WINDOW] < size:
        counters[C_WINDOW] += 1
    if counters[C_WINDOW] == size:
        first = counters[C_WINDOW_NEXT]  # the oldest entry
        span = 0.0
        evals = 0.0
        for i in range(size):
            k = (first + i) % size
            span += window[k, 0]
            evals += window[k, 1]
        if span > 0.0:
            cost[method] = evals / span


@njit
def auto_costlier(cost, candidate, running, margin):
    """Is method `candidate` measured to cost more than `margin` times method `running`?"""
    c, r = cost[candidate], cost[running]
    return not (math.isnan(c) or math.isnan(r)) and c > margin * r
