"""The linear model of a chain about a state, in its tangent space (docs/linearization.md).

    dx' = A dx + B du + f0        (continuous; f0 = x' at the point: zero at an equilibrium)
    z   = C dx + D du             (joint states of hinges and rotors, IMU gyros and accelerometers)

The state x is in the tangent space of the chain's configuration (docs/linearization.md,
"The state"): [positions (N) | generalized velocities (N) | torque-rotor spins p_i (nt) |
torque-rotor angles kappa_i (nt, only with `rotor_angles=True`)], where the positions are, in
the order of the velocity columns: the free base's point O^1 (3), the rotation vector of each
spherical body (3) and each hinge angle (1). The inputs are the commanded axis moments in
command order (`Simulator.axis_names`), then the servos' controls (`Simulator.control_names`:
A is then the closed loop of the servos, B's last columns act on their controls). The work
accumulators of a scene with friction are left out: they feed nothing back.

Three charts of the rotations:

- "world" (default): q = exp(theta / 2) (x) q0, theta in world components; velocities are the
  model's generalized velocities (relative angular velocities in world components).
- "body": the co-rotating chart of a steady spin, q = q0 (x) exp(delta / 2), with each spherical
  joint's relative angular velocity in its body's components, and the attitude error taken
  against the reference rotation that turns at the body's angular velocity at the point
  (delta' = J_r^-1(delta) (Omega - exp(-delta) Omega0)). A steady spin about a principal axis, or
  a sleeping top, is an equilibrium there (f0 = 0).
- "frame": the world chart seen from a frame turning at a constant angular velocity
  `frame_rate` (world components) about an axis through the base point O^1 (the world origin for
  a free base): theta' = J_l^-1(theta) (w - Omega), and every world vector of the state (joint
  rates, the free base's velocity and point) in the frame's axes. A regular precession written
  as a carrier precessing about the vertical with a rotor carrying the spin is an equilibrium
  there with frame_rate = the precession's rate.

Derivatives are by the complex step, Im f(x + i h e_j) / h with h = 1e-30, through the numpy
reference of the dynamics (:mod:`gyro_sim.dynamics.reference`), which takes complex states:
exact to round-off (no subtraction, so no step to tune), and it uses the same equations as
every simulation, so nothing is derived twice. The directions go through it stacked on a
leading axis (BATCH_ELEMENTS), each stack in one pass; the mass matrix is factorised once at
the point and never formed again (its change along a direction enters as the inertial forces
of the point's accelerations, O(n)), and one back-substitution serves a whole stack. Switches
(saturation, the friction's stick band, the speed limit's ramp) are decided on real parts: at a
non-differentiable point the model is the one-sided one of the side the code takes, and `notes`
says so. `method="fd"` gives central differences with the step FD_STEP times max(1, |value|)
per coordinate, as a cross-check.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.model import Model
from gyro_sim.dynamics.rotations import cross, quat_mul, quat_to_matrix
from gyro_sim.errors import GyroSimError

#: the complex step: below any term's round-off, above the smallest normal number squared
COMPLEX_STEP = 1e-30
#: central differences' relative step, the cube root of the double's epsilon (error ~ eps^(2/3))
FD_STEP = float(np.finfo(float).eps ** (1.0 / 3.0))
#: the most states a linearisation takes: A is dense (3000 states: 72 MB, some minutes)
MAX_STATES = 3000
#: the complex-step directions go through the reference in stacks of at most this many
#: directions x bodies (a stack's 3 x 3 complex arrays: about 0.6 MB each)
BATCH_ELEMENTS = 4096
#: an equilibrium: |f0| at most this (absolute, SI units of each state's rate)
EQUILIBRIUM_TOL = 1e-9
CHARTS = ("world", "body", "frame")
#: the fixed-step methods `discrete` knows by their Butcher tableaux; "zoh" is the exact
#: transition with the input held over the step
DISCRETE_METHODS = ("zoh", "rk4", "gauss4", "gauss4s")
_S3 = np.sqrt(3.0)
_TABLEAUX = {
    "rk4": (np.array([[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1.0, 0]]), np.array([1, 2, 2, 1]) / 6.0),
    "gauss4": (np.array([[0.25, 0.25 - _S3 / 6], [0.25 + _S3 / 6, 0.25]]), np.array([0.5, 0.5])),
}
_TABLEAUX["gauss4s"] = _TABLEAUX["gauss4"]  # the same map at an equilibrium (RK methods are affine covariant)


class LinearizationError(GyroSimError, ValueError):
    """A linearisation that cannot be made as asked (one line)."""


# --- rotations, complex-safe (series near zero: the complex step's arguments are tiny) ---------
def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _sqrt(t2):
    """The square root of theta . theta, complex-safe (the principal root)."""
    return np.sqrt(t2.astype(complex)) if np.iscomplexobj(t2) else np.sqrt(t2)


def _exp_half(theta: np.ndarray) -> np.ndarray:
    """The unit quaternions (..., 4) of rotation vectors theta (..., 3), real or complex."""
    t2 = _dot(theta, theta)
    small = np.abs(t2) < 1e-6
    a = _sqrt(np.where(small, 1.0, t2))
    c = np.where(small, 1.0 - t2 / 8.0 + t2 * t2 / 384.0, np.cos(a / 2.0))
    s = np.where(small, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0, np.sin(a / 2.0) / a)
    return np.concatenate((c[..., None], s[..., None] * theta), axis=-1)


def _jinv_coefficient(t2):
    """c(theta^2) of J^-1 = I -+ 1/2 [theta]x + c [theta]x^2: 1/t^2 - (1 + cos t) / (2 t sin t)."""
    small = np.abs(t2) < 1e-4
    t2s = np.where(small, 1.0, t2)
    a = _sqrt(t2s)
    return np.where(small, 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0,
                    1.0 / t2s - (1.0 + np.cos(a)) / (2.0 * a * np.sin(a)))


def _jl_inv(theta, w):
    """J_l^-1(theta) w (rows): theta' of q = exp(theta / 2) (x) q0 turning at w (world components)."""
    tw = cross(theta, w)
    return w - 0.5 * tw + _jinv_coefficient(_dot(theta, theta))[..., None] * cross(theta, tw)


def _jr_inv(delta, w):
    """J_r^-1(delta) w (rows): delta' of q = q0 (x) exp(delta / 2) turning at w (body components)."""
    tw = cross(delta, w)
    return w + 0.5 * tw + _jinv_coefficient(_dot(delta, delta))[..., None] * cross(delta, tw)


def _rotate(theta, v):
    """exp([theta]x) v (Rodrigues, rows), complex-safe."""
    t2 = _dot(theta, theta)
    small = np.abs(t2) < 1e-6
    t2s = np.where(small, 1.0, t2)
    a = _sqrt(t2s)
    s = np.where(small, 1.0 - t2 / 6.0, np.sin(a) / a)[..., None]
    c = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(a)) / t2s)[..., None]
    tv = cross(theta, v)
    return v + s * tv + c * cross(theta, tv)


def _lu_solve(lu, b):
    from scipy.linalg import lu_solve

    return lu_solve(lu, b)


# --- the layout ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Layout:
    """Where each part of the tangent state x and of the outputs z sits."""

    N: int
    nt: int
    rotor_angles: bool
    state_names: tuple[str, ...]
    output_names: tuple[str, ...]

    @property
    def size(self) -> int:
        return 2 * self.N + self.nt * (2 if self.rotor_angles else 1)


def _layout(model: Model, rotor_angles: bool, chart: str) -> Layout:
    N, nt = model.N, len(model.torque_body)
    pos, vel = [""] * N, [""] * N
    if model.free:
        for i, a in zip(model.col_base, "xyz"):
            pos[i], vel[i] = f"base_{a}", f"base_v{a}"
    rv, av = ("d", "v") if chart == "body" else ("r", "w")
    for j, k in enumerate(model.sph_bodies):
        for i, a in zip(model.col_sph[j], "xyz"):
            pos[i], vel[i] = f"{model.names[k]}_{rv}{a}", f"{model.names[k]}_{av}{a}"
    for j, k in enumerate(model.hinge_bodies):
        i = model.col_hinge[j]
        pos[i], vel[i] = model.names[k], f"{model.names[k]}_rate"
    names = pos + vel + [f"{r}_spin" for r in model.torque_names]
    if rotor_angles:
        names += [f"{r}_angle" for r in model.torque_names]
    outs = [f"{model.names[k]}.position" for k in model.hinge_bodies]
    outs += [f"{model.names[k]}.velocity" for k in model.hinge_bodies]
    if rotor_angles:
        outs += [f"{r}.position" for r in model.torque_names]
    outs += [f"{r}.velocity" for r in model.torque_names]
    for imu in model.scene.imus:
        outs += [f"{imu.name}.gyro_{a}" for a in "xyz"]
    for imu in model.scene.imus:
        outs += [f"{imu.name}.accel_{a}" for a in "xyz"]
    return Layout(N, nt, rotor_angles, tuple(names), tuple(outs))


# --- the vector field in the chart --------------------------------------------------------
class TangentField:
    """x' = g(x, v) and the outputs z(x, v) in the chart of a point (t, y0, p0, moments0):
    x the tangent state (Layout), v the change of the commanded moments. Real or complex."""

    def __init__(self, model: Model, t: float, y0: np.ndarray, p0: np.ndarray | None,
                 moments0: np.ndarray, rotor_angles: bool = False, chart: str = "world",
                 frame_rate: np.ndarray | None = None, controls0: np.ndarray | None = None):
        if chart not in CHARTS:
            raise LinearizationError(f"chart: {chart!r} is not one of {', '.join(CHARTS)}")
        if (chart == "frame") != (frame_rate is not None):
            raise LinearizationError("frame_rate: the frame chart's angular velocity (3 numbers), and only for it")
        self.model, self.t, self.chart = model, float(t), chart
        self.frame_rate = np.zeros(3) if frame_rate is None else np.asarray(frame_rate, dtype=float)
        if self.frame_rate.shape != (3,) or not np.all(np.isfinite(self.frame_rate)):
            raise LinearizationError(f"frame_rate: 3 finite numbers (rad/s, world axes), got {frame_rate!r}")
        self.y0 = np.asarray(y0, dtype=float).copy()
        self.p0 = np.zeros(0) if p0 is None else np.asarray(p0, dtype=float).copy()
        # the inputs at the point: the axis moments, then the servos' controls
        self.na = len(model.axis_names)
        controls0 = np.zeros(len(model.servo_names)) if controls0 is None else controls0
        self.m0 = np.concatenate((np.asarray(moments0, dtype=float), np.asarray(controls0, dtype=float)))
        self.layout = _layout(model, rotor_angles, chart)
        self.data = dyn.Data(model)  # its own workspace: the simulator's stays as it is
        m = model
        self._q0 = self.y0[m.i_quat] if len(m.sph_bodies) else np.zeros((0, 4))
        self._R0 = quat_to_matrix(self._q0) if len(m.sph_bodies) else np.zeros((0, 3, 3))
        # the body chart's reference: absolute angular velocities of the spherical bodies at the
        # point (body components), and their relative rates there (body components)
        self.data_point = dyn.Data(m)
        dyn.positions(m, self.data_point, self.t, self.y0)
        dyn.velocities(m, self.data_point, self.t, self.y0[m.i_vel])
        w0 = self.data_point.w[m.sph_bodies]
        u0 = self.y0[m.i_vel]
        self._Omega0 = np.einsum("nji,nj->ni", self._R0, w0)
        self._nu0 = np.einsum("nji,nj->ni", self._R0, u0[m.col_sph]) if len(m.sph_bodies) else np.zeros((0, 3))
        act = m.actuators
        na = len(m.axis_names)
        self._max = np.full(na, np.inf)
        if act is not None:
            self._max = np.array([act.hinge.max_torque[h] if h >= 0 else act.rotor.max_torque[r]
                                  for h, r in zip(m.axis_hinge, m.axis_rotor)]) if na else np.zeros(0)
        # the complex step's shortcut: M u' = rhs at the point, M factorised once (the real part
        # of every direction's M); a stack of directions then costs one back-substitution
        from scipy.linalg import lu_factor

        hinge_tau, L_rotor = self._inputs(np.zeros(len(self.m0)))
        point = dyn.Data(m)
        rhs0, parts = dyn.closure(m, point, self.t, self._y_with_spins(), hinge_tau, self.p0 if len(self.p0) else None,
                                  L_rotor)
        self._lu0 = lu_factor(dyn.mass_matrix(m, point, parts[0], parts[1]))
        self._at_point = point  # its positions serve every direction that moves none
        self._udot0 = _lu_solve(self._lu0, rhs0)
        self._imus = None
        if m.scene.imus:
            from gyro_sim.dynamics.imu import DEFAULT_IMU_RATE, ImuSet

            self._imus = ImuSet(m.scene, {name: k for k, name in enumerate(m.names)}, m.scene.gravity,
                                DEFAULT_IMU_RATE)

    def _y_with_spins(self) -> np.ndarray:
        y = self.y0.copy()
        if self.model.stateful:
            y[self.model.i_spin] = self.p0
        return y

    # the inputs: the commanded moments saturated as Simulator._inputs does; ties go inside;
    # the servos' drives from their controls (their ctrl_range clip decided on real parts)
    def _inputs(self, v):
        m = self.model
        c = self.m0 + v
        c, controls = c[..., :self.na], c[..., self.na:]
        over = np.abs(np.real(c)) > self._max
        if np.any(over):
            c = np.where(over, np.sign(np.real(c)) * np.where(over, self._max, 0.0), c)
        hinge_tau = L_rotor = None
        lead = c.shape[:-1]
        if m.servo is not None:
            hinge_tau = np.zeros(lead + (len(m.hinge_bodies),), dtype=controls.dtype)
            hinge_tau[..., m.servo_hinge] = dyn.servo_drives(m, controls)
        if c.shape[-1]:
            if hinge_tau is None:
                hinge_tau = np.zeros(lead + (len(m.hinge_bodies),), dtype=c.dtype)
            sel = m.axis_hinge >= 0
            hinge_tau[..., m.axis_hinge[sel]] = c[..., sel]
            if len(m.torque_body):
                L_rotor = np.zeros(lead + (len(m.torque_body),), dtype=c.dtype)
                sel = m.axis_rotor >= 0
                L_rotor[..., m.axis_rotor[sel]] = c[..., sel]
        return hinge_tau, L_rotor

    def state(self, x):
        """The model's state vector y and spins p of the tangent state x (or of a stack of
        them, x of shape (..., size): y then (..., model size))."""
        m, L = self.model, self.layout
        N, nt = L.N, L.nt
        dt = np.result_type(x, float)
        y = np.broadcast_to(self.y0.astype(dt), x.shape[:-1] + self.y0.shape).copy()
        if m.free:
            y[..., m.i_r0] = self.y0[m.i_r0] + x[..., m.col_base]
        body = self.chart == "body"
        if len(m.sph_bodies):
            e = _exp_half(x[..., m.col_sph])
            y[..., m.i_quat] = quat_mul(self._q0, e) if body else quat_mul(e, self._q0)
        y[..., m.i_phi] = self.y0[m.i_phi] + x[..., m.col_hinge]
        u = self.y0[m.i_vel].astype(dt) + x[..., N:2 * N]
        if body and len(m.sph_bodies):
            R = quat_to_matrix(y[..., m.i_quat])
            nu = self._nu0 + x[..., N:2 * N][..., m.col_sph]
            u[..., m.col_sph] = np.einsum("...nij,...nj->...ni", R, nu)  # body components -> world
        y[..., m.i_vel] = u
        p = self.p0 + x[..., 2 * N:2 * N + nt]
        if L.rotor_angles:
            y[..., m.i_kappa] = self.y0[m.i_kappa] + x[..., 2 * N + nt:]
        if m.stateful:
            y[..., m.i_spin] = p
        return y, p

    def __call__(self, x, v):
        """(x', z) at the tangent state x and the change of commands v: one point, or a stack
        of complex-step directions (x of shape (k, size), v of shape (k, inputs)) at once."""
        m, L, d = self.model, self.layout, self.data
        N, nt = L.N, L.nt
        y, p = self.state(x)
        hinge_tau, L_rotor = self._inputs(v)
        ev = dyn.Evaluation() if self._imus is not None else None  # the accelerations an IMU reads
        moved = np.any(np.imag(x[..., :N]))
        if np.iscomplexobj(x) and not moved:  # rates, spins, inputs: the point's positions serve
            d = self._at_point
        rhs, parts = dyn.closure(m, d, self.t, y, hinge_tau, p if nt else None, L_rotor,
                                 positions_done=d is self._at_point)
        if np.iscomplexobj(rhs):
            # a complex step (imaginary parts infinitesimal): with M = M0 + i M1, rhs = r0 + i r1,
            # u' = u0' + i M0^-1 (r1 - M1 u0') to first order; M1 = 0 unless positions moved, and
            # M1 u0' = Im(M u0') is the inertial forces of u0' at the moved positions (O(n))
            r = rhs.imag
            if moved:
                r = r - dyn.mass_times(m, d, parts[0], parts[1], self._udot0).imag
            udot = self._udot0 + 1j * _lu_solve(self._lu0, r.T).T
        elif x.ndim == 1 and not np.any(x) and not np.any(v):
            udot = self._udot0  # the point: its solve is done
        else:
            udot = np.linalg.solve(dyn.mass_matrix(m, d, parts[0], parts[1]), rhs)
        if ev is not None:
            dyn.fill_evaluation(m, d, udot, parts, ev)
        u = y[..., m.i_vel]
        dt = udot.dtype
        lead = udot.shape[:-1]
        xd = np.zeros(lead + (L.size,), dtype=dt)
        body, frame = self.chart == "body", self.chart == "frame"
        W = self.frame_rate
        if m.free:
            xd[..., m.col_base] = u[..., m.col_base]
            if frame:  # the point seen from the frame turning about the world origin
                xd[..., m.col_base] -= cross(W, y[..., m.i_r0])
        if len(m.sph_bodies):
            c, w = m.col_sph, d.w[..., m.sph_bodies, :]
            if frame:
                xd[..., c] = _jl_inv(x[..., c], w - W)
                xd[..., N + c] = udot[..., c] - cross(W, u[..., c])  # world vectors in the frame's axes
            elif body:
                Rk = d.R[..., m.sph_bodies, :, :]
                Omega = np.einsum("...nji,...nj->...ni", Rk, w)
                xd[..., c] = _jr_inv(x[..., c], Omega - _rotate(-x[..., c], self._Omega0))
                # nu = R^T u: nu' = R^T (u' - w x u)
                xd[..., N + c] = np.einsum("...nji,...nj->...ni", Rk, udot[..., c] - cross(w, u[..., c]))
            else:
                xd[..., c] = _jl_inv(x[..., c], w)
                xd[..., N + c] = udot[..., c]
        xd[..., m.col_hinge] = u[..., m.col_hinge]
        xd[..., N + m.col_hinge] = udot[..., m.col_hinge]
        if m.free:
            xd[..., N + m.col_base] = udot[..., m.col_base] - (cross(W, u[..., m.col_base]) if frame else 0.0)
        kdot = dyn.torque_rotor_rates(m, d, p) if nt else np.zeros(lead + (0,))
        if nt:
            if m.stateful:
                a = d.applied
                xd[..., 2 * N:2 * N + nt] = (a.rotor_motor + a.rotor_friction) / m.torque_A
            elif L_rotor is not None:
                xd[..., 2 * N:2 * N + nt] = L_rotor / m.torque_A  # (29): A_i p_i' = L_i
            if L.rotor_angles:
                xd[..., 2 * N + nt:] = kdot  # (18)-(19)
        z = [y[..., m.i_phi], u[..., m.col_hinge]]
        if L.rotor_angles:
            z.append(y[..., m.i_kappa])
        z.append(kdot)
        if self._imus is not None:  # noise-free readings (gyro_sim.dynamics.imu)
            gyro, accel, _ = self._imus.true_values(d.R, d.w, d.vO, ev.acc_w, ev.acc_v + cross(ev.acc_w, d.O))
            z += [gyro.reshape(lead + (-1,)), accel.reshape(lead + (-1,))]
        z = np.concatenate([np.broadcast_to(np.asarray(a, dtype=dt), lead + a.shape[-1:]) for a in z], axis=-1)
        return xd, z

    def fd_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """The central differences' steps of x and of the inputs: FD_STEP max(1, |value|), with the
        value of the coordinate at the point (0 for a rotation vector: its step is FD_STEP)."""
        m, L = self.model, self.layout
        N, nt = L.N, L.nt
        scale = np.ones(L.size)
        if m.free:
            scale[m.col_base] = np.maximum(1.0, np.abs(self.y0[m.i_r0]))
        scale[m.col_hinge] = np.maximum(1.0, np.abs(self.y0[m.i_phi]))
        u0 = self.y0[m.i_vel].copy()
        if self.chart == "body" and len(m.sph_bodies):
            u0[m.col_sph] = self._nu0
        scale[N:2 * N] = np.maximum(1.0, np.abs(u0))
        scale[2 * N:2 * N + nt] = np.maximum(1.0, np.abs(self.p0))
        if L.rotor_angles:
            scale[2 * N + nt:] = np.maximum(1.0, np.abs(self.y0[m.i_kappa]))
        return FD_STEP * scale, FD_STEP * np.maximum(1.0, np.abs(self.m0))

    def _servo_notes(self) -> list[str]:
        """The servos whose control or force is clipped at the point (a flat side, or a kink)."""
        m, out = self.model, []
        if m.servo is None:
            return out
        controls = self.m0[self.na:]
        hinge_tau, _ = self._inputs(np.zeros(len(self.m0)))
        gear, b1, b2 = m.servo[:, 0], m.servo[:, 1], m.servo[:, 2]
        y = self.y0
        force = (hinge_tau[m.servo_hinge] + b1 * (gear * y[m.i_phi][m.servo_hinge])
                 + b2 * (gear * y[m.i_vel][m.col_hinge[m.servo_hinge]]))  # before its clip
        for name, c, (_, _, c_low, c_high), f, (_, _, _, f_low, f_high) in zip(
                m.servo_names, controls, m.servo_input, force, m.servo):
            if not c_low < c < c_high and np.isfinite(c_low):
                out.append(f"{name}: control {c:g} at or beyond its ctrl_range [{c_low:g}, {c_high:g}]: clipped, "
                           "its column of B is that of the side inside" if c in (c_low, c_high) else
                           f"{name}: control {c:g} beyond its ctrl_range [{c_low:g}, {c_high:g}]: clipped, "
                           "its column of B is zero")
            if not f_low < f < f_high:
                out.append(f"{name}: force {f:g} at or beyond its force_range [{f_low:g}, {f_high:g}]: "
                           "clipped, the servo's terms of A and B are those of the side the clip takes")
        return out

    def notes(self) -> tuple[str, ...]:
        """Where the model is one-sided or time-varying at the point."""
        m, out = self.model, []
        if m.moving:
            out.append(f"the base moves: the model is the one at t = {self.t:g} s (time-varying)")
        for i, name in enumerate(m.axis_names):
            c, mx = abs(self.m0[i]), self._max[i]
            if c > mx:
                out.append(f"{name}: command {self.m0[i]:g} beyond max_torque {mx:g}: "
                           "saturated, its column of B is zero")
            elif c == mx:
                out.append(f"{name}: command at max_torque {mx:g}: not differentiable; the unsaturated side is used")
        out += self._servo_notes()
        act = m.actuators
        if act is None or not m.stateful:
            return tuple(out)
        d = self.data_point
        nt = len(m.torque_body)
        speeds = []
        if nt:
            speeds += [(m.torque_names[i], act.rotor, i, w)
                       for i, w in enumerate(dyn.torque_rotor_rates(m, d, self.p0))]
        u0 = self.y0[m.i_vel]
        speeds += [(m.names[k], act.hinge, j, u0[m.col_hinge[j]]) for j, k in enumerate(m.hinge_bodies)]
        _, L_rotor = self._inputs(np.zeros(len(self.m0)))
        for name, lim, i, w in speeds:
            aw = abs(w)
            if (lim.coulomb[i] or lim.viscous[i] or lim.stribeck_speed[i]) and aw == lim.stick_speed[i]:
                out.append(f"{name}: speed {w:g} at the edge of the friction's stick band: not differentiable; "
                               "the side outside the band is used")
            top = lim.max_speed[i]
            if np.isfinite(top) and lim is act.rotor:
                low = top * (1.0 - _max_speed_band())
                if aw >= low:
                    torque = 0.0 if L_rotor is None else L_rotor[i]
                    where = "at an edge of" if aw in (low, top) or torque * w == 0.0 else "inside"
                    out.append(f"{name}: speed {w:g} {where} the speed limit's ramp ({low:g}..{top:g} rad/s)"
                               + (": not differentiable; the side the code takes is used" if where != "inside" else ""))
        return tuple(out)


def _max_speed_band() -> float:
    from gyro_sim.dynamics.actuators import MAX_SPEED_BAND

    return MAX_SPEED_BAND


# --- derivatives -------------------------------------------------------------------------
def _complex_step(field: TangentField, nx: int, nu: int):
    """Every direction (the states', then the inputs') in stacks of at most BATCH_ELEMENTS / n
    directions, each stack one pass of the reference: the columns of [A B] and [C D]. The
    positions' directions and the others go in separate stacks: the others share the point's
    positions, computed once."""
    h = COMPLEX_STEP
    f0, z0 = field(np.zeros(nx), np.zeros(nu))
    total, npos = nx + nu, field.layout.N
    AB, CD = np.empty((nx, total)), np.empty((len(z0), total))
    per = max(1, BATCH_ELEMENTS // max(1, field.model.n))
    stacks = [np.arange(s, min(end, s + per)) for begin, end in ((0, npos), (npos, total))
              for s in range(begin, end, per)]
    for cols in stacks:
        dirs = np.zeros((len(cols), total), dtype=complex)
        dirs[np.arange(len(cols)), cols] = 1j * h
        xd, z = field(dirs[:, :nx], dirs[:, nx:])
        AB[:, cols], CD[:, cols] = xd.imag.T / h, z.imag.T / h
    return np.real(f0), np.real(z0), AB[:, :nx], AB[:, nx:], CD[:, :nx], CD[:, nx:]


def _central(field: TangentField, nx: int, nu: int):
    x0, v0 = np.zeros(nx), np.zeros(nu)
    f0, z0 = field(x0, v0)
    hx, hu = field.fd_steps()
    A, C = np.empty((nx, nx)), np.empty((len(z0), nx))
    for j in range(nx):
        e = np.zeros(nx)
        e[j] = hx[j]
        (fp, zp), (fm, zm) = field(e, v0), field(-e, v0)
        A[:, j], C[:, j] = (fp - fm) / (2 * hx[j]), (zp - zm) / (2 * hx[j])
    B, D = np.empty((nx, nu)), np.empty((len(z0), nu))
    for j in range(nu):
        e = np.zeros(nu)
        e[j] = hu[j]
        (fp, zp), (fm, zm) = field(x0, e), field(x0, -e)
        B[:, j], D[:, j] = (fp - fm) / (2 * hu[j]), (zp - zm) / (2 * hu[j])
    return f0, z0, A, B, C, D


# --- the result --------------------------------------------------------------------------
@dataclass(frozen=True)
class Discrete:
    """One step h of a method on the affine model: dx1 = Ad dx0 + Bd du + fd."""

    Ad: np.ndarray
    Bd: np.ndarray
    fd: np.ndarray
    h: float
    method: str


@dataclass(frozen=True)
class Linearization:
    """The affine model dx' = A dx + B du + f0, z = C dx + D du + z0 at a point (module docstring).

    Eigenvalue verdicts (`verdict`) are given only where `is_equilibrium`."""

    A: np.ndarray
    B: np.ndarray
    f0: np.ndarray
    C: np.ndarray
    D: np.ndarray
    z0: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    chart: str
    method: str
    t: float
    notes: tuple[str, ...] = ()
    seconds: float = 0.0
    evaluations: int = 0
    fd_steps: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    #: the rows of the cyclic rotor angles (with rotor_angles=True), left out of the equilibrium test
    cyclic: tuple[int, ...] = ()

    @property
    def equilibrium_residual(self) -> float:
        """max |f0| over the state without the cyclic rotor angles."""
        f = np.delete(self.f0, list(self.cyclic))
        return float(np.max(np.abs(f))) if len(f) else 0.0

    @property
    def is_equilibrium(self) -> bool:
        return self.equilibrium_residual <= EQUILIBRIUM_TOL

    def eigenvalues(self) -> np.ndarray:
        """The eigenvalues of A, largest real part first (then by imaginary part)."""
        ev = np.linalg.eigvals(self.A)
        return ev[np.lexsort((-ev.imag, -ev.real))]

    @property
    def tolerance(self) -> float:
        """Real parts within +-tolerance count as zero: sqrt(eps) max(1, |A|_2) (a double zero
        eigenvalue in a Jordan block comes out as +-sqrt(eps |A|))."""
        return float(np.sqrt(np.finfo(float).eps) * max(1.0, np.linalg.norm(self.A, 2)))

    def verdict(self) -> str:
        """"stable" (every real part below -tolerance), "marginal" (the largest within
        +-tolerance), "unstable", or "not an equilibrium" (no verdict: f0 != 0)."""
        if not self.is_equilibrium:
            return "not an equilibrium"
        if self.A.size == 0:
            return "marginal"
        top = float(np.max(self.eigenvalues().real))
        tol = self.tolerance
        return "stable" if top < -tol else ("unstable" if top > tol else "marginal")

    def controllability_rank(self) -> int:
        """The dimension of the reachable subspace span{B, AB, A^2 B, ...} (orthogonal Krylov
        iteration, directions below 1e-9 of the largest singular value dropped)."""
        return controllable_dimension(self.A, self.B)

    def discrete(self, h: float, method: str = "zoh") -> Discrete:
        """One step h of `method` on the affine model, the input held over the step: "zoh" (the
        exact transition, a matrix exponential) or a fixed-step method ("rk4", "gauss4",
        "gauss4s": its Runge-Kutta map, which at an equilibrium is the derivative of that
        method's step of the nonlinear system, as MuJoCo's mjd_transitionFD defines it)."""
        if not (h > 0 and np.isfinite(h)):
            raise LinearizationError(f"discrete: the step must be a positive finite number, got {h!r}")
        n, nu = self.B.shape
        if method == "zoh":
            from scipy.linalg import expm

            M = np.zeros((n + nu + 1, n + nu + 1))
            M[:n, :n], M[:n, n:n + nu], M[:n, -1] = self.A, self.B, self.f0
            E = expm(M * h)
            return Discrete(E[:n, :n], E[:n, n:n + nu], E[:n, -1], float(h), method)
        if method not in _TABLEAUX:
            raise LinearizationError(f"discrete: method {method!r} is not one of {', '.join(DISCRETE_METHODS)} "
                                     "(adaptive methods have no fixed step)")
        a, b = _TABLEAUX[method]
        s = len(b)
        K = np.eye(s * n) - h * np.kron(a, self.A)
        rhs = np.hstack([np.kron(np.ones((s, 1)), M) for M in (self.A, self.B, self.f0[:, None])])
        stages = np.linalg.solve(K, rhs)
        step = h * np.kron(b[None, :], np.eye(n)) @ stages
        return Discrete(np.eye(n) + step[:, :n], step[:, n:n + nu], step[:, -1], float(h), method)


def controllable_dimension(A: np.ndarray, B: np.ndarray, rtol: float = 1e-9) -> int:
    """dim span{B, AB, ...}: an orthonormal basis grown one Krylov block at a time."""
    n = A.shape[0]
    if n == 0 or B.size == 0:
        return 0
    scale = max(np.linalg.norm(A, 2), np.linalg.norm(B, 2), 1e-300)
    Q = np.zeros((n, 0))
    V = B / scale
    while Q.shape[1] < n:
        for _ in range(2):  # twice is enough (Kahan)
            V = V - Q @ (Q.T @ V)
        U, s, _ = np.linalg.svd(V, full_matrices=False)
        r = int(np.sum(s > rtol))
        if r == 0:
            break
        Qn = U[:, :r]
        Q = np.hstack([Q, Qn])
        V = (A / scale) @ Qn
    return Q.shape[1]


METHODS = ("complex", "fd")


def linearize(model: Model, t: float, y: np.ndarray, spins: np.ndarray | None, moments: np.ndarray, *,
              method: str = "complex", rotor_angles: bool = False, chart: str = "world",
              frame_rate=None, controls: np.ndarray | None = None) -> Linearization:
    """The linear model of `model` at time t, state y (the model's layout), torque-rotor spins
    (nt,), commanded axis moments (na,) and servo controls (nsv,; None: zero). method:
    "complex" (exact, the complex step) or "fd" (central differences, the steps in `fd_steps`)."""
    if method not in METHODS:
        raise LinearizationError(f"method: {method!r} is not one of {', '.join(METHODS)}")
    nt = len(model.torque_body)
    for name, value, shape in (("y", y, (model.size,)), ("spins", np.zeros(nt) if spins is None else spins, (nt,)),
                               ("moments", moments, (len(model.axis_names),)),
                               ("controls", np.zeros(len(model.servo_names)) if controls is None else controls,
                                (len(model.servo_names),))):
        a = np.asarray(value)
        if a.shape != shape or not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)):
            raise LinearizationError(f"{name}: expected {shape[0]} finite numbers (the model's layout), "
                                     f"got shape {a.shape}")
    start = _time.perf_counter()
    size = _layout(model, rotor_angles, chart).size
    if size > MAX_STATES:
        raise LinearizationError(f"{size} states: more than the {MAX_STATES} a dense linear model takes "
                                 "(gyro_sim.linear.linearize.MAX_STATES)")
    fld = TangentField(model, t, y, spins, moments, rotor_angles, chart, frame_rate, controls)
    nx, nu = fld.layout.size, len(model.axis_names) + len(model.servo_names)
    f0, z0, A, B, C, D = (_complex_step if method == "complex" else _central)(fld, nx, nu)
    evaluations = 1 + (nx + nu) * (1 if method == "complex" else 2)
    return Linearization(A=A, B=B, f0=f0, C=C, D=D, z0=z0, state_names=fld.layout.state_names,
                         input_names=tuple(model.axis_names) + tuple(model.servo_names),
                         output_names=fld.layout.output_names,
                         chart=chart, method=method, t=float(t), notes=fld.notes(),
                         seconds=_time.perf_counter() - start, evaluations=evaluations,
                         fd_steps=fld.fd_steps() if method == "fd" else None,
                         cyclic=tuple(range(2 * fld.layout.N + fld.layout.nt, nx)) if rotor_angles else ())
