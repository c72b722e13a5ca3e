"""The classical Runge-Kutta method (rk4): order 4, fixed step."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .base import ExplicitRungeKutta, FixedStepIntegrator

if TYPE_CHECKING:
    from ..system import OdeSystem


class RK4(ExplicitRungeKutta, FixedStepIntegrator):
    """The classical Runge-Kutta method, order 4, fixed step.

    Four rhs evaluations per step; no error estimate, no dense output (`t_eval` times are
    stepped to exactly).

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
        self._dy = np.empty(self.n)
        self._hA = np.empty_like(self.A)
        self._C_all = self.C

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        K = self._K
        K[0] = self._fun(t, y)
        np.multiply(self.A, h, out=self._hA)
        self._stages(t, y, self._hA, h, 1, self.n_stages)
        # y1 = y + h sum_i B_i K_i
        np.dot(h * self.B, K, out=self._dy)
        y += self._dy
