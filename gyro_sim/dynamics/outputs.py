"""What one publication shows, compiled with numba: joint states, poses, wrenches, invariants.

:func:`publication_kernel` computes at one (t, y), in one compiled call over the kernels of
:mod:`gyro_sim.dynamics.kernel` (its stages, and :func:`gyro_sim.dynamics.kernel.rhs_kernel` through its
compiled C function, `fast.rhs_call`), what
:class:`gyro_sim.simulator.Simulator` otherwise builds from the numpy reference
(`joint_states`, `body_states`, `wrenches`, `invariants`); :class:`gyro_sim.dynamics.system.
FastChainODE` offers everything it computes as `outputs`. Same equations, about each joint point O^k instead of
the world origin; the results agree to round-off (test/dynamics/test_outputs.py).

Pipeline (all world components, about O^k unless said):
    rhs_kernel      t, y          -> u', torque-rotor angle rates kappa'          (eqs 18-19, 48)
    stages of fast  t, y          -> R^k, s^k, w^k, v(O^k), c^k, I^k, p^k         (eqs 29-39, 50)
    accelerations   u', c         -> body accelerations (alpha, a(O^k))           (eq 34 differentiated)
    wrenches        I a + p       -> subtree sums: R^k (eq 40), L^k about O^k (eq 48), body frame
    poses           R, s          -> O^k, quaternions (w >= 0 for hinge bodies)
    joint angles    R, w          -> Euler angles and rates (rotations.matrices_to_euler)
    invariants      R, w, v       -> energy (eq 33 + potential), momenta (eq 79)

One publication (:func:`publication_kernel`, Simulator.write_outputs and snapshot) allocates
nothing: the kinematics are those fast.rhs_kernel leaves in its workspace when it runs (wrenches
and speed rotors need its accelerations; otherwise they are computed here into the same views),
the rest lives in a scratch vector the caller keeps (`scratch_size`), so the kernel is compiled
without reference counting; the numbers are computed first, then put into the messages' slots
and checked finite in plain loops.

Its cache is keyed on every file whose kernels it compiles in
(:func:`gyro_sim.jit.njit_with_dependencies`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

from pathlib import Path

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.kernel import (
    bias_forces, vec_cross, vec_cross_add, dot6, mat_vec, body_positions, body_velocities,
)
from gyro_sim.dynamics.rotations import EULER_SINGULAR_SIN
from gyro_sim.jit import block1, block2, block3

#: the files the kernels here compile in (the key of their numba cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)
#: always inlined by LLVM into its callers (numba's `forceinline`, as fast's stages): a helper
#: called per body or per value passes no array structs and makes no view. Same operations,
#: same results bit for bit.
_njit_inline = jit.njit_with_dependencies(*DEPENDENCIES, forceinline=True)
#: without numba's reference counting (as fast.rhs_kernel): for a kernel that allocates nothing
#: and returns no array, where counting every array argument and view costs ~20 %
_njit_uncounted = jit.njit_with_dependencies(*DEPENDENCIES, _nrt=False, forceinline=False)


# fast.rhs_kernel's workspace as publication_kernel reads it after the kernel ran (its first
# blocks, in its order: R 9, s_w 3, hk 3, Aw 9, e_w 3, w 3, vO 3, c 6, I6 36, pb 6, Dinv 36,
# lam_b 3, dlam_b 3 words per body; S, U, W 6, u 1 per column; p 1 per torque rotor)
assert fast.WORK_PER_BODY == 123 and fast.WORK_PER_COLUMN == 19 and fast.WORK_PER_ROTOR == 1, \
    "fast.rhs_kernel's workspace changed: update publication_kernel's views of it"

#: entries of `inv`, the invariants' output vector
INV_ENERGY, INV_KINETIC, INV_POTENTIAL, INV_JACOBI, INV_VERTICAL = 0, 1, 2, 3, 4
INV_H_O1, INV_P, INV_L_COM = slice(5, 8), slice(8, 11), slice(11, 14)
INV_SIZE = 14


@_njit
def _matrix_to_quat(R, q):
    """q (4,) of R (3, 3): Shepperd's method, unit, w >= 0 (rotations.matrix_to_quat)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    i, best = 0, tr
    for a in range(3):
        if R[a, a] > best:
            i, best = a + 1, R[a, a]
    if i == 0:
        r = 0.5 * math.sqrt(1.0 + tr)
        q[0], q[1], q[2], q[3] = r, (R[2, 1] - R[1, 2]) / (4 * r), (R[0, 2] - R[2, 0]) / (4 * r), \
            (R[1, 0] - R[0, 1]) / (4 * r)
    elif i == 1:
        r = 0.5 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q[0], q[1], q[2], q[3] = (R[2, 1] - R[1, 2]) / (4 * r), r, (R[0, 1] + R[1, 0]) / (4 * r), \
            (R[0, 2] + R[2, 0]) / (4 * r)
    elif i == 2:
        r = 0.5 * math.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q[0], q[1], q[2], q[3] = (R[0, 2] - R[2, 0]) / (4 * r), (R[0, 1] + R[1, 0]) / (4 * r), r, \
            (R[1, 2] + R[2, 1]) / (4 * r)
    else:
        r = 0.5 * math.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q[0], q[1], q[2], q[3] = (R[1, 0] - R[0, 1]) / (4 * r), (R[0, 2] + R[2, 0]) / (4 * r), \
            (R[1, 2] + R[2, 1]) / (4 * r), r
    nrm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sgn = 1.0 if q[0] >= 0.0 else -1.0
    for a in range(4):
        q[a] = sgn * q[a] / nrm


@_njit_inline
def _euler(Rs, ws, k, down, singular, angs, rates):
    """Euler angles (psi, theta, phi) and their rates of world_R_body R = Rs[k] (3, 3) turning at
    w = ws[k] (3,) (rotations.matrices_to_euler, omegas_to_euler_rates) into angs[k], rates[k],
    in scalars: cos and sin of psi from the entries atan2 takes them from, of theta from its
    cosine (the same numbers to round-off). The stacks and k, not views of them: no view is
    made per body."""
    D00 = down[0, 0] * Rs[k, 0, 0] + down[1, 0] * Rs[k, 1, 0] + down[2, 0] * Rs[k, 2, 0]
    D10 = down[0, 1] * Rs[k, 0, 0] + down[1, 1] * Rs[k, 1, 0] + down[2, 1] * Rs[k, 2, 0]
    D20 = down[0, 2] * Rs[k, 0, 0] + down[1, 2] * Rs[k, 1, 0] + down[2, 2] * Rs[k, 2, 0]
    D21 = down[0, 2] * Rs[k, 0, 1] + down[1, 2] * Rs[k, 1, 1] + down[2, 2] * Rs[k, 2, 1]
    D02 = down[0, 0] * Rs[k, 0, 2] + down[1, 0] * Rs[k, 1, 2] + down[2, 0] * Rs[k, 2, 2]
    D12 = down[0, 1] * Rs[k, 0, 2] + down[1, 1] * Rs[k, 1, 2] + down[2, 1] * Rs[k, 2, 2]
    D22 = down[0, 2] * Rs[k, 0, 2] + down[1, 2] * Rs[k, 1, 2] + down[2, 2] * Rs[k, 2, 2]
    ct = min(1.0, max(-1.0, D22))
    theta = math.acos(ct)
    h = math.hypot(D02, D12)
    if h >= singular:
        psi, phi = math.atan2(D02, -D12), math.atan2(D20, D21)
        c, s = -D12 / h, D02 / h
    else:
        psi, phi = math.atan2(D10, D00), 0.0
        h0 = math.hypot(D00, D10)
        c, s = (D00 / h0, D10 / h0) if h0 > 0.0 else (1.0, 0.0)
    angs[k, 0], angs[k, 1], angs[k, 2] = psi, theta, phi
    wd0 = ws[k, 0] * down[0, 0] + ws[k, 1] * down[1, 0] + ws[k, 2] * down[2, 0]
    wd1 = ws[k, 0] * down[0, 1] + ws[k, 1] * down[1, 1] + ws[k, 2] * down[2, 1]
    wd2 = ws[k, 0] * down[0, 2] + ws[k, 1] * down[1, 2] + ws[k, 2] * down[2, 2]
    st = math.sqrt((1.0 - ct) * (1.0 + ct))  # sin(theta) >= 0, theta in [0, pi]
    dphi = (wd0 * s - wd1 * c) / st if st > singular else 0.0
    rates[k, 0] = wd2 - dphi * ct
    rates[k, 1] = wd0 * c + wd1 * s
    rates[k, 2] = dphi


#: the held inputs written in place by a caller that holds its own (the Simulator's publications)
hold = fast.hold


class Layout(NamedTuple):
    """What a publication reads of the model beyond the kernel's records (`layout`): base_position
    (3,), down (3, 3) world_R_down of the Euler angles, singular the Euler singularity threshold
    (rotations.EULER_SINGULAR_SIN); speed rotors: body (nv,), axis (nv, 3), A (nv,), rate (nv,);
    joint_kind, joint_ref (J,) int64: what each joint-state entry is (JOINT_*)."""

    base_position: np.ndarray
    down: np.ndarray
    singular: float
    speed_body: np.ndarray
    speed_axis: np.ndarray
    speed_A: np.ndarray
    speed_rate: np.ndarray
    joint_kind: np.ndarray
    joint_ref: np.ndarray


class Outputs(NamedTuple):
    """Where a publication writes its numbers (see publication_kernel), and its scratch."""

    R: np.ndarray
    w: np.ndarray
    vO: np.ndarray
    O: np.ndarray
    quat: np.ndarray
    euler: np.ndarray
    euler_rate: np.ndarray
    L_speed: np.ndarray
    wrench_force: np.ndarray
    wrench_moment: np.ndarray
    inv: np.ndarray
    scratch: np.ndarray


#: Outputs' fields (the names of the arrays callers keep by name)
OUTPUT_NAMES = tuple(Outputs.__annotations__)


class JointStates(NamedTuple):
    """The joint states (J,) a publication writes."""

    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class Slots(NamedTuple):
    """Where a publication also writes its numbers: dst (m,) float64, and the slots of c copies
    (c = 0: none): at_joint (c, 3, J), at_position (c, n, 3), at_quat (c, n, 4), at_wrench (c, n, 6)."""

    dst: np.ndarray
    at_joint: np.ndarray
    at_position: np.ndarray
    at_quat: np.ndarray
    at_wrench: np.ndarray


def layout(model, joint_kind, joint_ref) -> Layout:
    """The Layout of `model` (gyro_sim.dynamics.model.Model) with these joint-state entries."""
    f64 = np.ascontiguousarray
    return Layout(f64(model.base_position, dtype=np.float64), f64(model.down, dtype=np.float64), EULER_SINGULAR_SIN,
                  f64(model.speed_body, dtype=np.int64), f64(np.reshape(model.speed_axis, (-1, 3)), dtype=np.float64),
                  f64(model.speed_A, dtype=np.float64), f64(model.speed_rate, dtype=np.float64),
                  f64(joint_kind, dtype=np.int64), f64(joint_ref, dtype=np.int64))


#: bits of `want` (publication_kernel): the parts computed beyond the joint states
WANT_WRENCHES, WANT_BODIES, WANT_INVARIANTS, WANT_EULER_ALL = 1, 2, 4, 8
WANT_ALL = WANT_WRENCHES | WANT_BODIES | WANT_INVARIANTS | WANT_EULER_ALL
#: joint-state entries (joint_kind): an Euler angle of a body (joint_ref = 3 k + axis), a hinge
#: (ref: its body), a torque rotor, a speed rotor (ref: the rotor's index)
JOINT_EULER, JOINT_HINGE, JOINT_TORQUE_ROTOR, JOINT_SPEED_ROTOR = 0, 1, 2, 3
#: what publication_kernel returns: 0, or the first field found non-finite (Snapshot's names)
NONFINITE_FIELDS = (None, "position", "velocity", "effort", "body_position", "body_quaternion",
                    "wrench_force", "wrench_moment")


@_njit_inline
def _scatter(dst, at, src, first):
    """src (m, q) into dst at the slots at[c, i, first + j] of every copy c (at (c, m, >= first + q))."""
    for c in range(at.shape[0]):
        for i in range(src.shape[0]):
            for j in range(src.shape[1]):
                dst[at[c, i, first + j]] = src[i, j]


@_njit_inline
def _tree_wrenches(R, I6, acc, pb, s_w, parent, motor_w, col_start, udot, force, moment):
    """A tree's joint forces R^k (eq 40) and moments L^k (eq 48T) in body k's frame into force,
    moment (n, 3): F^k = (I a + p)^k plus each child's F^j moved from O^j to O^k (s_w[j] =
    O^j - O^k), summed from the leaves in pb (the bodies' bias forces, overwritten); a child's
    geared motor adds J G phi_j'' a to its parent's moment (motor_w (n, 4), or (0, 4))."""
    for k in range(acc.shape[0] - 1, -1, -1):
        for r in range(6):
            pb[k, r] += dot6(I6[k, r], acc[k])
        kp = parent[k]
        if motor_w.shape[0] != 0 and kp >= 0 and motor_w[k, 3] != 0.0:
            ud = udot[col_start[k]]
            for r in range(3):
                pb[kp, r] += motor_w[k, r] * ud
        for a in range(3):
            force[k, a] = R[k, 0, a] * pb[k, 3] + R[k, 1, a] * pb[k, 4] + R[k, 2, a] * pb[k, 5]
            moment[k, a] = R[k, 0, a] * pb[k, 0] + R[k, 1, a] * pb[k, 1] + R[k, 2, a] * pb[k, 2]
        if kp >= 0:
            vec_cross_add(s_w[k], pb[k, 3:], pb[kp, :3])
            for r in range(6):
                pb[kp, r] += pb[k, r]


@_njit_inline
def _finite(a):
    """Every entry of a (m, q) finite."""
    ok = True
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            ok &= abs(a[i, j]) < math.inf
    return ok


@_njit_inline
def _finite_vector(a):
    """Every entry of a (m,) finite."""
    ok = True
    for i in range(a.shape[0]):
        ok &= abs(a[i]) < math.inf
    return ok


def scratch_size(n: int) -> int:
    """The words of publication_kernel's `scratch` for n bodies."""
    return SCRATCH_PER_BODY * n + SCRATCH_FIXED


#: publication_kernel's scratch: I6 36, pb 6, dlam_b 3, acc 6 words per body; 3-vectors and A (6)
SCRATCH_PER_BODY, SCRATCH_FIXED = 51, 24


@_njit_uncounted
def publication_kernel(t, y, ydot, model, data, inputs, layout, want, outputs, states, slots):
    """What one publication asks for at (t, y), in one pass: the joint states always, wrenches,
    poses and invariants when `want` says so; written into the output arrays and, for each
    copy c, into dst at the slots at_...[c] (any flat float64 buffer: the messages' bytes).
    The records: layout (Layout: base_position ... joint_ref below), outputs (Outputs: R ...
    inv, scratch), states (JointStates: position, velocity, effort), slots (Slots: dst,
    at_joint ... at_wrench).

    model, data, inputs: fast.rhs_kernel's records (its y' in ydot when it runs: only for
    wrenches or speed rotors, which need the accelerations). base_position (3,), down
    (3, 3) world_R_down of the Euler angles, singular: the Euler singularity threshold
    (rotations.EULER_SINGULAR_SIN); speed rotors: body (nv,), axis (nv, 3), A (nv,), rate
    (nv,). want: WANT_* bits. joint_kind, joint_ref (J,): what each joint-state entry is
    (JOINT_*). Out: R (n, 3, 3) world_R_body, w (n, 3) angular velocities, vO (n, 3) velocities
    of O^k, O (n, 3), quat (n, 4) world from body (WANT_BODIES), euler and euler_rate (n, 3)
    (spherical bodies; every body with WANT_EULER_ALL), L_speed (nv,) motor torques
    A_i (w' . e_i), wrench_force and wrench_moment (n, 3) R^k (eq 40), L^k (eq 48) in body k's
    frame (WANT_WRENCHES), inv (INV_SIZE,) (WANT_INVARIANTS), position, velocity, effort (J,)
    the joint states. Scatter: dst (m,) float64; at_joint (c, 3, J) slots of position, velocity,
    effort; at_position (c, n, 3), at_quat (c, n, 4) (w, x, y, z), at_wrench (c, n, 6) (force,
    moment); c = 0 writes none. scratch: float64 (scratch_size(n),), overwritten (this kernel
    allocates nothing: compiled without reference counting, as fast.rhs_kernel).

    A stateful model (flags[FLAG_ACTUATORS]: friction, max_speed) reads its spins from y and
    publishes as efforts the torques applied at this state, the kernel's (`fast.actuate`:
    commands after the speed cut, plus friction), as the numpy reference does.

    Returns 0, or the index in NONFINITE_FIELDS of a field found not finite (the joint states,
    and the poses and wrenches asked for, are all checked when written: the first field checked,
    wrenches, then poses, then joint states, holding one).
    """
    base_position, down, singular, speed_body, speed_axis, speed_A, speed_rate, joint_kind, joint_ref = layout
    R, w, vO, O, quat, euler, euler_rate, L_speed, wrench_force, wrench_moment, inv, scratch = outputs
    position, velocity, effort = states
    dst, at_joint, at_position, at_quat, at_wrench = slots
    (is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
     torque_axis, torque_A, flags, base, armature, spring, servo, motor, is_slide, parent) = model
    work = data.work
    t0, p0, pdot, L_rotor, tau = inputs.t0[0], inputs.p0, inputs.pdot, inputs.L_rotor, inputs.tau
    base_type, has_gravity, has_lam = flags[0], flags[1] != 0, flags[2] != 0
    i_r0, i_vel, i_kap, N = flags[3], flags[4], flags[5], flags[6]
    amp, W, gravity = base[0:3], base[3], base[4:7]
    n, nt, nv = mass.shape[0], torque_body.shape[0], speed_body.shape[0]
    do_wrench = (want & WANT_WRENCHES) != 0
    do_bodies = (want & WANT_BODIES) != 0
    do_inv = (want & WANT_INVARIANTS) != 0
    # the kinematics in the views fast.rhs_kernel cuts its workspace with (fast.workspace_views):
    # the kernel leaves them there when it runs, else they are computed here into the same views
    (R_k, s_w, hk, Aw, e_w, w_k, vO_k, c, _, _, _, lam_b, _, S, _, _, _, p,
     _, _, _, _, _, _, _) = fast.workspace_views(work, n, N, nt)
    stateful = flags[fast.FLAG_ACTUATORS] != 0
    if do_wrench or nv > 0:  # the accelerations: u' into ydot; the kinematics, p (29), S as above
        fast.rhs_call(t, y, ydot, model, data, inputs)
    else:
        if not stateful:  # a stateful model's spins are states: `fast.actuate` reads them from y
            for i in range(nt):
                p[i] = p0[i] + pdot[i] * (t - t0)  # (29)
        body_positions(y, model, R_k, s_w, hk, Aw, e_w)
        body_velocities(t, y, model, s_w, e_w, w_k, vO_k, c)
    L_applied, tau_applied = L_rotor, tau
    if stateful:  # the torques applied at this state (motors after the speed cut, friction): the
        # kernel's own computation, again after rhs_call (the same numbers, written again)
        L_applied, tau_applied = fast.actuate(y, ydot, model, data, inputs, R_k, w_k, p)
    for k in range(n):  # the outputs' copies
        for a in range(3):
            w[k, a] = w_k[k, a]
            vO[k, a] = vO_k[k, a]
            for b in range(3):
                R[k, a, b] = R_k[k, a, b]
    motors = flags[fast.FLAG_MOTORS] != 0 and (do_wrench or do_inv)
    motor_w = block2(work, 0, 0, 4)
    if motors:  # the geared motors' m = J G a (world) and J G^2
        motor_w = block2(work, fast.motor_offset(work, flags, n), n, 4)
        fast.motor_axes(model, R, motor_w)
    q = 0
    I6 = block3(scratch, q, n, 6, 6)
    q += 36 * n
    pb = block2(scratch, q, n, 6)
    q += 6 * n
    dlam_b = block2(scratch, q, n, 3)
    q += 3 * n
    acc = block2(scratch, q, n, 6)
    q += 6 * n
    tmp = block1(scratch, q, 3)
    A = block1(scratch, q + 3, 6)
    L = block1(scratch, q + 9, 3)
    P = block1(scratch, q + 12, 3)
    hsum = block1(scratch, q + 15, 3)
    ang = block1(scratch, q + 18, 3)
    lin = block1(scratch, q + 21, 3)  # q + 24 = scratch_size(n)
    bad = 0
    if do_wrench or nv > 0:
        # body inertias and forces at zero acceleration (as rhs_kernel, which overwrote its own)
        bias_forces(model, R, hk, Aw, w, vO, p, L_applied, lam_b, dlam_b, I6, pb)
        if motors:
            fast.motor_gyroscopic(y, model, w, motor_w, pb)
        udot = ydot[i_vel:i_vel + N]
        # body accelerations about O^k: A^k = A^{k-1} moved to O^k + c^k + S_k u'_k
        for a in range(6):
            A[a] = 0.0
        if base_type == fast.BASE_MOVING:
            sw = -W * W * math.sin(W * t)
            for a in range(3):
                A[3 + a] = amp[a] * sw
        tree = parent.shape[0] != 0
        for k in range(n):
            if tree:  # from the parent's A (a tree's s_w[k] is O^k - O^{parent}), or the base's
                kp = parent[k]
                for r in range(6):
                    A[r] = acc[kp, r] if kp >= 0 else (amp[r - 3] * -W * W * math.sin(W * t)
                                                       if r >= 3 and base_type == fast.BASE_MOVING else 0.0)
                if kp >= 0:
                    vec_cross_add(A[:3], s_w[k], A[3:])
            elif k > 0:
                vec_cross_add(A[:3], s_w[k - 1], A[3:])  # a kernel helper
            for r in range(6):
                A[r] += c[k, r]
            for j in range(col_start[k], col_start[k + 1]):
                for r in range(6):
                    A[r] += S[j, r] * udot[j]
            for r in range(6):
                acc[k, r] = A[r]
        if do_wrench and tree:
            _tree_wrenches(R, I6, acc, pb, s_w, parent, motor_w if motors else motor_w[:0], col_start, udot,
                           wrench_force, wrench_moment)
        if do_wrench:
            # F^k = sum_{p >= k} (I a + p)^p about O^k; R^k its force (40), L^k its moment (48)
            Fa0 = Fa1 = Fa2 = 0.0
            Fl0 = Fl1 = Fl2 = 0.0
            for k in range(n - 1, -1, -1):
                if tree:
                    break
                if k < n - 1:  # the moment of F^{k+1} moved to O^k
                    d0, d1, d2 = s_w[k, 0], s_w[k, 1], s_w[k, 2]
                    Fa0 += d1 * Fl2 - d2 * Fl1
                    Fa1 += d2 * Fl0 - d0 * Fl2
                    Fa2 += d0 * Fl1 - d1 * Fl0
                Fa0 += dot6(I6[k, 0], acc[k]) + pb[k, 0]
                Fa1 += dot6(I6[k, 1], acc[k]) + pb[k, 1]
                Fa2 += dot6(I6[k, 2], acc[k]) + pb[k, 2]
                Fl0 += dot6(I6[k, 3], acc[k]) + pb[k, 3]
                Fl1 += dot6(I6[k, 4], acc[k]) + pb[k, 4]
                Fl2 += dot6(I6[k, 5], acc[k]) + pb[k, 5]
                if motors and k + 1 < n:  # the child's motor's J G phi'' a on body k
                    ud = udot[col_start[k + 1]]
                    Fa0 += motor_w[k + 1, 0] * ud
                    Fa1 += motor_w[k + 1, 1] * ud
                    Fa2 += motor_w[k + 1, 2] * ud
                for a in range(3):
                    wrench_force[k, a] = R[k, 0, a] * Fl0 + R[k, 1, a] * Fl1 + R[k, 2, a] * Fl2
                    wrench_moment[k, a] = R[k, 0, a] * Fa0 + R[k, 1, a] * Fa1 + R[k, 2, a] * Fa2
            _scatter(dst, at_wrench, wrench_force, 0)
            _scatter(dst, at_wrench, wrench_moment, 3)
            if not _finite(wrench_force):
                bad = 6
            elif not _finite(wrench_moment):
                bad = 7
        # speed rotors: the motor keeps kappa' constant, L_i = A_i (w' . e_i)
        for i in range(nv):
            k = speed_body[i]
            mat_vec(R[k], speed_axis[i], tmp)
            L_speed[i] = speed_A[i] * (acc[k, 0] * tmp[0] + acc[k, 1] * tmp[1] + acc[k, 2] * tmp[2])
    elif do_inv and has_lam:
        bias_forces(model, R, hk, Aw, w, vO, p, L_applied, lam_b, dlam_b, I6, pb)
    # joint points
    if do_bodies or do_inv:
        for a in range(3):
            if base_type == fast.BASE_FREE:
                O[0, a] = y[i_r0 + a]
            elif base_type == fast.BASE_MOVING:
                O[0, a] = base_position[a] + amp[a] * math.sin(W * t)
            else:
                O[0, a] = base_position[a]
        if parent.shape[0] != 0:  # a tree: O^k = O^{parent} + s_w[k] (the base's point on the base)
            for a in range(3):
                tmp[a] = O[0, a]
            for k in range(n):
                kp = parent[k]
                for a in range(3):
                    O[k, a] = (O[kp, a] if kp >= 0 else tmp[a]) + s_w[k, a]
        else:
            if is_slide[0]:  # a first body's slide moves O^1 (the others' are in s_w[k - 1])
                for a in range(3):
                    O[0, a] += e_w[0, a] * y[qrow[0]]
            for k in range(1, n):
                for a in range(3):
                    O[k, a] = O[k - 1, a] + s_w[k - 1, a]
    # Euler angles (joint states of spherical joints; every body for the Lagrange integrals)
    all_euler = (want & WANT_EULER_ALL) != 0
    for k in range(n):
        if all_euler or not is_hinge[k]:
            _euler(R, w, k, down, singular, euler, euler_rate)
    # poses
    if do_bodies:
        for k in range(n):
            if is_hinge[k]:
                _matrix_to_quat(R[k], quat[k])
            else:
                i = qrow[k]
                nrm = math.sqrt(y[i] * y[i] + y[i + 1] * y[i + 1] + y[i + 2] * y[i + 2] + y[i + 3] * y[i + 3])
                for a in range(4):
                    quat[k, a] = y[i + a] / nrm
        _scatter(dst, at_position, O, 0)
        _scatter(dst, at_quat, quat, 0)
        if bad == 0 and not _finite(O):
            bad = 4
        elif bad == 0 and not _finite(quat):
            bad = 5
    # joint states: the numbers, then into their slots, then their check (three plain loops:
    # ~6 us less than one loop doing all three at n = 100)
    J = joint_kind.shape[0]
    for j in range(J):
        kind, ref = joint_kind[j], joint_ref[j]
        if kind == JOINT_EULER:
            k = ref // 3
            a = ref - 3 * k
            position[j], velocity[j], effort[j] = euler[k, a], euler_rate[k, a], 0.0
        elif kind == JOINT_HINGE:
            col = own_col[ref]
            position[j], velocity[j], effort[j] = y[qrow[ref]], y[i_vel + col], tau_applied[col]
        elif kind == JOINT_TORQUE_ROTOR:
            k = torque_body[ref]
            ax0, ax1, ax2 = torque_axis[ref, 0], torque_axis[ref, 1], torque_axis[ref, 2]
            e0 = R[k, 0, 0] * ax0 + R[k, 0, 1] * ax1 + R[k, 0, 2] * ax2  # the axis in world (mat_vec)
            e1 = R[k, 1, 0] * ax0 + R[k, 1, 1] * ax1 + R[k, 1, 2] * ax2
            e2 = R[k, 2, 0] * ax0 + R[k, 2, 1] * ax1 + R[k, 2, 2] * ax2
            position[j] = y[i_kap + ref]
            velocity[j] = p[ref] - (w[k, 0] * e0 + w[k, 1] * e1 + w[k, 2] * e2)  # (18-19)
            effort[j] = L_applied[ref]
        else:
            position[j], velocity[j], effort[j] = speed_rate[ref] * t, speed_rate[ref], L_speed[ref]
    for c in range(at_joint.shape[0]):
        for j in range(J):
            dst[at_joint[c, 0, j]] = position[j]
        for j in range(J):
            dst[at_joint[c, 1, j]] = velocity[j]
        for j in range(J):
            dst[at_joint[c, 2, j]] = effort[j]
    if bad == 0 and not _finite_vector(position):
        bad = 1
    elif bad == 0 and not _finite_vector(velocity):
        bad = 2
    elif bad == 0 and not _finite_vector(effort):
        bad = 3
    if not do_inv:
        return bad
    # invariants: momenta about O^k, then about the origin; (33) and the potential
    T = 0.0
    V = 0.0
    lam_dot = 0.0
    for a in range(3):
        L[a] = P[a] = hsum[a] = 0.0
    for k in range(n):
        mat_vec(Aw[k], w[k], ang)  # A w + h x v(O)
        vec_cross_add(hk[k], vO[k], ang)
        vec_cross(w[k], hk[k], lin)  # m v(O) + w x h
        for a in range(3):
            lin[a] += mass[k] * vO[k, a]
        T += 0.5 * (w[k, 0] * ang[0] + w[k, 1] * ang[1] + w[k, 2] * ang[2]
                    + vO[k, 0] * lin[0] + vO[k, 1] * lin[1] + vO[k, 2] * lin[2])
        vec_cross_add(O[k], lin, ang)  # about the origin
        if has_lam:
            mat_vec(R[k], lam_b[k], tmp)  # lambda^k, speed and torque rotors
            for a in range(3):
                ang[a] += tmp[a]
            mat_vec(R[k], lam_speed[k], tmp)
            lam_dot += w[k, 0] * tmp[0] + w[k, 1] * tmp[1] + w[k, 2] * tmp[2]
        for a in range(3):
            L[a] += ang[a]
            P[a] += lin[a]
            hsum[a] += mass[k] * O[k, a] + hk[k, a]
    spin2 = 0.0
    for i in range(nv):
        spin2 += speed_A[i] * speed_rate[i] * speed_rate[i]
    T += lam_dot + 0.5 * spin2
    for i in range(nt):
        T += 0.5 * torque_A[i] * p[i] * p[i]
    if has_gravity:
        V = -(gravity[0] * hsum[0] + gravity[1] * hsum[1] + gravity[2] * hsum[2])
    if motors:  # the geared motors: phi' m . w^{k-1} + 1/2 J G^2 phi'^2, and their spins m phi'
        for k in range(1, n):
            if motor_w[k, 3] != 0.0:
                rate = y[i_vel + own_col[k]]
                kp = parent[k] if parent.shape[0] != 0 else k - 1
                T += rate * (motor_w[k, 0] * w[kp, 0] + motor_w[k, 1] * w[kp, 1] + motor_w[k, 2] * w[kp, 2])
                T += 0.5 * motor_w[k, 3] * rate * rate
                for a in range(3):
                    L[a] += motor_w[k, a] * rate
    for k in range(n):  # the hinges' armatures 1/2 a phi'^2, springs 1/2 k (phi - phi_ref)^2
        if is_hinge[k] and armature[k] != 0.0:
            rate = y[i_vel + own_col[k]]
            T += 0.5 * armature[k] * rate * rate
        if is_hinge[k] and flags[fast.FLAG_SPRINGS] != 0:
            stretch = y[qrow[k]] - spring[k, 1]
            V += 0.5 * spring[k, 0] * stretch * stretch
    inv[INV_ENERGY], inv[INV_KINETIC], inv[INV_POTENTIAL] = T + V, T, V
    inv[INV_JACOBI] = T + V - lam_dot - spin2
    vec_cross(O[0], P, tmp)  # H_O1 = L - O^1 x P
    mtot = 0.0
    for k in range(n):
        mtot += mass[k]
    for a in range(3):
        inv[5 + a] = L[a] - tmp[a]
        inv[8 + a] = P[a]
        hsum[a] /= mtot  # the centre of mass
    inv[INV_VERTICAL] = -(down[0, 2] * inv[5] + down[1, 2] * inv[6] + down[2, 2] * inv[7])  # (79)
    vec_cross(hsum, P, tmp)
    for a in range(3):
        inv[11 + a] = L[a] - tmp[a]
    return bad

