"""The arithmetic of a fixed-step explicit Runge-Kutta method, compiled with numba.

One implementation, two drivers: :class:`gyro_sim.integrators.rk4.driver.RK4` calls these
between its rhs evaluations on any system (the numpy reference among them), and the compiled
loop :func:`gyro_sim.integrators.rk4.loop.erk_march` calls the same functions between calls of the
articulated-body kernel. The tableau is data (the method's class attributes `A`, `B`, `C`).

    ys = y + sum_{j<s} (h A)[s, j] K[j]      (erk_stage_state: the state of stage s)
    y += sum_j (h B)[j] K[j]                 (erk_update: the step)

The sums run over j in increasing order, one product added at a time, as numpy's `dot` of a
short vector with a (s, n) matrix does (bit for bit; test/integrators/test_rk4_loop.py). No
fastmath: IEEE arithmetic, no contraction into fused multiply-adds.
Without numba these stay plain Python (correct, slow).
"""
from __future__ import annotations

from gyro_sim.jit import njit


@njit
def erk_stage_state(y, K, hA, s, ys):
    """ys (n,) = y + sum_{j<s} hA[s, j] K[j]: the state at which stage s is evaluated.
    y (n,), K (stages, n), hA (stages, stages) = h A."""
    n = y.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(s):
            acc += hA[s, j] * K[j, i]
        ys[i] = acc + y[i]


@njit
def erk_update(y, K, hB):
    """y (n,) += sum_j hB[j] K[j]: the step's result in place. hB (stages,) = h B."""
    n = y.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(hB.shape[0]):
            acc += hB[j] * K[j, i]
        y[i] += acc
