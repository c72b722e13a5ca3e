"""The model: a scene compiled into the arrays the dynamics reads (docs/theory.md sections 1-2).

Like Pinocchio's Model, it is an immutable description; the per-evaluation workspace lives
in :class:`gyro_sim.dynamics.reference.Data`. It holds only the terms the scene has: `gravity` is
None without gravity, the rotor arrays are empty without rotors, `hinge_bodies` is empty in
an all-spherical chain, and the dynamics skips every term that is absent.

Generalized velocities (the unknowns of eqs (52)-(54), in a relative basis):
    free base: v0, the velocity of O^1 (3, world frame)
    spherical joint k: w^k - w^{k-1}, the angular velocity of body k relative to its parent
        (3, world-frame components; the paper's absolute w^k is their prefix sum)
    hinge k: phi_k' (eq 50)
    slide k: d_k', the rate of body k's translation d_k along its axis e^k (docs/theory.md
        section 12): body k keeps its parent's orientation and O^k moves by R^{k-1} e^k d_k
State vector y = [r0 (free base, 3) | quaternions of spherical bodies (4 each, w x y z, world
from body) | hinge angles phi_k and slide positions d_k | generalized velocities | torque-rotor
angles kappa_i].

A slide is a joint of one coordinate as a hinge is: the arrays named after hinges
(`hinge_bodies`, `col_hinge`, `i_phi`, `armature`, `spring`, servos, limits, the commanded
moments of the actuated axes) hold every joint of one coordinate, hinges and slides in chain
order, and `hinge_slide` tells the slides among them (a slide's "moment" is a force along its
axis, N; its armature a mass, kg; its spring's stiffness N/m). Only the kinematics differ
(`is_slide`); a scene without slides has `slide_bodies` empty and computes nothing for them.
The rotor angles are quadratures for output only: nothing feeds back from them.
A scene with state-dependent actuator terms (friction, max_speed: gyro_sim.dynamics.actuators;
servos) appends [absolute spins p_i of the torque rotors | work of the motors and servos | work
of friction]:
its applied torques depend on the state, so the spins are integrated with it (eq 29,
A_i p_i' = L_i) and so are the works (quadratures of the applied torques' power).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gyro_sim.dynamics.rotations import (
    axis_angle_matrix, down_frame, euler_rates_to_omega, euler_to_matrix, matrix_to_quat,
    quat_to_matrix,
)
from gyro_sim.dynamics.actuators import Actuators, AxisLimits
from gyro_sim.scene.records import ONE_AXIS_JOINTS, Scene


@dataclass(frozen=True)
class Model:
    """Immutable arrays of a compiled scene; n bodies, ns spherical, nh hinges, N velocities."""

    scene: Scene
    names: tuple[str, ...]
    n: int
    is_hinge: np.ndarray  # (n,) bool: a joint of one coordinate (hinge or slide)
    is_slide: np.ndarray  # (n,) bool: a slide
    sph_bodies: np.ndarray  # (ns,) int, chain order
    hinge_bodies: np.ndarray  # (nh,) int, chain order: the joints of one coordinate
    hinge_slide: np.ndarray  # (nh,) bool: which of hinge_bodies are slides
    slide_bodies: np.ndarray  # (nsl,) int, chain order
    hinge_axis: np.ndarray  # (n, 3) axis e^k of a hinge or slide (parent frame = own frame); zero on spherical bodies
    # gyrostat k composed with its rotors, body frame (eqs 22, 30)
    mass: np.ndarray  # (n,) m^k
    first_moment: np.ndarray  # (n, 3) m^k c^k
    inertia: np.ndarray  # (n, 3, 3) A^k at O^k (eq 30)
    s: np.ndarray  # (n, 3) s^k, zero on the last body
    # the tree (docs/theory.md section 11): parent[k] < k, -1 for a body on the base; on a chain
    # parent[k] = k - 1 and `chain` is True (every chain code path is then the one it was)
    parent: np.ndarray  # (n,) int
    chain: bool
    #: (n, 3) the joint point O^k from O^{parent(k)} in the parent's frame, s^{parent(k),k}
    #: (a body on the base: from the base's position, world frame); a chain's s^{k-1}
    offset: np.ndarray
    #: (n, n) bool: ancestor[k, l] when body l is on the path from the base to k (l == k included)
    ancestor: np.ndarray
    # rotors (eq 31): torque rotors carry lambda = A_i p_i e_i, speed rotors A_i kappa_i' e_i
    torque_body: np.ndarray  # (nt,) int
    torque_axis: np.ndarray  # (nt, 3)
    torque_A: np.ndarray  # (nt,)
    torque_p0: np.ndarray  # (nt,) initial absolute spins p_i
    torque_names: tuple[str, ...]
    speed_body: np.ndarray  # (nv,) int
    speed_axis: np.ndarray  # (nv, 3)
    speed_A: np.ndarray  # (nv,)
    speed_rate: np.ndarray  # (nv,) kappa_i'
    speed_names: tuple[str, ...]
    lam_speed: np.ndarray | None  # (n, 3) constant speed-rotor part of lambda^k, None without
    # actuated axes, in command order: each body's hinge, then its actuated torque rotors
    axis_names: tuple[str, ...]
    axis_hinge: np.ndarray  # (na,) index into hinge_bodies or -1
    axis_rotor: np.ndarray  # (na,) index into torque rotors or -1
    # base and gravity
    base_type: str
    base_position: np.ndarray
    base_amplitude: np.ndarray | None
    base_omega: float  # 2 pi f of a moving base
    gravity: np.ndarray | None  # (3,) world
    down: np.ndarray  # world_R_down of the Euler angles
    # velocity columns: col_body[j] = body whose joint column j belongs to (free base: 0)
    N: int
    col_body: np.ndarray  # (N,)
    col_upper: np.ndarray  # (N, N) bool: body col_body[i] is an ancestor of (or is) col_body[j]
    #: (N, N) bool: the columns' bodies are on one path from the base (one an ancestor of the
    #: other): M_ij vanishes elsewhere (branch-induced sparsity); all True on a chain
    col_related: np.ndarray
    col_sph: np.ndarray  # (ns, 3) column indices of spherical joints
    col_hinge: np.ndarray  # (nh,) column indices of hinges
    col_base: np.ndarray  # (3,) or (0,)
    # state layout
    size: int
    i_r0: slice
    i_quat: np.ndarray  # (ns, 4) indices of the quaternions in y
    i_phi: slice
    i_vel: slice  # the N generalized velocities
    i_kappa: slice  # torque-rotor angles
    # actuator limits and friction (None without any); the states of speed-dependent terms
    actuators: Actuators | None = None
    i_spin: slice = field(default_factory=lambda: slice(0, 0))  # absolute spins p_i of the torque rotors
    i_work: slice = field(default_factory=lambda: slice(0, 0))  # work of the motors, of friction (J)
    # the hinges' joint terms (docs/theory.md, "Armature and joint springs"), None without any:
    armature: np.ndarray | None = None  # (nh,) reflected rotor inertias on M's hinge diagonal
    spring: np.ndarray | None = None  # (nh, 2) stiffness, reference angle: moment -k (phi - ref)
    # the hinges' geared motors on a turning parent (docs/theory.md, "The geared motor"), None
    # without any; a zero row: none (a motor on the first body is folded into its armature):
    motor: np.ndarray | None = None  # (nh, 5) J, gear G, axis a in the parent's frame (3)
    # the hinges' servos (docs/models.md, "Servo actuators"), in chain order; None without any:
    servo_hinge: np.ndarray | None = None  # (nsv,) index into hinge_bodies
    servo: np.ndarray | None = None  # (nsv, 5) gear, b1, b2, force low, high (+-inf: none)
    servo_input: np.ndarray | None = None  # (nsv, 4) gain, b0, ctrl low, high (+-inf: none)
    servo_names: tuple[str, ...] = ()

    @property
    def stateful(self) -> bool:
        """Whether the applied torques depend on the state (friction, max_speed, servos): the
        spins and works are states (`i_spin`, `i_work`; a servo's work is the motors')."""
        return self.actuators is not None and self.actuators.speed_dependent

    @property
    def servo_joints(self) -> tuple:
        """Each servo's joint (its body's name) and its scene record (`Servo`: command kind,
        control, ...), in servo order (`servo_names`)."""
        if self.servo is None:
            return ()
        return tuple((self.names[self.hinge_bodies[h]], self.scene.bodies[self.hinge_bodies[h]].joint.servo)
                     for h in self.servo_hinge)

    @property
    def initial_controls(self) -> np.ndarray:
        """The servos' controls from the start, in servo order (`servo_names`): each servo's
        `control` (an imported model's keyframe `ctrl`; default 0)."""
        return np.array([servo.control for _, servo in self.servo_joints], dtype=float)

    @property
    def free(self) -> bool:
        return self.base_type == "free"

    @property
    def moving(self) -> bool:
        return self.base_type == "moving"


def _skew_sq(a: np.ndarray) -> np.ndarray:
    """|a|^2 I - a a^T: the inertia of a unit point mass at a (the term h x (w x h), eq 30)."""
    return (a @ a) * np.eye(3) - np.outer(a, a)


def compile_model(scene: Scene) -> Model:
    """Compose each gyrostat (eqs 22, 30, 31) and lay out columns and state for `scene`."""
    bodies = scene.bodies
    n = len(bodies)
    is_hinge = np.array([b.joint.type in ONE_AXIS_JOINTS for b in bodies], dtype=bool)
    is_slide = np.array([b.joint.type == "slide" for b in bodies], dtype=bool)
    hinge_axis = np.zeros((n, 3))
    mass = np.zeros(n)
    first = np.zeros((n, 3))
    inertia = np.zeros((n, 3, 3))
    s = np.zeros((n, 3))
    lam_speed = np.zeros((n, 3))
    tb, ta, tA, tp, tn, vb, va, vA, vr, vn = ([] for _ in range(10))
    axis_names, axis_hinge, axis_rotor = [], [], []
    hinge_index = np.cumsum(is_hinge) - 1
    motor = np.zeros((int(np.sum(is_hinge)), 5))
    parent, offset, ancestor = tree_of(bodies)
    for k, b in enumerate(bodies):
        if is_hinge[k]:
            hinge_axis[k] = b.joint.axis
        if is_hinge[k] and b.joint.motor is not None and parent[k] >= 0:
            # a motor's rotor on the parent: its axial inertia turns with the parent (eq 30,
            # as a prescribed rotor's A_i), its relative spin G phi_k' is lambda^{parent} (eq 31)
            mo = b.joint.motor
            inertia[parent[k]] += mo.inertia * np.outer(mo.axis, mo.axis)
            motor[hinge_index[k]] = (mo.inertia, mo.gear, *mo.axis)
        if is_hinge[k] and b.joint.servo is None:  # a servo's hinge is commanded by its control
            axis_names.append(b.name)
            axis_hinge.append(int(hinge_index[k]))
            axis_rotor.append(-1)
        mass[k] = b.mass
        first[k] = b.mass * b.com
        inertia[k] = b.inertia
        if b.next_joint is not None:
            s[k] = b.next_joint
        for r in b.rotors:
            e, h = r.axis, r.position
            mass[k] += r.mass
            first[k] += r.mass * h
            # (30): e x (w x e) B_i + h x (w x h) m_i, for every rotor
            inertia[k] += r.transverse_inertia * (np.eye(3) - np.outer(e, e)) + r.mass * _skew_sq(h)
            if r.mode == "speed":
                # (30): + A_i (w . e_i) e_i;  (31): lambda += A_i kappa_i' e_i
                inertia[k] += r.axial_inertia * np.outer(e, e)
                lam_speed[k] += r.axial_inertia * r.spin * e
                vb.append(k), va.append(e), vA.append(r.axial_inertia), vr.append(r.spin), vn.append(r.name)
            else:
                if r.actuated:
                    axis_names.append(r.name)
                    axis_hinge.append(-1)
                    axis_rotor.append(len(tb))
                tb.append(k), ta.append(e), tA.append(r.axial_inertia), tp.append(r.spin), tn.append(r.name)

    sph = np.flatnonzero(~is_hinge)
    hin = np.flatnonzero(is_hinge)
    free = scene.base.type == "free"
    # velocity columns
    col_body = []
    if free:
        col_body += [0, 0, 0]
    col_sph, col_hinge = [], []
    for k in range(n):
        if is_hinge[k]:
            col_hinge.append(len(col_body))
            col_body.append(k)
        else:
            col_sph.append([len(col_body) + i for i in range(3)])
            col_body += [k, k, k]
    col_body = np.array(col_body, dtype=int)
    N = len(col_body)
    ns, nh, nt = len(sph), len(hin), len(tb)
    # state layout
    off = 0
    i_r0 = slice(off, off + 3 * free)
    off += 3 * free
    i_quat = off + np.arange(4 * ns).reshape(ns, 4)
    off += 4 * ns
    i_phi = slice(off, off + nh)
    off += nh
    i_vel = slice(off, off + N)
    off += N
    i_kappa = slice(off, off + nt)
    off += nt
    actuators = _actuators(scene)
    i_spin = i_work = slice(off, off)
    if actuators is not None and actuators.speed_dependent:
        i_spin = slice(off, off + nt)
        off += nt
        i_work = slice(off, off + WORK_STATES)
        off += WORK_STATES

    def arr(x, shape):
        return np.array(x, dtype=float).reshape(shape)

    hinges = [bodies[k].joint for k in hin]
    # a motor on the first body turns against the base, which never rotates: exactly an
    # armature J G^2 (docs/theory.md, "The geared motor")
    armature = np.array([j.armature + (j.motor.inertia * j.motor.gear ** 2
                                       if j.motor is not None and parent[k] < 0 else 0.0)
                         for k, j in zip(hin, hinges)], dtype=float)
    spring = np.array([(j.spring.stiffness, j.spring.reference) if j.spring is not None else (0.0, 0.0)
                       for j in hinges], dtype=float).reshape(nh, 2)
    servo_hinge = [h for h, j in enumerate(hinges) if j.servo is not None]
    servos = [hinges[h].servo for h in servo_hinge]
    inf = (-np.inf, np.inf)
    servo = np.array([(v.gear, v.bias[1], v.bias[2], *(v.force_range or inf)) for v in servos],
                     dtype=float).reshape(-1, 5)
    servo_input = np.array([(v.gain, v.bias[0], *(v.ctrl_range or inf)) for v in servos],
                           dtype=float).reshape(-1, 4)
    g = None if scene.gravity is None else np.array(scene.gravity, dtype=float)
    nu = None if g is None or not np.any(g) else g / np.linalg.norm(g)
    base = scene.base
    return Model(
        scene=scene,
        names=tuple(b.name for b in bodies),
        n=n,
        is_hinge=is_hinge,
        is_slide=is_slide,
        sph_bodies=sph,
        hinge_bodies=hin,
        hinge_slide=is_slide[hin],
        slide_bodies=np.flatnonzero(is_slide),
        hinge_axis=hinge_axis,
        mass=mass,
        first_moment=first,
        inertia=inertia,
        s=s,
        parent=parent,
        chain=bool(np.array_equal(parent, np.arange(n) - 1) and not np.any(offset[0])
                   and np.array_equal(offset[1:], s[:-1])),
        offset=offset,
        ancestor=ancestor,
        torque_body=np.array(tb, dtype=int),
        torque_axis=arr(ta, (nt, 3)),
        torque_A=arr(tA, (nt,)),
        torque_p0=arr(tp, (nt,)),
        torque_names=tuple(tn),
        speed_body=np.array(vb, dtype=int),
        speed_axis=arr(va, (len(vb), 3)),
        speed_A=arr(vA, (len(vb),)),
        speed_rate=arr(vr, (len(vb),)),
        speed_names=tuple(vn),
        lam_speed=lam_speed if vb else None,
        axis_names=tuple(axis_names),
        axis_hinge=np.array(axis_hinge, dtype=int),
        axis_rotor=np.array(axis_rotor, dtype=int),
        base_type=base.type,
        base_position=np.array(base.position, dtype=float),
        base_amplitude=None if base.amplitude is None else np.array(base.amplitude, dtype=float),
        base_omega=0.0 if base.frequency is None else 2.0 * np.pi * float(base.frequency),
        gravity=g,
        down=down_frame(nu),
        N=N,
        col_body=col_body,
        col_upper=ancestor[col_body[None, :], col_body[:, None]],
        col_related=ancestor[col_body[None, :], col_body[:, None]] | ancestor[col_body[:, None], col_body[None, :]],
        col_sph=np.array(col_sph, dtype=int).reshape(ns, 3),
        col_hinge=np.array(col_hinge, dtype=int),
        col_base=np.arange(3) if free else np.arange(0),
        size=off,
        i_r0=i_r0,
        i_quat=i_quat,
        i_phi=i_phi,
        i_vel=i_vel,
        i_kappa=i_kappa,
        actuators=actuators,
        i_spin=i_spin,
        i_work=i_work,
        armature=armature if np.any(armature) else None,
        spring=spring if np.any(spring[:, 0]) else None,
        motor=motor if np.any(motor[:, 0]) else None,
        servo_hinge=np.array(servo_hinge, dtype=int) if servos else None,
        servo=servo if servos else None,
        servo_input=servo_input if servos else None,
        servo_names=tuple(v.name for v in servos),
    )


def tree_of(bodies) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tree of `bodies` (docs/theory.md section 11): each body's parent index (-1: the base;
    a Body's None: the body before it), its joint point from its parent's O in the parent's frame
    (`joint.at`, else the parent's next_joint; zero on the base: the base's position) and the
    ancestor relation (n, n), ancestor[k, l] when l is on the path from the base to k."""
    n = len(bodies)
    parent = np.array([k - 1 if b.parent is None else b.parent for k, b in enumerate(bodies)], dtype=int)
    offset = np.zeros((n, 3))
    ancestor = np.zeros((n, n), dtype=bool)
    for k, b in enumerate(bodies):
        q = parent[k]
        if b.joint.at is not None:
            offset[k] = b.joint.at
        elif q >= 0 and bodies[q].next_joint is not None:
            offset[k] = bodies[q].next_joint
        if q >= 0:
            ancestor[k] = ancestor[q]
        ancestor[k, k] = True
    return parent, offset, ancestor


#: the work states of a stateful model: the motors', friction's
WORK_STATES = 2


def _actuators(scene: Scene) -> Actuators | None:
    """The limits of the torque rotors and hinges (model order), None when no axis has any."""
    rotor, hinge, terms = [], [], []
    for b in scene.bodies:
        if b.joint.type in ONE_AXIS_JOINTS:
            hinge.append(b.joint.limits)
            if b.joint.limits is not None and b.joint.limits.friction is not None:
                terms.append(f"{b.name}.friction")
        for r in b.rotors:
            if r.mode != "speed":
                rotor.append(r.limits)
                for key in ("friction", "max_speed"):
                    if r.limits is not None and getattr(r.limits, key) is not None:
                        terms.append(f"{r.name}.{key}")
    servos = any(b.joint.servo is not None for b in scene.bodies)  # their work is a state too
    if all(lim is None for lim in rotor + hinge) and not servos:
        return None
    return Actuators(AxisLimits.of(rotor, exact=True), AxisLimits.of(hinge, exact=True), tuple(terms), servos)


def initial_state(model: Model) -> np.ndarray:
    """The state vector y (model.size,) of the scene's initial conditions."""
    y = np.zeros(model.size)
    bodies = model.scene.bodies
    Rs, ws = np.zeros((model.n, 3, 3)), np.zeros((model.n, 3))
    nu_rel = np.zeros((model.n, 3))
    q = np.zeros((len(model.sph_bodies), 4))
    phi = np.zeros(len(model.hinge_bodies))
    phid = np.zeros(len(model.hinge_bodies))
    isph = ihin = 0
    for k, b in enumerate(bodies):
        ini = b.initial
        q_k = model.parent[k]
        R_parent, w_parent = (np.eye(3), np.zeros(3)) if q_k < 0 else (Rs[q_k], ws[q_k])
        if model.is_slide[k]:  # the parent's orientation and angular velocity
            R, w = R_parent, w_parent
            phi[ihin], phid[ihin] = ini.position, ini.velocity
            ihin += 1
        elif model.is_hinge[k]:
            R = R_parent @ axis_angle_matrix(model.hinge_axis[k], ini.angle)
            w = w_parent + (R @ model.hinge_axis[k]) * ini.rate  # (50)
            phi[ihin], phid[ihin] = ini.angle, ini.rate
            ihin += 1
        else:
            if ini.quaternion is not None:
                qk = np.array(ini.quaternion, dtype=float)
                qk /= np.linalg.norm(qk)
                R = quat_to_matrix(qk)
                wb = np.zeros(3) if ini.angular_velocity is None else np.asarray(ini.angular_velocity)
                w = R @ wb
            else:
                euler = np.zeros(3) if ini.euler is None else np.asarray(ini.euler, dtype=float)
                rates = np.zeros(3) if ini.euler_rates is None else np.asarray(ini.euler_rates, dtype=float)
                R = euler_to_matrix(euler, model.down)
                qk = matrix_to_quat(R)
                w = euler_rates_to_omega(euler, rates, model.down)
            q[isph] = qk
            nu_rel[k] = w - w_parent
            isph += 1
        Rs[k], ws[k] = R, w
    if model.free:
        y[model.i_r0] = model.base_position
    y[model.i_quat.ravel()] = q.ravel()
    y[model.i_phi] = phi
    vel = np.zeros(model.N)
    if model.free:
        v0 = model.scene.base.velocity
        vel[model.col_base] = np.zeros(3) if v0 is None else v0
    vel[model.col_sph.ravel()] = nu_rel[model.sph_bodies].ravel()
    vel[model.col_hinge] = phid
    y[model.i_vel] = vel
    if model.stateful:
        y[model.i_spin] = model.torque_p0  # the works start at zero
    return y
