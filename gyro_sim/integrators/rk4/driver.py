"""The classical Runge-Kutta method (rk4): order 4, fixed step."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.rk4.kernels import erk_stage_state, erk_update
from gyro_sim.integrators.base import ExplicitRungeKutta, FixedStepIntegrator

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem


class RK4(ExplicitRungeKutta, FixedStepIntegrator):
    """The classical Runge-Kutta method, order 4, fixed step.

    Four rhs evaluations per step; no error estimate, no dense output (`t_eval` times are
    stepped to exactly).

    One implementation, two drivers: the tableau's arithmetic is
    :mod:`gyro_sim.integrators.rk4.kernels`. On a system that offers `kernel_arguments()` and
    `quaternion_block()` (the compiled :class:`gyro_sim.dynamics.system.FastChainODE`) the n
    substeps of an `advance` run in one compiled call with this class's tableau
    (:class:`gyro_sim.integrators.rk4.loop.ErkMarch`, compiled or loaded when this integrator is
    made); on any other system this class steps in Python (`_step`), calling the same
    arithmetic between its rhs evaluations.

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
           Nonstiff Problems", 2nd ed., Springer 1993, sec. II.1.
    """

    name = "rk4"
    order = 4
    n_stages = 4
    C = np.array([0.0, 0.5, 0.5, 1.0])
    A = np.array([
        [0.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ])
    B = np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6])

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._K = np.empty((self.n_stages, self.n))
        self._ys = np.empty(self.n)
        self._hA = np.empty_like(self.A)
        self._march_system = None
        if callable(getattr(system, "kernel_arguments", None)) and \
                callable(getattr(system, "quaternion_block", None)):
            from gyro_sim.integrators.rk4.loop import ErkMarch  # the compiled march (imports the kernel's module)

            self._march_system = ErkMarch(system)
            self._march_system.warm_up(0.0, np.zeros(self.n))  # not in the first advance

    def _march_compiled(self, t0: float, y: np.ndarray, h: float, n: int) -> int | None:
        if self._march_system is None:
            return None
        done = self._march_system(self.A, self.B, self.C, t0, y, h, n)
        self.nfev += self.n_stages * min(done + 1, n)
        return done

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        K, ys = self._K, self._ys
        K[0] = self._fun(t, y)
        np.multiply(self.A, h, out=self._hA)
        for s in range(1, self.n_stages):
            erk_stage_state(y, K, self._hA, s, ys)  # ys = y + h sum_j A[s, j] K[j]
            K[s] = self._fun(t + self.C[s] * h, ys)
        erk_update(y, K, h * self.B)  # y1 = y + h sum_i B_i K_i
