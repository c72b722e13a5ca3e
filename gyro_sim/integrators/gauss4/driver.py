"""Gauss-Legendre collocation, 2 stages (gauss4): order 4, fixed step, implicit, with a bounded
Newton iteration: dense simplified Newton (Jacobians kept across steps) on small systems,
Newton-Krylov in O(n) memory on large ones, and a bounded retake in substeps.

A-stable, symmetric, and conserving every quadratic invariant of the flow exactly (Hairer,
Lubich, Wanner, "Geometric Numerical Integration", 2nd ed., Springer 2006, sec. IV.2, Thm.
2.1): the norms |q|^2 of the quaternion blocks (q' = 1/2 (0, w) (x) q keeps them for any w),
so rotations stay on SO(3) without projection (`project` is still called, a no-op to
round-off) -- provided the collocation equations are solved to round-off, which the stop test
below asks for. For stiff (gyroscopic) scenes at the node's fixed step, where rk4 goes unstable.
Symplectic only on a Hamiltonian system in canonical coordinates: not on the package's state
of quaternions and joint rates (the world angular momentum is cubic there, and the double
gyroscope's energy error grows as t^2: docs/integrators.md); gauss4s
(gauss_canonical.py) is this class stepping the chain's canonical equations, where it is.

Measured (compiled, h = 1 ms, `Simulator.advance` in 10 ms calls; "before": the
Krylov-only iteration this replaced; rhs evaluations a step are exact counts, times are CPU on
the shared 2-core machine under a load of 3-4 and vary by 30 %):

Per case (size), before and after:

- heavy tip, mass ratio 1e6 (21), compiled
    before: fails at t = 0.087 s ("diverging")
    after: 0.1 s; 1e-9 energy until the whip at t = 0.0874 s, which is retaken down to h / 2^12 (worst step 7244
    evaluations); the energy jumps 40x there (see below)
- heavy tip 1e6, numpy backend
    before: fails at the first step (rhs round-off 6e-8: "not converged")
    after: 0.1 s; measured floor ~1e4 units; energy within 0.5 %
- step moments 1e3 x gravity torque (19)
    before: fails at t = 0.01 s
    after: 0.05 s; rates reach 3e3-3e4 rad/s (3-30 rad a step): 39 of 40 steps retaken, 1000 evaluations and ~3.4 ms
    a step (not real time)
- double gyroscope 1e3 rad/s (15), 3 s
    before: 43 evaluations a step, energy 9.5e-10
    after: 48 a step (a new Jacobian pair every step: the bodies turn 1 rad), ~70 us, energy 9.5e-10
- double gyroscope 1e4 rad/s, 3 s
    before: fails at the first step ("not converged in 8 iterations")
    after: 109 a step, ~130 us, energy 1.3e-7
- heavy top 1e2 / 1e3 / 1e4 rad/s (7), 3 s
    before: 16 / 38 / 94 a step
    after: 17 / 32 / 60 a step, energy 8e-15 / 5e-14 / 1e-9

Long runs (spin sweep, 1e5 steps): the double gyroscope at 1e3 rad/s still shows the energy
error growing as t^2 (to 1.0e-6 at 100 s) -- the before and after solvers give the same
curve to 6 digits, so it is the discretisation at 1 rad a step, not the solve (gauss4 keeps
quadratic invariants; this energy is not one); at 1e4 rad/s t^2 to 6e-5, the axis off by
1.7 rad (10 rad a step does not resolve the spin).

At 10 rad a step the collocation equations have several solutions, and which one Newton finds
depends on how it is steered: DIVERGENCE_REFRESHES trades the two hard cases. At 1 (a
divergence with Jacobians of this (sub)step fails it: retake in halves) the heavy tip's whip
is resolved in 1 us pieces (energy 2 %, 46 evaluations a step) but the double gyroscope at
1e4 rad/s lands on other roots (energy 0.05-0.2 over 3 s, 150-440 evaluations a step); at 2-4
the gyroscope keeps 4e-8 - 9e-7 (98-180 evaluations) and the whip's 1 ms step converges to
a root 40x off in energy. Consistent over 4 call lengths each. The fast spin is the issue's
case: 4. An error-controlled method (the node's `fixed` with its energy watchdog falls back to
dop853) is the answer to the whip.

Cost per step on gyro_sim.bench.scenes spherical chains with gravity (median over 100 calls):

| n (states) | rk4 | gauss4 before | gauss4 after |
|---:|---:|---:|---:|
| 2 (14) | 4.8 us | 21 us (12.0 evaluations) | 17 us (9.7, dense; worst step 36) |
| 10 (70) | 8.6 us | 57 us (15.6) | 39 us (15.6, Krylov: the same steps) |
| 20 (140) | 13.5 us | 105 us (17.2) | 70 us (17.2, Krylov) |
| 100 (700) | 53 us | 722 us (18.1) | 623 us (18.1, Krylov) |

(the README's 33/64/97/373 us were measured on a quiet machine; above n = 5 the paths are the
same algorithm, the differences are the load). DENSE_MAX_SIZE = 40 is the crossover measured
on soft chains: dense 13 / 18 / 38 / 117 us at n = 1 / 2 / 5 / 9 against Krylov 21 / 25 / 34
/ 56 us -- each dense iteration's solve is O(size^2) and a new matrix O(size^3) (at n = 20 a
pair of Jacobians and a 280 x 280 factorisation cost ~15 ms, and a falling chain asks for
one every ~16 steps), while the Krylov path's cost stays O(size) per product.

Nonlinear solve (Hairer, Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
Springer 1996, sec. IV.8): Newton on the stage increments Z (2, size) of
G(Z) = Z - h (A (x) I) F(Z) = 0, iteration matrix I - h (A (x) I) diag(J_1, J_2). Two paths,
by the system's size (`DENSE_MAX_SIZE`; the option `dense` overrides):

- **dense** (size <= DENSE_MAX_SIZE): the stage Jacobians J_s = f'(y + Z_s) by forward
  differences (size rhs evaluations per stage; in compiled code on the compiled path), the
  real (2 size)^2 iteration matrix factored with partial pivoting, both KEPT ACROSS STEPS:
  each iteration costs 2 rhs evaluations and a solve. They are formed anew at the current
  iterate (a) at the first step and whenever the step changes (a substep, another `step`),
  (b) when the contraction rate theta of successive updates exceeds JACOBIAN_REFRESH_RATE or
  is too slow to converge within the cap (HW IV.8, eq. (8.15)), (c) when the iteration
  diverges (theta >= 1) or gives a non-finite update: back to the last iterate, Jacobians
  there, while fewer than DIVERGENCE_REFRESHES were formed in the (sub)step -- at most
  JACOBIAN_REFRESH_CAP times a (sub)step; else the (sub)step fails. The stop test is the
  one below with DENSE_KAPPA for NEWTON_KAPPA. Two
  stage Jacobians, not one: on a fast top (1e4 rad/s, 10 rad a step) the Jacobian in
  quaternion coordinates turns with the body between the stages, and a single Jacobian (at
  the stages' mean, the classic complex N x N form of the eigen-decomposition of A) did not
  converge within 20 iterations on the first step of the double gyroscope and the heavy top
  at 1e4 rad/s, where the stagewise pair converges. The real 2 size system is the same
  matrix the complex form factors at twice the flops, immaterial at these sizes.
- **Newton-Krylov** (size > DENSE_MAX_SIZE; O(n) memory): each Newton system solved by GMRES
  without forming any matrix, J_s v a forward difference of the rhs in the direction v (2
  rhs evaluations per Krylov vector, both stages), the Jacobian at the current iterate
  (Kelley, "Solving Nonlinear Equations with Newton's Method", SIAM 2003, ch. 3). GMRES stops
  at GMRES_RTOL of its initial residual or at GMRES_ATOL (rms, tolerance units), else after
  GMRES_CAP vectors (no restart: the partial solution is the update).

Both in per-component scaled variables dZ_i / w_i, w_i = NEWTON_TOL (1 + |y_i|); the stop
test is Hairer-Wanner's (IV.8, eq. (8.13)): converged when theta / (1 - theta) |dZ| <=
NEWTON_KAPPA (the first update after a new matrix: when |dZ| <= NEWTON_FIRST_TOL); theta >=
NEWTON_SLOW_RATE is divergence, except at the round-off floor: an update below the floor that
stopped contracting (theta >= NEWTON_STALL_RATE) is the noise of the rhs and is accepted
(counted). The floor is NEWTON_STALL units (1e-10 relative) on the Krylov path; on the dense
path it is MEASURED whenever the matrix is formed: the Newton update that moving the stage
states by NOISE_ULPS ulps causes (2 rhs evaluations and a solve), times FLOOR_FACTOR, at least
NEWTON_STALL -- the numpy reference's rhs carries ~6e-8 relative round-off on the heavy tip
(mass ratio 1e6), a floor of ~1e4 units there, where the compiled kernel's (1e-14) leaves
NEWTON_STALL. The starting guess extrapolates the previous (sub)step's collocation polynomial
(HW IV.8, "starting values") when the step continues it, else Z = 0.

Retake: a (sub)step whose iteration fails (not converged, diverging, non-finite rhs or
update, singular matrix) is taken again from its start as two halves, the failing half again
as two quarters, ... down to h / 2^RETAKE_DEPTH; after a success the pieces coarsen by one
level whenever the position allows (a dyadic grid: only the hard spot is refined, back to
whole steps after it), at most RETAKE_BUDGET attempts a step. Counted (`counts`: pieces
retaken, steps that needed it, the deepest level); when the finest piece fails or the budget
is spent, IntegrationError ("Newton iteration failed: <reason> (the step retaken in halves
down to h / 2^k, ...)"), y at the step's start; never silent. Uniform halving (2, 4, 8
substeps) was not enough: the heavy tip (mass ratio 1e6) whips at t = 0.0874 s, its two
light links passing through alignment with accelerations of 4e9 rad/s^2 for microseconds
(dop853 takes 207 steps in that millisecond), and its Newton iteration failed at 1/128 ms;
the dyadic retake passes it at ~1 us pieces (h / 2^10) in 11 attempts. With `level_max` > 0
(gauss4s) the steps start at a level kept across steps (gauss_kernels.level_next): where most
steps need a retake, the next ones start a level deeper (equal pieces), and a coarser level is
probed after LEVEL_PATIENCE calm steps; the coarsening after a hard spot stops at that level.

Cost per step, worst case (known, `worst_step_rhs`): dense, a (sub)step is at most
DENSE_NEWTON_CAP iterations of 2 rhs evaluations and JACOBIAN_REFRESH_CAP matrices of
2 (size + 1) evaluations and one (2 size)^3 factorisation; Krylov, NEWTON_CAP (2 + 2
GMRES_CAP) evaluations; a step at most RETAKE_BUDGET (sub)steps of those (13,824 evaluations
for the heavy tip, 21 states). `counts[COUNT_MAX_STEP_RHS]` records the most any step took.
A step that needs it is not real time, by design: it is the bounded price of not stopping.

One implementation, two drivers: the arithmetic is :mod:`gyro_sim.integrators.gauss4.kernels`. On a
system that offers `kernel_arguments()` and `quaternion_block()` (the compiled
:class:`gyro_sim.dynamics.system.FastChainODE`) the steps of an `advance` run in one compiled
call (:func:`gyro_sim.integrators.gauss4.loop.gauss_march`); on any other system this class steps in
Python, calling the same kernels between its rhs evaluations: the same steps, bit for bit.
The compiled march takes ~1 min to compile once per version of its files, then loads from
numba's cache in ~0.1 s (when the integrator is built).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.gauss4 import kernels as gk
from gyro_sim.integrators.gauss4.kernels import (
    COUNT_JACOBIAN, COUNT_KRYLOV, COUNT_LU, COUNT_MAX_KRYLOV, COUNT_MAX_NEWTON, COUNT_MAX_DEPTH,
    COUNT_MAX_STEP_RHS, COUNT_STEPS_RETAKEN, COUNT_NEWTON, COUNT_RETAKEN, COUNT_RHS, COUNT_STALLED,
    DST_FLOOR, DST_H, DST_HPRED, DST_REFRESH, H_REUSE, STEP_BUDGET, STEP_DIVERGED, STEP_LINEAR,
    STEP_NONFINITE, STEP_OK, STEP_RHS_NONFINITE, STEP_SINGULAR,
)
from gyro_sim.integrators.base import EPS, FixedStepIntegrator, IntegrationError, describe_nonfinite

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

_S3 = math.sqrt(3.0)
#: the dense path up to this many states (the Krylov path above: O(n) memory)
DENSE_MAX_SIZE = 40
#: most Newton iterations per (sub)step, Krylov path (each: 2 rhs evaluations + a GMRES solve)
NEWTON_CAP = 8
#: most Krylov vectors per GMRES solve (each: 2 rhs evaluations); no restart
GMRES_CAP = 20
#: most Newton iterations per (sub)step, dense path (each: 2 rhs evaluations + a solve)
DENSE_NEWTON_CAP = 20
#: dense path: new stage Jacobians when the contraction rate is above this ...
JACOBIAN_REFRESH_RATE = 0.25
#: ... at most this many times a (sub)step (the first included)
JACOBIAN_REFRESH_CAP = 4
#: dense path: a diverging iteration goes back to its last iterate with new Jacobians there
#: only while fewer than this many were formed in the (sub)step; then the (sub)step fails
DIVERGENCE_REFRESHES = 4
#: a failed (sub)step is taken again as two halves, down to h / 2^RETAKE_DEPTH ...
RETAKE_DEPTH = 12
#: ... with at most this many (sub)step attempts a step
RETAKE_BUDGET = 64
#: where most steps need a retake, the next ones start in halves, one level deeper, down to
#: h / 2^LEVEL_MAX (16 pieces: the budget keeps 48 attempts for retakes) ...
LEVEL_MAX = 4
#: ... and after this many steps without a retake a level coarser is tried (gauss_kernels.level_next;
#: a failed probe doubles the wait for the next, up to 128x).
#: gauss4s's choice (option level_max): on the heavy top at 1e4 rad/s (10 rad a step) no whole
#: step converges; tried whole, then in halves, then quarters, step after step, 487 rhs
#: evaluations a step and the energy off by 5.6e-10 after 1000 s (growing: the pieces' sizes
#: follow the state); in quarters, 295 a step (the double gyroscope: 465 against 799). gauss4
#: keeps 0: on the package's state most of its whole steps converge there, and on the double
#: gyroscope at 1e4 rad/s its retakes come in bursts, where halves cost it 2x (224 evaluations
#: a step against 113, measured)
LEVEL_PATIENCE = 100
#: dense path: the round-off floor is this many times the measured noise of the update
FLOOR_FACTOR = 10.0
#: scale of the Newton iteration: w_i = NEWTON_TOL (1 + |y_i|) is the unit of its stop test
NEWTON_TOL = 1e-13
#: converged when the estimated error theta / (1 - theta) |dZ| is below this (HW IV.8: 0.01-0.1)
NEWTON_KAPPA = 0.1
#: the same on the dense path (1e-18 relative): its simplified iteration converges linearly,
#: so what it leaves has the sign of the next update, step after step -- a systematic error
#: that adds up: stopping at NEWTON_KAPPA, |q| drifted by 4e-13 over 500 steps (a 3-body
#: chain), and at 1e-3 the quadratic invariants of Euler's rigid body by 3.3e-13 over 1e4
#: steps, growing linearly; at 1e-5, 3e-15 (round-off, no growth) for 1.2 more rhs
#: evaluations a step (8.3 against 7.2 there)
DENSE_KAPPA = 1e-5
#: the first update (no rate yet) converges alone when below this
NEWTON_FIRST_TOL = 0.01
#: a contraction rate theta at or above this: the iteration diverges
NEWTON_SLOW_RATE = 1.0
#: the round-off floor (at least): an update below NEWTON_STALL tolerance units (1e-10
#: relative) that no longer contracts (theta >= NEWTON_STALL_RATE) is the noise of the rhs
NEWTON_STALL = 1e3
NEWTON_STALL_RATE = 0.5
#: GMRES stops at this fraction of its initial residual (the inexact Newton forcing term) ...
GMRES_RTOL = 1e-6
#: ... or below this rms residual (units of the tolerance): more accuracy is not needed
GMRES_ATOL = 0.01
#: forward differences J v: a perturbation of rms FD_REL_STEP (1 + |y_i|) per component
FD_REL_STEP = math.sqrt(EPS)

_WHY = {STEP_RHS_NONFINITE: "rhs not finite at the stages",
        STEP_SINGULAR: "iteration matrix singular or not finite",
        STEP_BUDGET: "the step's retake budget is spent"}


class Gauss4(FixedStepIntegrator):
    """Two-stage Gauss-Legendre collocation, order 4, fixed step (see the module docstring).

    Parameters (besides the base's)
    -------------------------------
    dense : None (default: size <= DENSE_MAX_SIZE), True or False: the Newton path.
    kappa : the dense path's stop test (tolerance units, default DENSE_KAPPA); its Jacobian
        refresh test keeps DENSE_KAPPA. gauss4s asks for STRUCTURE_KAPPA.
    level_max : the deepest level (pieces of h / 2^level) the steps may start at when most
        need a retake (gauss_kernels.level_next), at most LEVEL_MAX; 0 (default): every step
        is tried whole first. gauss4s asks for LEVEL_MAX.

    Attributes (besides the base's counters; njev counts stage Jacobians, nlu factorisations)
    -----------------------------------------------------------------------------------------
    counts : int64 (gauss_kernels.N_COUNTS,), cumulative, indexed by gauss_kernels.COUNT_*:
        Newton iterations, Krylov vectors, the most Newton iterations of one (sub)step, the
        most Krylov vectors of one GMRES solve, rhs evaluations of the steps, (sub)steps
        accepted at the round-off floor, stage-Jacobian pairs formed, matrices factored,
        pieces retaken as halves, the most rhs evaluations of one step, the deepest halving
        (a piece of h / 2^k), steps that needed a retake.
    dense : bool, the path taken.
    use_compiled : True (default): march in compiled code when the system offers it; False:
        step in Python on any system (the same steps, bit for bit).
    workspace_bytes : bytes of the arrays the steps use: O(size) on the Krylov path,
        6 size^2 floats more on the dense one.

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
           Springer 1996, sec. IV.5 (tableau, Table 5.1) and IV.8 (simplified Newton, stop
           test, starting values).
    .. [2] E. Hairer, C. Lubich, G. Wanner, "Geometric Numerical Integration", 2nd ed.,
           Springer 2006, sec. IV.2 (quadratic invariants).
    .. [3] C. T. Kelley, "Solving Nonlinear Equations with Newton's Method", SIAM 2003, ch. 3
           (Newton-Krylov, finite-difference directional derivatives); "Iterative Methods
           for Linear and Nonlinear Equations", SIAM 1995, sec. 3.4-3.5 (GMRES, Givens).
    .. [4] G. H. Golub, C. F. Van Loan, "Matrix Computations", 4th ed., Johns Hopkins 2013,
           sec. 3.4 (Gaussian elimination with partial pivoting).
    """

    name = "gauss4"
    order = 4
    n_stages = 2
    C = np.array([0.5 - _S3 / 6, 0.5 + _S3 / 6])
    A = np.array([[0.25, 0.25 - _S3 / 6], [0.25 + _S3 / 6, 0.25]])
    B = np.array([0.5, 0.5])
    #: B^T A^-1: y1 = y + D . Z (no rhs evaluation at the stages' end); computed as
    #: y + h B . F + D . (Z - h A F) (gauss_kernels.gauss_update: the rounded D only on the last
    #: Newton correction), with h A from gauss_kernels.gauss_scaled
    D = np.array([-_S3, _S3])
    #: extrapolate the previous step's collocation polynomial for the starting guess
    predict = True

    def __init__(self, system: OdeSystem, dense: bool | None = None, kappa: float | None = None,
                 level_max: int = 0, **options):
        super().__init__(system, **options)
        n = self.n
        self.dense = bool(n <= DENSE_MAX_SIZE if dense is None else dense)
        m = 0 if self.dense else GMRES_CAP
        nd = n if self.dense else 0
        ws = {"Z": np.zeros((2, n)), "Zp": np.zeros((2, n)), "Zs": np.zeros((2, n)),
              "Zb": np.zeros((2, n)), "ys": np.zeros(n), "y0": np.zeros(n), "Ys": np.zeros((2, n)),
              "F": np.zeros((2, n)), "Fp": np.zeros((2, n)), "Yp": np.zeros(n), "w": np.zeros(n),
              "V": np.zeros((m + 1, 2, n)), "H": np.zeros((m + 1, m)), "cs": np.zeros(m),
              "sn": np.zeros(m), "coef": np.zeros(m), "g": np.zeros(m + 1),
              "J": np.zeros((2, nd, nd)), "M": np.zeros((2 * nd, 2 * nd)),
              "piv": np.zeros(2 * nd, dtype=np.int64), "r": np.zeros(2 * nd), "P": np.zeros((2, 2)),
              "hA": np.zeros((2, 2))}
        # the compiled march's workspace order (numba-free import)
        from gyro_sim.integrators.gauss4.loop import WS_FIELDS

        self._ws = tuple(ws[k] for k in WS_FIELDS)
        self._wsd = ws
        self._info = np.zeros(3)  # a failing step: iteration, rate, update norm
        self._dstate = np.zeros(gk.N_DSTATE)  # the dense matrix's step, floor, refresh flag; predictor step
        self.counts = np.zeros(gk.N_COUNTS, dtype=np.int64)
        self._t_end: float | None = None
        self._y_end = np.empty(n)
        self._fd_eps = FD_REL_STEP * math.sqrt(2.0 * n) / NEWTON_TOL if n else 1.0
        self._params = np.zeros(gk.N_PARAMS)
        for k, v in ((gk.PAR_TOL, NEWTON_TOL), (gk.PAR_KAPPA, NEWTON_KAPPA),
                     (gk.PAR_FIRST_TOL, NEWTON_FIRST_TOL), (gk.PAR_DIVERGE, NEWTON_SLOW_RATE),
                     (gk.PAR_GMRES_RTOL, GMRES_RTOL), (gk.PAR_GMRES_ATOL, GMRES_ATOL),
                     (gk.PAR_FD_EPS, self._fd_eps), (gk.PAR_NEWTON_CAP, NEWTON_CAP),
                     (gk.PAR_STALL, NEWTON_STALL), (gk.PAR_STALL_RATE, NEWTON_STALL_RATE),
                     (gk.PAR_DENSE_CAP, DENSE_NEWTON_CAP), (gk.PAR_REFRESH_RATE, JACOBIAN_REFRESH_RATE),
                     (gk.PAR_REFRESH_CAP, JACOBIAN_REFRESH_CAP), (gk.PAR_DEPTH, RETAKE_DEPTH),
                     (gk.PAR_FLOOR_FACTOR, FLOOR_FACTOR), (gk.PAR_DENSE, float(self.dense)),
                     (gk.PAR_BUDGET, RETAKE_BUDGET),
                     (gk.PAR_DENSE_KAPPA, DENSE_KAPPA if kappa is None else kappa),
                     (gk.PAR_DIV_REFRESH, DIVERGENCE_REFRESHES), (gk.PAR_REFRESH_KAPPA, DENSE_KAPPA),
                     (gk.PAR_LEVEL_MAX, min(int(level_max), LEVEL_MAX)), (gk.PAR_PATIENCE, LEVEL_PATIENCE)):
            self._params[k] = v
        self._A = np.array(self.A, dtype=np.float64)
        self._C = np.array(self.C, dtype=np.float64)
        self._D = np.array(self.D, dtype=np.float64)
        has_kernel = callable(getattr(system, "kernel_arguments", None)) and \
            callable(getattr(system, "quaternion_block", None))
        #: march in compiled code when the system allows it; False: step in Python (the same steps)
        self.use_compiled = True
        self._compiled = None
        if has_kernel:
            # the compiled march (imports the kernel's module)
            from gyro_sim.integrators.gauss4 import loop as fast_gauss

            # compiled (or loaded from numba's disk cache, ~0.1 s) by the first march: the node
            # runs one before real time (its warm-up); "fixed" builds a gauss4s it may never run
            self._compiled = fast_gauss.GaussMarch(system)

    def reset(self) -> None:
        """Forget the predictor and the dense path's matrix (after a reset of the state)."""
        super().reset()
        self._dstate[:] = 0.0
        self._t_end = None

    @property
    def workspace_bytes(self) -> int:
        """Bytes of the arrays the steps use (O(size) on the Krylov path: GMRES_CAP + 10 rows
        of 2 size floats; 6 size^2 floats more on the dense path)."""
        return sum(a.nbytes for a in self._ws) + self._y_end.nbytes

    @property
    def worst_step_rhs(self) -> int:
        """The most rhs evaluations one step can take (the known worst case): the retake
        budget times a (sub)step's most -- dense: DENSE_NEWTON_CAP iterations of 2 and
        JACOBIAN_REFRESH_CAP matrices of 2 (size + 1); Krylov: NEWTON_CAP iterations of
        2 + 2 GMRES_CAP."""
        p = self._params
        if self.dense:
            sub = 2 * int(p[gk.PAR_DENSE_CAP]) + int(p[gk.PAR_REFRESH_CAP]) * 2 * (self.n + 1)
        else:
            sub = int(p[gk.PAR_NEWTON_CAP]) * (2 + 2 * self._wsd["H"].shape[1])
        return int(p[gk.PAR_BUDGET]) * sub

    # --- the starting guess ---------------------------------------------------------------
    def predictor(self, ratio: float) -> np.ndarray:
        """P (2, 2): Z_new = P Z_old extrapolates the collocation polynomial u of the last step
        (u(t0 + x h) = y0 + sum_i L_i(x) Z_i, nodes {0, c_1, c_2}) to the next step of
        `ratio` times its size: Z_new[s] = u(1 + ratio c_s) - u(1) (HW IV.8)."""
        P = np.empty((2, 2))
        gk.predictor_matrix(self._C, float(ratio), P)
        return P

    # --- the march -----------------------------------------------------------------------------
    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        if not self.predict or self._t_end != t0 or not np.array_equal(y, self._y_end):
            self._dstate[DST_HPRED] = 0.0  # not where the last march ended: no predictor
        self._t_end = None
        jac0, lu0 = int(self.counts[COUNT_JACOBIAN]), int(self.counts[COUNT_LU])
        try:
            super()._march(t0, y, t1)
        finally:
            self.njev += 2 * (int(self.counts[COUNT_JACOBIAN]) - jac0)
            self.nlu += int(self.counts[COUNT_LU]) - lu0
        if not self.predict:
            self._dstate[DST_HPRED] = 0.0
        self._t_end = t1
        self._y_end[:] = y

    def _march_compiled(self, t0: float, y: np.ndarray, h: float, n: int) -> int | None:
        if self._compiled is None or not self.use_compiled:
            return None
        done, status, rhs_calls = self._compiled(
            t0, y, h, n, self._A, self._C, self._D, self._params, self._dstate, self._ws,
            self._info, self.counts)
        self.nfev += rhs_calls
        if status not in (STEP_OK, STEP_NONFINITE):
            self.nsteps += done
            raise self._failure(status, t0 + done * h, h)
        return done

    def _failure(self, status: int, t: float, h: float) -> IntegrationError:
        it, theta, norm = self._info
        depth = int(self._params[gk.PAR_DEPTH])
        if status in _WHY:
            why = _WHY[status]
            if status == STEP_RHS_NONFINITE:
                why += f" ({describe_nonfinite(self._wsd['F'])})"
        elif status == STEP_DIVERGED:
            why = f"diverging (rate {theta:.2g} at iteration {int(it)}, update {norm:.2g} x tolerance)"
        elif status == STEP_LINEAR:
            why = f"the linear solve gave a non-finite update at iteration {int(it)}"
        else:
            cap = self._params[gk.PAR_DENSE_CAP if self.dense else gk.PAR_NEWTON_CAP]
            why = f"not converged in {int(cap)} iterations (rate {theta:.2g}, update {norm:.2g} x tolerance)"
        if depth and int(self.counts[COUNT_RETAKEN]) > 0:
            deepest = int(self.counts[COUNT_MAX_DEPTH])
            why += (f" (the step retaken in halves down to h / 2^{deepest}, at most "
                    f"h / 2^{depth} and {int(self._params[gk.PAR_BUDGET])} attempts a step)")
        return IntegrationError(self.name, "Newton iteration failed", t, h, why)

    # --- the Python driver (gauss_march statement for statement) ----------------------------
    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        """One step with its bounded dyadic retake (fast_gauss.gauss_march, statement for
        statement, but raising the failure)."""
        ws, dst, counts = self._wsd, self._dstate, self.counts
        ys, y0, Zp, Zs = ws["ys"], ws["y0"], ws["Zp"], ws["Zs"]
        max_depth = int(self._params[gk.PAR_DEPTH])
        budget = int(self._params[gk.PAR_BUDGET])
        end = 1 << max_depth
        unit = h / end
        level_max, patience = int(self._params[gk.PAR_LEVEL_MAX]), self._params[gk.PAR_PATIENCE]
        before = counts[COUNT_RHS]
        y0[:] = y
        pos = 0
        level = gk.level_start(h, dst, max_depth)
        depth = level
        attempts = 0
        retaken = False
        status = STEP_OK
        while pos < end:
            ys[:] = y
            Zs[:] = Zp
            hs = dst[DST_HPRED]
            before_end = pos + (1 << (max_depth - depth)) < end  # not the step's last piece
            status = self._substep(t + pos * unit, y, h / (1 << depth), before_end)
            attempts += 1
            if status != STEP_OK:
                y[:] = ys
                Zp[:] = Zs
                dst[DST_HPRED] = hs
                counts[COUNT_RETAKEN] += 1
                if not retaken:
                    counts[COUNT_STEPS_RETAKEN] += 1
                retaken = True
            pos, depth = gk.retake_next(status == STEP_OK, pos, depth, max_depth, level)
            if depth > max_depth:
                break
            counts[COUNT_MAX_DEPTH] = max(counts[COUNT_MAX_DEPTH], depth)
            if attempts >= budget and pos < end:
                if status == STEP_OK:
                    status = STEP_BUDGET
                break
        counts[COUNT_MAX_STEP_RHS] = max(counts[COUNT_MAX_STEP_RHS], counts[COUNT_RHS] - before)
        if status != STEP_OK:
            y[:] = y0
            dst[DST_HPRED] = 0.0
            dst[DST_H] = 0.0
            raise self._failure(status, t, h)
        gk.level_next(level, retaken, dst, level_max, patience)

    def _substep(self, t: float, y: np.ndarray, h: float, project: bool) -> int:
        """One (sub)step (fast_gauss.substep). The compiled march renormalises after every
        (sub)step; here the base does it after the step, this after the substeps before its
        end (`project`): the same operations."""
        ws, dst = self._wsd, self._dstate
        Z, Zp = ws["Z"], ws["Zp"]
        hp = dst[DST_HPRED]
        if hp > 0.0:
            gk.predictor_matrix(self._C, h / hp, ws["P"])
            gk.gauss_predict(Zp, ws["P"], Z)
        else:
            Z[:] = 0.0
        gk.gauss_scaled(self._A, h, ws["hA"])
        status = self._newton_dense(t, y, h) if self.dense else self._newton_krylov(t, y, h)
        if status != STEP_OK:
            return status
        gk.gauss_update(y, Z, ws["F"], ws["hA"], h, self._D)
        Zp[:] = Z
        dst[DST_HPRED] = h
        if project:
            self._project(y)
        return STEP_OK

    def _rhs_into(self, t: float, ys: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._fun(t, ys)
        self.counts[COUNT_RHS] += 1

    def _newton_dense(self, t: float, y: np.ndarray, h: float) -> int:
        """The dense Newton iteration of one (sub)step (fast_gauss.newton_dense, statement for
        statement): Z (2, size) the solution on success; returns a STEP_ status."""
        ws, dst, counts, par = self._wsd, self._dstate, self.counts, self._params
        Z, Zb, Ys, F, Fp, Yp, w = ws["Z"], ws["Zb"], ws["Ys"], ws["F"], ws["Fp"], ws["Yp"], ws["w"]
        J, M, piv, r = ws["J"], ws["M"], ws["piv"], ws["r"]
        n = self.n
        tol, kappa, first_tol, diverge = par[gk.PAR_TOL], par[gk.PAR_DENSE_KAPPA], par[gk.PAR_FIRST_TOL], \
            par[gk.PAR_DIVERGE]
        cap, rate, rcap = int(par[gk.PAR_DENSE_CAP]), par[gk.PAR_REFRESH_RATE], int(par[gk.PAR_REFRESH_CAP])
        stall, stall_rate, floor_factor = par[gk.PAR_STALL], par[gk.PAR_STALL_RATE], par[gk.PAR_FLOOR_FACTOR]
        hA = ws["hA"]
        tc = (t + self._C[0] * h, t + self._C[1] * h)
        gk.gauss_weights(y, tol, w)
        if abs(dst[DST_H] - h) > H_REUSE * h:
            dst[DST_REFRESH] = 1.0
        refreshes = 0
        norm_prev = 0.0
        k = 0
        for it in range(cap):
            counts[COUNT_NEWTON] += 1
            counts[COUNT_MAX_NEWTON] = max(counts[COUNT_MAX_NEWTON], it + 1)
            for st in range(2):
                gk.gauss_stage_state(y, Z, st, Ys[st])
                self._rhs_into(tc[st], Ys[st], F[st])
            if not gk.all_finite(F):
                return STEP_RHS_NONFINITE
            if dst[DST_REFRESH] != 0.0:
                for st in range(2):
                    for j in range(n):
                        d = gk.jac_perturb(Ys[st], j, Yp)
                        self._rhs_into(tc[st], Yp, Fp[st])
                        gk.jac_column(Fp[st], F[st], d, J[st], j)
                counts[COUNT_JACOBIAN] += 1
                for st in range(2):
                    gk.noise_perturb(Ys[st], Yp)
                    self._rhs_into(tc[st], Yp, Fp[st])
                gk.newton_matrix(J, hA, M)
                counts[COUNT_LU] += 1
                if gk.lu_factor(M, piv) != 0:
                    dst[DST_H] = 0.0
                    return STEP_SINGULAR
                gk.noise_residual(Fp, F, hA, r)
                gk.lu_solve(M, piv, r)
                dst[DST_FLOOR] = gk.noise_floor(gk.scaled_rms(r, w), floor_factor, stall)
                dst[DST_H] = h
                dst[DST_REFRESH] = 0.0
                refreshes += 1
                norm_prev = 0.0
                k = 0
            Zb[:] = Z
            gk.dense_residual(Z, F, hA, r)
            gk.lu_solve(M, piv, r)
            norm = gk.dense_update(r, w, Z)
            code, theta = gk.newton_test(norm, norm_prev, k, kappa, first_tol, diverge, dst[DST_FLOOR],
                                         stall_rate)
            self._info[:] = (it, theta, norm)
            if code == gk.NEWTON_CONVERGED:
                return STEP_OK
            if code == gk.NEWTON_STALLED:
                counts[COUNT_STALLED] += 1
                return STEP_OK
            if code == gk.NEWTON_DIVERGING or code == gk.NEWTON_NOT_FINITE:
                if refreshes >= min(rcap, int(par[gk.PAR_DIV_REFRESH])):
                    return STEP_DIVERGED if code == gk.NEWTON_DIVERGING else STEP_LINEAR
                Z[:] = Zb
                dst[DST_REFRESH] = 1.0
                norm_prev = 0.0
                k = 0
                continue
            if k > 0 and refreshes < rcap and gk.refresh_wanted(theta, norm, cap - 1 - it,
                                                                par[gk.PAR_REFRESH_KAPPA], rate):
                dst[DST_REFRESH] = 1.0
            norm_prev = norm
            k += 1
        return gk.STEP_NOT_CONVERGED

    def _newton_krylov(self, t: float, y: np.ndarray, h: float) -> int:
        """The Newton-Krylov iteration of one (sub)step (fast_gauss.newton_krylov, statement for
        statement): Z (2, size) the solution on success; returns a STEP_ status."""
        ws, counts, par = self._wsd, self.counts, self._params
        Z, Ys, F, Fp, Yp, w = ws["Z"], ws["Ys"], ws["F"], ws["Fp"], ws["Yp"], ws["w"]
        V, H, cs, sn, g, coef = ws["V"], ws["H"], ws["cs"], ws["sn"], ws["g"], ws["coef"]
        n, m = self.n, H.shape[1]
        tol, kappa, first_tol, diverge = par[gk.PAR_TOL], par[gk.PAR_KAPPA], par[gk.PAR_FIRST_TOL], \
            par[gk.PAR_DIVERGE]
        grtol, gatol, eps = par[gk.PAR_GMRES_RTOL], par[gk.PAR_GMRES_ATOL], par[gk.PAR_FD_EPS]
        newton_cap = int(par[gk.PAR_NEWTON_CAP])
        stall, stall_rate = par[gk.PAR_STALL], par[gk.PAR_STALL_RATE]
        inv_eps = 1.0 / eps
        hA = ws["hA"]
        tc = (t + self._C[0] * h, t + self._C[1] * h)
        gk.gauss_weights(y, tol, w)
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
            j = 0
            while j < m:
                for st in range(2):
                    gk.gauss_perturbed(Ys[st], w, V[j], st, eps, Yp)
                    self._rhs_into(tc[st], Yp, Fp[st])
                gk.gauss_operator(V[j], Fp, F, hA, w, inv_eps, V[j + 1])
                res = gk.gmres_arnoldi(V, H, cs, sn, g, j)
                j += 1
                if res <= goal:
                    break
            counts[COUNT_KRYLOV] += j
            counts[COUNT_MAX_KRYLOV] = max(counts[COUNT_MAX_KRYLOV], j)
            norm = gk.gmres_update(V, H, g, j, w, Z, coef)
            code, theta = gk.newton_test(norm, norm_prev, it, kappa, first_tol, diverge, stall, stall_rate)
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
        return gk.STEP_NOT_CONVERGED
