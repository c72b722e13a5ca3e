"""The commutator-free Lie group Runge-Kutta method CF4 (lie4): order 4, fixed step."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.lie4.kernels import lie_field, lie_stage, lie_start, lie_update
from gyro_sim.integrators.base import FixedStepIntegrator

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem


class Lie4(FixedStepIntegrator):
    """Commutator-free Lie group Runge-Kutta method CF4, order 4, fixed step.

    The group SO(3)^nq x R^m acts on the state: a quaternion block by q <- exp(theta) (x) q
    (left multiplication, theta a world-frame rotation vector), every other component by
    translation y <- y + d. The vector field in the algebra is F = (omega, y'), omega the
    world angular velocity recovered from rhs as omega = 2 vec(q' (x) conj(q)). With
    exp(h F) y as that action, the order-4 scheme CF4 of [1] is

        Y1 = y                                  F1 = F(t, Y1)
        Y2 = exp(h/2 F1) y                      F2 = F(t + h/2, Y2)
        Y3 = exp(h/2 F2) y                      F3 = F(t + h/2, Y3)
        Y4 = exp(h F3 - h/2 F1) Y2              F4 = F(t + h, Y4)
        y1 = exp(h sum_i BETA2_i F_i) exp(h sum_i BETA1_i F_i) y   (the right one acts first)

    On the translation part it is the classical RK4. Quaternions stay unit to round-off by
    construction (no projection needed; `project` is called anyway), rotations stay on
    SO(3). Four rhs evaluations per step; no error estimate.

    One implementation, two drivers: the arithmetic of a step (omega from q', the stage
    exponents, the action exp(theta) (x) q with the translation, the output's two
    exponentials) is :mod:`gyro_sim.integrators.lie4.kernels`. On a system that offers
    `kernel_arguments()` and `quaternion_block()` (the compiled
    :class:`gyro_sim.dynamics.system.FastChainODE`) the n substeps of an `advance` run in one
    compiled call (:func:`gyro_sim.integrators.lie4.loop.lie_march`); on any other system (or with
    `use_compiled` False) this class steps in Python (`_step`), calling the same kernels between
    its rhs evaluations: the same steps, bit for bit.

    Measured (gyro_sim.bench.scenes.spherical_chain(10, rotors=True), h = 1 ms, CPU per
    simulated second, best of 5 on a shared 2-core machine): compiled march 24 ms in one
    advance, 27 ms in 10 ms advances (rk4's compiled march: 21 and 24 ms; the Python driver
    on the same FastChainODE ~115 ms; the former numpy step ~290 ms). The march compiles in
    ~17 s once per version of its files (when the integrator is built), then loads from
    numba's disk cache.

    References
    ----------
    .. [1] E. Celledoni, A. Marthinsen, B. Owren, "Commutator-free Lie group methods",
           Future Generation Computer Systems 19 (2003) 341-352.
    """

    name = "lie4"
    order = 4
    n_stages = 4
    C = np.array([0.0, 0.5, 0.5, 1.0])
    #: stage exponents: Y_s = exp(h sum_j ALPHA[s, j] F_j) Y_{BASE[s]}
    ALPHA = np.array([
        [0.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0],
        [-0.5, 0.0, 1.0, 0.0],
    ])
    BASE = (0, 0, 0, 1)
    #: output: y1 = exp(h BETA2 . F) exp(h BETA1 . F) y
    BETA1 = np.array([1 / 4, 1 / 6, 1 / 6, -1 / 12])
    BETA2 = np.array([-1 / 12, 1 / 6, 1 / 6, 1 / 4])
    #: BETA1 + BETA2: the weights of the translation part (classical RK4)
    B = BETA1 + BETA2

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        nq, nl = len(self.quat_index), self.lin_index.size
        self._Y = np.empty((self.n_stages, self.n))  # stage states
        self._W = np.empty((self.n_stages, nq, 3))  # omega of each stage (world)
        self._V = np.empty((self.n_stages, nl))  # y' of each stage, translation part
        self._qi = np.ascontiguousarray(self.quat_index, dtype=np.int64)
        self._li = np.ascontiguousarray(self.lin_index, dtype=np.int64)
        self._hALPHA = np.empty_like(self.ALPHA)
        #: the output's exponents, one row each: B (translation), BETA1, BETA2 (quaternions)
        self._BETA = np.array([self.B, self.BETA1, self.BETA2], dtype=np.float64)
        self._hBETA = np.empty_like(self._BETA)
        #: march in compiled code when the system allows it; False: step in Python (the same steps)
        self.use_compiled = True
        self._compiled = None
        if callable(getattr(system, "kernel_arguments", None)) and \
                callable(getattr(system, "quaternion_block", None)):
            from gyro_sim.integrators.lie4 import loop as fast_lie  # the compiled march (imports the kernel's module)

            self._compiled = fast_lie.LieMarch(system, self._qi, self._li, self.ALPHA, self.BASE,
                                               self._BETA, self.C)
            self._march_compiled(0.0, np.zeros(self.n), self.step, 0)  # compile or load it now,
            # not in the first advance (a node's first steps)

    def _march_compiled(self, t0: float, y: np.ndarray, h: float, n: int) -> int | None:
        if self._compiled is None or not self.use_compiled:
            return None
        done = self._compiled(t0, y, h, n, self._Y, self._W, self._V)
        self.nfev += self.n_stages * min(done + 1, n)
        return done

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        """One step (the compiled march's, statement for statement)."""
        Y, W, V, qi, li = self._Y, self._W, self._V, self._qi, self._li
        hALPHA, hBETA = self._hALPHA, self._hBETA
        np.multiply(self.ALPHA, h, out=hALPHA)
        np.multiply(self._BETA, h, out=hBETA)
        lie_start(y, Y)
        lie_field(Y, self._fun(t, Y[0]), 0, qi, li, W, V)
        for s in range(1, self.n_stages):
            lie_stage(Y, W, V, hALPHA, s, self.BASE[s], qi, li)
            lie_field(Y, self._fun(t + self.C[s] * h, Y[s]), s, qi, li, W, V)
        lie_update(y, W, V, hBETA, qi, li)
