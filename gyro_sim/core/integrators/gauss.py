"""Gauss-Legendre collocation, 2 stages (gauss4): order 4, fixed step, implicit, solved by a
Jacobian-free Newton-Krylov iteration in O(n) memory with a bounded cost per step.

A-stable, symplectic and conserving every quadratic invariant of the flow exactly (Hairer,
Lubich, Wanner, "Geometric Numerical Integration", 2nd ed., Springer 2006, sec. IV.2, Thm.
2.1): the norms |q|^2 of the quaternion blocks (q' = 1/2 (0, w) (x) q keeps them for any w),
so rotations stay on SO(3) without projection (`project` is still called, a no-op to
round-off) -- provided the collocation equations are solved to round-off, which the stop test
below asks for. For stiff (gyroscopic) scenes at the node's fixed step, where rk4 goes unstable.

Nonlinear solve (Hairer, Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
Springer 1996, sec. IV.8; Kelley, "Solving Nonlinear Equations with Newton's Method", SIAM
2003, ch. 3): Newton on the stage increments Z (2, size) of G(Z) = Z - h (A (x) I) F(Z) = 0,
with the Jacobian at the current iterate (full Newton: on a fast top the Jacobian turns with
the body within a step. Measured against J at the step's start, everything else equal: 15.6
against 22.4 rhs evaluations a step on a 20-link chain under gravity, 16 against 25 on the
heavy top at 1e2 rad/s, and the step-start Jacobian diverges on the first step at 1e3 and
1e4 rad/s). Each Newton system
(I - h (A (x) I) diag(J_s)) dZ = -G is solved by GMRES without forming any matrix: J_s v is a
forward difference of the rhs in the direction v (2 rhs evaluations per Krylov vector, both
stages). All in per-component scaled variables dZ_i / w_i, w_i = NEWTON_TOL (1 + |y_i|)
(atol = rtol = NEWTON_TOL); the stop test is Hairer-Wanner's (IV.8, eq. (8.13)): with the
contraction rate theta of successive updates, converged when theta / (1 - theta) |dZ| <=
NEWTON_KAPPA (the first update: when |dZ| <= NEWTON_FIRST_TOL); theta >= NEWTON_SLOW_RATE is
divergence, except at the round-off floor: an update already below NEWTON_STALL units (1e-10
relative) that stopped contracting (theta >= NEWTON_STALL_RATE) is the noise of the rhs and is
accepted (counted in `counts`): a per-component scale gives a component passing through 0 of
a large vector (a world angular velocity at 1e4 rad/s) a tolerance below its round-off. GMRES
stops at GMRES_RTOL of its initial residual (the inexact-Newton forcing term, Kelley 2003 sec.
3.2; 1e-4 was too loose for the top at 1e4 rad/s, 1e-8 costs more evaluations elsewhere) or at
GMRES_ATOL (rms, in units of the tolerance), else after GMRES_CAP vectors (no restart: the
partial solution is the update). The starting guess extrapolates the previous step's collocation polynomial (HW IV.8,
"starting values"), when the step continues the previous one (the same call, or a call that
starts where the last one ended), else Z = 0 (measured: 12 against 18 rhs evaluations a
step on a free chain, 16 against 23.5 on the top at 1e2 rad/s; no gain at 1e4 rad/s).

Cost per step, worst case (known): NEWTON_CAP iterations of 2 rhs evaluations (the stages) +
GMRES_CAP Krylov vectors of 2 evaluations: NEWTON_CAP (2 + 2 GMRES_CAP) = 336 evaluations and
O(GMRES_CAP^2 size) flops, memory (GMRES_CAP + 10) x 2 size floats. A step that does not
converge within NEWTON_CAP raises IntegrationError ("Newton iteration failed: ..." with the
reason); never silent.

Measured (compiled, h = 1 ms, `Simulator.advance` in 10 ms calls, gyro_sim.bench.scenes
spherical chains): 2 Newton iterations a step and 1.5-4 Krylov vectors each, 10-25 rhs
evaluations a step, 2.5-5.5 x rk4's cost per step (n = 100: ~0.35 ms without gravity, ~0.65 ms
with); the heavy top at 1e3 rad/s 3 iterations, 38 evaluations; at 1e4 rad/s (10 rad a step)
4 iterations (at most 6), ~95 evaluations -- it converges, but the precession of the axis is
wrong at that step (the spin is not resolved: -0.009 rad/s against +0.0245 rad/s; 0.0256 at
h = 0.25 ms). Memory: the workspace is 3 MB at n = 1000, 15 MB at n = 5000 (the dense
predecessor's iteration matrix alone: 39 GB at n = 5000). The compiled march takes ~15-45 s
to compile once per version of its files, then loads from numba's cache in ~0.1 s (when the
integrator is built).

One implementation, two drivers: the arithmetic is :mod:`gyro_sim.core.gauss_kernels`. On a
system that offers `kernel_arguments()` and `quaternion_block()` (the compiled
:class:`gyro_sim.core.system.FastChainODE`) the substeps of an `advance` run in one compiled
call (:func:`gyro_sim.core.fast_gauss.gauss_march`); on any other system this class steps in
Python, calling the same kernels between its rhs evaluations: the same steps, bit for bit.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import gauss_kernels as gk
from ..gauss_kernels import (
    COUNT_KRYLOV,
    COUNT_MAX_KRYLOV,
    COUNT_MAX_NEWTON,
    COUNT_NEWTON,
    COUNT_RHS,
    COUNT_STALLED,
    STEP_DIVERGED,
    STEP_LINEAR,
    STEP_NONFINITE,
    STEP_NOT_CONVERGED,
    STEP_OK,
    STEP_RHS_NONFINITE,
)
from .base import EPS, FixedStepIntegrator, IntegrationError, describe_nonfinite

if TYPE_CHECKING:
    from ..system import OdeSystem

_S3 = math.sqrt(3.0)
#: most Newton iterations per step (each: 2 rhs evaluations + a GMRES solve)
NEWTON_CAP = 8
#: most Krylov vectors per GMRES solve (each: 2 rhs evaluations); no restart
GMRES_CAP = 20
#: scale of the Newton iteration: w_i = NEWTON_TOL (1 + |y_i|) is the unit of its stop test
NEWTON_TOL = 1e-13
#: converged when the estimated error theta / (1 - theta) |dZ| is below this (HW IV.8: 0.01-0.1)
NEWTON_KAPPA = 0.1
#: the first update (no rate yet) converges alone when below this
NEWTON_FIRST_TOL = 0.01
#: a contraction rate theta at or above this: the iteration diverges (the step fails)
NEWTON_SLOW_RATE = 1.0
#: the round-off floor: an update below NEWTON_STALL tolerance units (1e-10 relative) that no
#: longer contracts (theta >= NEWTON_STALL_RATE) is the noise of the rhs: accepted (counted)
NEWTON_STALL = 1e3
NEWTON_STALL_RATE = 0.5
#: GMRES stops at this fraction of its initial residual (the inexact Newton forcing term) ...
GMRES_RTOL = 1e-6
#: ... or below this rms residual (units of the tolerance): more accuracy is not needed
GMRES_ATOL = 0.01
#: forward differences J v: a perturbation of rms FD_REL_STEP (1 + |y_i|) per component
FD_REL_STEP = math.sqrt(EPS)

#: the parameters of both drivers, indexed by gauss_kernels.PAR_* (the eps of the differences
#: depends on the size and is set per integrator)
_PARAMS = (NEWTON_TOL, NEWTON_KAPPA, NEWTON_FIRST_TOL, NEWTON_SLOW_RATE, GMRES_RTOL, GMRES_ATOL,
           math.nan, NEWTON_CAP, NEWTON_STALL, NEWTON_STALL_RATE)


def _lagrange(theta: float, ci: float, cj: float) -> float:
    """L_i(theta) of the nodes {0, c_i, c_j}: 1 at c_i, 0 at 0 and c_j."""
    return theta * (theta - cj) / (ci * (ci - cj))


class Gauss4(FixedStepIntegrator):
    """Two-stage Gauss-Legendre collocation, order 4, fixed step (see the module docstring).

    Attributes (besides the base's counters)
    ----------------------------------------
    counts : int64 (6,), cumulative, indexed by gauss_kernels.COUNT_*: Newton iterations,
        Krylov vectors (each 2 rhs evaluations), the most Newton iterations of one step, the
        most Krylov vectors of one GMRES solve, rhs evaluations of the steps, steps accepted
        at the round-off floor.
    use_compiled : True (default): march in compiled code when the system offers it; False:
        step in Python on any system (the same steps, bit for bit).
    workspace_bytes : bytes of the arrays the steps use, O(size).

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
           Springer 1996, sec. IV.5 (tableau, Table 5.1) and IV.8 (Newton, stop test,
           starting values).
    .. [2] E. Hairer, C. Lubich, G. Wanner, "Geometric Numerical Integration", 2nd ed.,
           Springer 2006, sec. IV.2 (quadratic invariants).
    .. [3] C. T. Kelley, "Solving Nonlinear Equations with Newton's Method", SIAM 2003, ch. 3
           (Newton-Krylov, finite-difference directional derivatives); "Iterative Methods
           for Linear and Nonlinear Equations", SIAM 1995, sec. 3.4-3.5 (GMRES, Givens).
    """

    name = "gauss4"
    order = 4
    n_stages = 2
    C = np.array([0.5 - _S3 / 6, 0.5 + _S3 / 6])
    A = np.array([[0.25, 0.25 - _S3 / 6], [0.25 + _S3 / 6, 0.25]])
    B = np.array([0.5, 0.5])
    #: y1 = y + D . Z: B^T A^-1 (no rhs evaluation at the stages' end)
    D = np.array([-_S3, _S3])
    #: extrapolate the previous step's collocation polynomial for the starting guess
    predict = True

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        n, m = self.n, GMRES_CAP
        self._Z = np.zeros((2, n))
        self._Zp = np.zeros((2, n))  # the previous step's stage increments (the predictor)
        self._Ys = np.empty((2, n))
        self._F = np.empty((2, n))
        self._Fp = np.empty((2, n))
        self._Yp = np.empty(n)
        self._w = np.empty(n)
        self._V = np.zeros((m + 1, 2, n))
        self._H = np.zeros((m + 1, m))
        self._cs = np.zeros(m)
        self._sn = np.zeros(m)
        self._g = np.zeros(m + 1)
        self._coef = np.zeros(m)
        self._info = np.zeros(3)  # a failing step: iteration, rate, update norm
        self.counts = np.zeros(6, dtype=np.int64)
        self._h_prev: float | None = None  # step of _Zp; None: no predictor
        self._t_end: float | None = None
        self._y_end = np.empty(n)
        self._fd_eps = FD_REL_STEP * math.sqrt(2.0 * n) / NEWTON_TOL if n else 1.0
        self._params = np.array(_PARAMS, dtype=np.float64)
        self._params[gk.PAR_FD_EPS] = self._fd_eps
        has_kernel = callable(getattr(system, "kernel_arguments", None)) and \
            callable(getattr(system, "quaternion_block", None))
        #: march in compiled code when the system allows it; False: step in Python (the same steps)
        self.use_compiled = True
        self._compiled = None
        if has_kernel:
            from .. import fast_gauss  # the compiled march (imports the kernel's module)

            self._compiled = fast_gauss.GaussMarch(system)
            self._A = np.array(self.A, dtype=np.float64)
            self._C = np.array(self.C, dtype=np.float64)
            self._D = np.array(self.D, dtype=np.float64)
            self._march_compiled(0.0, np.zeros(n), self.step, 0)  # compile or load it now, not
            # in the first advance (a node's first steps): ~0.1 s from numba's disk cache

    def reset(self) -> None:
        super().reset()
        self._h_prev = None
        self._t_end = None

    @property
    def workspace_bytes(self) -> int:
        """Bytes of the arrays the steps use (O(size): GMRES_CAP + 10 rows of 2 size)."""
        return sum(a.nbytes for a in (self._Z, self._Zp, self._Ys, self._F, self._Fp, self._Yp,
                                      self._w, self._V, self._H, self._cs, self._sn, self._g,
                                      self._coef, self._y_end))

    # --- the starting guess ---------------------------------------------------------------
    def predictor(self, ratio: float) -> np.ndarray:
        """P (2, 2): Z_new = P Z_old extrapolates the collocation polynomial u of the last step
        (u(t0 + x h) = y0 + sum_i L_i(x) Z_i, nodes {0, c_1, c_2}) to the next step of
        `ratio` times its size: Z_new[s] = u(1 + ratio c_s) - u(1) (HW IV.8)."""
        c1, c2 = self.C
        P = np.empty((2, 2))
        for s in range(2):
            x = 1.0 + ratio * self.C[s]
            P[s, 0] = _lagrange(x, c1, c2) - _lagrange(1.0, c1, c2)
            P[s, 1] = _lagrange(x, c2, c1) - _lagrange(1.0, c2, c1)
        return P

    def _start(self, h: float) -> np.ndarray | None:
        """The predictor matrix of the first step of size h of a march, or None (Z = 0)."""
        if not self.predict or self._h_prev is None:
            return None
        return self.predictor(h / self._h_prev)

    # --- the march -----------------------------------------------------------------------------
    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        if self._t_end != t0 or not np.array_equal(y, self._y_end):
            self._h_prev = None  # not where the last march ended: no predictor
        self._t_end = None
        super()._march(t0, y, t1)
        self._t_end = t1
        self._y_end[:] = y

    def _march_compiled(self, t0: float, y: np.ndarray, h: float, n: int) -> int | None:
        if self._compiled is None or not self.use_compiled:
            return None
        P1 = self.predictor(1.0) if self.predict else None
        done, status, rhs_calls = self._compiled(
            t0, y, h, n, self._A, self._C, self._D, self._start(h), P1, self._params, self._Zp,
            self._Z, self._Ys, self._F, self._Fp, self._Yp, self._w, self._V, self._H, self._cs,
            self._sn, self._g, self._coef, self._info, self.counts)
        self.nfev += rhs_calls
        if status not in (STEP_OK, STEP_NONFINITE):
            self.nsteps += done
            self._h_prev = None
            raise self._failure(status, t0 + done * h, h)
        self._h_prev = h if done == n else None
        return done

    def _failure(self, status: int, t: float, h: float) -> IntegrationError:
        it, theta, norm = self._info
        if status == STEP_RHS_NONFINITE:
            why = f"rhs not finite at the stages ({describe_nonfinite(self._F)})"
        elif status == STEP_DIVERGED:
            why = f"diverging (rate {theta:.2g} at iteration {int(it)}, update {norm:.2g} x tolerance)"
        elif status == STEP_LINEAR:
            why = f"GMRES gave a non-finite update at iteration {int(it)}"
        else:
            why = (f"not converged in {int(self._params[gk.PAR_NEWTON_CAP])} iterations (rate {theta:.2g}, update "
                   f"{norm:.2g} x tolerance)")
        return IntegrationError(self.name, "Newton iteration failed", t, h, why)

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        P = self._start(h)
        status = self._newton(t, y, h, P)
        if status != STEP_OK:
            self._h_prev = None
            raise self._failure(status, t, h)
        gk.gauss_update(y, self._Z, self.D)
        self._Zp[:] = self._Z
        self._h_prev = h

    def _rhs_into(self, t: float, ys: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._fun(t, ys)
        self.counts[COUNT_RHS] += 1

    def _newton(self, t: float, y: np.ndarray, h: float, P: np.ndarray | None) -> int:
        """The Newton iteration of one step (the compiled march's, statement for statement):
        Z (2, size) the stage increments on success; returns a STEP_ status."""
        n, m = self.n, GMRES_CAP
        Z, Ys, F, Fp, Yp, w = self._Z, self._Ys, self._F, self._Fp, self._Yp, self._w
        V, H, cs, sn, g, coef, counts = self._V, self._H, self._cs, self._sn, self._g, \
            self._coef, self.counts
        par = self._params
        tol, kappa, first_tol, diverge = par[gk.PAR_TOL], par[gk.PAR_KAPPA], par[gk.PAR_FIRST_TOL], \
            par[gk.PAR_DIVERGE]
        grtol, gatol, eps = par[gk.PAR_GMRES_RTOL], par[gk.PAR_GMRES_ATOL], par[gk.PAR_FD_EPS]
        newton_cap = int(par[gk.PAR_NEWTON_CAP])
        stall, stall_rate = par[gk.PAR_STALL], par[gk.PAR_STALL_RATE]
        hA = self.A * h
        tc = (t + self.C[0] * h, t + self.C[1] * h)
        inv_eps = 1.0 / eps
        gk.gauss_weights(y, tol, w)
        if P is None:
            Z[:] = 0.0
        else:
            gk.gauss_predict(self._Zp, P, Z)
        norm_prev = 0.0
        for it in range(newton_cap):
            counts[COUNT_NEWTON] += 1
            counts[COUNT_MAX_NEWTON] = max(counts[COUNT_MAX_NEWTON], it + 1)
            for st in range(2):
                gk.gauss_stage_state(y, Z, st, Ys[st])
                self._rhs_into(tc[st], Ys[st], F[st])
            if not gk.all_finite(F):
                return STEP_RHS_NONFINITE
            beta = gk.gmres_start(Z, F, hA, w, V, g)
            if beta == 0.0:
                return STEP_OK
            goal = gk.gmres_goal(beta, grtol, gatol, n)
            k = 0
            while k < m:
                for st in range(2):
                    gk.gauss_perturbed(Ys[st], w, V[k], st, eps, Yp)
                    self._rhs_into(tc[st], Yp, Fp[st])
                gk.gauss_operator(V[k], Fp, F, hA, w, inv_eps, V[k + 1])
                res = gk.gmres_arnoldi(V, H, cs, sn, g, k)
                k += 1
                if res <= goal:
                    break
            counts[COUNT_KRYLOV] += k
            counts[COUNT_MAX_KRYLOV] = max(counts[COUNT_MAX_KRYLOV], k)
            norm = gk.gmres_update(V, H, g, k, w, Z, coef)
            code, theta = gk.newton_test(norm, norm_prev, it, kappa, first_tol, diverge, stall,
                                         stall_rate)
            self._info[:] = (it, theta, norm)
            if code == gk.NEWTON_CONVERGED:
                return STEP_OK
            if code == gk.NEWTON_STALLED:
                counts[COUNT_STALLED] += 1
                return STEP_OK
            if code == gk.NEWTON_DIVERGING:
                return STEP_DIVERGED
            if code == gk.NEWTON_NOT_FINITE:
                return STEP_LINEAR
            norm_prev = norm
        return STEP_NOT_CONVERGED
