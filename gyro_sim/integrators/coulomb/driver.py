"""Exact Coulomb friction of hinges and torque rotors: stick and slip by time-stepping
(docs/integrators.md, "Coulomb friction: stick and slip").

An axis whose friction is `exact` (:attr:`gyro_sim.scene.records.Friction.exact`: a `coulomb`
with neither `stick_speed` nor a Stribeck term written; MJCF `frictionloss`, URDF `<dynamics
friction>`) has a friction torque tau_f in [-mu, mu] that opposes its slip w (a hinge's phi', a
rotor's spin relative to its carrier kappa_i', eqs 18-19) while it slips (tau_f = -mu sgn w)
and holds it while it sticks (w = 0, |tau_f| <= mu). It is not a function of the state, and the
regularised law (linear below `stick_speed`) makes the ODE as stiff as mu / (I stick_speed).
Here it is solved per step of size h (the Simulator's `step`), as the time-stepping schemes of
MuJoCo and Drake do, on the velocity level:

1. the integrator the user chose advances the smooth motion over [t, t + h] with each axis's
   friction held as a constant moment (a hinge moment, a rotor torque): -mu sgn(w(t)) where the
   axis slips at t; where the last step left it at rest, the moment that held it then. While
   every slipping axis keeps its sign over the step and every axis at rest stays exactly at
   rest, that is the exact motion (to the integrator's tolerance) and the step is kept as it is;
2. otherwise (an axis at rest, or one whose speed crossed zero) the friction impulses
   lambda (the step's mean friction moment times h) are solved at t + h from the box-constrained
   linear complementarity problem
       v = b + W lambda,   |lambda_i| <= h mu_i,   lambda_i = -h mu_i sgn v_i where v_i != 0,
   with b the axes' speeds without friction over the step (the smooth step's speeds minus
   W h tau_f held) and W = (M^-1)_FF the joint-space inverse mass of the friction axes, found as
   the responses of the accelerations to unit moments on the axes (one rhs evaluation each:
   the accelerations are affine in the moments; a rotor's row adds its own spin's 1 / A_i and
   its carrier's response along its axis). An axis whose bound holds sticks (v_i = 0,
   exactly); the others slip against +-h mu_i. The velocities take the change
   M^-1 (lambda - h tau_f) (a rotor's spin its impulse / A_i), the positions half a step of it
   (exact for a constant moment over the step), and an axis at rest throughout keeps its angle
   exactly.

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
    """Advances a Simulator's state with the exact Coulomb friction of its hinges and rotors (the module's scheme)
    by steps of at most `step`, the smooth motion between by `integrator` on `system`.

    Attributes: `work` (J), the work of the exact friction since the reset; `held_work`, the part
    of the moments held during the smooth steps that a stateful model's motor work counted (to
    take back out); `torque` (nf,), the friction moments held in the last smooth step; `applied`
    (nf,), their mean over the last step (with its impulses); `impulse_steps`,
    the steps solved with impulses; `axes` (nf,), the hinges (model order) with exact friction.
    """

    def __init__(self, model, system, integrator, step: float):
        m = model
        self.model, self.h = m, float(step)
        act = m.actuators
        hinge = np.zeros(len(m.hinge_bodies)) if act.hinge.exact is None else act.hinge.exact
        rotor = np.zeros(len(m.torque_body)) if act.rotor.exact is None else act.rotor.exact
        self.axes = np.flatnonzero(hinge > 0.0)  # hinges (model order) with exact friction
        self.rotors = np.flatnonzero(rotor > 0.0)  # torque rotors with exact friction
        self.nh = len(self.axes)
        self.mu = np.concatenate((hinge[self.axes], rotor[self.rotors]))
        self.cols = np.ascontiguousarray(m.col_hinge[self.axes], dtype=np.int64)
        self.i_vel = m.i_vel.start
        self.vel = self.i_vel + self.cols
        index = np.arange(m.size)
        self.i_kappa = index[m.i_kappa][self.rotors]  # the rotors' angles kappa_i; their rates are kappa_i'
        self.ang = np.concatenate((m.i_phi.start + self.axes, self.i_kappa)).astype(np.intp)
        self.inv_A = 1.0 / m.torque_A[self.rotors]
        self._zero_tau = np.zeros(len(m.hinge_bodies))
        self._zero_L = np.zeros(len(m.torque_body))
        # positions other than hinge angles (free base, quaternions, rotor angles): moved by the
        # change of their rates, one more evaluation; a fixed base of hinges moves by u directly
        self._others = np.concatenate((index[m.i_r0], m.i_quat.ravel(), index[m.i_kappa])).astype(np.intp)
        self._response = np.zeros((m.N, len(self.mu)))
        self._ydot = np.empty(m.size)
        # `_correct_works`: the hinges' then the torque rotors' angles
        self._angles = np.concatenate((index[m.i_phi], index[m.i_kappa])).astype(np.intp)
        self.bind(system, integrator)
        self.reset()

    def bind(self, system, integrator) -> None:
        """Step on `system` with `integrator` from now on (a Simulator's backend switch): the
        friction's own state (held and applied moments, axes at rest, work) is kept."""
        self.system, self.integrator = system, integrator
        self._compiled = hasattr(system, "kernel_arguments")
        self._direct = jit.Direct(responses) if self._compiled else None

    def reset(self) -> None:
        self.work = self.held_work = 0.0
        nf = len(self.mu)
        self.torque = np.zeros(nf)
        self.applied = np.zeros(nf)  # the friction moments' mean over the last step
        self._holding = np.zeros(nf)  # the moments that held the stuck axes in the last impulse step
        self._rest = np.zeros(nf, dtype=bool)  # the axes the last step left at rest
        self.impulse_steps = 0

    def warm_up(self, t: float, y: np.ndarray, hinge_tau, L_rotor, p) -> None:
        """Compile (or load) the responses' kernel by one call at (t, y); not counted."""
        if self._compiled:
            nfev = self.system.nfev
            self.system.hold(t, p, self._zero_tau if hinge_tau is None else hinge_tau, L_rotor)
            self._responses(t, np.ascontiguousarray(y, dtype=np.float64))
            self.system.nfev = nfev

    def speeds(self, t: float, y: np.ndarray) -> np.ndarray:
        """The friction axes' speeds (nf,) at (t, y) with the inputs held: the hinges' phi', the
        rotors' kappa_i' (eqs 18-19, one evaluation of y')."""
        v = y[self.vel]
        if len(self.rotors):
            v = np.concatenate((v, self.system.rhs(t, y)[self.i_kappa]))
        return v

    def _hold(self, t: float, y: np.ndarray, tau: np.ndarray, L_rotor: np.ndarray, p=None) -> None:
        """Hold the moments tau (nh,) and rotor torques L_rotor (nt,) from t on; the spins at t are
        kept (or p)."""
        s = self.system
        if not len(self.rotors):  # the spins' hold (p0 at t0, rate L / A) does not change
            t_hold, p_hold = s.held[:2]
            s.hold(t_hold, p_hold, tau, L_rotor)
            return
        s.hold(t, s.spins(t, y) if p is None else p, tau, L_rotor)

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
        base = (self._zero_tau if hinge_tau is None else np.asarray(hinge_tau, dtype=float),
                self._zero_L if L_rotor is None else np.asarray(L_rotor, dtype=float))
        kept = (self.work, self.held_work, self.torque, self.applied, self._holding, self._rest, self.impulse_steps)
        try:
            return self._steps(t0, t1, n, h, y, base)
        except BaseException:  # the caller keeps its state: so does the friction's account
            self.work, self.held_work, self.torque, self.applied, self._holding, self._rest, self.impulse_steps = kept
            raise

    def _steps(self, t0: float, t1: float, n: int, h: float, y: np.ndarray, base: tuple) -> np.ndarray:
        """`advance`'s n steps of size h from (t0, y) (y is advanced in place or replaced)."""
        held_torque = None
        v0 = self.speeds(t0, y)
        for k in range(n):
            t = t0 + k * h
            t_end = t1 if k == n - 1 else t0 + (k + 1) * h
            v0 = np.where(self._rest, 0.0, v0)  # at rest: a rotor's kappa' to round-off
            torque = np.where(v0 != 0.0, -self.mu * np.sign(v0), self._holding)
            if held_torque is None or not np.array_equal(torque, held_torque):
                self._hold(t, y, *self._with(base, torque))
                held_torque = torque
            self.torque = torque
            y_plus = self.integrator.advance(t, y, t_end)
            v_plus = self.speeds(t_end, y_plus)
            held_work = self.held(y, y_plus)
            self.held_work += held_work
            if np.all(np.sign(v_plus) == np.sign(v0)):
                # every axis slipped the whole step one way, or stayed exactly at rest: exact
                self.work += held_work
                self.applied = torque
                self._rest = v_plus == 0.0
                y, v0 = y_plus, v_plus
                continue
            y = self._impulses(t_end, y, y_plus, h, torque, v0, self._with(base, torque))
            if self.model.stateful:  # the works integrated along the smooth step, corrected
                self._correct_works(t_end, y_plus, y, base)
            v0 = self.speeds(t_end, y)
        return y

    def _correct_works(self, t: float, smooth: np.ndarray, out: np.ndarray, base: tuple) -> None:
        """A stateful model's work states in `out` (the impulses' correction of the smooth
        step's end `smooth`), from the smooth step's integrals to the corrected step's: the
        torques applied at `out` (the commands `base`, the servos' moments, the motors after
        their speed cut, the friction in F; the exact friction's is `work`'s: the system's
        `applied`) times the change the correction made to their axes' angles, as the held
        commands' work is theirs."""
        m = self.model
        dangle = out[self._angles] - smooth[self._angles]
        motor, friction = self.system.applied(t, out, *base)
        out[m.i_work.start] += float(motor @ dangle)
        out[m.i_work.start + 1] += float(friction @ dangle)

    def _with(self, base: tuple, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The commands `base` (hinge moments, rotor torques) with the friction moments added."""
        tau, L = base[0].copy(), base[1].copy()
        tau[self.axes] += torque[:self.nh]
        L[self.rotors] += torque[self.nh:]
        return tau, L

    def _responses(self, t: float, y: np.ndarray) -> None:
        """self._response (N, nf) at (t, y): the generalised accelerations' responses to a unit
        moment on each friction axis; and self._ydot = y' with the moments held."""
        s, m = self.system, self.model
        if self._compiled:  # the hinges' in one compiled call
            self._direct(float(t), y, self.cols, self.i_vel, self._response, self._ydot, *s.kernel_arguments())
            s.nfev += self.nh + 1
        else:
            self._ydot[:] = s.rhs(t, y)
        held = s.held
        for j in range(len(self.mu)):
            if j < self.nh and self._compiled:
                continue
            tau, L = held[2].copy(), (self._zero_L if held[3] is None else held[3]).copy()
            if j < self.nh:
                tau[self.axes[j]] += 1.0
                s.hold(held[0], held[1], tau, held[3])
            else:  # a rotor's torque changes its spin's rate: held from t, its spin at t kept
                L[self.rotors[j - self.nh]] += 1.0
                s.hold(t, s.spins(t, y), tau, L)
            self._response[:, j] = s.rhs(t, y)[m.i_vel] - self._ydot[m.i_vel]
        if len(self.rotors) or not self._compiled:
            s.hold(*held)

    def _delassus(self, t: float, y: np.ndarray) -> np.ndarray:
        """W (nf, nf): the friction axes' speed changes per unit impulse on each, at (t, y):
        a hinge's phi' by the responses; a rotor's kappa_i' = p_i - omega . e_i by its spin (1 / A_i
        of its own impulse) and its carrier's angular velocity (the change of kappa_i' at the
        velocities moved by each response: one evaluation each)."""
        R = self._response
        W = np.empty((len(self.mu), len(self.mu)))
        W[:self.nh] = R[self.cols]
        if len(self.rotors):
            moved = np.array(y)
            u = moved[self.i_vel:self.i_vel + self.model.N]
            for j in range(len(self.mu)):
                u[:] = y[self.i_vel:self.i_vel + self.model.N] + R[:, j]
                W[self.nh:, j] = self.system.rhs(t, moved)[self.i_kappa] - self._ydot[self.i_kappa]
            W[self.nh:, self.nh:] += np.diag(self.inv_A)
        return 0.5 * (W + W.T)

    def _impulses(self, t: float, y0: np.ndarray, y: np.ndarray, h: float, torque: np.ndarray,
                  v0: np.ndarray, held_inputs: tuple) -> np.ndarray:
        """The step's friction impulses solved at (t, y), the smooth step's end from y0 (with
        the moments `held_inputs` held over it); the corrected state (a new array)."""
        self.impulse_steps += 1
        m = self.model
        y = np.ascontiguousarray(y)
        self._responses(t, y)
        W = self._delassus(t, y)
        R = self._response
        v = np.concatenate((y[self.vel], self._ydot[self.i_kappa]))
        held = h * torque
        b = v - W @ held
        guess = np.where(v0 == 0.0, 0, np.where(v > 0.0, -1, 1)).astype(np.int64)
        lam, stuck = box_lcp(W, b, h * self.mu, guess)
        self._holding = np.where(stuck, lam / h, 0.0)
        self._rest = stuck
        self.applied = lam / h
        impulse = lam - held
        du = R @ impulse
        out = y.copy()
        out[self.i_vel:self.i_vel + m.N] += du
        out[self.vel[stuck[:self.nh]]] = 0.0
        if len(self.rotors):  # the rotors' spins take their impulses (A_i dp_i = impulse)
            p = self.system.spins(t, y).copy()
            p[self.rotors] += impulse[self.nh:] * self.inv_A
            if m.stateful:
                out[m.i_spin] = p
            else:
                self._hold(t, out, *held_inputs, p=p)
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
