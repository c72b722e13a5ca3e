"""Time integrators behind one small interface, selected by name (`integrator=`).

    integ = make_integrator("dop853", system, rtol=1e-8, atol=1e-10)
    y1 = integ.advance(t0, y0, t1)                    # a new array, the state at exactly t1
    y1, Y = integ.advance(t0, y0, t1, t_eval=times)   # and Y (len(times), size) on the way

========  ======================================  =====  ========  ============  ==================
name      method                                  order  steps     dense output  home
========  ======================================  =====  ========  ============  ==================
rk4       classical Runge-Kutta                   4      fixed     no            rk4/
dop853    Dormand-Prince 8(5,3)                   8      adaptive  order 7       dop853/
radau     Radau IIA, 3 stages (stiff)             5      adaptive  collocation   radau/
lie4      commutator-free Lie group RK (CF4)      4      fixed     no            lie4/
gauss4    Gauss-Legendre collocation, 2 stages    4      fixed     no            gauss4/
gauss4s   gauss4 on the canonical equations       4      fixed     no            gauss4/gauss4s.py
fixed     rk4, gauss4 where stiff (estimated)     4      fixed     no            fixed.py
auto      dop853, radau while stiff (detected)    8 / 5  adaptive  yes           auto.py
========  ======================================  =====  ========  ============  ==================

One folder per method, holding its driver, its compiled kernels and its compiled loop; `base.py`
holds the interface (:class:`Integrator` and its public `advance`, the fixed-step and adaptive bases with the
adaptive methods' public single step
`begin` / `take_step` / `dense` / `end`), the error-control constants and
:class:`IntegrationError`. The layout follows scipy's `integrate/_ivp` (`base.py`, `rk.py`,
`radau.py`); an explicit Runge-Kutta method is data: its tableau `A`, `B`, `C`, `E` and its
`order` are class attributes. The systems they advance follow
:class:`gyro_sim.dynamics.system.OdeSystem`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.auto import (
    COST_MARGIN, COST_WINDOW, DOP853_BOUNDARY, DOP853_EVALS, EIG_MAX_SIZE, NONSTIFF_HRHO,
    NONSTIFF_RESET, NONSTIFF_STEPS, POWER_ITERATIONS, REJECT_FRACTION, REJECT_WINDOW, STIFF_HLAMB,
    STIFF_STEPS, Auto, StiffnessWarning,
)
from gyro_sim.integrators.base import (
    EPS, LAST_STEP_STRETCH, MAX_FACTOR, MAX_REPORTED_COMPONENTS, MIN_FACTOR, MIN_RTOL,
    MIN_STEP_RELATIVE, SAFETY, STEP_COUNT_SLACK, AdaptiveIntegrator, ExplicitRungeKutta,
    FixedStepIntegrator, IntegrationError, Integrator,
)
from gyro_sim.integrators.fixed import CHECK_PERIOD, RK4_RETURN, SceneFixedStep
from gyro_sim.integrators.dop853.driver import DOP853
from gyro_sim.integrators.gauss4.driver import NEWTON_CAP, NEWTON_SLOW_RATE, NEWTON_TOL, Gauss4
from gyro_sim.integrators.gauss4.gauss4s import Gauss4S
from gyro_sim.integrators.lie4.driver import Lie4
from gyro_sim.integrators.radau.driver import (
    FD_MIN_SCALE, FD_REL_STEP, LU_REUSE_RTOL, NEWTON_MAXITER, RADAU_KEEP_STEP,
    RADAU_NEWTON_FAIL_FACTOR, RADAU_SLOW_ITER, RADAU_SLOW_RATE, Radau,
)
from gyro_sim.integrators.rk4.driver import RK4

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

#: the methods by name
INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (RK4, DOP853, Radau, Lie4, Auto, Gauss4, Gauss4S, SceneFixedStep)
}


def make_integrator(
    name: str,
    system: OdeSystem,
    *,
    rtol: float = 1e-8,
    atol: float | np.ndarray = 1e-10,
    step: float = 1e-3,
    max_step: float = np.inf,
) -> Integrator:
    """The integrator registered as `name` (see INTEGRATORS) for `system`."""
    try:
        cls = INTEGRATORS[name]
    except (KeyError, TypeError):
        valid = ", ".join(INTEGRATORS)
        raise ValueError(f"unknown integrator {name!r}; valid names: {valid}") from None
    return cls(system, rtol=rtol, atol=atol, step=step, max_step=max_step)


__all__ = [
    "INTEGRATORS", "make_integrator", "Integrator", "FixedStepIntegrator", "AdaptiveIntegrator",
    "ExplicitRungeKutta", "RK4", "Lie4", "Gauss4", "Gauss4S", "SceneFixedStep", "CHECK_PERIOD", "RK4_RETURN", "DOP853",
    "Radau", "Auto", "IntegrationError",
    "StiffnessWarning", "EPS", "SAFETY", "MIN_FACTOR", "MAX_FACTOR", "MIN_RTOL",
    "MIN_STEP_RELATIVE", "LAST_STEP_STRETCH", "STEP_COUNT_SLACK", "MAX_REPORTED_COMPONENTS",
    "NEWTON_MAXITER", "RADAU_SLOW_ITER", "RADAU_SLOW_RATE", "RADAU_KEEP_STEP",
    "RADAU_NEWTON_FAIL_FACTOR", "LU_REUSE_RTOL", "FD_REL_STEP", "FD_MIN_SCALE", "STIFF_HLAMB",
    "STIFF_STEPS", "NONSTIFF_RESET", "REJECT_WINDOW", "REJECT_FRACTION", "NONSTIFF_HRHO",
    "NONSTIFF_STEPS", "COST_WINDOW", "COST_MARGIN", "DOP853_EVALS", "DOP853_BOUNDARY",
    "EIG_MAX_SIZE", "POWER_ITERATIONS", "NEWTON_CAP", "NEWTON_SLOW_RATE", "NEWTON_TOL",
]
