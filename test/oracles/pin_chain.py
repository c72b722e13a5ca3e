"""A chain of gyrostats in Pinocchio: the independent engine gyro_sim is checked against.

Nothing here shares code with gyro_sim's dynamics. The scene (gyro_sim.scene.records records)
is compiled into a `pinocchio.Model` in the most literal way:

- body k is a pinocchio body on the joint at O^k: spherical -> ``JointModelSpherical``
  (rotation relative to the parent), hinge -> ``JointModelRevoluteUnaligned`` about the
  axis in the parent's frame; on a free base body 1 sits on a ``JointModelFreeFlyer``, on a
  moving base the chain hangs from a massless ``JointModelTranslation`` whose motion is
  prescribed. Joint k+1 is placed at s^k in body k's frame with no rotation, so pinocchio's
  joint frame of body k IS the scene's body frame (origin O^k).
- every rotor is its own pinocchio body on a revolute joint about its axis e_i through its
  centre h_i (coordinate kappa_i, relative to the carrier), inertia diag(B, B, A) about its
  centre in axes whose z is e_i. A torque rotor's joint is free (joint torque = the commanded
  axial torque, 0 when not actuated); a speed rotor's angle is a prescribed coordinate
  kappa_i = kappa_i' t.

Dynamics: generalised coordinates split into free (f) and prescribed (p: moving-base
translation, speed-rotor angles, with known accelerations a_p(t)),

    M_ff a_f = tau_f - h_f - M_fp a_p,    M = crba(q), h = nonLinearEffects(q, v),

integrated with scipy's DOP853 on (q, v); quaternions (pinocchio stores x, y, z, w) follow
q' = 1/2 q (x) (0, omega_local) and are renormalised when read.

Rotations: Pinocchio's own (``pin.exp3``, ``pin.Quaternion``) and the Euler convention built
here from its definition (docs/scene-format.md: z-x-z angles of the body relative to the
"down" frame whose z is gravity's direction nu), so that a convention error in
gyro_sim.dynamics.rotations is not shared by the oracle.

Joint reactions: rnea(q, v, a) leaves in ``data.f[j]`` the spatial force that the parent
exerts on the subtree of joint j, at the joint origin, in joint j's frame. For a carrier's
joint the subtree is the carrier, its rotors and every later body: exactly the paper's
R^k (eq 40) and L^k (eq 48), in body k's frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

from gyro_sim.scene.records import Scene

RTOL = 1e-12
ATOL = 1e-12


@dataclass(frozen=True)
class BodyOut:
    """Kinematic state of one carrier, world frame."""

    name: str
    position: np.ndarray  # (3,) O^k
    rotation: np.ndarray  # (3, 3) world_R_body
    angular_velocity: np.ndarray  # (3,) world frame
    velocity: np.ndarray  # (3,) of O^k, world frame


@dataclass(frozen=True)
class WrenchOut:
    """Force R^k and moment L^k (about O^k) that body k-1 (or the base) exerts on body k."""

    joint: str  # body name
    force: np.ndarray  # (3,) R^k, body k's frame
    moment: np.ndarray  # (3,) L^k, body k's frame


@dataclass(frozen=True)
class RotorOut:
    """One rotor: angle kappa_i and rate kappa_i' relative to its carrier, absolute spin p_i."""

    name: str
    angle: float
    rate: float
    spin: float


@dataclass(frozen=True)
class State:
    """Pinocchio configuration q (nq,) and velocity v (nv,) at time t."""

    t: float
    q: np.ndarray
    v: np.ndarray


def _inertia_about_com(mass: float, com: np.ndarray, inertia_O: np.ndarray) -> np.ndarray:
    """Parallel-axis theorem: inertia about the centre of mass from the inertia about O."""
    c = np.asarray(com, dtype=float)
    return np.asarray(inertia_O, dtype=float) - mass * ((c @ c) * np.eye(3) - np.outer(c, c))


def _quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Pinocchio's quaternion storage (x, y, z, w) of a rotation matrix."""
    return np.array(pin.Quaternion(np.asarray(R, dtype=float)).coeffs())


def _quat_matrix(wxyz: np.ndarray) -> np.ndarray:
    """The rotation of a quaternion (w, x, y, z), of any non-zero norm."""
    w, x, y, z = np.asarray(wxyz, dtype=float)
    return pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation by `angle` about the unit vector `axis` (Pinocchio's exponential map)."""
    return pin.exp3(np.asarray(axis, dtype=float) * float(angle))


_EX, _EY, _EZ = np.eye(3)


def _down_frame(nu: np.ndarray | None) -> np.ndarray:
    """The frame of the Euler angles, world_R_down: its z is nu (no gravity: -z of the world),
    its x the world's x made orthogonal to nu (the world's y when nu is along x)."""
    z = -_EZ if nu is None else np.asarray(nu, dtype=float) / np.linalg.norm(nu)
    ref = _EY if abs(z @ _EX) > 1 - 1e-9 else _EX
    x = ref - (ref @ z) * z
    x = x / np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _euler_state(euler: np.ndarray, rates: np.ndarray, down: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """world_R_body and the world angular velocity of z-x-z Euler angles (psi, theta, phi)
    relative to `down`: precession psi about down's z, nutation theta about the line of nodes
    (the x after the precession), proper rotation phi about the body's z; each rate turns about
    the axis its angle turns about."""
    psi, theta, phi = euler
    after_psi = down @ _axis_angle(_EZ, psi)
    after_theta = after_psi @ _axis_angle(_EX, theta)
    R = after_theta @ _axis_angle(_EZ, phi)
    w = rates[0] * down[:, 2] + rates[1] * after_psi[:, 0] + rates[2] * after_theta[:, 2]
    return R, w


def _quat_rate_xyzw(quat: np.ndarray, omega_local: np.ndarray) -> np.ndarray:
    """q' = 1/2 q (x) (0, omega) with q stored (x, y, z, w) and omega in the child frame."""
    qv, qw = quat[:3], quat[3]
    return 0.5 * np.concatenate([qw * omega_local + np.cross(qv, omega_local), [-qv @ omega_local]])


class PinChain:
    """A scene compiled to a pinocchio model, with forward dynamics and reactions."""

    def __init__(self, scene: Scene):
        self.scene = scene
        model = pin.Model()
        g = np.zeros(3) if scene.gravity is None else np.asarray(scene.gravity, dtype=float)
        model.gravity = pin.Motion(g, np.zeros(3))
        base = scene.base

        # prescribed coordinates: (idx_q, idx_v, nv, function t -> (q, v, a))
        self._prescribed: list[tuple[int, int, int, object]] = []
        parent = 0
        placement = pin.SE3(np.eye(3), np.asarray(base.position, dtype=float))
        if base.type == "moving":
            jt = model.addJoint(0, pin.JointModelTranslation(), pin.SE3.Identity(), "base")
            pos = np.asarray(base.position, dtype=float)
            amp = np.asarray(base.amplitude, dtype=float)
            om = 2.0 * np.pi * float(base.frequency)

            def base_motion(t, pos=pos, amp=amp, om=om):
                return (pos + amp * np.sin(om * t), amp * om * np.cos(om * t),
                        -amp * om * om * np.sin(om * t))

            self._prescribed.append((model.joints[jt].idx_q, model.joints[jt].idx_v, 3,
                                     base_motion))
            parent = jt
            placement = pin.SE3.Identity()

        self.carrier_joint: list[int] = []
        self.rotor_joint: list[list[int]] = []
        self.axis_names: list[str] = []
        self._axis_v: list[int] = []
        for k, body in enumerate(scene.bodies):
            if k == 0 and base.type == "free":
                jm = pin.JointModelFreeFlyer()
                placement = pin.SE3(np.eye(3), np.zeros(3))
            elif body.joint.type == "spherical":
                jm = pin.JointModelSpherical()
            elif body.joint.type == "hinge":
                axis = np.asarray(body.joint.axis, dtype=float)
                jm = pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis))
            else:
                raise ValueError(f"unknown joint type {body.joint.type!r}")
            j = model.addJoint(parent, jm, placement, f"body:{body.name}")
            com = np.asarray(body.com, dtype=float)
            model.appendBodyToJoint(
                j, pin.Inertia(float(body.mass), com,
                               _inertia_about_com(body.mass, com, body.inertia)),
                pin.SE3.Identity())
            self.carrier_joint.append(j)
            if body.joint.type == "hinge" and not (k == 0 and base.type == "free"):
                self.axis_names.append(body.name)
                self._axis_v.append(model.joints[j].idx_v)
            rotor_ids = []
            for rotor in body.rotors:
                e = np.asarray(rotor.axis, dtype=float)
                e = e / np.linalg.norm(e)
                jr = model.addJoint(j, pin.JointModelRevoluteUnaligned(e),
                                    pin.SE3(np.eye(3), np.asarray(rotor.position, dtype=float)),
                                    f"rotor:{rotor.name}")
                A, B = float(rotor.axial_inertia), float(rotor.transverse_inertia)
                model.appendBodyToJoint(
                    jr, pin.Inertia(float(rotor.mass), np.zeros(3),
                                    B * np.eye(3) + (A - B) * np.outer(e, e)),
                    pin.SE3.Identity())
                rotor_ids.append(jr)
                if rotor.mode == "speed":
                    rate = float(rotor.spin)

                    def spin_motion(t, rate=rate):
                        return np.array([rate * t]), np.array([rate]), np.zeros(1)

                    self._prescribed.append((model.joints[jr].idx_q, model.joints[jr].idx_v,
                                             1, spin_motion))
                elif rotor.actuated:
                    self.axis_names.append(rotor.name)
                    self._axis_v.append(model.joints[jr].idx_v)
            self.rotor_joint.append(rotor_ids)
            parent = j
            if body.next_joint is not None:
                placement = pin.SE3(np.eye(3), np.asarray(body.next_joint, dtype=float))

        self.model = model
        self.data = model.createData()
        self._quat_q = [
            model.joints[j].idx_q + (3 if model.joints[j].shortname() == "JointModelFreeFlyer"
                                     else 0)
            for j in range(1, model.njoints)
            if model.joints[j].shortname() in ("JointModelFreeFlyer", "JointModelSpherical")
        ]
        p_idx = [iv + i for (_, iv, n, _) in self._prescribed for i in range(n)]
        self._p = np.array(sorted(p_idx), dtype=int)
        self._f = np.array([i for i in range(model.nv) if i not in set(p_idx)], dtype=int)

    # ------------------------------------------------------------------ state
    def initial_state(self) -> State:
        """The scene's initial state as pinocchio (q, v), t = 0."""
        scene, model = self.scene, self.model
        q = pin.neutral(model)
        v = np.zeros(model.nv)
        nu = None
        if scene.gravity is not None and np.linalg.norm(scene.gravity) > 0.0:
            nu = np.asarray(scene.gravity, dtype=float) / np.linalg.norm(scene.gravity)
        down = _down_frame(nu)
        parent_R, parent_w = np.eye(3), np.zeros(3)
        for k, body in enumerate(scene.bodies):
            jmodel = model.joints[self.carrier_joint[k]]
            iq, iv = jmodel.idx_q, jmodel.idx_v
            init = body.initial
            if body.joint.type == "hinge" and not (k == 0 and scene.base.type == "free"):
                axis = np.asarray(body.joint.axis, dtype=float)
                axis = axis / np.linalg.norm(axis)
                R = parent_R @ _axis_angle(axis, float(init.angle))
                w = parent_w + parent_R @ axis * float(init.rate)
                q[iq] = float(init.angle)
                v[iv] = float(init.rate)
            else:
                if init.quaternion is not None:
                    quat = np.asarray(init.quaternion, dtype=float)
                    R = _quat_matrix(quat)
                    w = R @ np.asarray(init.angular_velocity if init.angular_velocity is not None
                                       else np.zeros(3), dtype=float)
                else:
                    euler = np.zeros(3) if init.euler is None else np.asarray(init.euler, float)
                    rates = (np.zeros(3) if init.euler_rates is None
                             else np.asarray(init.euler_rates, float))
                    R, w = _euler_state(euler, rates, down)
                if k == 0 and scene.base.type == "free":
                    vel = (np.zeros(3) if scene.base.velocity is None
                           else np.asarray(scene.base.velocity, dtype=float))
                    q[iq:iq + 3] = np.asarray(scene.base.position, dtype=float)
                    q[iq + 3:iq + 7] = _quat_xyzw(R)
                    v[iv:iv + 3] = R.T @ vel  # free-flyer linear velocity: local frame
                    v[iv + 3:iv + 6] = R.T @ w
                else:
                    q[iq:iq + 4] = _quat_xyzw(parent_R.T @ R)
                    v[iv:iv + 3] = R.T @ (w - parent_w)  # relative, child frame
            w_body = R.T @ w
            for rotor, jr in zip(body.rotors, self.rotor_joint[k]):
                e = np.asarray(rotor.axis, dtype=float)
                e = e / np.linalg.norm(e)
                ivr = model.joints[jr].idx_v
                q[model.joints[jr].idx_q] = 0.0
                # torque rotor: spin is the absolute p_i = w . e_i + kappa_i' (eq 18-19)
                v[ivr] = rotor.spin - w_body @ e if rotor.mode == "torque" else rotor.spin
            parent_R, parent_w = R, w
        return self._consistent(0.0, q, v)

    def state_from_bodies(self, t: float, bodies, rotor_rates: dict[str, float]) -> State:
        """The pinocchio state of another engine's output at time t.

        `bodies`: per carrier, objects with .position, .rotation (world_R_body),
        .angular_velocity and .velocity (world); `rotor_rates`: kappa_i' by rotor name.
        Rotor angles are set to 0: the rotors are axisymmetric, nothing depends on them.
        """
        model = self.model
        q = pin.neutral(model)
        v = np.zeros(model.nv)
        parent_R, parent_w = np.eye(3), np.zeros(3)
        for k, (body, b) in enumerate(zip(self.scene.bodies, bodies, strict=True)):
            jm = model.joints[self.carrier_joint[k]]
            iq, iv = jm.idx_q, jm.idx_v
            R = np.asarray(b.rotation, dtype=float)
            w = np.asarray(b.angular_velocity, dtype=float)
            if jm.shortname() == "JointModelFreeFlyer":
                q[iq:iq + 3] = b.position
                q[iq + 3:iq + 7] = _quat_xyzw(R)
                v[iv:iv + 3] = R.T @ np.asarray(b.velocity, dtype=float)
                v[iv + 3:iv + 6] = R.T @ w
            elif jm.shortname() == "JointModelSpherical":
                q[iq:iq + 4] = _quat_xyzw(parent_R.T @ R)
                v[iv:iv + 3] = R.T @ (w - parent_w)
            else:  # hinge: the angle of parent_R^T R about the axis
                axis = np.asarray(body.joint.axis, dtype=float)
                axis = axis / np.linalg.norm(axis)
                Rrel = parent_R.T @ R
                sin = 0.5 * axis @ np.array([Rrel[2, 1] - Rrel[1, 2], Rrel[0, 2] - Rrel[2, 0],
                                             Rrel[1, 0] - Rrel[0, 1]])
                cos = 0.5 * (np.trace(Rrel) - 1.0)
                q[iq] = np.arctan2(sin, cos)
                v[iv] = axis @ (parent_R.T @ (w - parent_w))
            for rotor, jr in zip(body.rotors, self.rotor_joint[k]):
                v[model.joints[jr].idx_v] = rotor_rates[rotor.name]
            parent_R, parent_w = R, w
        return self._consistent(t, q, v)

    def _consistent(self, t: float, q: np.ndarray, v: np.ndarray) -> State:
        """Prescribed coordinates set from t, quaternions renormalised."""
        q = np.array(q, dtype=float)
        v = np.array(v, dtype=float)
        for iq, iv, n, motion in self._prescribed:
            qp, vp, _ = motion(t)
            q[iq:iq + n] = qp
            v[iv:iv + n] = vp
        for i in self._quat_q:
            q[i:i + 4] /= np.linalg.norm(q[i:i + 4])
        return State(float(t), q, v)

    def _prescribed_acc(self, t: float) -> np.ndarray:
        a = np.zeros(self.model.nv)
        for _, iv, n, motion in self._prescribed:
            a[iv:iv + n] = motion(t)[2]
        return a

    def _tau(self, axis_moments) -> np.ndarray:
        tau = np.zeros(self.model.nv)
        if axis_moments is None:
            return tau
        axis_moments = np.asarray(axis_moments, dtype=float)
        if axis_moments.shape != (len(self._axis_v),):
            raise ValueError(f"expected {len(self._axis_v)} axis moments ({self.axis_names}), "
                             f"got shape {axis_moments.shape}")
        tau[self._axis_v] = axis_moments
        return tau

    # --------------------------------------------------------------- dynamics
    def accelerations(self, state: State, axis_moments=None) -> np.ndarray:
        """Joint accelerations a (nv,): M_ff a_f = tau_f - h_f - M_fp a_p."""
        model, data = self.model, self.data
        M = pin.crba(model, data, state.q)
        M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper triangle
        h = pin.nonLinearEffects(model, data, state.q, state.v)
        tau = self._tau(axis_moments)
        a = self._prescribed_acc(state.t)
        f, p = self._f, self._p
        rhs = tau[f] - h[f] - M[np.ix_(f, p)] @ a[p]
        a[f] = np.linalg.solve(M[np.ix_(f, f)], rhs)
        return a

    def _qdot(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        model = self.model
        qd = np.zeros(model.nq)
        for j in range(1, model.njoints):
            jm = model.joints[j]
            iq, iv, kind = jm.idx_q, jm.idx_v, jm.shortname()
            if kind == "JointModelFreeFlyer":
                R = pin.XYZQUATToSE3(q[iq:iq + 7]).rotation
                qd[iq:iq + 3] = R @ v[iv:iv + 3]
                qd[iq + 3:iq + 7] = _quat_rate_xyzw(q[iq + 3:iq + 7], v[iv + 3:iv + 6])
            elif kind == "JointModelSpherical":
                qd[iq:iq + 4] = _quat_rate_xyzw(q[iq:iq + 4], v[iv:iv + 3])
            else:  # revolute (1) or translation (3): q' = v
                qd[iq:iq + jm.nq] = v[iv:iv + jm.nv]
        return qd

    def _rhs(self, t: float, y: np.ndarray, axis_moments) -> np.ndarray:
        nq = self.model.nq
        state = self._consistent(t, y[:nq], y[nq:])
        a = self.accelerations(state, axis_moments)
        return np.concatenate([self._qdot(state.q, state.v), a])

    def run(self, t_final: float, axis_moments=None, t_eval=None, rtol: float = RTOL,
            atol: float = ATOL) -> list[State]:
        """Integrate from the initial state; the states at t_eval (default: [t_final])."""
        s0 = self.initial_state()
        t_eval = np.array([t_final] if t_eval is None else t_eval, dtype=float)
        if t_final == 0.0:
            return [s0 for _ in t_eval]
        y0 = np.concatenate([s0.q, s0.v])
        sol = solve_ivp(self._rhs, (0.0, t_final), y0, method="DOP853", rtol=rtol, atol=atol,
                        t_eval=t_eval, args=(axis_moments,))
        if not sol.success:
            raise RuntimeError(f"oracle integration failed: {sol.message}")
        nq = self.model.nq
        return [self._consistent(t, y[:nq], y[nq:]) for t, y in zip(sol.t, sol.y.T)]

    # ---------------------------------------------------------------- outputs
    def bodies(self, state: State) -> list[BodyOut]:
        """Per carrier: O^k, world_R_body, world angular velocity, world velocity of O^k."""
        pin.forwardKinematics(self.model, self.data, state.q, state.v)
        out = []
        for body, j in zip(self.scene.bodies, self.carrier_joint):
            oMi = self.data.oMi[j]
            R = oMi.rotation.copy()
            vj = self.data.v[j]  # spatial velocity at the joint origin, joint frame
            out.append(BodyOut(body.name, oMi.translation.copy(), R, R @ vj.angular,
                               R @ vj.linear))
        return out

    def rotors(self, state: State) -> list[RotorOut]:
        """Rotor angles and rates relative to the carrier, and absolute spins p_i."""
        pin.forwardKinematics(self.model, self.data, state.q, state.v)
        out = []
        for body, j, ids in zip(self.scene.bodies, self.carrier_joint, self.rotor_joint):
            w_body = self.data.v[j].angular
            for rotor, jr in zip(body.rotors, ids):
                e = np.asarray(rotor.axis, dtype=float)
                e = e / np.linalg.norm(e)
                jm = self.model.joints[jr]
                rate = float(state.v[jm.idx_v])
                out.append(RotorOut(rotor.name, float(state.q[jm.idx_q]), rate,
                                    float(w_body @ e) + rate))
        return out

    def reactions(self, state: State, axis_moments=None) -> list[WrenchOut]:
        """R^k, L^k at every O^k in body k's frame (eqs 40, 48), from rnea's data.f."""
        a = self.accelerations(state, axis_moments)
        pin.rnea(self.model, self.data, state.q, state.v, a)
        return [WrenchOut(body.name, self.data.f[j].linear.copy(), self.data.f[j].angular.copy())
                for body, j in zip(self.scene.bodies, self.carrier_joint)]

    def energy(self, state: State) -> float:
        """T + V from pinocchio's own energy functions (meaningful for conservative scenes)."""
        T = pin.computeKineticEnergy(self.model, self.data, state.q, state.v)
        V = pin.computePotentialEnergy(self.model, self.data, state.q)
        return float(T + V)


def simulate(scene: Scene, t_final: float, axis_moments=None) -> list[BodyOut]:
    """Body states at t_final, axis moments held constant (order: `PinChain.axis_names`)."""
    chain = PinChain(scene)
    return chain.bodies(chain.run(t_final, axis_moments)[-1])


def reactions(scene: Scene, state: State | None = None, axis_moments=None) -> list[WrenchOut]:
    """Joint reactions R^k, L^k at `state` (default: the scene's initial state)."""
    chain = PinChain(scene)
    return chain.reactions(chain.initial_state() if state is None else state, axis_moments)
