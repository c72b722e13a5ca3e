"""The chain's canonical equations compiled with numba: :mod:`gyro_sim.dynamics.canonical`'s field
in one call, O(n), nothing allocated.

`canonical_kernel(t, z, zdot, *kargs)` computes what `CanonicalChain.rhs` computes, and
`state_kernel(t, z, y, *kargs)` what `CanonicalChain.state` does, from the same model arrays
and held inputs as :func:`gyro_sim.dynamics.kernel.rhs_kernel` (its `kernel_arguments`, first) and
three more: `zrow` (n, 2), the z index of each body's coordinate (quaternion or hinge angle)
and of its momentum; `cflags` (i_pr, i_kappa of z, the model's size); `cwork`, the scratch
(`canonical_workspace`). The stages, about each body's O^k in world axes as in fast.py:

    positions   z        -> R^k (of q / |q|), s^k, m^k c^k, A^k, e^k      (fast.positions_stage)
    momenta     z, t     -> pi^k = Im(p^k (x) conj(q^k)) / 2, the joint momenta p_rel (sums
                            of pi over the spherical bodies from k on; e . that + p_phi at a
                            hinge), minus their part at zero rates b (gyrostatic moments
                            lambda(t), a moving base's velocity)
    rates       p_rel    -> u: M u = p_rel - b by the articulated-body elimination with no
                            bias force, no bias acceleration (fast.articulated_solve: its square-root form
                            for heavy subtrees too)
    velocities  u        -> w^k, v(O^k)                                  (fast.velocities_stage)
    field                -> subtree momenta (H_k about O^k, P_k), external wrench (gravity),
                            p_rel' = S' . h + S . F + tau, then the canonical rates

On a tree (ChainModel's `parent`, flags[FLAG_TREE]) the backward sweeps keep each body's sums
in `cwork` (TREE_BLOCKS) and add a child's into its parent's as they leave it, a moment moved
by s_w[k] = O^k - O^{parent(k)} (`_to_parent`), where a chain's carry them in scalars from
O^{k+1} to O^k; the chain's arithmetic is unchanged. Geared motors (flags[FLAG_MOTORS]): the
elimination takes their columns (`fast.motor_axes`), and each motor's J G phi' a joins its
parent's subtree momentum.

The derivation and the formulas are in canonical.py's docstring; this is the same arithmetic
in scalar loops (test/integrators/test_gauss4s.py and test_gauss4s_trees.py check the two
against each other).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.canonical import CanonicalChain
from gyro_sim.jit import block2, block3

if jit.compiling():
    from gyro_sim.jit import address_of, call_address, vector_at

#: the files the kernels compile in (the key of their numba cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)
#: arguments of fast.rhs_kernel after (t, y, out): its records model, data, inputs
CHAIN_RECORDS = 3
#: a tree's per-body sums in `cwork` (3 floats a body each): the sum A of pi over the subtree,
#: the subtree's momenta H, P, its external moment M and force F, the sum D of the next spherical
#: bodies' p_rel' (the chain's sweeps carry them in scalars)
TREE_BLOCKS = 6
#: floats of `cwork` per velocity column (p_rel, p_rel', u) and per body (pi; a tree's sums after)
CWORK_PER_COLUMN = 3
CWORK_PER_BODY = 3
#: `cflags`: i_pr, i_kappa of z, the model's size, then the address of `canonical_kernel`
#: compiled as a C function (`canonical_address`), which gauss4's compiled march calls
#: (`canonical_call`) instead of compiling the field into itself
CFLAG_KERNEL = 3
CFLAGS_SIZE = 4


@jit.inline_ir
def _clear(sums, first, last):
    """Zero blocks first..last - 1 of a tree's `sums` (none on a chain: sums is empty)."""
    for b in range(first, min(last, sums.shape[0])):
        for k in range(sums.shape[1]):
            sums[b, k, 0], sums[b, k, 1], sums[b, k, 2] = 0.0, 0.0, 0.0


@jit.inline_ir
def _to_parent(sums, b, k, kp, s_w, H0, H1, H2, P0, P1, P2):
    """A child k's subtree sums, a moment H about O^k and a force P, added to its parent kp's in
    blocks b (the moment, now about O^kp: H + s x P with s = O^k - O^kp = s_w[k]) and b + 1."""
    s0, s1, s2 = s_w[k, 0], s_w[k, 1], s_w[k, 2]
    sums[b, kp, 0] += H0 + (s1 * P2 - s2 * P1)
    sums[b, kp, 1] += H1 + (s2 * P0 - s0 * P2)
    sums[b, kp, 2] += H2 + (s0 * P1 - s1 * P0)
    sums[b + 1, kp, 0] += P0
    sums[b + 1, kp, 1] += P1
    sums[b + 1, kp, 2] += P2


@jit.inline_ir
def _rates(t, z, model, data, inputs, zrow, cflags, cwork):
    """Positions of z, pi^k, p_rel and the rates u (into y's velocity block in cwork's y and in
    `rate`), then w^k, v(O^k). Returns nothing: everything is left in the workspaces."""
    (is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
     torque_axis, torque_A, flags, base, armature, spring, servo, motor, is_slide, parent) = model
    work = data.work
    t0, p0, pdot = inputs.t0[0], inputs.p0, inputs.pdot
    base_type, has_lam = flags[0], flags[2] != 0
    i_r0, i_vel, N = flags[3], flags[4], flags[6]
    base_amplitude, base_omega = base[0:3], base[3]
    n = mass.shape[0]
    nt = torque_body.shape[0]
    i_pr, size = cflags[0], cflags[2]
    (R, s_w, hk, Aw, e_w, w, vO, c, I6, pb, Dinv, lam_b, dlam_b, S, U, W, u, p,
     Ia, pa, Dx, T, G, x, a_base) = fast.workspace_views(work, n, N, nt)
    y = cwork[0:size]
    prel = cwork[size:size + N]
    rate = cwork[size + 2 * N:size + 3 * N]
    o = size + 3 * N
    pi = cwork[o:o + 3 * n]
    # positions: y's coordinates from z (unit quaternions)
    if base_type == fast.BASE_FREE:
        for a in range(3):
            y[i_r0 + a] = z[a]
    for k in range(n):
        i, j = qrow[k], zrow[k, 0]
        if is_hinge[k]:
            y[i] = z[j]
        else:
            q0, q1, q2, q3 = z[j], z[j + 1], z[j + 2], z[j + 3]
            nq = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            y[i], y[i + 1], y[i + 2], y[i + 3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
    fast.positions_stage(y, model, R, s_w, hk, Aw, e_w)
    # gyrostatic moments lambda^k (body axes) at t (eq 31, p_i(t) by eq 29)
    if has_lam:
        for k in range(n):
            for a in range(3):
                lam_b[k, a] = lam_speed[k, a]
        for i in range(nt):
            k = torque_body[i]
            pt = p0[i] + pdot[i] * (t - t0)
            for a in range(3):
                lam_b[k, a] += torque_A[i] * pt * torque_axis[i, a]
    # base velocity at zero joint rates
    vb0, vb1, vb2 = 0.0, 0.0, 0.0
    if base_type == fast.BASE_MOVING:
        cw = base_omega * math.cos(base_omega * t)
        vb0, vb1, vb2 = base_amplitude[0] * cw, base_amplitude[1] * cw, base_amplitude[2] * cw
    # backward: pi^k, p_rel, and b (the momenta at zero joint rates) subtracted from p_rel
    A0, A1, A2 = 0.0, 0.0, 0.0  # sum of pi over the spherical bodies after k (then from k)
    H0, H1, H2 = 0.0, 0.0, 0.0  # b: subtree angular momentum about O^{k+1} (then O^k)
    P0, P1, P2 = 0.0, 0.0, 0.0  # b: subtree linear momentum
    # a tree's (docs/theory.md section 11): the same sums per body, its children's added to it
    # (moved from their O^j to O^k) before it is reached: A in `sums` block 0, H, P in 1, 2
    tree = parent.shape[0] != 0
    sums = block3(cwork, o + 3 * n, TREE_BLOCKS if tree else 0, n, 3)
    _clear(sums, 0, 3)
    for k in range(n - 1, -1, -1):
        if tree:  # the children's sums, already about O^k
            A0, A1, A2 = sums[0, k, 0], sums[0, k, 1], sums[0, k, 2]
            H0, H1, H2 = sums[1, k, 0], sums[1, k, 1], sums[1, k, 2]
            P0, P1, P2 = sums[2, k, 0], sums[2, k, 1], sums[2, k, 2]
        else:
            # b's subtree momenta moved from O^{k+1} to O^k, body k's own added
            s0, s1, s2 = s_w[k, 0], s_w[k, 1], s_w[k, 2]
            H0 += s1 * P2 - s2 * P1
            H1 += s2 * P0 - s0 * P2
            H2 += s0 * P1 - s1 * P0
        h0, h1, h2 = hk[k, 0], hk[k, 1], hk[k, 2]
        m = mass[k]
        H0 += h1 * vb2 - h2 * vb1
        H1 += h2 * vb0 - h0 * vb2
        H2 += h0 * vb1 - h1 * vb0
        if has_lam:
            l0, l1, l2 = lam_b[k, 0], lam_b[k, 1], lam_b[k, 2]
            H0 += R[k, 0, 0] * l0 + R[k, 0, 1] * l1 + R[k, 0, 2] * l2
            H1 += R[k, 1, 0] * l0 + R[k, 1, 1] * l1 + R[k, 1, 2] * l2
            H2 += R[k, 2, 0] * l0 + R[k, 2, 1] * l1 + R[k, 2, 2] * l2
        P0 += m * vb0
        P1 += m * vb1
        P2 += m * vb2
        jc, jm = own_col[k], zrow[k, 1]
        if is_slide[k]:  # its momentum is its relative one, e . P (canonical.py)
            e0, e1, e2 = e_w[k, 0], e_w[k, 1], e_w[k, 2]
            prel[jc] = z[jm] - (e0 * P0 + e1 * P1 + e2 * P2)
        elif is_hinge[k]:
            e0, e1, e2 = e_w[k, 0], e_w[k, 1], e_w[k, 2]
            prel[jc] = z[jm] + (e0 * A0 + e1 * A1 + e2 * A2) - (e0 * H0 + e1 * H1 + e2 * H2)
        else:
            j = zrow[k, 0]
            q0, q1, q2, q3 = z[j], z[j + 1], z[j + 2], z[j + 3]
            r0, r1, r2, r3 = z[jm], z[jm + 1], z[jm + 2], z[jm + 3]
            # pi = Im(p (x) conj(q)) / 2
            x0 = 0.5 * (-r0 * q1 + r1 * q0 - r2 * q3 + r3 * q2)
            x1 = 0.5 * (-r0 * q2 + r1 * q3 + r2 * q0 - r3 * q1)
            x2 = 0.5 * (-r0 * q3 - r1 * q2 + r2 * q1 + r3 * q0)
            pi[3 * k], pi[3 * k + 1], pi[3 * k + 2] = x0, x1, x2
            A0 += x0
            A1 += x1
            A2 += x2
            prel[jc], prel[jc + 1], prel[jc + 2] = A0 - H0, A1 - H1, A2 - H2
        if tree:  # k's A kept (the field's hinges read it); the sums passed to its parent
            sums[0, k, 0], sums[0, k, 1], sums[0, k, 2] = A0, A1, A2
            kp = parent[k]
            if kp >= 0:
                sums[0, kp, 0] += A0
                sums[0, kp, 1] += A1
                sums[0, kp, 2] += A2
                _to_parent(sums, 1, k, kp, s_w, H0, H1, H2, P0, P1, P2)
    if base_type == fast.BASE_FREE:  # (P: body 0's subtree, the whole chain or tree)
        prel[0], prel[1], prel[2] = z[i_pr] - P0, z[i_pr + 1] - P1, z[i_pr + 2] - P2
    # rates: M u = p_rel - b, the elimination with no bias force or acceleration
    for k in range(n):
        for a in range(6):
            pb[k, a] = 0.0
            c[k, a] = 0.0
        fast.spatial_inertia(k, mass[k], hk[k, 0], hk[k, 1], hk[k, 2], Aw, I6)
    for a in range(6):
        a_base[a] = 0.0
    fast.joint_columns_stage(is_hinge, is_slide, own_col, base_type, e_w, S)
    motor_w = block2(work, 0, 0, 4)
    if flags[fast.FLAG_MOTORS] != 0:  # geared motors (eq 51b): m = J G a (world), J G^2, for M
        motor_w = block2(work, fast.motor_offset(work, flags, n), n, 4)
        fast.motor_axes(model, R, motor_w)
    fast.articulated_solve(is_hinge, col_start,
                           fast.Elimination(S, I6, pb, c, a_base, s_w, U, W, u, Dinv, Ia, pa, Dx, T, G, x, armature,
                                            motor_w),
                           prel, rate, flags[fast.FLAG_HEAVY], parent)
    for j in range(N):
        y[i_vel + j] = rate[j]
    fast.velocities_stage(t, y, model, s_w, e_w, w, vO, c)


@_njit
def canonical_kernel(t, z, zdot, model, data, inputs, zrow, cflags, cwork):
    """z' (size,) at (t, z) into zdot: `_canonical_rhs` compiled on its own, for callers from
    Python with records of numpy arrays."""
    _canonical_rhs(t, z, zdot, model, data, inputs, zrow, cflags, cwork)


@jit.inline_ir
def _canonical_rhs(t, z, zdot, model, data, inputs, zrow, cflags, cwork):
    """z' (size,) at (t, z) into zdot: what canonical.CanonicalChain.rhs computes."""
    _rates(t, z, model, data, inputs, zrow, cflags, cwork)
    (is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
     torque_axis, torque_A, flags, base, armature, spring, servo, motor, is_slide, parent) = model
    work = data.work
    t0, p0, pdot, tau = inputs.t0[0], inputs.p0, inputs.pdot, inputs.tau
    base_type, has_gravity, has_lam = flags[0], flags[1] != 0, flags[2] != 0
    N = flags[6]
    g0, g1, g2 = base[4], base[5], base[6]
    n = mass.shape[0]
    nt = torque_body.shape[0]
    i_pr, i_kap, size = cflags[0], cflags[1], cflags[2]
    (R, s_w, hk, Aw, e_w, w, vO, c, I6, pb, Dinv, lam_b, dlam_b, S, U, W, u, p,
     Ia, pa, Dx, T, G, x, a_base) = fast.workspace_views(work, n, N, nt)
    dprel = cwork[size + N:size + 2 * N]
    rate = cwork[size + 2 * N:size + 3 * N]
    o = size + 3 * N
    pi = cwork[o:o + 3 * n]
    # backward: subtree momenta H (about O^k), P; external moment M (about O^k) and force F;
    # p_rel' of each column
    H0, H1, H2, P0, P1, P2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    M0, M1, M2, F0, F1, F2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    # a tree's: per body, the children's (about O^k) in `sums` blocks 1-4 (block 0: _rates' A)
    tree = parent.shape[0] != 0
    sums = block3(cwork, o + 3 * n, TREE_BLOCKS if tree else 0, n, 3)
    _clear(sums, 1, TREE_BLOCKS)
    motors = flags[fast.FLAG_MOTORS] != 0
    motor_w = block2(work, fast.motor_offset(work, flags, n) if motors else 0, n if motors else 0, 4)  # _rates'
    for k in range(n - 1, -1, -1):
        if tree:
            H0, H1, H2 = sums[1, k, 0], sums[1, k, 1], sums[1, k, 2]
            P0, P1, P2 = sums[2, k, 0], sums[2, k, 1], sums[2, k, 2]
            M0, M1, M2 = sums[3, k, 0], sums[3, k, 1], sums[3, k, 2]
            F0, F1, F2 = sums[4, k, 0], sums[4, k, 1], sums[4, k, 2]
        else:
            s0, s1, s2 = s_w[k, 0], s_w[k, 1], s_w[k, 2]
            H0 += s1 * P2 - s2 * P1
            H1 += s2 * P0 - s0 * P2
            H2 += s0 * P1 - s1 * P0
            M0 += s1 * F2 - s2 * F1
            M1 += s2 * F0 - s0 * F2
            M2 += s0 * F1 - s1 * F0
        m = mass[k]
        h0, h1, h2 = hk[k, 0], hk[k, 1], hk[k, 2]
        w0, w1, w2 = w[k, 0], w[k, 1], w[k, 2]
        v0, v1, v2 = vO[k, 0], vO[k, 1], vO[k, 2]
        # body k's momentum about O^k: (A w + h x v + lambda, m v + w x h)
        H0 += (Aw[k, 0, 0] * w0 + Aw[k, 0, 1] * w1 + Aw[k, 0, 2] * w2) + (h1 * v2 - h2 * v1)
        H1 += (Aw[k, 1, 0] * w0 + Aw[k, 1, 1] * w1 + Aw[k, 1, 2] * w2) + (h2 * v0 - h0 * v2)
        H2 += (Aw[k, 2, 0] * w0 + Aw[k, 2, 1] * w1 + Aw[k, 2, 2] * w2) + (h0 * v1 - h1 * v0)
        if has_lam:
            l0, l1, l2 = lam_b[k, 0], lam_b[k, 1], lam_b[k, 2]
            H0 += R[k, 0, 0] * l0 + R[k, 0, 1] * l1 + R[k, 0, 2] * l2
            H1 += R[k, 1, 0] * l0 + R[k, 1, 1] * l1 + R[k, 1, 2] * l2
            H2 += R[k, 2, 0] * l0 + R[k, 2, 1] * l1 + R[k, 2, 2] * l2
        P0 += (w1 * h2 - w2 * h1) + m * v0
        P1 += (w2 * h0 - w0 * h2) + m * v1
        P2 += (w0 * h1 - w1 * h0) + m * v2
        if has_gravity:
            M0 += h1 * g2 - h2 * g1
            M1 += h2 * g0 - h0 * g2
            M2 += h0 * g1 - h1 * g0
            F0 += m * g0
            F1 += m * g1
            F2 += m * g2
        # S' . h + S . F for a rotation about O^k with fixed axes: P x v(O^k) + M
        G0 = (P1 * v2 - P2 * v1) + M0
        G1 = (P2 * v0 - P0 * v2) + M1
        G2 = (P0 * v1 - P1 * v0) + M2
        jc = own_col[k]
        kp = parent[k] if tree else k - 1
        if is_hinge[k]:
            e0, e1, e2 = e_w[k, 0], e_w[k, 1], e_w[k, 2]
            if kp >= 0:
                a0, a1, a2 = w[kp, 0], w[kp, 1], w[kp, 2]
            else:
                a0, a1, a2 = 0.0, 0.0, 0.0
            # (50): e' = w^{k-1} x e (w of the parent)
            d0, d1, d2 = a1 * e2 - a2 * e1, a2 * e0 - a0 * e2, a0 * e1 - a1 * e0
            if is_slide[k]:  # S = (0, e): (w^{k-1} x e) . P + e . F (canonical.py)
                dprel[jc] = (d0 * P0 + d1 * P1 + d2 * P2) + (e0 * F0 + e1 * F1 + e2 * F2) + tau[jc]
            else:
                dprel[jc] = (d0 * H0 + d1 * H1 + d2 * H2) + (e0 * G0 + e1 * G1 + e2 * G2) + tau[jc]  # (51)
            if flags[fast.FLAG_SPRINGS] != 0:  # the spring's moment -k (phi - phi_ref)
                dprel[jc] += -spring[k, 0] * (z[zrow[k, 0]] - spring[k, 1])
        else:
            dprel[jc], dprel[jc + 1], dprel[jc + 2] = G0, G1, G2
        if motors and motor_w[k, 3] != 0.0:  # its rotor's spin J G phi' a: the parent's moment (eq 31)
            H0 += motor_w[k, 0] * rate[jc]
            H1 += motor_w[k, 1] * rate[jc]
            H2 += motor_w[k, 2] * rate[jc]
        if tree and kp >= 0:
            _to_parent(sums, 1, k, kp, s_w, H0, H1, H2, P0, P1, P2)
            _to_parent(sums, 3, k, kp, s_w, M0, M1, M2, F0, F1, F2)
    if base_type == fast.BASE_FREE:
        dprel[0], dprel[1], dprel[2] = F0, F1, F2  # the total external force
    # the canonical rates, backward again: B, D the next spherical body's p_rel (the sum of pi
    # from it on) and p_rel'
    # (a tree's: B is _rates' A, the sum of pi over the subtree; D, per body in `sums` block 5,
    # the sum of p_rel' over the next spherical bodies on each branch below)
    B0, B1, B2, D0, D1, D2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for k in range(n - 1, -1, -1):
        jc, jq, jm = own_col[k], zrow[k, 0], zrow[k, 1]
        w0, w1, w2 = w[k, 0], w[k, 1], w[k, 2]
        kp = parent[k] if tree else k - 1
        if tree:
            B0, B1, B2 = sums[0, k, 0], sums[0, k, 1], sums[0, k, 2]
            D0, D1, D2 = sums[5, k, 0], sums[5, k, 1], sums[5, k, 2]
        if is_hinge[k]:
            e0, e1, e2 = e_w[k, 0], e_w[k, 1], e_w[k, 2]
            if kp >= 0:
                a0, a1, a2 = w[kp, 0], w[kp, 1], w[kp, 2]
            else:
                a0, a1, a2 = 0.0, 0.0, 0.0
            d0, d1, d2 = a1 * e2 - a2 * e1, a2 * e0 - a0 * e2, a0 * e1 - a1 * e0
            zdot[jq] = rate[jc]
            if is_slide[k]:  # no correction: a slide changes no angular velocity
                zdot[jm] = dprel[jc]
            else:
                zdot[jm] = dprel[jc] - (d0 * B0 + d1 * B1 + d2 * B2) - (e0 * D0 + e1 * D1 + e2 * D2)
        else:
            # pi' = p_rel'(k) - p_rel'(k'); p' = (2 (0, pi') + Pi (x) (0, w)) (x) q / |q|^2
            x0, x1, x2 = dprel[jc] - D0, dprel[jc + 1] - D1, dprel[jc + 2] - D2
            q0, q1, q2, q3 = z[jq], z[jq + 1], z[jq + 2], z[jq + 3]
            r0, r1, r2, r3 = z[jm], z[jm + 1], z[jm + 2], z[jm + 3]
            # Pi = p (x) conj(q) / 2: its scalar part, then pi (computed in _rates)
            c0 = 0.5 * (r0 * q0 + r1 * q1 + r2 * q2 + r3 * q3)
            c1, c2, c3 = pi[3 * k], pi[3 * k + 1], pi[3 * k + 2]
            # Pi (x) (0, w)
            m0 = -(c1 * w0 + c2 * w1 + c3 * w2)
            m1 = c0 * w0 + (c2 * w2 - c3 * w1)
            m2 = c0 * w1 + (c3 * w0 - c1 * w2)
            m3 = c0 * w2 + (c1 * w1 - c2 * w0)
            a0, a1, a2, a3 = m0, 2.0 * x0 + m1, 2.0 * x1 + m2, 2.0 * x2 + m3
            inv = 1.0 / (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            zdot[jm] = (a0 * q0 - a1 * q1 - a2 * q2 - a3 * q3) * inv
            zdot[jm + 1] = (a0 * q1 + a1 * q0 + a2 * q3 - a3 * q2) * inv
            zdot[jm + 2] = (a0 * q2 - a1 * q3 + a2 * q0 + a3 * q1) * inv
            zdot[jm + 3] = (a0 * q3 + a1 * q2 - a2 * q1 + a3 * q0) * inv
            zdot[jq], zdot[jq + 1], zdot[jq + 2], zdot[jq + 3] = fast.quat_rate(q0, q1, q2, q3, w0, w1, w2)
            B0, B1, B2 = B0 + c1, B1 + c2, B2 + c3
            D0, D1, D2 = dprel[jc], dprel[jc + 1], dprel[jc + 2]
        if tree and kp >= 0:  # what the parent sees below: k's p_rel' (spherical) or k's D
            sums[5, kp, 0] += D0
            sums[5, kp, 1] += D1
            sums[5, kp, 2] += D2
    if base_type == fast.BASE_FREE:
        for a in range(3):
            zdot[a] = rate[a]
            zdot[i_pr + a] = dprel[a]
    for i in range(nt):
        k = torque_body[i]
        pt = p0[i] + pdot[i] * (t - t0)
        ax0, ax1, ax2 = torque_axis[i, 0], torque_axis[i, 1], torque_axis[i, 2]
        e0 = R[k, 0, 0] * ax0 + R[k, 0, 1] * ax1 + R[k, 0, 2] * ax2
        e1 = R[k, 1, 0] * ax0 + R[k, 1, 1] * ax1 + R[k, 1, 2] * ax2
        e2 = R[k, 2, 0] * ax0 + R[k, 2, 1] * ax1 + R[k, 2, 2] * ax2
        zdot[i_kap + i] = fast.rotor_angle_rate(pt, w[k, 0], w[k, 1], w[k, 2], e0, e1, e2)


if jit.compiling():
    @_njit
    def canonical_call(t, z, zdot, model, data, inputs, zrow, cflags, cwork):
        """`canonical_kernel` (same arguments, C-contiguous) through its C function at
        cflags[CFLAG_KERNEL] (`canonical_address`): for compiled loops."""
        call_address(cflags[CFLAG_KERNEL], (t, address_of(z), address_of(zdot), z.shape[0],
                                            address_of(data.descriptor), address_of(zrow), address_of(cflags),
                                            address_of(cwork), cwork.shape[0]))
else:  # plain Python: the field called directly
    def canonical_call(*arguments):
        canonical_kernel(*arguments)


def _canonical_entry(t, z, zdot, size, descriptor, zrow, cflags, cwork, ncwork):
    """`canonical_kernel` on z, zdot (`size` floats at these addresses), the chain's records
    `descriptor` (an address: `fast.records_at`) describes, then zrow (n, 2), cflags, cwork
    (`ncwork` floats) at these addresses: compiled as a C function (`canonical_address`)."""
    model, data, inputs = fast.records_at(descriptor)
    f, i = np.float64, np.int64
    n = model.mass.shape[0]
    _canonical_rhs(t, vector_at(z, size, f), vector_at(zdot, size, f), model, data, inputs,
                     block2(vector_at(zrow, 2 * n, i), 0, n, 2), vector_at(cflags, CFLAGS_SIZE, i),
                     vector_at(cwork, ncwork, f))


def canonical_address() -> int:
    """The address of `canonical_kernel` compiled as a C function (`_canonical_entry`: t, the
    addresses of z, zdot, their size, the chain's descriptor, then the addresses of zrow, cflags,
    cwork and cwork's size), compiled or loaded from
    numba's disk cache on the first call; 0 without numba or with NUMBA_DISABLE_JIT."""
    if not jit.compiling():
        return 0
    return jit.c_address(_canonical_entry, lambda: fast.kernel_signature(*(jit.numba.types.int64,) * 4),
                         DEPENDENCIES, _nrt=False)


@_njit
def state_kernel(t, z, y, model, data, inputs, zrow, cflags, cwork):
    """The package's state y (model size) of z at t: what canonical.CanonicalChain.state does."""
    _rates(t, z, model, data, inputs, zrow, cflags, cwork)
    (is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
     torque_axis, torque_A, flags, base, armature, spring, servo, motor, is_slide, parent) = model
    i_kap, size = cflags[1], cflags[2]
    i_kap_y = flags[5]
    for i in range(size):
        y[i] = cwork[i]
    for i in range(torque_body.shape[0]):
        y[i_kap_y + i] = z[i_kap + i]


def canonical_workspace(model, size: int) -> np.ndarray:
    """`cwork`: the package's state (model.size), then CWORK_PER_COLUMN N + CWORK_PER_BODY n, and
    a tree's sums (TREE_BLOCKS blocks of 3 n)."""
    per_body = CWORK_PER_BODY + (0 if model.chain else 3 * TREE_BLOCKS)
    return np.zeros(model.size + CWORK_PER_COLUMN * model.N + per_body * model.n)


class FastCanonicalChain(CanonicalChain):
    """CanonicalChain with the field and `state` compiled (`canonical_kernel`, `state_kernel`)
    over a :class:`gyro_sim.dynamics.system.FastChainODE` (its kernel arguments, held inputs and
    workspace); `momenta` stays numpy (once per run of `advance` calls). Offers
    `kernel_arguments()` and `quaternion_block()`, so gauss4's compiled march steps it."""

    def __init__(self, ode):
        super().__init__(ode)
        m = self.model
        zrow = np.empty((m.n, 2), dtype=np.int64)
        zrow[m.sph_bodies, 0] = self.i_quat[:, 0]
        zrow[m.sph_bodies, 1] = self.i_pq[:, 0]
        zrow[m.hinge_bodies, 0] = self.i_phi.start + np.arange(len(m.hinge_bodies))
        zrow[m.hinge_bodies, 1] = self.i_pphi.start + np.arange(len(m.hinge_bodies))
        # cflags[CFLAG_KERNEL]: set by the first `kernel_arguments` (the C function compiled, or
        # loaded, when a compiled march first needs it: "fixed" builds a gauss4s it may never run)
        cflags = np.array([self.i_pr.start, self.i_kappa.start, m.size, 0], dtype=np.int64)
        self._extra = (zrow, cflags, canonical_workspace(m, self.size))
        self._field = jit.Direct(canonical_kernel)
        self._state = jit.Direct(state_kernel)

    def kernel_arguments(self) -> tuple:
        """`canonical_kernel`'s arguments after (t, z, out): the chain kernel's, then zrow,
        cflags, cwork. Valid until the next `hold`."""
        cflags = self._extra[1]
        if not cflags[CFLAG_KERNEL]:
            cflags[CFLAG_KERNEL] = canonical_address()
        return (*self.ode.kernel_arguments(), *self._extra)

    def quaternion_block(self) -> tuple[int, int]:
        """(0, 0): nothing to normalise (see `CanonicalChain.project`)."""
        return 0, 0

    def rhs(self, t: float, z: np.ndarray) -> np.ndarray:
        self.nfev += 1
        out = np.empty(self.size)
        self._field(float(t), z, out, *self.kernel_arguments())
        return out

    def state(self, t: float, z: np.ndarray) -> np.ndarray:
        y = np.empty(self.model.size)
        self._state(float(t), np.ascontiguousarray(z, dtype=np.float64), y, *self.kernel_arguments())
        return y
