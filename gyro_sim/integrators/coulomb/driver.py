"""Exact Coulomb friction of hinges: stick and slip by time-stepping (docs/integrators.md,
"Coulomb friction: stick and slip").

A hinge whose friction is `exact` (:attr:`gyro_sim.scene.records.Friction.exact`: a `coulomb`
with neither `stick_speed` nor a Stribeck term written; MJCF `frictionloss`, URDF `<dynamics
friction>`) has a friction torque tau_f in [-mu, mu] that opposes the slip phi' while the
joint slips (tau_f = -mu sgn phi') and holds it while it sticks (phi' = 0, |tau_f| <= mu). It is
not a function of the state, and the regularised law (linear below `stick_speed`) makes the
ODE as stiff as mu / (I stick_speed). Here it is solved per step of size h (the Simulator's
`step`), as the time-stepping schemes of MuJoCo and Drake do, on the velocity level:

1. the integrator the user chose advances the smooth motion over [t, t + h] with each axis's
   friction held as a constant moment: -mu sgn(phi'(t)) where the axis slips at t; where it is
   at rest (phi'(t) = 0), the moment that held it in the last step. While every slipping axis
   keeps its sign over the step and every axis at rest stays exactly at rest, that is the exact
   motion (to the integrator's tolerance) and the step is kept as it is;
2. otherwise (an axis at rest, or one whose speed crossed zero) the friction impulses
   lambda (the step's mean friction moment times h) are solved at t + h from the box-constrained
   linear complementarity problem
       v = b + W lambda,   |lambda_i| <= h mu_i,   lambda_i = -h mu_i sgn v_i where v_i != 0,
   with b the axes' speeds without friction over the step (the smooth step's speeds minus
   W h tau_f held) and W = (M^-1)_FF the joint-space inverse mass of the friction axes, found as
   the responses of the accelerations to unit moments on the axes (one rhs evaluation each:
   the accelerations are affine in the moments). An axis whose bound holds sticks (v_i = 0,
   exactly); the others slip against +-h mu_i. The velocities take the change
   M^-1 (lambda - h tau_f), the positions half a step of it (exact for a constant moment over
   the step), and an axis at rest throughout keeps its angle exactly.

So a slip is exact to the integrator's tolerance, the moment of sticking is found to within one
step, and a stuck axis stays at rest exactly while |required moment| <= mu. The impulse step is
first order in h at a transition; a stuck axis coupled to a moving one, held over the smooth
step by its last holding moment, moves by O(h^2) within it, which the impulse takes back. The
work of friction is the mean moment lambda / h times each step's change of angle.
"""
from __future__ import annotations

import math

import numpy as np

from gyro_sim import jit
from gyro_sim.integrators.base import STEP_COUNT_SLACK
from gyro_sim.integrators.coulomb.kernels import responses

#: iterations of the block principal pivoting before the single-pivot rule (Murty's)
FULL_PIVOT_ITERATIONS = 8
#: a complementarity condition is met to this fraction of the problem's speed scale
LCP_TOL = 1e-12


def box_lcp(W: np.ndarray, b: np.ndarray, c: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The impulses lambda (n,) with |lambda_i| <= c_i, v = b + W lambda, v_i = 0 where |lambda_i| <
    c_i, lambda_i = -c_i where v_i > 0 and +c_i where v_i < 0; W (n, n) symmetric positive definite.

    Block principal pivoting (Judice and Pires, 1994) from `state` (n,) int: 0 an axis guessed
    stuck, -1 slipping forward (lambda = -c), +1 backward; after FULL_PIVOT_ITERATIONS without
    fewer violations, one violation at a time (the last, Murty's rule: finite for a P-matrix).
    Returns (lambda, stuck: bool (n,))."""
    n = b.shape[0]
    state = state.copy()
    scale = float(np.max(np.abs(b)) + np.max(np.abs(W)) * np.max(c)) * LCP_TOL + 1e-300
    best, since = n + 1, 0
    for _ in range(10 * n + 20):
        lam = state * c
        free = state == 0
        if free.any():
            bound = ~free
            rhs = b[free] + W[np.ix_(free, bound)] @ lam[bound]
            lam[free] = np.linalg.solve(W[np.ix_(free, free)], -rhs)
        v = b + W @ lam
        over = free & (np.abs(lam) > c * (1.0 + LCP_TOL))
        wrong = (~free) & (state * v > scale)  # lambda = -c needs v >= 0; +c needs v <= 0
        bad = np.flatnonzero(over | wrong)
        if not bad.size:
            lam[~free] = state[~free] * c[~free]
            return lam, free
        if bad.size < best:
            best, since = bad.size, 0
        else:
            since += 1
        pick = bad if since < FULL_PIVOT_ITERATIONS else bad[-1:]
        for i in pick:
            state[i] = int(np.sign(lam[i])) if free[i] else 0
    raise ArithmeticError("the friction impulses did not converge (box LCP)")


class CoulombStepping:
    """Advances a Simulator's state with its hinges' exact Coulomb friction (the module's scheme)
    by steps of at most `step`, the smooth motion between by `integrator` on `system`.

    Attributes: `work` (J), the work of the exact friction since the reset; `held_work`, the part
    of the moments held during the smooth steps that a stateful model's motor work counted (to
    take back out); `torque` (nf,), the friction moments held in the last smooth step; `applied`
    (nf,), their mean over the last step (with its impulses); `impulse_steps`,
    the steps solved with impulses; `axes` (nf,), the hinges (model order) with exact friction.
    """

    def __init__(self, model, system, integrator, step: float):
        m = model
        self.model, self.system, self.integrator, self.h = m, system, integrator, float(step)
        bound = m.actuators.exact
        self.axes = np.flatnonzero(bound > 0.0)
        self.mu = bound[self.axes]
        self.cols = np.ascontiguousarray(m.col_hinge[self.axes], dtype=np.int64)
        self.i_vel = m.i_vel.start
        self.vel = self.i_vel + self.cols
        self.ang = m.i_phi.start + self.axes
        nh = len(m.hinge_bodies)
        self._zero_tau = np.zeros(nh)
        # positions other than hinge angles (free base, quaternions, rotor angles): moved by the
        # change of their rates, one more evaluation; a fixed base of hinges moves by u directly
        index = np.arange(m.size)
        self._others = np.concatenate((index[m.i_r0], m.i_quat.ravel(), index[m.i_kappa])).astype(np.intp)
        self._compiled = hasattr(system, "kernel_arguments")
        self._response = np.zeros((m.N, len(self.axes)))
        self._ydot = np.empty(m.size)
        self._direct = jit.Direct(responses) if self._compiled else None
        self.reset()

    def reset(self) -> None:
        self.work = self.held_work = 0.0
        self.torque = np.zeros(len(self.axes))
        self.applied = np.zeros(len(self.axes))  # the friction moments' mean over the last step
        self._holding = np.zeros(len(self.axes))  # the moments that held the stuck axes in the last impulse step
        self.impulse_steps = 0

    def warm_up(self, t: float, y: np.ndarray, hinge_tau, L_rotor, p) -> None:
        """Compile (or load) the responses' kernel by one call at (t, y); not counted."""
        if self._compiled:
            nfev = self.system.nfev
            self.system.hold(t, p, self._zero_tau if hinge_tau is None else hinge_tau, L_rotor)
            self._responses(t, np.ascontiguousarray(y, dtype=np.float64))
            self.system.nfev = nfev

    def held(self, y0: np.ndarray, y1: np.ndarray) -> float:
        """The work of the friction moments held in the last smooth step from y0 to y1 (J)."""
        return float(self.torque @ (y1[self.ang] - y0[self.ang]))

    # --- the step ------------------------------------------------------------------------------
    def advance(self, t0: float, y0: np.ndarray, t1: float, hinge_tau, L_rotor) -> np.ndarray:
        """The state at t1 from (t0, y0) (a new array), the commands held (hinge_tau (nh,) or None,
        L_rotor); the system holds them from t0 on (`Simulator.advance` did)."""
        span = t1 - t0
        n = max(1, math.ceil(span / self.h - STEP_COUNT_SLACK))
        h = span / n
        y = np.array(y0, dtype=float)
        base = self._zero_tau if hinge_tau is None else np.asarray(hinge_tau, dtype=float)
        kept = (self.work, self.held_work, self.torque, self.applied, self._holding, self.impulse_steps)
        try:
            return self._steps(t0, t1, n, h, y, base, L_rotor)
        except BaseException:  # the caller keeps its state: so does the friction's account
            self.work, self.held_work, self.torque, self.applied, self._holding, self.impulse_steps = kept
            raise

    def _steps(self, t0: float, t1: float, n: int, h: float, y: np.ndarray, base: np.ndarray, L_rotor) -> np.ndarray:
        """`advance`'s n steps of size h from (t0, y) (y is advanced in place or replaced)."""
        held_torque = None
        for k in range(n):
            t = t0 + k * h
            t_end = t1 if k == n - 1 else t0 + (k + 1) * h
            v0 = y[self.vel]
            torque = np.where(v0 != 0.0, -self.mu * np.sign(v0), self._holding)
            if held_torque is None or not np.array_equal(torque, held_torque):
                tau = base.copy()
                tau[self.axes] += torque
                t_hold, p_hold = self.system.held[:2]  # the hold's start and spins stay
                self.system.hold(t_hold, p_hold, tau, L_rotor)
                held_torque = torque
            self.torque = torque
            y_plus = self.integrator.advance(t, y, t_end)
            v_plus = y_plus[self.vel]
            self.held_work += self.held(y, y_plus)
            if np.all(np.sign(v_plus) == np.sign(v0)):
                # every axis slipped the whole step one way, or stayed exactly at rest: exact
                self.work += self.held(y, y_plus)
                self.applied = torque
                y = y_plus
                continue
            y = self._impulses(t_end, y, y_plus, h, torque, v0)
        return y

    def _responses(self, t: float, y: np.ndarray) -> None:
        """self._response (N, nf) at (t, y) and self._ydot = y' with the moments held."""
        s = self.system
        if self._compiled:
            self._direct(float(t), y, self.cols, self.i_vel, self._response, self._ydot, *s.kernel_arguments())
            s.nfev += len(self.axes) + 1
            return
        m, held = self.model, s.held
        self._ydot[:] = s.rhs(t, y)
        for j, axis in enumerate(self.axes):
            tau = held[2].copy()
            tau[axis] += 1.0
            s.hold(held[0], held[1], tau, held[3])
            self._response[:, j] = s.rhs(t, y)[m.i_vel] - self._ydot[m.i_vel]
        s.hold(*held)

    def _impulses(self, t: float, y0: np.ndarray, y: np.ndarray, h: float, torque: np.ndarray,
                  v0: np.ndarray) -> np.ndarray:
        """The step's friction impulses solved at (t, y), the smooth step's end from y0; the
        corrected state (a new array, or y itself)."""
        self.impulse_steps += 1
        y = np.ascontiguousarray(y)
        self._responses(t, y)
        R = self._response
        W = R[self.cols]
        W = 0.5 * (W + W.T)
        held = h * torque
        b = y[self.vel] - W @ held
        guess = np.where(v0 == 0.0, 0, np.where(y[self.vel] > 0.0, -1, 1)).astype(np.int64)
        lam, stuck = box_lcp(W, b, h * self.mu, guess)
        self._holding = np.where(stuck, lam / h, 0.0)
        self.applied = lam / h
        du = R @ (lam - held)
        out = y.copy()
        out[self.i_vel:self.i_vel + self.model.N] += du
        out[self.vel[stuck]] = 0.0
        m = self.model
        if len(m.hinge_bodies):
            out[m.i_phi] += 0.5 * h * du[m.col_hinge]
        if self._others.size:  # the other positions by the change of their rates over half a step
            rates = self.system.rhs(t, out)
            out[self._others] += 0.5 * h * (rates[self._others] - self._ydot[self._others])
            self.system.project(out)
        rest = stuck & (v0 == 0.0)
        out[self.ang[rest]] = y0[self.ang[rest]]
        self.work += float(lam @ (out[self.ang] - y0[self.ang])) / h
        return out
