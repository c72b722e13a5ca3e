"""Rotations: unit quaternions (w, x, y, z), rotation matrices and the paper's Euler angles.

Quaternions are world-from-body and stored w first. Functions accept stacks: a quaternion
array of shape (..., 4) gives matrices of shape (..., 3, 3). Also the home of the quaternion
rates q' = 1/2 (0, w) (x) q (`quat_rates`) and of the row-wise cross product (`cross`).

Euler angles are the paper's z-x-z angles (psi, theta, phi) relative to the "down" frame,
whose z-axis is nu, the unit gravity direction (docs/scene-format.md; docs/theory.md section 6):

    world_R_body = world_R_down Rz(psi) Rx(theta) Rz(phi),  world_R_down e_z = nu

For nu = -e_z, world_R_down = Rx(pi). Euler angles are an output only; the state never
holds them.
"""
from __future__ import annotations

import numpy as np

DEFAULT_DOWN = np.array([0.0, 0.0, -1.0])
#: below this sin(theta) the Euler angles psi and phi are not separable
EULER_SINGULAR_SIN = 1e-9

_P = np.array([1, 2, 0])
_Q = np.array([2, 0, 1])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (..., 3) arrays (np.cross is several times slower on small stacks)."""
    return a.take(_P, -1) * b.take(_Q, -1) - a.take(_Q, -1) * b.take(_P, -1)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a (x) b of quaternions of shape (..., 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_rates(q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """q' = 1/2 (0, w) (x) q (n, 4) of quaternions q (n, 4), world from body, turning with the
    angular velocities w (n, 3) in world components.

    The numba kernel's scalar twin is `gyro_sim.dynamics.kernel._quat_rate`, in the same operations.
    """
    qd = np.empty_like(q)
    qd[:, 0] = -0.5 * np.einsum("ni,ni->n", w, q[:, 1:])
    qd[:, 1:] = 0.5 * (q[:, :1] * w + cross(w, q[:, 1:]))
    return qd


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion), shape (..., 4)."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _quat_outer_map() -> np.ndarray:
    """(16, 9) map from the outer product q q^T (flattened) to |q|^2 R (flattened)."""
    terms = {  # R[i, j] = sum of c q_a q_b over (a, b, c); indices w=0, x=1, y=2, z=3
        (0, 0): [(0, 0, 1), (1, 1, 1), (2, 2, -1), (3, 3, -1)],
        (0, 1): [(1, 2, 2), (0, 3, -2)],
        (0, 2): [(1, 3, 2), (0, 2, 2)],
        (1, 0): [(1, 2, 2), (0, 3, 2)],
        (1, 1): [(0, 0, 1), (1, 1, -1), (2, 2, 1), (3, 3, -1)],
        (1, 2): [(2, 3, 2), (0, 1, -2)],
        (2, 0): [(1, 3, 2), (0, 2, -2)],
        (2, 1): [(2, 3, 2), (0, 1, 2)],
        (2, 2): [(0, 0, 1), (1, 1, -1), (2, 2, -1), (3, 3, 1)],
    }
    M = np.zeros((16, 9))
    for (i, j), row in terms.items():
        for a, b, c in row:
            M[4 * a + b, 3 * i + j] += c
    return M


_QUAT_OUTER = _quat_outer_map()


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4).

    The homogeneous form (|q|^2 R is quadratic in q) divided by |q|^2, so the result is a
    rotation even for the slightly non-unit quaternions of intermediate integrator stages.
    The numba kernel's scalar twin is `gyro_sim.dynamics.kernel._quat_to_matrix`.
    """
    q = np.asarray(q)
    q = q.astype(np.result_type(q, float), copy=False)  # complex too (linearisation's complex step)
    qq = q[..., :, None] * q[..., None, :]
    R = (qq.reshape(q.shape[:-1] + (16,)) @ _QUAT_OUTER).reshape(q.shape[:-1] + (3, 3))
    return R / np.einsum("...i,...i->...", q, q)[..., None, None]


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) with w >= 0 of a rotation matrix (3, 3) (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    d = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    i = int(np.argmax(d))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                      (R[1, 0] - R[0, 1]) / (4 * w)])
    elif i == 1:
        x = 0.5 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x),
                      (R[0, 2] + R[2, 0]) / (4 * x)])
    elif i == 2:
        y = 0.5 * np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y,
                      (R[1, 2] + R[2, 1]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q = np.array([(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z),
                      (R[1, 2] + R[2, 1]) / (4 * z), z])
    q = q / np.linalg.norm(q)
    return q if q[0] >= 0.0 else -q


def quat_exp(theta: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation vectors theta (..., 3): exp(theta / 2)."""
    theta = np.asarray(theta, dtype=float)
    angle = np.linalg.norm(theta, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(a/2)/a, with its series near 0
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), scale * theta], axis=-1)


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by `angle` about the unit vector `axis` (Rodrigues)."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def down_frame(nu: np.ndarray | None) -> np.ndarray:
    """world_R_down (3, 3): columns x_d, y_d, z_d = nu; equals Rx(pi) for nu = -e_z.

    `nu` is the unit gravity direction (None: no gravity, the down axis is -z of the world).
    """
    nu = DEFAULT_DOWN if nu is None else np.asarray(nu, dtype=float) / np.linalg.norm(nu)
    ex = np.array([1.0, 0.0, 0.0])
    x = ex - nu * (ex @ nu)
    if np.linalg.norm(x) < 1e-6:  # gravity along x: take y as the reference
        ey = np.array([0.0, 1.0, 0.0])
        x = ey - nu * (ey @ nu)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(nu, x), nu])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def euler_to_matrix(euler: np.ndarray, down: np.ndarray) -> np.ndarray:
    """world_R_body (3, 3) of Euler angles (psi, theta, phi); `down` = down_frame(nu)."""
    psi, theta, phi = euler
    return down @ _rz(psi) @ _rx(theta) @ _rz(phi)


def euler_rates_to_omega(euler: np.ndarray, rates: np.ndarray, down: np.ndarray) -> np.ndarray:
    """World-frame angular velocity (3,) from Euler angles and rates.

    w = psi' nu + theta' (line of nodes) + phi' eps  (docs/theory.md section 6).
    """
    psi, theta, _ = euler
    dpsi, dtheta, dphi = rates
    nodes = down @ np.array([np.cos(psi), np.sin(psi), 0.0])
    eps = down @ np.array([np.sin(psi) * np.sin(theta), -np.cos(psi) * np.sin(theta), np.cos(theta)])
    return dpsi * down[:, 2] + dtheta * nodes + dphi * eps


def matrix_to_euler(R: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Euler angles (psi, theta, phi) of world_R_body; theta in [0, pi], psi, phi in (-pi, pi].

    At theta = 0 or pi only psi +- phi is defined: phi is then reported as 0.
    """
    D = down.T @ R  # = Rz(psi) Rx(theta) Rz(phi)
    theta = float(np.arccos(np.clip(D[2, 2], -1.0, 1.0)))
    if np.hypot(D[0, 2], D[1, 2]) < EULER_SINGULAR_SIN:
        # D = Rz(psi +- phi) (with a flip about x for theta = pi): put the whole turn in psi
        return np.array([np.arctan2(D[1, 0], D[0, 0]), theta, 0.0])
    psi = float(np.arctan2(D[0, 2], -D[1, 2]))
    phi = float(np.arctan2(D[2, 0], D[2, 1]))
    return np.array([psi, theta, phi])


def omega_to_euler_rates(euler: np.ndarray, omega: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Euler rates (psi', theta', phi') from Euler angles and world angular velocity.

    Singular at sin(theta) = 0, where phi' is reported as 0 and psi' takes the whole spin.
    """
    psi, theta, _ = euler
    wx, wy, wz = down.T @ omega
    c, s = np.cos(psi), np.sin(psi)
    dtheta = wx * c + wy * s
    st = np.sin(theta)
    dphi = (wx * s - wy * c) / st if abs(st) > EULER_SINGULAR_SIN else 0.0
    dpsi = wz - dphi * np.cos(theta)
    return np.array([dpsi, dtheta, dphi])


def matrices_to_euler(R: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Euler angles (n, 3) of a stack of world_R_body (n, 3, 3); as :func:`matrix_to_euler`."""
    D = down.T @ R
    theta = np.arccos(np.clip(D[:, 2, 2], -1.0, 1.0))
    regular = np.hypot(D[:, 0, 2], D[:, 1, 2]) >= EULER_SINGULAR_SIN
    psi = np.where(regular, np.arctan2(D[:, 0, 2], -D[:, 1, 2]), np.arctan2(D[:, 1, 0], D[:, 0, 0]))
    phi = np.where(regular, np.arctan2(D[:, 2, 0], D[:, 2, 1]), 0.0)
    return np.stack([psi, theta, phi], axis=1)


def omegas_to_euler_rates(euler: np.ndarray, omega: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Euler rates (n, 3) from Euler angles (n, 3) and world angular velocities (n, 3)."""
    psi, theta = euler[:, 0], euler[:, 1]
    w = omega @ down  # rows: down.T @ omega_k
    c, s = np.cos(psi), np.sin(psi)
    dtheta = w[:, 0] * c + w[:, 1] * s
    st = np.sin(theta)
    regular = np.abs(st) > EULER_SINGULAR_SIN
    dphi = np.where(regular, (w[:, 0] * s - w[:, 1] * c) / np.where(regular, st, 1.0), 0.0)
    dpsi = w[:, 2] - dphi * np.cos(theta)
    return np.stack([dpsi, dtheta, dphi], axis=1)
