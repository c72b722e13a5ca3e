"""Chains of Lagrange gyroscopes: the paper's closed-form results (eqs 60-88).

A *Lagrange chain* (docs/theory.md section 3) is a chain of gyrostats on a fixed point O^1, joined
by spherical joints, under gravity only, each gyrostat axially symmetric about its body axis
eps^k (the body z-axis): carrier inertia at O^k diag(B0, B0, A0), centre of mass and next joint
on the axis (eq 61), rotors on the axis with axes +-eps^k (so lambda^k is along eps^k, eq 64).

This module gives, for such a chain,

- the composed constants A^k, B^k, m^k, c^k, s^k, lambda^k (eqs 30, 31, 61-64) and mu_k (72):
  :meth:`LagrangeChain.from_scene`;
- the two first integrals in the paper's own Euler-angle form: the vertical angular momentum
  k of eq (82) (from (79)) and the energy integral h of eq (85) (from (84)), with their exact
  relation to the physical energy T + V and vertical angular momentum K
  (:func:`physical_invariants`);
- the regular precessions (the paper's closing result, eq 88 for n = 2 and the unnumbered
  general-n conditions before it): :func:`regular_precession_spins`,
  :func:`regular_precession_state`, and the scene files built on them
  (:func:`precession_scene_dict`, :data:`SHIPPED_SCENES`).

Euler angles are gyro_sim's (docs/theory.md section 6, :mod:`gyro_sim.dynamics.rotations`): theta_k
between eps^k and the downward vertical nu, psi_k the precession about nu, phi_k the proper
rotation; in the "down" frame (z = nu) the axis is eps^k = sin(th) u_k + cos(th) nu with the
horizontal unit vector u_k = (sin psi_k, -cos psi_k, 0), and the line of nodes is
n_k = (cos psi_k, sin psi_k, 0) = du_k/dpsi_k.

Transcription errors corrected here (the paper's text, seed/000_31335571ec580f22.txt):

- (82): the factors printed as theta_p' and theta_q' after the square brackets are
  sin(theta_p) and sin(theta_q); c^p is the scalar c^p (printed bold).
- (83)-(85): the potential term is -2 mu_k cos(theta_k), not -mu_k cos(theta_k): (83) has
  mu_k theta_k' sin(theta_k) B^k, which is d/dt (1/2)(-2 mu_k cos theta_k) B^k.
- (85): the double sum sum_{l=1}^{k-1} sum_{q=l+1}^{k-1} s^l s^q [...] must run over all
  l, q = 1..k-1 as in (84) (the diagonal l = q once, each pair l != q twice); the printed
  form drops the diagonal and halves the off-diagonal terms.
- Regular precession, general n: in the rows for k = 2..n-1 the factor of the inner sum
  s^l sin(theta_l) is eps_{kl} (relative to body k), not eps_{ql}; likewise eps_{kq}
  (= eps_{qk}) in front of c^q sin(theta_q). The last row's eps_{l1} is right.
- (87)-(88): c^3 is c^2; B_1^1, B_2^2 in (88) are B_*^1, B_*^2 of (87), and n_2^*, mu_2^*
  are n_2, mu_2 (B_*^2 only rescales B^2). The solved form for phi_1', phi_2' (docs/theory.md
  section 4) is correct as printed.
- The n = 2 integrals after (87): -2 mu_1^* cos(theta_1) and -2 mu_2 cos(theta_2) (the same
  factor 2 as in (85)); their k_* form is (82) divided by m^2 c^2 s^1 and is right.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyro_sim.jit import njit
from gyro_sim.scene.records import Body, Scene

__all__ = [
    "LagrangeChain",
    "vertical_momentum_82",
    "energy_integral_85",
    "axial_energy",
    "physical_invariants",
    "regular_precession_spins",
    "regular_precession_state",
    "precession_scene_dict",
    "SHIPPED_SCENES",
    "shipped_scene_dicts",
    "scene_yaml",
    "write_shipped_scenes",
]

#: relative tolerance of the axial-symmetry tests of :meth:`LagrangeChain.from_scene`
AXISYM_RTOL = 1e-10
#: below this |sin(theta_k)| a regular precession's spin is undefined (the axis is vertical)
VERTICAL_SIN = 1e-9


# ------------------------------------------------------------------ composed constants


@dataclass(frozen=True)
class _Rotor:
    """A rotor on the axis: sign of its axis along eps^k, and its constants."""

    sign: float  # e_i . eps^k = +-1
    h: float  # its centre at h eps^k
    mass: float
    A: float
    B: float
    mode: str
    spin: float  # torque: absolute spin p_i; speed: kappa_i'


@dataclass(frozen=True)
class _Gyrostat:
    """One gyrostat of a Lagrange chain, as written: carrier constants and its rotors."""

    name: str
    mass: float
    c0: float  # carrier centre of mass at c0 eps^k
    A0: float  # carrier axial inertia at O^k
    B0: float  # carrier transverse inertia at O^k
    s: float  # next joint at s eps^k (0 on the last body)
    rotors: tuple[_Rotor, ...]


@dataclass(frozen=True)
class LagrangeChain:
    """The constants of a chain of Lagrange gyroscopes (arrays of shape (n,), body order).

    Attributes
    ----------
    A, B : axial and transverse moments of inertia of gyrostat k at O^k (eq 30): carrier plus
        every rotor's B_i + m_i h_i^2 transversally; axially the carrier plus the *speed*
        rotors' A_i (a torque rotor's axial inertia enters only through lambda^k).
    m, c, s : mass of gyrostat k, its centre of mass c^k eps^k and next joint s^k eps^k
        (eq 61); s[-1] = 0.
    lam : gyrostatic moment lambda^k along eps^k (eqs 31, 64): sum over torque rotors of
        +-A_i p_i plus sum over speed rotors of +-A_i kappa_i' (sign: e_i . eps^k).
    lam_speed : the speed rotors' part of lam.
    rotor_energy : (1/2) sum_torque A_i p_i^2 + (1/2) sum_speed A_i kappa_i'^2 (eq 33).
    g : |gravity|; nu : (3,) unit downward vertical (world); base : (3,) O^1 (world).
    """

    names: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    m: np.ndarray
    c: np.ndarray
    s: np.ndarray
    lam: np.ndarray
    lam_speed: np.ndarray
    rotor_energy: np.ndarray
    g: float
    nu: np.ndarray
    base: np.ndarray

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def mu(self) -> np.ndarray:
        """mu_k (n,): (m^k c^k + s^k sum_{q>k} m^q) g = B^k mu_k, eq (72)."""
        tail = np.concatenate([np.cumsum(self.m[::-1])[::-1][1:], [0.0]])  # sum_{q>k} m^q
        return (self.m * self.c + self.s * tail) * self.g / self.B

    @classmethod
    def from_scene(cls, scene: Scene) -> LagrangeChain | None:
        """The chain's constants, or None when `scene` is not a Lagrange chain.

        A Lagrange chain: fixed base, a chain (no `parent` but the body before, no `joint.at`),
        every joint spherical, gravity present, and every
        gyrostat axially symmetric about its body z-axis (carrier inertia at O^k diagonal
        with Ixx = Iyy, com and next_joint on the z-axis, rotors centred on the z-axis with
        axis +-z), to the relative tolerance AXISYM_RTOL.

        lambda^k is taken from the scene's rotor spins: the torque rotors' p_i stay at these
        values as long as no axial torque is commanded (eq 29), which is when (82) and (85)
        are first integrals.
        """
        if scene.base.type != "fixed" or scene.gravity is None:
            return None
        if any(b.joint.at is not None or b.parent not in (None, k - 1) for k, b in enumerate(scene.bodies)):
            return None  # a tree, or a chain whose joint points are written as joint.at
        g = float(np.linalg.norm(scene.gravity))
        if g == 0.0 or not scene.bodies:
            return None
        gyrostats = []
        for k, body in enumerate(scene.bodies):
            gyro = _gyrostat_of_body(body, last=k == len(scene.bodies) - 1)
            if gyro is None:
                return None
            gyrostats.append(gyro)
        return _compose(gyrostats, np.asarray(scene.gravity, dtype=float),
                        np.asarray(scene.base.position, dtype=float))


def _on_axis(v: np.ndarray | None, scale: float) -> float | None:
    """v[2] when v lies on the z-axis (to AXISYM_RTOL of `scale`), else None."""
    if v is None:
        return 0.0
    v = np.asarray(v, dtype=float)
    if math.hypot(v[0], v[1]) > AXISYM_RTOL * max(scale, float(np.linalg.norm(v))):
        return None
    return float(v[2])


def _gyrostat_of_body(body: Body, last: bool) -> _Gyrostat | None:
    if body.joint.type != "spherical":
        return None
    inertia = np.asarray(body.inertia, dtype=float)
    scale = float(np.max(np.abs(inertia)))
    off = inertia - np.diag(np.diag(inertia))
    if np.max(np.abs(off)) > AXISYM_RTOL * scale or \
            abs(inertia[0, 0] - inertia[1, 1]) > AXISYM_RTOL * scale:
        return None
    length = max(float(np.linalg.norm(body.com)),
                 0.0 if body.next_joint is None else float(np.linalg.norm(body.next_joint)))
    c0 = _on_axis(body.com, length)
    s = 0.0 if last else _on_axis(body.next_joint, length)
    if c0 is None or s is None:
        return None
    rotors = []
    for rotor in body.rotors:
        e = np.asarray(rotor.axis, dtype=float)
        e = e / np.linalg.norm(e)
        h = _on_axis(rotor.position, length)
        if h is None or math.hypot(e[0], e[1]) > AXISYM_RTOL:
            return None
        rotors.append(_Rotor(sign=math.copysign(1.0, e[2]), h=h, mass=float(rotor.mass),
                             A=float(rotor.axial_inertia), B=float(rotor.transverse_inertia),
                             mode=rotor.mode, spin=float(rotor.spin)))
    return _Gyrostat(body.name, float(body.mass), c0, float(inertia[2, 2]),
                     0.5 * float(inertia[0, 0] + inertia[1, 1]), s, tuple(rotors))


def _compose(gyrostats: Sequence[_Gyrostat], gravity: np.ndarray,
             base: np.ndarray) -> LagrangeChain:
    """Eqs (30), (31), (61)-(64): each gyrostat's constants at O^k."""
    n = len(gyrostats)
    A, B, m, c, s, lam, lam_speed, e_rot = (np.zeros(n) for _ in range(8))
    for k, gy in enumerate(gyrostats):
        mass, moment = gy.mass, gy.mass * gy.c0
        A[k], B[k] = gy.A0, gy.B0
        for r in gy.rotors:
            mass += r.mass
            moment += r.mass * r.h
            B[k] += r.B + r.mass * r.h**2  # (30): e x (w x e) B_i + h x (w x h) m_i
            if r.mode == "speed":
                A[k] += r.A  # (30): sum_speed A_i (w . e_i) e_i
                lam_speed[k] += r.A * r.spin * r.sign  # (31): A_i kappa_i' e_i
            else:
                lam[k] += r.A * r.spin * r.sign  # (31): A_i p_i e_i
            e_rot[k] += 0.5 * r.A * r.spin**2  # (33): A_i p_i^2, A_i kappa_i'^2
        m[k], c[k], s[k] = mass, moment / mass, gy.s
    g = float(np.linalg.norm(gravity))
    return LagrangeChain(names=tuple(gy.name for gy in gyrostats), A=A, B=B, m=m, c=c, s=s,
                         lam=lam + lam_speed, lam_speed=lam_speed, rotor_energy=e_rot, g=g,
                         nu=gravity / g, base=np.asarray(base, dtype=float))


# --------------------------------------------------------------------- first integrals


def _angles(euler: np.ndarray, rates: np.ndarray, n: int):
    euler = np.asarray(euler, dtype=float).reshape(n, 3)
    rates = np.asarray(rates, dtype=float).reshape(n, 3)
    return euler[:, 0], euler[:, 1], rates[:, 0], rates[:, 1], rates[:, 2]


def _spin_p(th, dpsi, dphi):
    """p_k = phi_k' + psi_k' cos(theta_k), eq (63)."""
    return dphi + dpsi * np.cos(th)


def vertical_momentum_82(chain: LagrangeChain, euler: np.ndarray, rates: np.ndarray) -> float:
    """The paper's vertical angular momentum k, eq (82) (= nu . (79)), corrected.

    ``euler``, ``rates``: (n, 3) psi, theta, phi and their rates, body order.

        k = sum_p B^p (n_p cos th_p + psi_p' sin^2 th_p)
            + sum_{p>=2} m^p [ c^p sum_{l<p} s^l C_pl + sum_{q<p} sum_{l<p} s^q s^l C_ql
                               + c^p sum_{q<p} s^q C_qp ],
        C_ij = nu . (eps^i x (w^j x eps^j))
             = sin th_i [th_j' cos th_j sin(psi_j - psi_i) + psi_j' sin th_j cos(psi_j - psi_i)],

    with B^p n_p = A^p p_p + lambda^p (70) and p_p from (63). k is the angular momentum of the
    whole chain about O^1 projected on the DOWNWARD vertical nu; the upward component
    (``Simulator.invariants()["vertical_momentum"]``) is K = -k (see physical_invariants).
    """
    psi, th, dpsi, dth, dphi = _angles(euler, rates, chain.n)
    sin, cos = np.sin(th), np.cos(th)
    Bn = chain.A * _spin_p(th, dpsi, dphi) + chain.lam  # (70)
    k = float(np.sum(Bn * cos + chain.B * dpsi * sin**2))  # (82), first sum
    return k + _sums_82(chain.m, chain.c, chain.s, psi, th, dpsi, dth)


@njit
def _sums_82(m, c, s, psi, th, dpsi, dth):
    """The double sums of (82), O(n^2): the running sum S_p = sum_{q<p} sum_{l<p} s^q s^l C_ql
    grows by s^p (sum_{l<p} s^l (C_pl + C_lp)) + (s^p)^2 C_pp from p to p + 1; C_ij from the
    sines and cosines of the angles (sin(psi_j - psi_i) expanded), no (n, n) array."""
    n = psi.shape[0]
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(psi), np.cos(psi)
    a = dth * ct  # C_ij = st_i [a_j sin(psi_j - psi_i) + b_j cos(psi_j - psi_i)]
    b = dpsi * st
    total = 0.0
    S = 0.0  # sum_{q<p} sum_{l<p} s^q s^l C_ql
    for p in range(n):
        row = 0.0  # sum_{l<p} s^l C_pl
        col = 0.0  # sum_{l<p} s^l C_lp
        for l in range(p):
            sin_lp = sp[p] * cp[l] - cp[p] * sp[l]  # sin(psi_p - psi_l)
            cos_lp = cp[p] * cp[l] + sp[p] * sp[l]
            row += s[l] * st[p] * (-a[l] * sin_lp + b[l] * cos_lp)  # C_pl: psi_l - psi_p
            col += s[l] * st[l] * (a[p] * sin_lp + b[p] * cos_lp)  # C_lp: psi_p - psi_l
        if p >= 1:
            total += m[p] * (c[p] * row + S + c[p] * col)
        S += s[p] * (row + col) + s[p] * s[p] * st[p] * b[p]  # C_pp = st_p b_p
    return total


def energy_integral_85(chain: LagrangeChain, euler: np.ndarray, rates: np.ndarray) -> float:
    """The paper's energy integral h, eq (85) (from (84)), corrected.

    ``euler``, ``rates``: (n, 3) psi, theta, phi and their rates, body order.

        h = sum_k (th_k'^2 + psi_k'^2 sin^2 th_k - 2 mu_k cos th_k) B^k
            + sum_{k>=2} m^k [ 2 c^k sum_{l<k} s^l G_lk + sum_{l<k} sum_{q<k} s^l s^q G_lq ],
        G_lq = (w^l x eps^l) . (w^q x eps^q)
             = th_l' th_q' sin th_l sin th_q
               + (th_l' th_q' cos th_l cos th_q + psi_l' psi_q' sin th_l sin th_q)
                 cos(psi_l - psi_q)
               + (th_l' psi_q' cos th_l sin th_q - th_q' psi_l' cos th_q sin th_l)
                 sin(psi_l - psi_q).

    h = 2 (T + V) - 2 axial_energy - 2 V_base: see :func:`physical_invariants`.
    """
    psi, th, dpsi, dth, _ = _angles(euler, rates, chain.n)
    sin, cos = np.sin(th), np.cos(th)
    h = float(np.sum((dth**2 + dpsi**2 * sin**2 - 2.0 * chain.mu * cos) * chain.B))  # (85)
    return h + _sums_85(chain.m, chain.c, chain.s, psi, th, dpsi, dth)


@njit
def _sums_85(m, c, s, psi, th, dpsi, dth):
    """The double sums of (85), O(n^2): G is symmetric, so the running sum
    T_k = sum_{l<k} sum_{q<k} s^l s^q G_lq grows by 2 s^k sum_{l<k} s^l G_lk + (s^k)^2 G_kk;
    G_lq from the sines and cosines of the angles, no (n, n) array."""
    n = psi.shape[0]
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(psi), np.cos(psi)
    total = 0.0
    T = 0.0
    for k in range(n):
        col = 0.0  # sum_{l<k} s^l G_lk
        for l in range(k):
            cos_lk = cp[l] * cp[k] + sp[l] * sp[k]  # cos(psi_l - psi_k)
            sin_lk = sp[l] * cp[k] - cp[l] * sp[k]  # sin(psi_l - psi_k)
            G = (dth[l] * dth[k] * st[l] * st[k]
                 + (dth[l] * dth[k] * ct[l] * ct[k] + dpsi[l] * dpsi[k] * st[l] * st[k]) * cos_lk
                 + (dth[l] * ct[l] * dpsi[k] * st[k] - dth[k] * ct[k] * dpsi[l] * st[l]) * sin_lk)
            col += s[l] * G
        if k >= 1:
            total += m[k] * (2.0 * c[k] * col + T)
        Gkk = dth[k] * dth[k] * st[k] * st[k] + dth[k] * dth[k] * ct[k] * ct[k] + dpsi[k] * dpsi[k] * st[k] * st[k]
        T += 2.0 * s[k] * col + s[k] * s[k] * Gkk
    return total


def axial_energy(chain: LagrangeChain, euler: np.ndarray, rates: np.ndarray) -> float:
    """The part of T that (85) leaves out, constant along a Lagrange chain's motion.

        T_ax = sum_k [ (1/2) A^k p_k^2 + p_k lambda_speed^k + rotor_energy^k ]   (eq 33)

    (the axial spin energy of each carrier with its speed rotors, the speed rotors' cross
    term A_i (w . e_i) kappa_i', and the rotors' own spin energy); constant because
    A^k p_k + lambda^k = B^k n_k (70) and the rotor spins are.
    """
    _, th, dpsi, _, dphi = _angles(euler, rates, chain.n)
    p = _spin_p(th, dpsi, dphi)
    return float(np.sum(0.5 * chain.A * p**2 + p * chain.lam_speed + chain.rotor_energy))


def physical_invariants(chain: LagrangeChain, euler: np.ndarray,
                        rates: np.ndarray) -> dict[str, float]:
    """Energy and vertical angular momentum from the paper's integrals (82), (85).

    The relations (exact, at every instant):

        energy            = T + V = h / 2 + axial_energy + V_base,
                            V_base = -M g nu . O^1 (M: total mass; 0 when O^1 is the origin)
        vertical_momentum = K = -nu . L_{O^1} = -k

    where h is (85), k is (82), T the kinetic energy (eq 33 summed over the chain), V the
    gravity potential -sum_k m^k g nu . r_com^k (r from the world origin), and L_{O^1} the
    total angular momentum about O^1 (rotor spins included). K is the component along the
    UPWARD vertical -nu (along +z for gravity along -z): this is the sign convention of
    ``Simulator.invariants()["vertical_momentum"]``.
    """
    h = energy_integral_85(chain, euler, rates)
    k = vertical_momentum_82(chain, euler, rates)
    V_base = -float(np.sum(chain.m)) * chain.g * float(chain.nu @ chain.base)
    return {"energy": 0.5 * h + axial_energy(chain, euler, rates) + V_base,
            "vertical_momentum": -k}


# ------------------------------------------------------------------- regular precessions


def _signs(n: int, eps21) -> np.ndarray:
    """sigma_k = eps_{k1} = cos(psi_k - psi_1) from eps_k = cos(psi_k - psi_{k-1}), k = 2..n."""
    if n == 1:
        return np.ones(1)
    eps = np.atleast_1d(np.asarray(eps21, dtype=float))
    if eps.shape == (1,):
        eps = np.full(n - 1, eps[0]) if n == 2 else eps
    if eps.shape != (n - 1,) or not np.all(np.abs(eps) == 1.0):
        raise ValueError(f"eps21: expected +-1 for n = 2, or n - 1 = {n - 1} values +-1 "
                         f"(eps_k = cos(psi_k - psi_(k-1)), k = 2..n), got {eps21!r}")
    return np.concatenate([[1.0], np.cumprod(eps)])


def regular_precession_spins(chain: LagrangeChain, thetas: Sequence[float], kappa: float,
                             eps21: float | Sequence[float] = 1.0) -> np.ndarray:
    """The proper-rotation rates phi_k' (n,) of the regular precession theta_k, psi_k' = kappa.

    Parameters
    ----------
    thetas : (n,) constant nutation angles, in (0, pi).
    kappa : the common precession rate psi_k' (nonzero).
    eps21 : for n = 2, eps_21 = cos(psi_2 - psi_1) = +-1; for general n, the n - 1 values
        eps_k = cos(psi_k - psi_{k-1}), k = 2..n (ignored for n = 1).

    The conditions (the paper's rows before (88), with eps_{kl} = cos(psi_k - psi_l) as
    corrected in this module's docstring) are, for every k,

        [(n_k - kappa cos th_k) kappa + mu_k] B^k sin th_k = kappa^2 cos th_k S_k,
        S_k = m^k c^k sum_{l<k} eps_kl s^l sin th_l
              + s^k sum_{q>k} m^q (eps_kq c^q sin th_q + sum_{l<q} eps_kl s^l sin th_l),

    each linear in its own n_k, and phi_k' = (B^k n_k - lambda^k) / A^k - kappa cos th_k
    ((70), (63)). For n = 1: A phi' = (B - A) kappa cos th - m c g / kappa - lambda (the
    heavy top); for n = 2 these are docs/theory.md's (88):

        A^1 phi_1' = (B^1 - A^1 + m^2 s^1 s^1 + eps21 (sin th2/sin th1) m^2 c^2 s^1) kappa cos th1
                     - (m^1 c^1 + m^2 s^1) g / kappa - lambda^1
        A^2 phi_2' = (B^2 - A^2 + eps21 (sin th1/sin th2) m^2 c^2 s^1) kappa cos th2
                     - m^2 c^2 g / kappa - lambda^2
    """
    n = chain.n
    th = np.asarray(thetas, dtype=float).reshape(n)
    if kappa == 0.0:
        raise ValueError("kappa = 0: no regular precession (psi' must be nonzero)")
    sin, cos = np.sin(th), np.cos(th)
    if np.any(np.abs(sin) < VERTICAL_SIN):
        raise ValueError(f"thetas {th}: a vertical axis (sin theta = 0) has no regular precession")
    sigma = _signs(n, eps21)
    eps = np.outer(sigma, sigma)  # eps[k, l] = eps_kl
    m, c, s = chain.m, chain.c, chain.s
    S = np.zeros(n)
    for k in range(n):
        S[k] = m[k] * c[k] * sum(eps[k, l] * s[l] * sin[l] for l in range(k))
        S[k] += s[k] * sum(m[q] * (eps[k, q] * c[q] * sin[q]
                                   + sum(eps[k, l] * s[l] * sin[l] for l in range(q)))
                           for q in range(k + 1, n))
    # B^k n_k from [(n_k - kappa cos th_k) kappa + mu_k] B^k sin th_k = kappa^2 cos th_k S_k
    Bn = chain.B * (kappa * cos - chain.mu / kappa) + kappa * cos * S / sin
    return (Bn - chain.lam) / chain.A - kappa * cos  # (70), (63)


def regular_precession_state(chain: LagrangeChain, thetas: Sequence[float], kappa: float,
                             eps21: float | Sequence[float] = 1.0, psi1: float = 0.0,
                             phis: Sequence[float] | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Euler angles and rates (each (n, 3): psi, theta, phi) starting a regular precession.

    psi_k = psi_1 where eps_k1 = cos(psi_k - psi_1) = +1, psi_1 + pi where it is -1;
    theta_k' = 0, psi_k' = kappa, phi_k' from :func:`regular_precession_spins`; phi_k = `phis`
    (default 0).
    """
    n = chain.n
    sigma = _signs(n, eps21)
    psi = psi1 + np.where(sigma > 0.0, 0.0, math.pi)
    phi = np.zeros(n) if phis is None else np.asarray(phis, dtype=float)
    euler = np.column_stack([psi, np.asarray(thetas, dtype=float), phi])
    dphi = regular_precession_spins(chain, thetas, kappa, eps21)
    rates = np.column_stack([np.full(n, float(kappa)), np.zeros(n), dphi])
    return euler, rates


# ------------------------------------------------------------------------- scene files


def _gyrostat_of_dict(body: Mapping[str, Any], last: bool) -> _Gyrostat:
    """A body entry as written by :func:`precession_scene_dict` (inertia {axial, transverse})."""
    rotors = tuple(
        _Rotor(sign=math.copysign(1.0, r["axis"][2]), h=float(r["position"][2]),
               mass=float(r["mass"]), A=float(r["axial_inertia"]),
               B=float(r["transverse_inertia"]), mode=r["mode"], spin=float(r["spin"]))
        for r in body.get("rotors", ()))
    return _Gyrostat(body["name"], float(body["mass"]), float(body["com"][2]),
                     float(body["inertia"]["axial"]), float(body["inertia"]["transverse"]),
                     0.0 if last else float(body["next_joint"][2]), rotors)


def precession_scene_dict(name: str, bodies: Sequence[Mapping[str, Any]],
                          thetas: Sequence[float], kappa: float,
                          eps21: float | Sequence[float] = 1.0,
                          gravity: Sequence[float] = (0.0, 0.0, -9.81),
                          position: Sequence[float] = (0.0, 0.0, 0.0),
                          psi1: float = 0.0) -> dict[str, Any]:
    """A scene mapping (docs/scene-format.md) of a Lagrange chain in regular precession.

    `bodies`: the body entries without `joint` and `initial` (mass, com, inertia
    {axial, transverse}, next_joint, rotors, visual; vectors on the z-axis). The result has
    joint {type: spherical} and initial {euler, euler_rates} from
    :func:`regular_precession_state` (phi_k = 0), all numbers Python floats.
    """
    gyrostats = [_gyrostat_of_dict(b, last=i == len(bodies) - 1) for i, b in enumerate(bodies)]
    chain = _compose(gyrostats, np.asarray(gravity, dtype=float), np.asarray(position, float))
    euler, rates = regular_precession_state(chain, thetas, kappa, eps21, psi1)
    out_bodies = []
    for k, b in enumerate(bodies):
        entry: dict[str, Any] = {"name": b["name"], "joint": {"type": "spherical"}}
        entry.update({key: value for key, value in b.items() if key != "name"})
        entry["initial"] = {"euler": [float(x) for x in euler[k]],
                            "euler_rates": [float(x) for x in rates[k]]}
        out_bodies.append(entry)
    return {"name": name, "gravity": [float(x) for x in gravity],
            "base": {"type": "fixed", "position": [float(x) for x in position]},
            "bodies": out_bodies}


_TOP1 = {"name": "top1", "mass": 1.0, "com": [0.0, 0.0, 0.1],
         "inertia": {"axial": 0.004, "transverse": 0.015}, "next_joint": [0.0, 0.0, 0.2],
         "rotors": [{"name": "wheel1", "axis": [0.0, 0.0, 1.0], "position": [0.0, 0.0, 0.1],
                     "mass": 0.2, "axial_inertia": 2.0e-4, "transverse_inertia": 1.0e-4,
                     "mode": "torque", "spin": -300.0, "actuated": False}],
         "visual": {"radius": 0.03}}
_TOP2 = {"name": "top2", "mass": 0.8, "com": [0.0, 0.0, 0.08],
         "inertia": {"axial": 0.002, "transverse": 0.008}, "visual": {"radius": 0.025}}
_TOP = {"name": "top", "mass": 1.0, "com": [0.0, 0.0, 0.1],
        "inertia": {"axial": 0.004, "transverse": 0.015}, "visual": {"radius": 0.03}}

#: The shipped regular-precession scenes: file name -> precession_scene_dict arguments
SHIPPED_SCENES: dict[str, dict[str, Any]] = {
    "heavy_top.yaml": dict(
        name="heavy top (hanging), regular precession, eq (88) with n = 1",
        bodies=[_TOP], thetas=[0.6], kappa=-3.0),
    "double_gyro_plus.yaml": dict(
        name="double Lagrange gyroscope, regular precession, eps21 = +1",
        bodies=[_TOP1, _TOP2], thetas=[0.6, 0.9], kappa=-6.0, eps21=1.0),
    "double_gyro_minus.yaml": dict(
        name="double Lagrange gyroscope, regular precession, eps21 = -1",
        bodies=[_TOP1, _TOP2], thetas=[0.6, 0.9], kappa=-6.0, eps21=-1.0),
}


def shipped_scene_dicts() -> dict[str, dict[str, Any]]:
    """file name -> scene mapping of every shipped regular-precession scene."""
    return {fname: precession_scene_dict(**args) for fname, args in SHIPPED_SCENES.items()}


# YAML writer: the shipped scenes with comments, numbers written as repr (round-trips exactly)

_KEY_COMMENTS = {
    "gravity": "world frame, m/s^2 (nu = gravity / |gravity|: the downward vertical)",
    "position": None,
    "mass": "the carrier alone (kg); rotors add their own",
    "com": "from O^k to the carrier's centre of mass (body frame, on the axis)",
    "inertia": "about O^k, symmetric about the body z-axis",
    "next_joint": "s^k: from O^k to O^{k+1}",
    "spin": "torque mode: absolute axial spin p_i (rad/s)",
    "euler": "psi, theta, phi (psi_k = psi_1 or psi_1 + pi: one vertical plane)",
    "euler_rates": "psi' = kappa, theta' = 0, phi' from eq (88)",
}
_FLOW_KEYS = ("joint", "inertia", "visual")


def _yaml_scalar(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = repr(value)
        if "e" in text and "." not in text:  # YAML 1.1 reads 1e-05 as a string
            text = text.replace("e", ".0e")
        return text
    if isinstance(value, int):
        return repr(value)
    text = str(value)
    if text.replace("_", "a").isalnum() and text not in ("true", "false", "null", "yes", "no",
                                                         "on", "off"):
        return text
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _yaml_flow(value: Any) -> str:
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {_yaml_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_yaml_flow(v) for v in value) + "]"
    return _yaml_scalar(value)


def _yaml_lines(value: Mapping[str, Any], indent: int, seen: set[str]) -> list[str]:
    lines = []
    pad = " " * indent
    for key, item in value.items():
        if isinstance(item, Mapping) and key not in _FLOW_KEYS:
            lines.append(f"{pad}{key}:")
            lines += _yaml_lines(item, indent + 2, seen)
        elif isinstance(item, (list, tuple)) and item and isinstance(item[0], Mapping):
            lines.append(f"{pad}{key}:")
            for entry in item:
                sub = _yaml_lines(entry, indent + 4, seen)
                lines.append(f"{pad}  - {sub[0].lstrip()}")
                lines += sub[1:]
        else:
            line = f"{pad}{key}: {_yaml_flow(item)}"
            comment = _KEY_COMMENTS.get(key)
            if comment and key not in seen:
                seen.add(key)
                line = f"{line}  # {comment}"
            lines.append(line)
    return lines


def scene_yaml(scene: Mapping[str, Any], header: str) -> str:
    """YAML text of a scene mapping, `header` as leading comment lines; floats as repr."""
    lines = ["# " + line if line else "#" for line in header.splitlines()]
    return "\n".join(lines + _yaml_lines(scene, 0, set())) + "\n"


def _header(fname: str, args: Mapping[str, Any]) -> str:
    n = len(args["bodies"])
    what = {1: "one heavy top (theta from the DOWNWARD vertical: it hangs and precesses)",
            2: "two Lagrange gyroscopes on spherical joints"}.get(
                n, f"{n} Lagrange gyroscopes on spherical joints")
    eps = "" if n == 1 else f", eps21 = {args.get('eps21', 1.0):+g}"
    return (
        f"{args['name']}\n"
        f"\n"
        f"{what},\nfixed at O^1 = the world origin, started in a regular precession "
        f"(docs/theory.md section 4):\ntheta_k = {list(args['thetas'])} constant, psi_k' = kappa = "
        f"{args['kappa']:g} rad/s{eps}.\n"
        f"\n"
        f"GENERATED, do not edit by hand: the initial states are phi_k' of eq (88) in full "
        f"double\nprecision, written by\n"
        f"    python -m gyro_sim.analytic.lagrange config\n"
        f"from gyro_sim.analytic.lagrange.SHIPPED_SCENES[{fname!r}] (precession_scene_dict);\n"
        f"test/analytic/test_lagrange.py regenerates them and checks this file is unchanged.\n"
        f"Inertia is about O^k (about the centre of mass the transverse moment is B - m c^2).\n")


def write_shipped_scenes(config_dir: str) -> list[str]:
    """Write every shipped regular-precession scene into `config_dir`; the paths written."""
    import os

    paths = []
    for fname, scene in shipped_scene_dicts().items():
        path = os.path.join(config_dir, fname)
        with open(path, "w", encoding="utf-8") as f:
            f.write(scene_yaml(scene, _header(fname, SHIPPED_SCENES[fname])))
        paths.append(path)
    return paths


if __name__ == "__main__":
    import sys

    for written in write_shipped_scenes(sys.argv[1] if len(sys.argv) > 1 else "config"):
        print(written)
