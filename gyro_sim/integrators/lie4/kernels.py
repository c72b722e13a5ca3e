"""The arithmetic of a step of the commutator-free Lie group method CF4 (lie4), compiled with
numba.

One implementation, two drivers, as :mod:`gyro_sim.integrators.rk4.kernels`:
:class:`gyro_sim.integrators.lie4.driver.Lie4` calls these between its rhs evaluations on any
system (the numpy reference among them), and the compiled loop
:func:`gyro_sim.integrators.lie4.loop.lie_march` calls the same functions between calls of the
articulated-body kernel: both take the same steps bit for bit (test/integrators/test_lie4.py).
The method's coefficients are data (the class attributes of `Lie4`: ALPHA, BASE, BETA1,
BETA2, B, C).

The group acts on the state y (n,): a quaternion block q = y[qi[b]] (qi (nq, 4)) by
q <- exp(theta) (x) q, theta a world-frame rotation vector; every other component y[li]
(li (nl,)) by translation y <- y + d. A stage's vector field in the algebra is stored as
W[s] (nq, 3), the world angular velocity omega = 2 vec(q' (x) conj(q)) of each block, and
V[s] (nl,), the rest of y'.

    lie_field:  W[s], V[s] from the rhs f at the state Y[s]
    lie_stage:  Y[s] = exp(sum_{j<s} hALPHA[s, j] (W[j], V[j])) Y[base]
    lie_update: y <- exp(sum_j hBETA[2, j] W[j]) exp(sum_j hBETA[1, j] W[j]) y on the
                quaternions (the right one acts first), y + sum_j hBETA[0, j] V[j] elsewhere

Every sum runs over j in increasing order, one product added at a time. `quat_exp` is the
exponential both drivers use (rotations.quat_exp is its numpy reference, in the same
operations). No fastmath: IEEE arithmetic, no contraction into fused multiply-adds. Without
numba these stay plain Python (correct, slow).
"""
from __future__ import annotations

import math

from gyro_sim.jit import njit

#: below this angle (rad) sin(a/2)/a is its series 1/2 - a^2/48 (as rotations.quat_exp)
SMALL_ANGLE = 1e-8


@njit
def quat_exp(tx, ty, tz):
    """The unit quaternion exp(theta / 2) (w, x, y, z) of the rotation vector theta = (tx, ty,
    tz): rotations.quat_exp of one vector, in the same operations."""
    angle = math.sqrt(tx * tx + ty * ty + tz * tz)
    half = 0.5 * angle
    if angle < SMALL_ANGLE:
        scale = 0.5 - angle**2 / 48.0
    else:
        scale = math.sin(half) / angle
    return math.cos(half), scale * tx, scale * ty, scale * tz


@njit
def quat_left(aw, ax, ay, az, q, i):
    """q[i] (4 consecutive indices i[0..3]) = a (x) q[i]: the Hamilton product of
    rotations.quat_mul, in its operations."""
    bw, bx, by, bz = q[i[0]], q[i[1]], q[i[2]], q[i[3]]
    q[i[0]] = aw * bw - ax * bx - ay * by - az * bz
    q[i[1]] = aw * bx + ax * bw + ay * bz - az * by
    q[i[2]] = aw * by - ax * bz + ay * bw + az * bx
    q[i[3]] = aw * bz + ax * by - ay * bx + az * bw


@njit
def lie_field(Y, f, s, qi, li, W, V):
    """The field of stage s from f (n,) = rhs at Y[s] (Y (stages, n)): W[s, b] (3,) = 2 vec(q'
    (x) conj(q)) of every quaternion block q = Y[s, qi[b]], q' = f[qi[b]]; V[s] (nl,) =
    f[li]."""
    for b in range(qi.shape[0]):
        i0, i1, i2, i3 = qi[b, 0], qi[b, 1], qi[b, 2], qi[b, 3]
        qw, qx, qy, qz = Y[s, i0], Y[s, i1], Y[s, i2], Y[s, i3]
        aw, ax, ay, az = f[i0], f[i1], f[i2], f[i3]
        # vec(a (x) conj(q)), conj(q) = (qw, -qx, -qy, -qz)
        W[s, b, 0] = 2.0 * (-aw * qx + ax * qw - ay * qz + az * qy)
        W[s, b, 1] = 2.0 * (-aw * qy + ax * qz + ay * qw - az * qx)
        W[s, b, 2] = 2.0 * (-aw * qz - ax * qy + ay * qx + az * qw)
    for i in range(li.shape[0]):
        V[s, i] = f[li[i]]


@njit
def lie_stage(Y, W, V, hALPHA, s, base, qi, li):
    """Y[s] (n,) = exp(sum_{j<s} hALPHA[s, j] (W[j], V[j])) Y[base]: the state of stage s.
    Y (stages, n), W (stages, nq, 3), V (stages, nl), hALPHA (stages, stages) = h ALPHA;
    base < s."""
    for b in range(qi.shape[0]):
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        for j in range(s):
            a = hALPHA[s, j]
            t0 += a * W[j, b, 0]
            t1 += a * W[j, b, 1]
            t2 += a * W[j, b, 2]
        ew, ex, ey, ez = quat_exp(t0, t1, t2)
        for c in range(4):
            Y[s, qi[b, c]] = Y[base, qi[b, c]]
        quat_left(ew, ex, ey, ez, Y[s], qi[b])
    for i in range(li.shape[0]):
        acc = 0.0
        for j in range(s):
            acc += hALPHA[s, j] * V[j, i]
        Y[s, li[i]] = Y[base, li[i]] + acc


@njit
def lie_update(y, W, V, hBETA, qi, li):
    """The step's result in place: y (n,) <- exp(sum_j hBETA[2, j] W[j]) exp(sum_j hBETA[1, j]
    W[j]) y on every quaternion block (the right exponential acts first), y[li] += sum_j
    hBETA[0, j] V[j] (the two exponentials commute there). hBETA (3, stages) = h (B, BETA1,
    BETA2)."""
    stages = hBETA.shape[1]
    for i in range(li.shape[0]):
        acc = 0.0
        for j in range(stages):
            acc += hBETA[0, j] * V[j, i]
        y[li[i]] += acc
    for b in range(qi.shape[0]):
        for r in range(1, 3):
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            for j in range(stages):
                a = hBETA[r, j]
                t0 += a * W[j, b, 0]
                t1 += a * W[j, b, 1]
                t2 += a * W[j, b, 2]
            ew, ex, ey, ez = quat_exp(t0, t1, t2)
            quat_left(ew, ex, ey, ez, y, qi[b])


@njit
def lie_start(y, Y):
    """Y[0] (n,) = y: the first stage's state."""
    for i in range(y.shape[0]):
        Y[0, i] = y[i]
