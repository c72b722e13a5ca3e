"""Chain dynamics: eqs (34)-(54) of the paper as a world-frame Newton-Euler recursion.

Pipeline of one evaluation (MuJoCo-style stages, each filling `Data`):
    positions   q        -> R^k, O^k, world vectors            (eqs 34, 50 for hinges; slides: section 12)
    velocities  q, u     -> w^k, v0^k                          (eqs 34-35, 50, 53)
    bias        q, u, t  -> body forces at zero acceleration   (eqs 36-39, 58)
    mass matrix q        -> M                                  (the part of (52)-(54) linear in u')
    solve       M u' = tau - C                                 (eqs 52-54 closed: 44, 51)
    reactions   u'       -> R^k (40), L^k (48)                 (only when asked for)

All vectors are world components, spatial quantities about the world origin (angular part
first). For body p with mass m, first moment h = m r_c about the origin and inertia J about
the origin, the momentum of velocity (w, v_o) (v_o: velocity of the body point at the origin)
is (J w + h x v_o + lambda, m v_o + w x h): the gyrostatic moment lambda (eq 31) is a free
vector added to the angular momentum, as in eq (32).

A subtree sum of (rate of momentum - external force) is exactly the paper's joint reaction:
its linear part is R^k (eq 40), its moment about O^k is L^k (eq 48). The closure rows are
then the joint kinds: spherical L^k = 0 (eq 44), hinge e^k . L^k = L_k(t) (eq 51), free base
R^1 = 0 and L^1 = 0 (eq 54). Each row is S_j . F_subtree(k(j)) for the joint's unit motions
S_j (a rotation about O^k, or a translation), so the rows are affine in u' and the matrix is
the symmetric composite-inertia matrix (docs/theory.md section 5).

Every stage but the mass matrix and the reactions also takes a stack of states (leading axes
before the bodies' axis: y of shape (..., size)), evaluated at once by the same operations, the
same values as one at a time; the linearisation passes all its complex-step directions so.
"""
from __future__ import annotations

import numpy as np

from gyro_sim.dynamics.model import Model
from gyro_sim.dynamics.rotations import cross, quat_to_matrix

EYE3 = np.eye(3)


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Stacked matrix-vector products (n, 3, 3) x (n, 3) -> (n, 3)."""
    return (A @ x[..., None])[..., 0]


#: the chain's axis reversed, for the axes `rcumsum` takes (0, or -2: the bodies before (3,))
_REVERSED = {0: (slice(None, None, -1),), -2: (Ellipsis, slice(None, None, -1), slice(None))}


def rcumsum(a: np.ndarray, axis: int = 0) -> np.ndarray:
    """Suffix sums over the chain (its axis `axis`, 0 or -2): out[k] = sum_{p >= k} a[p] (the
    sums of eq 48): prefix sums of the reversed view, reversed (np.flip's views, without its
    per-call axis checks: this runs several times per evaluation)."""
    rev = _REVERSED[axis]
    return a[rev].cumsum(axis)[rev]


def _body_axis(a: np.ndarray, axis: int, k: int) -> tuple:
    """The index of body k along the bodies' axis `axis` (0 or -2) of a."""
    return (k,) if axis == 0 else (Ellipsis, k, slice(None))


def subtree_sum(model: Model, a: np.ndarray, axis: int = 0) -> np.ndarray:
    """Sums over each body's subtree (docs/theory.md section 11: eqs 40, 48T), along the bodies'
    axis `axis` (0 or -2): out[k] = sum_{p in sub(k)} a[p]; a chain's suffix sums (`rcumsum`)."""
    if model.chain:
        return rcumsum(a, axis)
    out = np.array(a, copy=True)
    for k in range(model.n - 1, -1, -1):  # children before parents
        q = model.parent[k]
        if q >= 0:
            out[_body_axis(out, axis, q)] += out[_body_axis(out, axis, k)]
    return out


def path_sum(model: Model, a: np.ndarray) -> np.ndarray:
    """Sums over the path from the base to each body along the bodies' axis -2 (eqs 34, 53 on a
    tree): out[k] = a[k] + out[parent(k)]; a chain's prefix sums (cumsum)."""
    if model.chain:
        return a.cumsum(-2)
    out = np.array(a, copy=True)
    for k in range(model.n):  # parents before children
        q = model.parent[k]
        if q >= 0:
            out[..., k, :] += out[..., q, :]
    return out


def of_parents(model: Model, a: np.ndarray) -> np.ndarray:
    """a[..., parent(k), :] for every body k along the axis -2, zero for a body on the base."""
    out = np.zeros(a.shape, dtype=a.dtype)
    if model.chain:
        out[..., 1:, :] = a[..., :-1, :]
        return out
    on_body = model.parent >= 0
    out[..., on_body, :] = a[..., model.parent[on_body], :]
    return out


class Data:
    """Workspace of one evaluation; its fields are the results of the last stage run."""

    def __init__(self, model: Model):
        n = model.n
        self.R = np.zeros((n, 3, 3))  # world_R_body
        self.R[:] = EYE3
        self.O = np.zeros((n, 3))  # joint points O^k
        # torque-rotor incidence: lambda^k = sum over rotors on k (eq 31)
        self.rotor_incidence = np.zeros((n, len(model.torque_body)))
        self.rotor_incidence[model.torque_body, np.arange(len(model.torque_body))] = 1.0
        self.hinge_K = np.array([_skew(model.hinge_axis[k]) for k in model.hinge_bodies]).reshape(-1, 3, 3)
        self.hinge_K2 = self.hinge_K @ self.hinge_K
        self.sph_axes = np.tile(EYE3, (len(model.sph_bodies), 1))  # a spherical joint's unit motions (joint_columns)
        # each hinge's parent (a motor's rotor is on it; a row without motor points at body 0 and
        # is zero)
        self.motor_parent = np.maximum(model.parent[model.hinge_bodies], 0)


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def base_motion(model: Model, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, acceleration of a moving base O^1(t) = position + a sin(W t)."""
    W, a = model.base_omega, model.base_amplitude
    return (model.base_position + a * np.sin(W * t), a * W * np.cos(W * t), -a * W * W * np.sin(W * t))


def positions(model: Model, data: Data, t: float, y: np.ndarray) -> None:
    """R^k and O^k of every body; eq (34) summed: O^k = O^1 + sum_{l<k} s^l."""
    R = data.R
    lead = np.shape(y)[:-1]  # a stack of states: its leading axes
    if R.dtype != np.result_type(y, float) or R.shape[:-3] != lead:
        # a complex y (linearisation's complex step) or a stack: a workspace of its type and shape
        R = data.R = np.tile(EYE3.astype(np.result_type(y, float)), lead + (model.n, 1, 1))
    if len(model.sph_bodies):
        R[..., model.sph_bodies, :, :] = quat_to_matrix(y[..., model.i_quat])
    if len(model.hinge_bodies):
        phi = y[..., model.i_phi]
        # (50): body k is its parent turned by phi_k about e^k
        Rrel = (EYE3 + np.sin(phi)[..., None, None] * data.hinge_K
                + (1.0 - np.cos(phi))[..., None, None] * data.hinge_K2)
        for i, k in enumerate(model.hinge_bodies):
            q = model.parent[k]
            if model.hinge_slide[i]:  # a slide keeps its parent's orientation (section 12)
                R[..., k, :, :] = EYE3 if q < 0 else R[..., q, :, :]
                continue
            R[..., k, :, :] = Rrel[..., i, :, :] if q < 0 else R[..., q, :, :] @ Rrel[..., i, :, :]
    if model.free:
        O1 = y[..., model.i_r0][..., None, :]
    elif model.moving:
        O1 = base_motion(model, t)[0]
    else:
        O1 = model.base_position
    if model.chain:
        s_w = matvec(R, model.s)
        data.O = O1 + s_w.cumsum(-2) - s_w
    else:  # (34) on a tree: O^k = O^{parent(k)} + R^{parent(k)} s^{parent(k),k}
        R_parent = np.array(R, copy=True)
        on_base = model.parent < 0
        R_parent[..., on_base, :, :] = EYE3
        R_parent[..., ~on_base, :, :] = R[..., model.parent[~on_base], :, :]
        data.O = O1 + path_sum(model, matvec(R_parent, model.offset))
    if len(model.slide_bodies):  # a slide moves O^k (and the bodies after it) by e^k d_k
        sl = model.slide_bodies
        d_w = np.zeros(R.shape[:-1], dtype=R.dtype)
        d_w[..., sl, :] = (matvec(R[..., sl, :, :], model.hinge_axis[sl])
                           * y[..., model.i_phi][..., model.hinge_slide][..., None])
        data.O = data.O + path_sum(model, d_w)
    hk = matvec(R, model.first_moment)  # m^k c^k, world components
    data.h = model.mass[:, None] * data.O + hk  # first moments about the origin
    data.e_w = matvec(R[..., model.hinge_bodies, :, :], model.hinge_axis[model.hinge_bodies])  # hinge axes
    if model.motor is not None:  # m = J G a of each hinge's motor, world components (its parent's R)
        J, G = model.motor[:, 0], model.motor[:, 1]
        data.motor_w = matvec(R[..., data.motor_parent, :, :], (J * G)[:, None] * model.motor[:, 2:])
    # inertia about the origin: J_O^k (rotated) shifted from O^k to the origin
    A_w = R @ model.inertia @ R.swapaxes(-1, -2)
    O = data.O
    m = model.mass
    OO = O[..., :, None] * O[..., None, :]  # outer products: one product per entry
    Oh = O[..., :, None] * hk[..., None, :]
    dd = np.einsum("...ni,...ni->...n", O, O)
    dh = np.einsum("...ni,...ni->...n", O, hk)
    data.J = (
        A_w
        + m[:, None, None] * (dd[..., None, None] * EYE3 - OO)
        + (2.0 * dh)[..., None, None] * EYE3
        - Oh
        - Oh.swapaxes(-1, -2)
    )


def velocities(model: Model, data: Data, t: float, u: np.ndarray) -> None:
    """Angular velocities w^k (prefix sums of joint rates, eqs 50, 53) and velocities of O^k (eq 34)."""
    n = model.n
    lead = np.shape(u)[:-1]
    wrel = np.zeros(lead + (n, 3), dtype=np.result_type(u, data.R))
    if len(model.sph_bodies):
        wrel[..., model.sph_bodies, :] = u[..., model.col_sph]
    if len(model.hinge_bodies):
        wrel[..., model.hinge_bodies, :] = data.e_w * u[..., model.col_hinge][..., None]  # (50): e^k phi_k'
    vrel = None
    if len(model.slide_bodies):  # a slide: no rotation, the translation e^k d_k' (section 12)
        vrel = np.zeros(wrel.shape, dtype=wrel.dtype)
        vrel[..., model.slide_bodies, :] = wrel[..., model.slide_bodies, :]
        wrel[..., model.slide_bodies, :] = 0.0
    w = path_sum(model, wrel)
    O = data.O
    v_o = path_sum(model, cross(O, wrel))  # velocity of the body point at the origin
    if vrel is not None:
        v_o = v_o + path_sum(model, vrel)
    data.vrel = vrel
    if model.free:
        v_o += u[..., model.col_base][..., None, :]
    elif model.moving:
        v_o += base_motion(model, t)[1]
    data.wrel, data.w, data.v_o = wrel, w, v_o
    data.hinge_rate = u[..., model.col_hinge]
    data.vO = v_o + cross(w, O)  # (34): velocity of O^k
    data.w_parent = of_parents(model, w)


def torque_rotor_rates(model: Model, data: Data, p: np.ndarray) -> np.ndarray:
    """kappa_i' = p_i - w^k . e_i (eqs 18-19): the angle rates (nt,) of the torque rotors
    relative to their bodies, from their absolute spins p (nt,) and the velocities in `data`.

    The numba kernel's scalar twin is `gyro_sim.dynamics.kernel._rotor_angle_rate`.
    """
    e_w = matvec(data.R[..., model.torque_body, :, :], model.torque_axis)
    return p - np.einsum("...ni,...ni->...n", data.w[..., model.torque_body, :], e_w)


def lam(model: Model, data: Data, p: np.ndarray | None, L_rotor: np.ndarray | None):
    """Gyrostatic moments lambda^k (eq 31) and their rates, world frame, or (None, None).

    A hinge's geared motor adds J G phi_k' a to its parent's lambda (its rotor's spin relative
    to the parent, eq 31 with kappa' = G phi_k'); the rate of that, J G phi_k'' a, is linear in
    the accelerations and so is left to the mass matrix (`mass_matrix`, `motor_forces`)."""
    lam_w, dlam_w = rotor_lam(model, data, p, L_rotor)
    if model.motor is None:
        return lam_w, dlam_w
    motor = motor_forces(model, data, data.hinge_rate)
    return (motor if lam_w is None else lam_w + motor), dlam_w


def motor_forces(model: Model, data: Data, rates: np.ndarray) -> np.ndarray:
    """(n, 3), world: the moments m_k x rates_k of the hinges' motors (m_k = J G a, `positions`)
    summed on their parents: lambda of the motors for the joint rates, the part of lambda' linear
    in the accelerations for the joint accelerations (a stack too)."""
    moments = data.motor_w * rates[..., None]  # one configuration may serve a stack of rates
    f = np.zeros(moments.shape[:-2] + (model.n, 3), dtype=moments.dtype)
    np.add.at(np.moveaxis(f, -2, 0), data.motor_parent, np.moveaxis(moments, -2, 0))
    return f


def rotor_lam(model: Model, data: Data, p: np.ndarray | None, L_rotor: np.ndarray | None):
    """lambda^k and lambda^k' of the rotors (eqs 29, 31), world frame, or (None, None)."""
    lam_b = model.lam_speed.copy() if model.lam_speed is not None else None
    dlam_b = None
    if len(model.torque_body):
        lt = data.rotor_incidence @ ((model.torque_A * p)[..., None] * model.torque_axis)
        lam_b = lt if lam_b is None else lam_b + lt
        if L_rotor is not None:
            # (29): A_i p_i' = L_i
            dlam_b = data.rotor_incidence @ (L_rotor[..., None] * model.torque_axis)
    if lam_b is None:
        return None, None
    return matvec(data.R, lam_b), (None if dlam_b is None else matvec(data.R, dlam_b))


def body_forces(model: Model, data: Data, acc_w: np.ndarray, acc_v: np.ndarray, lam_w, dlam_w):
    """Rate of momentum minus external force of each body, about the origin (eqs 36-39).

    f = I A + V x* (I V + (lambda, 0)) + (lambda', 0) - (h x g, m g)
    """
    m, h, J, w, v = model.mass, data.h, data.J, data.w, data.v_o
    mom_ang = matvec(J, w) + cross(h, v)
    mom_lin = m[:, None] * v + cross(w, h)
    if lam_w is not None:
        mom_ang = mom_ang + lam_w
    f_ang = matvec(J, acc_w) + cross(h, acc_v) + cross(w, mom_ang) + cross(v, mom_lin)
    f_lin = m[:, None] * acc_v + cross(acc_w, h) + cross(w, mom_lin)
    if dlam_w is not None:
        f_ang += dlam_w
    if model.gravity is not None:
        f_ang -= cross(h, model.gravity[None, :])
        f_lin -= m[:, None] * model.gravity
    return f_ang, f_lin


def bias_accelerations(model: Model, data: Data, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Spatial accelerations of the bodies at u' = 0: prefix sums of S_j' u_j.

    Spherical joint (world-component axes a through O^k): S' u = (0, v(O^k) x w_rel).
    Hinge: e^k' = w^{k-1} x e^k, so S' u = (w^{k-1} x e^k phi', v(O^k) x e^k phi' + O^k x (w^{k-1} x e^k) phi').
    Slide: S = (0, e^k), so S' u = (0, w^{k-1} x e^k d_k').
    """
    da = cross(data.w_parent, data.wrel)
    da[..., model.sph_bodies, :] = 0.0  # spherical joints: world-component axes do not turn
    dv = cross(data.vO, data.wrel) + cross(data.O, da)
    if data.vrel is not None:  # a slide's axis turns with its parent: S' u = (0, w^{k-1} x e^k d_k')
        dv = dv + cross(data.w_parent, data.vrel)
    acc_w = path_sum(model, da)
    acc_v = path_sum(model, dv)
    if model.moving:
        acc_v += base_motion(model, t)[2]
    return acc_w, acc_v


def joint_columns(model: Model, data: Data) -> tuple[np.ndarray, np.ndarray]:
    """Unit motions S_j (angular, linear-at-origin) of every velocity column, (N, 3) each."""
    Sa = np.zeros(data.R.shape[:-3] + (model.N, 3), dtype=data.R.dtype)
    Sa[..., model.col_sph.ravel(), :] = data.sph_axes
    Sa[..., model.col_hinge, :] = data.e_w
    Sb = cross(data.O[..., model.col_body, :], Sa)
    if len(model.slide_bodies):  # a slide's unit motion is the translation (0, e^k) (section 12)
        cols = model.col_hinge[model.hinge_slide]
        Sb[..., cols, :] = Sa[..., cols, :]
        Sa[..., cols, :] = 0.0
    if model.free:
        Sb[..., model.col_base, :] = EYE3
    return Sa, Sb


def mass_matrix(model: Model, data: Data, Sa: np.ndarray, Sb: np.ndarray) -> np.ndarray:
    """M_ij = S_i . I^C_{max(k_i, k_j)} S_j with I^C_k the composite inertia of bodies k..n (on
    a tree, of the deeper body's subtree, and zero unless one body is the other's ancestor:
    docs/theory.md section 11)."""
    JC = subtree_sum(model, data.J)[model.col_body]
    hC = subtree_sum(model, data.h)[model.col_body]
    mC = subtree_sum(model, model.mass)[model.col_body]
    F_ang = matvec(JC, Sa) + cross(hC, Sb)
    F_lin = mC[:, None] * Sb + cross(Sa, hC)
    Mfull = Sa @ F_ang.T + Sb @ F_lin.T
    M = np.where(model.col_upper, Mfull, Mfull.T)
    if not model.chain:  # branch-induced sparsity
        M = np.where(model.col_related, M, 0.0)
    if model.armature is not None:  # a reflected rotor inertia on its hinge's own diagonal
        M[model.col_hinge, model.col_hinge] += model.armature
    if model.motor is not None:
        # a geared motor: T gains phi_k' (m . w^{k-1}) + 1/2 J G^2 phi_k'^2, w^{k-1} the sum of
        # Sa_j u_j over the columns of bodies up to the parent
        J, G = model.motor[:, 0], model.motor[:, 1]
        col = model.col_hinge  # a hinge without motor: m = 0
        coupling = (Sa @ data.motor_w.T) * model.ancestor[data.motor_parent[None, :], model.col_body[:, None]]
        M[:, col] += coupling
        M[col, :] += coupling.T
        M[col, col] += J * G * G
    return M


def mass_times(model: Model, data: Data, Sa: np.ndarray, Sb: np.ndarray, udot: np.ndarray) -> np.ndarray:
    """M u' without forming M (the inertial part of body_forces, linear in the accelerations,
    projected as the rows of eqs 52-54 are): O(n), for a stack of states too."""
    acc_w, acc_v = accelerations_from(model, data, Sa, Sb, udot, 0.0, 0.0)
    f_ang = matvec(data.J, acc_w) + cross(data.h, acc_v)
    f_lin = model.mass[:, None] * acc_v + cross(acc_w, data.h)
    if model.motor is not None:  # the motors' J G phi'' a on their parents
        f_ang = f_ang + motor_forces(model, data, udot[..., model.col_hinge])
    out = project_subtree(model, Sa, Sb, f_ang, f_lin)
    if model.armature is not None:
        out[..., model.col_hinge] += model.armature * udot[..., model.col_hinge]
    if model.motor is not None:
        out[..., model.col_hinge] += motor_row(model, data, acc_w, udot[..., model.col_hinge])
    return out


def motor_row(model: Model, data: Data, acc_w: np.ndarray, hinge_udot: np.ndarray) -> np.ndarray:
    """(nh,): what the geared motors add to their hinges' rows of eqs (51)-(52), J G times the
    rate of the rotor's absolute spin, J G (a . w^{k-1}' + G phi_k'') = m . w^{k-1}' + J G^2
    phi_k'' (eq 51b), for the bodies' angular accelerations acc_w (n, 3) (a stack too)."""
    J, G = model.motor[:, 0], model.motor[:, 1]
    parent = acc_w[..., data.motor_parent, :]
    return np.einsum("...ni,...ni->...n", data.motor_w, parent) + J * G * G * hinge_udot


def project_subtree(model: Model, Sa, Sb, f_ang, f_lin) -> np.ndarray:
    """Generalized forces S_j . sum_{p >= k(j)} f_p (the rows of eqs 52-54)."""
    FCa = subtree_sum(model, f_ang, -2)[..., model.col_body, :]
    FCl = subtree_sum(model, f_lin, -2)[..., model.col_body, :]
    return np.einsum("...ni,...ni->...n", Sa, FCa) + np.einsum("...ni,...ni->...n", Sb, FCl)


def reactions(model: Model, data: Data, f_ang: np.ndarray, f_lin: np.ndarray):
    """Joint reactions on body k from its parent (or the base), world components.

    R^k = sum_{p>=k} (m^p (v^p)' - F^p) (eq 40); L^k = moment about O^k of the same subtree
    sums (eq 48; on a tree the sums are over sub(k), eq 48T). Returns (R, L), each (n, 3).
    """
    FCa = subtree_sum(model, f_ang)
    R = subtree_sum(model, f_lin)
    L = FCa - cross(data.O, R)
    return R, L


def accelerations_from(model: Model, data: Data, Sa, Sb, udot, acc_w0, acc_v0):
    """Body spatial accelerations for generalized accelerations udot (bias included)."""
    lead = np.broadcast_shapes(Sa.shape[:-2], np.shape(udot)[:-1])
    da = np.zeros(lead + (model.n, 3), dtype=np.result_type(Sa, udot))
    dv = np.zeros(lead + (model.n, 3), dtype=da.dtype)
    # summed over each body's columns along the bodies' axis, moved first for np.add.at
    np.add.at(np.moveaxis(da, -2, 0), model.col_body, np.moveaxis(Sa * udot[..., None], -2, 0))
    np.add.at(np.moveaxis(dv, -2, 0), model.col_body, np.moveaxis(Sb * udot[..., None], -2, 0))
    return acc_w0 + path_sum(model, da), acc_v0 + path_sum(model, dv)


class Applied:
    """The torques applied at one state of a stateful model (gyro_sim.dynamics.actuators): the
    motors' (commands after saturation and the speed cut) and friction's, on the torque rotors
    (nt,) and the hinges (nh,), with the relative speeds they were evaluated at."""

    __slots__ = ("rotor_motor", "rotor_friction", "rotor_speed", "hinge_motor", "hinge_friction", "hinge_speed")

    def power(self) -> tuple[float, float]:
        """The power of the motors and of friction (W): torque times relative speed."""
        motor = float(self.rotor_motor @ self.rotor_speed + self.hinge_motor @ self.hinge_speed)
        friction = float(self.rotor_friction @ self.rotor_speed + self.hinge_friction @ self.hinge_speed)
        return motor, friction


def applied_torques(model: Model, data: Data, y: np.ndarray, p: np.ndarray | None,
                    hinge_tau: np.ndarray | None, L_rotor: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The hinge moments (nh,) and rotor torques (nt,) or None applied at state y of a stateful
    model, from the (saturated) commands (None: zero) and the relative speeds: kappa_i' of the
    rotors (eqs 18-19, from the spins p and the velocities in `data`), phi_k' of the hinges.
    Leaves the parts in `data.applied` (:class:`Applied`)."""
    act = model.actuators
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    a = data.applied = Applied()
    a.rotor_speed = torque_rotor_rates(model, data, p) if nt else np.zeros(0)
    a.hinge_speed = y[..., model.i_vel][..., model.col_hinge]
    a.rotor_motor = act.rotor.cut(np.zeros(nt) if L_rotor is None else L_rotor, a.rotor_speed)
    a.rotor_friction = act.rotor.friction(a.rotor_speed)
    a.hinge_motor = np.zeros(nh) if hinge_tau is None else hinge_tau
    a.hinge_friction = act.hinge.friction(a.hinge_speed)
    return a.hinge_motor + a.hinge_friction, (a.rotor_motor + a.rotor_friction if nt else None)


def applied_at(model: Model, data: Data, t: float, y: np.ndarray, hinge_tau: np.ndarray | None,
               L_rotor: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The motors' (the servos' moments included) and the friction's (in F) torques at state y
    of a stateful model under the commands hinge_tau (a servo's hinge: its drive) and L_rotor:
    each (nh + nt,), the hinges' then the torque rotors' (`applied_torques`, as `closure`
    applies them)."""
    positions(model, data, t, y)
    velocities(model, data, t, y[..., model.i_vel])
    if model.servo is not None:
        hinge_tau = servo_moments(model, y, hinge_tau)
    applied_torques(model, data, y, y[model.i_spin], hinge_tau, L_rotor)
    a = data.applied
    return np.concatenate((a.hinge_motor, a.rotor_motor)), np.concatenate((a.hinge_friction, a.rotor_friction))


class Evaluation:
    """What one forward evaluation leaves behind for outputs (reactions, rotor torques)."""

    __slots__ = ("udot", "acc_w", "acc_v", "f_ang", "f_lin", "Sa", "Sb", "lam_w", "dlam_w")


def forward(
    model: Model,
    data: Data,
    t: float,
    y: np.ndarray,
    hinge_tau: np.ndarray | None,
    p: np.ndarray | None,
    L_rotor: np.ndarray | None,
    out: Evaluation | None = None,
) -> np.ndarray:
    """Generalized accelerations u' (N,) at (t, y): the closure of eq (48), solved.

    hinge_tau: commanded hinge moments L_k (eq 51), one per hinge, or None for all zero.
    p: absolute spins of the torque rotors at t; L_rotor: their axial torques (eq 29).
    If `out` is given, the intermediate results needed for reactions are stored in it.
    """
    rhs, parts = closure(model, data, t, y, hinge_tau, p, L_rotor)
    udot = np.linalg.solve(mass_matrix(model, data, parts[0], parts[1]), rhs)
    if out is not None:
        fill_evaluation(model, data, udot, parts, out)
    return udot


def closure(model: Model, data: Data, t: float, y: np.ndarray, hinge_tau: np.ndarray | None,
            p: np.ndarray | None, L_rotor: np.ndarray | None, positions_done: bool = False) -> tuple[np.ndarray, tuple]:
    """The rows of eqs (52)-(54) at (t, y) before the solve (arguments as `forward`): rhs (N,)
    of M u' = rhs, and parts = (Sa, Sb, lam_w, dlam_w, acc_w0, acc_v0), the joint columns (M is
    mass_matrix(model, data, Sa, Sb)), the gyrostatic moments and the bias accelerations, for
    `fill_evaluation`. positions_done: `data` already holds the positions of y's configuration
    (one configuration serves a stack of states that differ only in their rates)."""
    if not positions_done:
        positions(model, data, t, y)
    velocities(model, data, t, y[..., model.i_vel])
    if model.servo is not None:  # a servo's hinge moment from its held drive and the state
        hinge_tau = servo_moments(model, y, hinge_tau)
    if model.stateful:  # the torques applied at this state: motors after the cut, and friction
        hinge_tau, L_rotor = applied_torques(model, data, y, p, hinge_tau, L_rotor)
    lam_w, dlam_w = lam(model, data, p, L_rotor)
    acc_w0, acc_v0 = bias_accelerations(model, data, t)
    f_ang, f_lin = body_forces(model, data, acc_w0, acc_v0, lam_w, dlam_w)
    Sa, Sb = joint_columns(model, data)
    rhs = -project_subtree(model, Sa, Sb, f_ang, f_lin)
    if model.motor is not None:  # (51b): the motors' rows at the bias accelerations
        rhs[..., model.col_hinge] -= motor_row(model, data, acc_w0, 0.0)
    if hinge_tau is not None:
        rhs[..., model.col_hinge] += hinge_tau  # (51): e^k . L^k = L_k
    if model.spring is not None:
        rhs[..., model.col_hinge] += spring_moments(model, y)
    return rhs, (Sa, Sb, lam_w, dlam_w, acc_w0, acc_v0)


def spring_moments(model: Model, y: np.ndarray) -> np.ndarray:
    """The hinges' spring moments -k (phi - phi_ref) (nh,) at y (a stack of states too), added
    to the commanded moment of eq (51) (docs/theory.md, "Armature and joint springs")."""
    k, ref = model.spring[:, 0], model.spring[:, 1]
    return -k * (y[..., model.i_phi] - ref)


def servo_moments(model: Model, y: np.ndarray, hinge_tau: np.ndarray) -> np.ndarray:
    """The hinge moments (nh,) at y (a stack of states too) with each servo's hinge's held drive
    d = gain clip(ctrl) + b0 (`servo_drives`) turned into its moment gear clip(d + b1 gear phi
    + b2 gear phi', force_range) (docs/models.md, "Servo actuators"); the other hinges' as held.
    The clip is complex-step safe: it compares real parts."""
    h = model.servo_hinge
    if hinge_tau is None:
        hinge_tau = np.zeros(len(model.hinge_bodies))
    gear, b1, b2, low, high = model.servo.T
    phi = y[..., model.i_phi][..., h]
    rate = y[..., model.i_vel][..., model.col_hinge[h]]
    force = hinge_tau[..., h] + b1 * (gear * phi) + b2 * (gear * rate)
    force = np.where(force.real < low, low, np.where(force.real > high, high, force))
    out = hinge_tau.astype(np.result_type(hinge_tau, force), copy=True)
    out[..., h] = gear * force
    return out


def servo_drives(model: Model, controls: np.ndarray) -> np.ndarray:
    """Each servo's held drive gain clip(ctrl, ctrl_range) + b0 (nsv,) from its control (a stack
    too; the clip complex-step safe, as `servo_moments`')."""
    gain, b0, low, high = model.servo_input.T
    ctrl = np.where(controls.real < low, low, np.where(controls.real > high, high, controls))
    return gain * ctrl + b0


def joint_energy(model: Model, y: np.ndarray, data: Data | None = None) -> tuple[float, float]:
    """What the hinges' joint terms add to the energy at y: the armatures' kinetic energy
    1/2 a phi'^2, the geared motors' phi' (m . w^{k-1}) + 1/2 J G^2 phi'^2 (velocities of y in
    `data`) and the springs' potential 1/2 k (phi - phi_ref)^2 (zero without them)."""
    T = V = 0.0
    if model.armature is not None:
        rate = y[model.i_vel][model.col_hinge]
        T = 0.5 * float(np.sum(model.armature * rate * rate))
    if model.motor is not None:
        rate = y[model.i_vel][model.col_hinge]
        J, G = model.motor[:, 0], model.motor[:, 1]
        w_parent = data.w[data.motor_parent]
        T += float(np.sum(rate * np.einsum("ni,ni->n", data.motor_w, w_parent) + 0.5 * J * G * G * rate * rate))
    if model.spring is not None:
        stretch = y[model.i_phi] - model.spring[:, 1]
        V = 0.5 * float(np.sum(model.spring[:, 0] * stretch * stretch))
    return T, V


def fill_evaluation(model: Model, data: Data, udot: np.ndarray, parts: tuple, out: Evaluation) -> None:
    """`out` for the accelerations udot of a `closure` (its parts): body accelerations and
    forces, for reactions."""
    Sa, Sb, lam_w, dlam_w, acc_w0, acc_v0 = parts
    out.udot, out.Sa, out.Sb, out.lam_w, out.dlam_w = udot, Sa, Sb, lam_w, dlam_w
    out.acc_w, out.acc_v = accelerations_from(model, data, Sa, Sb, udot, acc_w0, acc_v0)
    if model.motor is not None:  # the motors' J G phi'' a on their parents (eq 31's lambda')
        motor = motor_forces(model, data, udot[..., model.col_hinge])
        dlam_w = motor if dlam_w is None else dlam_w + motor
    out.f_ang, out.f_lin = body_forces(model, data, out.acc_w, out.acc_v, lam_w, dlam_w)
