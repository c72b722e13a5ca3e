"""What the adaptive methods' compiled code shares (numba): the RMS norm of the error, a trial
step clipped to t1, and what a whole-`advance` loop returns: its status and the reason of a
switch (gyro_sim.integrators.dop853.loop and gyro_sim.integrators.radau.loop, whose Python
drivers read them). The methods' kernels compile these in: their caches are keyed on this file
too (DEPENDENCIES of gyro_sim.integrators.dop853.kernels and gyro_sim.integrators.radau.kernels).
"""
from __future__ import annotations

import math

from gyro_sim.jit import njit

# --- what a loop returns as its status ------------------------------------------------------
#: t1 reached
DONE = 0
#: the step size fell below MIN_STEP_RELATIVE max(|t|, |t1|) (HNW's "step size too small")
COLLAPSED = 1
#: the fresh rhs at (t0, y0) is not finite
INITIAL_RHS_NONFINITE = 2
#: the rhs at an accepted state (FSAL, or for the dense output) is not finite
ACCEPTED_RHS_NONFINITE = 3
#: no starting step is representable (|f0| too large against |y0|: radau)
NO_STARTING_STEP = 4
#: detection mode ("auto"): a test asks for a switch at an accepted state before t1
SWITCH = 5

# --- the reasons of a SWITCH ----------------------------------------------------------------
#: dop853: dop853.f's test, STIFF_STEPS steps with h |lambda| > STIFF_HLAMB
REASON_STIFF = 1
#: dop853: REJECT_FRACTION of the last REJECT_WINDOW step attempts rejected
REASON_REJECTED = 2
#: radau: h rho(J) < NONSTIFF_HRHO in the steps needed in a row
REASON_NONSTIFF = 3
#: radau: it costs COST_MARGIN times what dop853 did (or would)
REASON_COSTLY = 4


@njit
def rms_scaled(x, sc):
    """sqrt(sum_i (x_i / sc_i)^2 / n), 0 for n = 0 (scipy's `norm` of x / scale: RMS)."""
    n = x.shape[0]
    acc = 0.0
    for i in range(n):
        v = x[i] / sc[i]
        acc += v * v
    return math.sqrt(acc / n) if n else 0.0


@njit
def clip_step(t, h_abs, t1, stretch):
    """(h, t_new) of a trial step of h_abs from t: to exactly t1 when t + h_abs (1 + stretch)
    reaches it (dop853.f stretches the step before t1 rather than leave a sliver), else
    t_new = t + h_abs and h = t_new - t (the step as represented; AdaptiveIntegrator._clip)."""
    if t + h_abs * (1.0 + stretch) >= t1:
        return t1 - t, t1
    t_new = t + h_abs
    return t_new - t, t_new
