"""Peers for the accuracy report: the same scene in MuJoCo, and scipy's solvers on our rhs.

MuJoCo (`mujoco` package) gets the scene as MJCF, in the most literal way (the mapping of
test/oracles/pin_chain.py, which checks gyro_sim against Pinocchio):

- body k is an MJCF body whose frame is the scene's body frame (origin O^k): a ``ball``
  joint for a spherical joint, a ``hinge`` joint about the axis (the same vector in the
  parent's and the child's frame at angle 0) for a hinge, a ``freejoint`` on body 1 of a free
  base; the next body sits at s^k with no rotation;
- the carrier's inertia is written about its centre of mass (`fullinertia`, parallel-axis
  theorem from the scene's inertia about O^k);
- every rotor is a child body on a ``hinge`` joint about its axis e_i through its centre
  h_i, inertia B_i 1 + (A_i - B_i) e_i e_i^T; its joint velocity is kappa_i' = p_i - w . e_i;
- commanded axis moments are generalised forces (`qfrc_applied`) on the hinge and rotor
  joints; no contacts, no damping; a hinge's armature and spring are MuJoCo's `armature`,
  `stiffness` and `springref` (docs/models.md, "Armature and joint springs").

MuJoCo cannot hold a speed rotor's kappa_i' constant (a rheonomic constraint: only an
actuator that approximately tracks it) nor move the base along a prescribed path with the
exact accelerations (a mocap body has no dynamics), nor gear a rotor exactly to a joint (a
geared motor: its equality constraints are soft): such scenes are skipped, with that reason, by
:func:`mujoco_unsupported`.
"""
from __future__ import annotations

import math

import contextlib
import time
from dataclasses import dataclass

import numpy as np

from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics import invariants as inv
from gyro_sim.dynamics.model import Model, compile_model, initial_state
from gyro_sim.dynamics.rotations import matrix_to_quat
from gyro_sim.scene.records import Scene
from gyro_sim.dynamics.system import make_system


@dataclass(frozen=True)
class Frames:
    """What the error is measured on: every carrier's attitude and angular velocity, and the
    base point O^1 with its velocity (world frame). Engines with other state layouts all
    produce this."""

    R: np.ndarray  # (n, 3, 3) world_R_body
    w: np.ndarray  # (n, 3) angular velocities
    O1: np.ndarray  # (3,)
    v1: np.ndarray  # (3,)


def frames_of_state(model: Model, t: float, y: np.ndarray) -> Frames:
    """Frames of a gyro_sim state vector y (quaternions renormalised first)."""
    y = np.array(y, dtype=float)
    q = y[model.i_quat]
    if q.size:
        y[model.i_quat] = q / np.linalg.norm(q, axis=1, keepdims=True)
    d = dyn.Data(model)
    dyn.positions(model, d, t, y)
    dyn.velocities(model, d, t, y[model.i_vel])
    return Frames(d.R.copy(), d.w.copy(), d.O[0].copy(), d.vO[0].copy())


def spins_at(model: Model, t: float, L_rotor: np.ndarray | None) -> np.ndarray | None:
    """Torque-rotor spins p_i(t) from t = 0 under constant axial torques (eq 29)."""
    if not len(model.torque_body):
        return None
    p = model.torque_p0.copy()
    return p if L_rotor is None else p + L_rotor / model.torque_A * t


def invariants_of_state(model: Model, t: float, y: np.ndarray, L_rotor=None) -> dict:
    """gyro_sim's invariants (energy, momenta) of a state vector y at time t."""
    y = np.array(y, dtype=float)
    q = y[model.i_quat]
    if q.size:
        y[model.i_quat] = q / np.linalg.norm(q, axis=1, keepdims=True)
    d = dyn.Data(model)
    dyn.positions(model, d, t, y)
    dyn.velocities(model, d, t, y[model.i_vel])
    return inv.invariants(model, d, spins_at(model, t, L_rotor), t, y)


def split_moments(model: Model, moments) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(hinge_tau, L_rotor) of axis moments in `model.axis_names` order (as Simulator)."""
    if moments is None or not len(model.axis_names):
        return None, None
    v = np.asarray(moments, dtype=float)
    hinge_tau = np.zeros(len(model.hinge_bodies))
    sel = model.axis_hinge >= 0
    hinge_tau[model.axis_hinge[sel]] = v[sel]
    L_rotor = None
    if len(model.torque_body):
        L_rotor = np.zeros(len(model.torque_body))
        sel = model.axis_rotor >= 0
        L_rotor[model.axis_rotor[sel]] = v[sel]
    return hinge_tau, L_rotor


# ------------------------------------------------------------------------------ scipy
@dataclass
class PeerRun:
    frames: Frames | None
    invariants: dict | None  # name -> value at the end (the engine's own where it has them)
    invariants0: dict | None
    cpu: float
    nfev: int
    nsteps: int
    failed: str | None = None


def run_scipy(scene: Scene, method: str, rtol: float, atol: float, horizon: float, moments=None,
              backend: str = "auto") -> PeerRun:
    """scipy.integrate.solve_ivp(method) on gyro_sim's right-hand side (the Simulator's
    `backend`), one call to `horizon`."""
    from scipy.integrate import solve_ivp

    model = compile_model(scene)
    system = make_system(model, backend)
    hinge_tau, L_rotor = split_moments(model, moments)
    system.hold(0.0, model.torque_p0.copy() if len(model.torque_body) else None, hinge_tau, L_rotor)
    y0 = initial_state(model)
    inv0 = invariants_of_state(model, 0.0, y0, L_rotor)
    with np.errstate(all="ignore"):
        t0 = time.process_time()
        sol = solve_ivp(system.rhs, (0.0, horizon), y0, method=method, rtol=rtol, atol=atol)
        cpu = time.process_time() - t0
    y = sol.y[:, -1]
    if not sol.success or sol.t[-1] != horizon or not np.all(np.isfinite(y)):
        return PeerRun(None, None, inv0, cpu, system.nfev, sol.t.size - 1, f"scipy {method}: {sol.message}")
    return PeerRun(frames_of_state(model, horizon, y), invariants_of_state(model, horizon, y, L_rotor), inv0,
                   cpu, system.nfev, sol.t.size - 1)


# ----------------------------------------------------------------------------- MuJoCo
def mujoco_unsupported(scene: Scene) -> str | None:
    """Why MuJoCo cannot represent `scene` exactly, or None."""
    if scene.base.type == "moving":
        return "moving base: MuJoCo cannot prescribe the base motion with its exact accelerations"
    for b in scene.bodies:
        if b.joint.motor is not None:
            return (f"geared motor of {b.name}: MuJoCo couples a rotor to a joint only through a soft "
                    "equality constraint, not an exact gear")
        if b.mass == 0.0:  # a frame of an MJCF body with several joints (docs/models.md)
            return f"massless body {b.name}: MuJoCo gives every moving body a mass (write its joint in the next body)"
        for r in b.rotors:
            if r.mode == "speed":
                return f"speed rotor {r.name}: MuJoCo cannot hold kappa' constant (rheonomic constraint)"
    return None


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(v))


def _full_inertia(I: np.ndarray) -> str:
    return _vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def mjcf(scene: Scene, timestep: float, integrator: str) -> str:
    """The MJCF text of `scene` (see the module docstring for the mapping)."""
    g = np.zeros(3) if scene.gravity is None else np.asarray(scene.gravity, dtype=float)
    lines = [
        f'<mujoco model="{scene.name.replace(chr(34), "")}">',
        f'  <option timestep="{timestep!r}" integrator="{integrator}" gravity="{_vec(g)}">',
        '    <flag contact="disable" energy="enable"/>',
        "  </option>",
        "  <worldbody>",
    ]
    closing = []
    indent = "    "
    pos = np.asarray(scene.base.position, dtype=float)
    for k, b in enumerate(scene.bodies):
        lines.append(f'{indent}<body name="body:{b.name}" pos="{_vec(pos)}">')
        if k == 0 and scene.base.type == "free":
            lines.append(f'{indent}  <freejoint name="joint:{b.name}"/>')
        elif b.joint.type == "spherical":
            lines.append(f'{indent}  <joint name="joint:{b.name}" type="ball"/>')
        else:
            axis = np.asarray(b.joint.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            terms = f' armature="{float(b.joint.armature)!r}"' if b.joint.armature else ""
            if b.joint.spring is not None:  # a hinge's springref in the compiler's default unit, degrees
                ref = b.joint.spring.reference
                terms += (f' stiffness="{float(b.joint.spring.stiffness)!r}" '
                          f'springref="{math.degrees(ref) if b.joint.type == "hinge" else float(ref)!r}"')
            lines.append(f'{indent}  <joint name="joint:{b.name}" type="{b.joint.type}" axis="{_vec(axis)}"{terms}/>')
        c = np.asarray(b.com, dtype=float)
        I_c = np.asarray(b.inertia, dtype=float) - b.mass * ((c @ c) * np.eye(3) - np.outer(c, c))
        lines.append(f'{indent}  <inertial pos="{_vec(c)}" mass="{float(b.mass)!r}" '
                     f'fullinertia="{_full_inertia(I_c)}"/>')
        for r in b.rotors:
            e = np.asarray(r.axis, dtype=float)
            e = e / np.linalg.norm(e)
            I_r = r.transverse_inertia * np.eye(3) + (r.axial_inertia - r.transverse_inertia) * np.outer(e, e)
            lines += [
                f'{indent}  <body name="rotor:{r.name}" pos="{_vec(r.position)}">',
                f'{indent}    <joint name="joint:{r.name}" type="hinge" axis="{_vec(e)}"/>',
                f'{indent}    <inertial pos="0 0 0" mass="{float(r.mass)!r}" fullinertia="{_full_inertia(I_r)}"/>',
                f"{indent}  </body>",
            ]
        closing.append(f"{indent}</body>")
        indent += "  "
        pos = np.zeros(3) if b.next_joint is None else np.asarray(b.next_joint, dtype=float)
    lines += closing[::-1]
    lines += ["  </worldbody>", "</mujoco>"]
    return "\n".join(lines)


#: MuJoCo's names of the two integrators the report runs
MUJOCO_INTEGRATORS = {"RK4": "RK4", "implicitfast": "implicitfast"}


class MujocoChain:
    """A scene in MuJoCo, started in gyro_sim's initial state, with the report's outputs."""

    def __init__(self, scene: Scene, timestep: float, integrator: str, moments=None):
        import mujoco

        self.mj = mujoco
        self.scene = scene
        self.model = compile_model(scene)
        self.m = mujoco.MjModel.from_xml_string(mjcf(scene, timestep, integrator))
        self.d = mujoco.MjData(self.m)
        names = [b.name for b in scene.bodies]
        self.body_ids = [mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, f"body:{n}") for n in names]
        self._set_initial(moments)

    def _jnt(self, name: str) -> tuple[int, int]:
        j = self.mj.mj_name2id(self.m, self.mj.mjtObj.mjOBJ_JOINT, f"joint:{name}")
        return int(self.m.jnt_qposadr[j]), int(self.m.jnt_dofadr[j])

    def _set_initial(self, moments) -> None:
        model, scene = self.model, self.scene
        y = initial_state(model)
        d = dyn.Data(model)
        dyn.positions(model, d, 0.0, y)
        dyn.velocities(model, d, 0.0, y[model.i_vel])
        qpos, qvel = self.d.qpos, self.d.qvel
        R_par, w_par = np.eye(3), np.zeros(3)
        ih = 0
        i_rot = 0
        for k, b in enumerate(scene.bodies):
            R, w = d.R[k], d.w[k]
            iq, iv = self._jnt(b.name)
            if k == 0 and scene.base.type == "free":
                qpos[iq:iq + 3] = d.O[0]
                qpos[iq + 3:iq + 7] = matrix_to_quat(R)
                qvel[iv:iv + 3] = d.vO[0]
                qvel[iv + 3:iv + 6] = R.T @ w
            elif b.joint.type == "spherical":
                qpos[iq:iq + 4] = matrix_to_quat(R_par.T @ R)
                qvel[iv:iv + 3] = R.T @ (w - w_par)  # relative, child frame
            else:
                qpos[iq] = y[model.i_phi][ih]
                qvel[iv] = y[model.i_vel][model.col_hinge[ih]]
                ih += 1
            for r in b.rotors:  # torque rotors only (speed rotors are unsupported)
                e = R @ (np.asarray(r.axis, dtype=float) / np.linalg.norm(r.axis))
                iq_r, iv_r = self._jnt(r.name)
                qpos[iq_r] = 0.0
                qvel[iv_r] = model.torque_p0[i_rot] - w @ e  # kappa' = p - w . e (eqs 18-19)
                i_rot += 1
            R_par, w_par = R, w
        if moments is not None:
            self.set_moments(moments)
        self.mj.mj_forward(self.m, self.d)

    def set_moments(self, moments) -> None:
        """Commanded axis moments (`model.axis_names` order) as generalised forces on the hinge
        and rotor joints (`qfrc_applied`), held until set again."""
        for name, value in zip(self.model.axis_names, moments):
            self.d.qfrc_applied[self._jnt(name)[1]] = float(value)

    @property
    def time(self) -> float:
        return float(self.d.time)

    def step(self, nstep: int) -> None:
        self.mj.mj_step(self.m, self.d, nstep=nstep)

    def frames(self) -> Frames:
        self.mj.mj_forward(self.m, self.d)
        R = np.array([self.d.xmat[i].reshape(3, 3) for i in self.body_ids])
        vel = np.zeros((len(self.body_ids), 6))
        for k, i in enumerate(self.body_ids):
            # XBODY: at the body frame's origin O^k (BODY would be at the centre of mass)
            self.mj.mj_objectVelocity(self.m, self.d, self.mj.mjtObj.mjOBJ_XBODY, i, vel[k], 0)
        return Frames(R, vel[:, :3].copy(), self.d.xpos[self.body_ids[0]].copy(), vel[0, 3:].copy())

    def invariants(self) -> dict:
        """MuJoCo's own energy (potential + kinetic), and momenta from its subtree sums."""
        mj, m, d = self.mj, self.m, self.d
        mj.mj_forward(m, d)
        mj.mj_subtreeVel(m, d)
        b1 = self.body_ids[0]
        M = float(m.body_subtreemass[b1])
        com, vcom = d.subtree_com[b1], d.subtree_linvel[b1]
        O1 = d.xpos[b1]
        L_O1 = d.subtree_angmom[b1] + np.cross(com - O1, M * vcom)
        up = -self.model.down[:, 2]
        out = {"energy": float(d.energy[0] + d.energy[1]), "vertical_momentum": float(up @ L_O1)}
        if self.scene.base.type == "free":
            out["linear_momentum"] = M * vcom
            out["angular_momentum"] = d.subtree_angmom[b1].copy()
        return out


def run_mujoco(scene: Scene, integrator: str, step: float, horizon: float, moments=None) -> PeerRun:
    """MuJoCo from gyro_sim's initial state to `horizon` in n = ceil(horizon / step) steps."""
    n = max(1, int(np.ceil(horizon / step - 1e-9)))
    chain = MujocoChain(scene, horizon / n, MUJOCO_INTEGRATORS[integrator], moments)
    inv0 = chain.invariants()
    with mujoco_warnings() as messages:
        t0 = time.process_time()
        chain.step(n)
        cpu = time.process_time() - t0
    what = mujoco_failure(chain, messages)
    if what:
        return PeerRun(None, None, inv0, cpu, 0, n, f"MuJoCo {integrator}: {what}")
    return PeerRun(chain.frames(), chain.invariants(), inv0, cpu, 0, n)


@contextlib.contextmanager
def mujoco_warnings():
    """Collect MuJoCo's warning messages (it prints them otherwise) into the list yielded."""
    import mujoco

    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


def mujoco_failure(chain: MujocoChain, messages: list[str]) -> str | None:
    """Why the MuJoCo run of `chain` is not to be trusted, or None: a warning was raised, an
    instability flag is set (MuJoCo resets an unstable simulation to the model's rest state
    and goes on: detect it) or the state is not finite."""
    import mujoco

    bad = [mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQPOS]
    if messages or any(chain.d.warning[int(w)].number for w in bad) or not (
            np.all(np.isfinite(chain.d.qpos)) and np.all(np.isfinite(chain.d.qvel))):
        return messages[0].strip() if messages else "non-finite state"
    return None
