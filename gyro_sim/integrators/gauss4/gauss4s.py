"""gauss4s: the two-stage Gauss-Legendre method on the chain's (or tree's) canonical equations.

The same method and Newton iteration as gauss4 (:mod:`.gauss`), applied to the Hamiltonian form
of the equations (:mod:`gyro_sim.dynamics.canonical`: quaternions and their conjugate momenta,
hinge angles and theirs, the free base's position and linear momentum) instead of the
package's state of quaternions and joint rates. There the method is symplectic (Hairer,
Lubich, Wanner, "Geometric Numerical Integration", 2nd ed., Springer 2006, VI.4, Thm. 4.2):
the energy error stays bounded over long times instead of growing, and every quadratic
invariant of the canonical flow is kept to round-off: the world angular momentum (sum of the
bodies' quasi-momenta, bilinear in (q, p); docs/integrators.md), |q|^2 and q . p.

The caller's state y (the package's layout) is converted to canonical z at the start of a march
(`advance`, or "fixed"'s `march`) and back at its end; the z of the last end is kept, so a run
of calls that continue each other converts once (the conversion's round-off would otherwise
enter each call).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.dynamics.canonical import CanonicalChain
from gyro_sim.integrators.base import FixedStepIntegrator, IntegrationError, describe_nonfinite
from gyro_sim.integrators.gauss4.driver import LEVEL_MAX, Gauss4

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

#: the dense Newton iteration's stop (tolerance units, gauss4's DENSE_KAPPA is 1e-5): in
#: practice "iterate to the round-off floor" (the iteration stops there, NEWTON_STALLED). The
#: simplified iteration converges linearly, so what a looser stop leaves has the sign of the
#: next update, step after step: on the heavy top at 1e3 rad/s that drifted the energy and the
#: vertical momentum linearly (1.1e-12 of K over 4e5 steps); at this stop both wander at
#: round-off (3e-14), for ~1 more iteration a step (the Jacobian refreshes unchanged).
#: Hairer, McLachlan, Razakarivony, "Achieving Brouwer's law with implicit Runge-Kutta
#: methods", BIT 48 (2008) 231-243: iterate to round-off, coefficients that keep the
#: symplecticity condition exactly (gauss_kernels.gauss_scaled), no rounded b^T A^-1 on the
#: step's increment (gauss_kernels.gauss_update).
STRUCTURE_KAPPA = 1e-9


class Gauss4S(FixedStepIntegrator):
    """gauss4 on the canonical equations (see the module docstring): order 4, fixed step,
    implicit, symplectic. Same options as gauss4; its dense path stops at STRUCTURE_KAPPA, and
    where most steps need a retake they start in equal pieces (level_max = LEVEL_MAX).

    Attributes: `canonical` (the Hamiltonian system), `inner` (the gauss4 stepping it; its
    `counts` are this method's); the base's counters mirror the inner ones. The system must be
    a scene's, a chain or a tree (ChainODE or FastChainODE: it has a `model`).

    References
    ----------
    .. [1] E. Hairer, C. Lubich, G. Wanner, "Geometric Numerical Integration", 2nd ed.,
           Springer 2006, sec. VI.4 (Gauss methods are symplectic), IV.2 (quadratic
           invariants), VII.5 (the rigid body in quaternions and conjugate momenta).
    """

    name = "gauss4s"
    order = 4

    def __init__(self, system: OdeSystem, dense: bool | None = None, kappa: float | None = STRUCTURE_KAPPA,
                 level_max: int = LEVEL_MAX, **options):
        if getattr(system, "model", None) is None:
            raise ValueError("gauss4s integrates a chain or tree (a system with a `model`), not a general ODE")
        super().__init__(system, **options)
        if callable(getattr(system, "kernel_arguments", None)):  # compiled: FastChainODE
            from gyro_sim.dynamics.canonical_kernel import FastCanonicalChain

            self.canonical: CanonicalChain = FastCanonicalChain(system)
        else:
            self.canonical = CanonicalChain(system)
        self.inner = Gauss4(self.canonical, dense=dense, kappa=kappa, level_max=level_max, **options)
        self.counts = self.inner.counts
        self._end: tuple[float, np.ndarray, np.ndarray] | None = None

    @property
    def step(self) -> float:
        """The step; setting it sets the inner gauss4's too (as "fixed" does for substeps)."""
        return self._step

    @step.setter
    def step(self, value: float) -> None:
        self._step = float(value)
        inner = self.__dict__.get("inner")
        if inner is not None:
            inner.step = self._step

    def reset(self) -> None:
        super().reset()
        self.inner.reset()
        self._end = None

    def _z(self, t0: float, y: np.ndarray) -> np.ndarray:
        end = self._end
        if end is not None and end[0] == t0 and np.array_equal(end[1], y):
            return end[2]
        return self.canonical.momenta(t0, y)

    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        """y (the package's state) from t0 to t1 in place, through z: steps of the inner gauss4
        on the canonical system."""
        z = self._z(t0, y)
        try:
            self.inner.march(t0, z, t1)
        except IntegrationError as err:
            self._end = None
            raise IntegrationError(self.name, err.reason, err.t, err.h) from None
        finally:
            self._mirror()
        y[:] = self.canonical.state(t1, z)
        if not np.isfinite(y).all():
            self._end = None
            raise IntegrationError(self.name, "state is not finite after the step", t0, self.step,
                                   describe_nonfinite(y))
        self._end = (t1, y.copy(), z)

    def _mirror(self) -> None:
        i = self.inner
        self.nfev, self.nsteps, self.njev, self.nlu = i.nfev, i.nsteps, i.njev, i.nlu
        self.last_step = i.last_step
