"""The chain's (or tree's) equations in canonical (Hamiltonian) form, for a symplectic integrator.

Why: a Gauss-Legendre method is symplectic, and keeps every quadratic invariant exactly, only
for a Hamiltonian system in canonical coordinates (Hairer, Lubich, Wanner, "Geometric
Numerical Integration", 2nd ed., 2006, VI.4 and IV.2). The package's state (quaternions and
joint rates, :mod:`gyro_sim.dynamics.model`) is not canonical: gauss4 on it keeps |q| but lets the
energy of the double gyroscope grow as t^2 and the world angular momentum drift as h^4
(docs/integrators.md). This module writes the same equations (docs/theory.md sections
1-2, 5) in canonical pairs, and `gauss4s` (:mod:`gyro_sim.integrators.gauss4.gauss4s`)
runs the same Gauss method on them.

Coordinates and momenta (the state z):

    z = [r0 (free base, 3) | q^k (4 per spherical body) | phi_k (hinges) |
         p_r (3) | p^k (4 per spherical body) | p_phi_k (hinges) | kappa_i (torque rotors)]

- q^k is the body's orientation quaternion (world from body), p^k its conjugate momentum;
- the momenta are those of the reduced Lagrangian: the torque rotors' cyclic angles are
  eliminated (Routh), which leaves the gyrostatic moment lambda^k(t) (eq 31) as a term
  lambda . w linear in the rates; the rotor angles kappa_i are carried as quadratures
  (kappa_i' = p_i - w . e_i, eqs 18-19), for output only, as in the package's state.

The quaternion's momentum (the standard extension, Hairer-Lubich-Wanner VII.5): for any
q != 0 and p, Pi = 1/2 p (x) conj(q) = (Pi_0, pi) with pi the body's angular quasi-momentum in
world axes. The Hamiltonian H(q, p) is the physical one evaluated at the rotation of q/|q| and
at pi; it does not depend on Pi_0 or |q|. So q . p (the scaling's momentum) and |q|^2 are kept by
the flow, and the flow of (R, pi) is the physical motion for any |q| (the map (q, p) -> (R, pi)
is a Poisson map everywhere, not only on |q| = 1). What this module evaluates:

    q' = dH/dp = 1/2 (0, w) (x) q                          w: the body's angular velocity
    p' = -dH/dq = (2 (0, pi') + Pi (x) (0, w)) (x) q / |q|^2

which follows from p = 2 Pi (x) q / |q|^2, q . q' = 0 and Pi_0' = 0.

The quasi-momenta and their rates come from the numpy reference's spatial quantities
(:mod:`gyro_sim.dynamics.reference`, about the world origin). For joint column j of body k with unit
motion S_j, the relative (the package's) momentum is p_rel,j = S_j . sum_{l >= k} h_l (h_l the
spatial momentum of body l, lambda^l included), and along the motion

    p_rel,j' = S_j' . sum_{l >= k} h_l + S_j . sum_{l >= k} F_l + tau_j

(the subtree's momentum changes by the external wrench F and the joint's reaction, whose
component along S_j is zero at a spherical joint, eq 44, and the commanded moment at a hinge,
eq 51). No acceleration is needed. The canonical momenta are the relative ones seen through
the change of rates: a spherical body's absolute angular velocity w^k is the sum of the joint
rates up to it, so

    pi^k = p_rel(k) - p_rel(k'),   p_phi_l = p_rel(l) - e_l . p_rel(k'),   p_r = p_rel(base)

where k' is the next spherical body after k (after the hinge l); without one, the subtracted
term is zero. A slide l (docs/theory.md section 12) turns nothing: its momentum is its relative
one, p_d_l = p_rel(l) = e_l . P_l (P_l the subtree's linear momentum), with
p_rel(l)' = (w^{l-1} x e_l) . P_l + e_l . F_l + tau_l. The rates follow from the momenta by
the mass matrix: M u = p_rel - b(q, t), b the momentum at zero joint rates (gyrostatic moments,
a moving base).

On a tree (docs/theory.md section 11) "l >= k" is "l in k's subtree" (`reference.subtree_sum`),
w^{l-1} the parent's angular velocity, and k' each of the next spherical bodies below k: the
first spherical body on each branch going down from k, past hinges and slides. Then
pi^k = p_rel(k) - sum_k' p_rel(k'), p_phi_l = p_rel(l) - e_l . sum_k' p_rel(k'), and p_rel(k)
is the sum of pi over the spherical bodies of k's subtree (`_tree_maps`). A chain has one k'
at most, and its code path is the chain's own.

A hinge's geared motor on a turning parent (docs/theory.md section 10, eq 51b): its rotor's spin
J G phi_k' a relative to the parent is the parent's gyrostatic moment (in the subtree momenta
from the rates, `_subtree`), and hinge k's momentum gains m . w^{parent} + J G^2 phi_k'
(m = J G a: the derivative of T_motor). The momentum rates keep their form: the rotor's
J G (a . w^{parent}' + G phi_k'') is both in the rate of hinge k's momentum and in its joint
moment (51b), and cancels. M (`reference.mass_matrix`) holds the motors' coupling.

This module is the numpy form (a dense solve of M: for checks and small chains).
"""
from __future__ import annotations

import numpy as np

from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.model import Model
from gyro_sim.dynamics.rotations import cross, quat_conj, quat_mul, quat_rates


def _next_spherical(model: Model) -> np.ndarray:
    """For every body k, the first spherical body after it (-1 if none)."""
    nxt = np.full(model.n, -1, dtype=int)
    following = -1
    for k in range(model.n - 1, -1, -1):
        nxt[k] = following
        if not model.is_hinge[k]:
            following = k
    return nxt


class CanonicalChain:
    """The chain (or tree) as a Hamiltonian ODE system z' = f(t, z) (same interface as ChainODE).

    Wraps a numpy :class:`gyro_sim.dynamics.system.ChainODE` (its model, held inputs and spins).
    `momenta(t, y)` and `state(t, z)` convert between the package's state y and z.
    """

    def __init__(self, ode):
        self.ode = ode
        m = self.model = ode.model
        self.data = dyn.Data(m)
        self.free = m.free
        ns, nh, nt = len(m.sph_bodies), len(m.hinge_bodies), len(m.torque_body)
        nf = 3 if m.free else 0
        self.nq = nf + 4 * ns + nh  # coordinates (and momenta)
        self.size = 2 * self.nq + nt
        off = 0
        self.i_r0 = slice(off, off + nf)
        off += nf
        self.i_quat = off + np.arange(4 * ns).reshape(ns, 4)
        off += 4 * ns
        self.i_phi = slice(off, off + nh)
        off += nh
        self.i_pr = slice(off, off + nf)
        off += nf
        self.i_pq = off + np.arange(4 * ns).reshape(ns, 4)
        off += 4 * ns
        self.i_pphi = slice(off, off + nh)
        off += nh
        self.i_kappa = slice(off, off + nt)
        self.quat_index = self.i_quat
        self.nfev = 0
        nxt = _next_spherical(m)
        # for spherical body k (in sph order) and hinge l: the next spherical body's index in
        # sph order, -1 if none
        sph_pos = np.full(m.n, -1, dtype=int)
        sph_pos[m.sph_bodies] = np.arange(ns)
        self._sph_next = np.array([sph_pos[nxt[k]] if nxt[k] >= 0 else -1 for k in m.sph_bodies],
                                  dtype=int)
        # (a slide's momentum e . P_k needs no correction: it changes no angular velocity)
        self._hinge_next = np.array([sph_pos[nxt[k]] if nxt[k] >= 0 and not m.is_slide[k] else -1
                                     for k in m.hinge_bodies], dtype=int)
        if not m.chain:
            self._tree_maps()
        self._slide_cols = m.col_hinge[m.hinge_slide]
        self._slides = m.hinge_slide
        self._y = np.empty(m.size)  # the coordinates of z in the package's layout (positions)

    def _tree_maps(self) -> None:
        """A tree's (docs/theory.md section 11) `_sph_next`, `_hinge_next`: a spherical body k
        can have several next spherical bodies k' (the first ones on each branch below it), and
        so can a hinge. (ns, ns) `_sph_below`[k, k'] and (nh, ns) `_hinge_below`[l, k'] are 1
        where k' is one (the path up from k' meets k, or the hinge l, before any other spherical
        body; slides are passed, as on the chain). Then pi^k = p_rel(k) - sum_k' p_rel(k'),
        p_phi_l = p_rel(l) - e_l . sum_k' p_rel(k'), and p_rel(k) is the sum of pi over the
        spherical bodies of k's subtree."""
        m = self.model
        ns, nh = len(m.sph_bodies), len(m.hinge_bodies)
        sph_pos = np.full(m.n, -1, dtype=int)
        sph_pos[m.sph_bodies] = np.arange(ns)
        hinge_pos = np.full(m.n, -1, dtype=int)
        hinge_pos[m.hinge_bodies] = np.arange(nh)
        self._sph_below = np.zeros((ns, ns))
        self._hinge_below = np.zeros((nh, ns))
        for b, k in enumerate(m.sph_bodies):
            q = m.parent[k]
            while q >= 0 and m.is_hinge[q]:
                if not m.is_slide[q]:
                    self._hinge_below[hinge_pos[q], b] = 1.0
                q = m.parent[q]
            if q >= 0:
                self._sph_below[sph_pos[q], b] = 1.0

    # --- the package's state <-> canonical ------------------------------------------------------
    def _subtree(self, t: float, u: np.ndarray):
        """Velocities for rates u, then per body k: H_k, the subtree's angular momentum about
        O^k (lambda included); P_k its linear momentum (world)."""
        m, d = self.model, self.data
        dyn.velocities(m, d, t, u)
        mom_ang = dyn.matvec(d.J, d.w) + cross(d.h, d.v_o)
        mom_lin = m.mass[:, None] * d.v_o + cross(d.w, d.h)
        if self._lam_w is not None:
            mom_ang = mom_ang + self._lam_w
        if m.motor is not None:  # a geared motor's rotor spin J G phi' a, on its parent (eq 31)
            mom_ang = mom_ang + dyn.motor_forces(m, d, u[m.col_hinge])
        Hs, Ps = dyn.subtree_sum(m, mom_ang), dyn.subtree_sum(m, mom_lin)  # a chain's rcumsum
        return Hs - cross(d.O, Ps), Ps

    def _relative(self, Hk: np.ndarray, Pk: np.ndarray) -> np.ndarray:
        """The package's joint momenta p_rel (N,) from the subtree momenta."""
        m, d = self.model, self.data
        p = np.empty(m.N, dtype=Hk.dtype)
        if m.free:
            p[m.col_base] = Pk[0]
        p[m.col_sph] = Hk[m.sph_bodies]
        p[m.col_hinge] = np.einsum("ni,ni->n", d.e_w, Hk[m.hinge_bodies])
        if len(self._slide_cols):  # a slide's: the subtree's linear momentum along e^k (section 12)
            p[self._slide_cols] = np.einsum("ni,ni->n", d.e_w[self._slides], Pk[m.slide_bodies])
        return p

    def _positions(self, t: float, q: np.ndarray, z: np.ndarray) -> None:
        m, y = self.model, self._y
        if y.dtype != np.result_type(q, z, t):  # a complex step (the tests' derivatives)
            y = self._y = np.empty(m.size, dtype=np.result_type(q, z, t))
        if m.free:
            y[m.i_r0] = z[self.i_r0]
        y[m.i_quat] = q
        y[m.i_phi] = z[self.i_phi]
        dyn.positions(m, self.data, t, y)
        # the rotors' (a geared motor's part is the rates', added in `_subtree`)
        self._lam_w = dyn.rotor_lam(m, self.data, self.ode.spins(t), None)[0]

    def momenta(self, t: float, y: np.ndarray) -> np.ndarray:
        """z (size,) of the package's state y at time t."""
        m = self.model
        z = np.empty(self.size, dtype=np.result_type(y, t))  # complex for a complex step
        q = y[m.i_quat]
        if m.free:
            z[self.i_r0] = y[m.i_r0]
        z[self.i_quat] = q
        z[self.i_phi] = y[m.i_phi]
        self._positions(t, q, z)
        Hk, Pk = self._subtree(t, y[m.i_vel])
        p_rel = self._relative(Hk, Pk)
        if m.armature is not None:  # a hinge's momentum gains its armature's a phi'
            p_rel[m.col_hinge] += m.armature * y[m.i_vel][m.col_hinge]
        if m.motor is not None:  # and its geared motor's, m . w^{parent} + J G^2 phi' (eq 51b)
            rates = y[m.i_vel][m.col_hinge]
            w_parent = self.data.w_parent[m.hinge_bodies]
            p_rel[m.col_hinge] += (np.einsum("ni,ni->n", self.data.motor_w, w_parent)
                                   + m.motor[:, 0] * m.motor[:, 1] ** 2 * rates)
        pi, p_phi, p_r = self._to_absolute(p_rel)
        if m.free:
            z[self.i_pr] = p_r
        z[self.i_pphi] = p_phi
        z[self.i_pq] = 2.0 * quat_mul(_pure(pi), q)  # p = 2 Pi (x) q with Pi_0 = 0, |q| = 1
        z[self.i_kappa] = y[m.i_kappa]
        return z

    def _to_absolute(self, p_rel: np.ndarray):
        """(pi (ns, 3), p_phi (nh,), p_r (3,)) from the joint momenta p_rel (N,)."""
        m, d = self.model, self.data
        Ps = p_rel[m.col_sph]  # (ns, 3)
        if not m.chain:  # a tree: the sums over each body's next spherical bodies
            p_phi = p_rel[m.col_hinge] - np.einsum("ni,ni->n", d.e_w, self._hinge_below @ Ps)
            return Ps - self._sph_below @ Ps, p_phi, p_rel[m.col_base]
        pi = Ps.copy()
        has = self._sph_next >= 0
        pi[has] -= Ps[self._sph_next[has]]
        p_phi = p_rel[m.col_hinge].copy()
        hh = self._hinge_next >= 0
        if hh.any():
            p_phi[hh] -= np.einsum("ni,ni->n", d.e_w[hh], Ps[self._hinge_next[hh]])
        return pi, p_phi, p_rel[m.col_base]

    def _from_absolute(self, pi: np.ndarray, p_phi: np.ndarray, p_r: np.ndarray) -> np.ndarray:
        """p_rel (N,) from the canonical quasi-momenta (the inverse of `_to_absolute`)."""
        m, d = self.model, self.data
        p = np.empty(m.N)
        if m.chain:
            Ps = np.cumsum(pi[::-1], axis=0)[::-1]  # p_rel(k) = sum of pi over spherical bodies >= k
            p[m.col_sph] = Ps
            ph = p_phi.copy()
            hh = self._hinge_next >= 0
            if hh.any():
                ph[hh] += np.einsum("ni,ni->n", d.e_w[hh], Ps[self._hinge_next[hh]])
        else:  # a tree: the sums of pi over the spherical bodies of each subtree
            full = np.zeros((m.n, 3))
            full[m.sph_bodies] = pi
            sums = dyn.subtree_sum(m, full)
            p[m.col_sph] = sums[m.sph_bodies]
            ph = p_phi + np.einsum("ni,ni->n", d.e_w, sums[m.hinge_bodies]) * ~m.hinge_slide
        p[m.col_hinge] = ph
        if m.free:
            p[m.col_base] = p_r
        return p

    def _rates(self, t: float, z: np.ndarray):
        """Positions at z, then the joint rates u (N,), the quasi-momenta pi (ns, 3) and the
        full quaternion momenta Pi (ns, 4) = 1/2 p (x) conj(q)."""
        m, d = self.model, self.data
        q = z[self.i_quat]
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        self._positions(t, qn, z)
        Pi = 0.5 * quat_mul(z[self.i_pq], quat_conj(q))
        pi = Pi[:, 1:]
        p_rel = self._from_absolute(pi, z[self.i_pphi], z[self.i_pr])
        Hk0, Pk0 = self._subtree(t, np.zeros(m.N))  # b: the momentum at zero joint rates
        b = self._relative(Hk0, Pk0)
        Sa, Sb = dyn.joint_columns(m, d)
        M = dyn.mass_matrix(m, d, Sa, Sb)
        u = np.linalg.solve(M, p_rel - b)
        return q, u, Pi, p_rel

    def state(self, t: float, z: np.ndarray) -> np.ndarray:
        """The package's state y (model.size,) of z at time t (unit quaternions)."""
        m = self.model
        q, u, _, _ = self._rates(t, z)
        y = np.empty(m.size)
        if m.free:
            y[m.i_r0] = z[self.i_r0]
        y[m.i_quat] = q / np.linalg.norm(q, axis=1, keepdims=True)
        y[m.i_phi] = z[self.i_phi]
        y[m.i_vel] = u
        y[m.i_kappa] = z[self.i_kappa]
        return y

    # --- the vector field -------------------------------------------------------------------------
    def rhs(self, t: float, z: np.ndarray) -> np.ndarray:
        m, d = self.model, self.data
        self.nfev += 1
        q, u, Pi, p_rel = self._rates(t, z)
        Hk, Pk = self._subtree(t, u)
        # external wrench on each subtree: gravity, (h x g, m g) about the origin
        if m.gravity is not None:
            Fl = dyn.subtree_sum(m, m.mass[:, None] * m.gravity)  # a chain's rcumsum
            Fa = dyn.subtree_sum(m, cross(d.h, m.gravity[None, :]))
            Mk = Fa - cross(d.O, Fl)  # about O^k
        else:
            Fl = np.zeros((m.n, 3))
            Mk = np.zeros((m.n, 3))
        G = cross(Pk, d.vO) + Mk  # S' . h + S . F for a rotation about O^k with fixed axes
        dp = np.empty(m.N)
        if m.free:
            dp[m.col_base] = Fl[0]
        dp[m.col_sph] = G[m.sph_bodies]
        hb = m.hinge_bodies
        if len(hb):
            e = d.e_w
            de = cross(d.w_parent[hb], e)  # (50): e' = w^{k-1} x e
            dp[m.col_hinge] = np.einsum("ni,ni->n", de, Hk[hb]) + np.einsum("ni,ni->n", e, G[hb])
            if len(self._slide_cols):  # a slide's S = (0, e): S' . h + S . F = (w^{k-1} x e) . P + e . F
                sl = self._slides
                dp[self._slide_cols] = (np.einsum("ni,ni->n", de[sl], Pk[m.slide_bodies])
                                        + np.einsum("ni,ni->n", e[sl], Fl[m.slide_bodies]))
            if self.ode.hinge_tau is not None:
                dp[m.col_hinge] += self.ode.hinge_tau  # (51)
            if m.spring is not None:
                dp[m.col_hinge] += dyn.spring_moments(m, self._y)
        # canonical momenta's rates: the rates of `_to_absolute`'s map, whose hinge rows carry
        # e_l . p_rel(k'), so also - e_l' . p_rel(k')
        dpi, dpphi, _ = self._to_absolute(dp)
        if not m.chain:
            if len(hb):
                dpphi -= np.einsum("ni,ni->n", de, self._hinge_below @ p_rel[m.col_sph])
        else:
            hh = self._hinge_next >= 0
            if hh.any():
                dpphi[hh] -= np.einsum("ni,ni->n", de[hh], p_rel[m.col_sph][self._hinge_next[hh]])
        zdot = np.empty(self.size)
        if m.free:
            zdot[self.i_r0] = u[m.col_base]
            zdot[self.i_pr] = dp[m.col_base]
        w = d.w[m.sph_bodies]
        zdot[self.i_quat] = quat_rates(q, w)  # q' = 1/2 (0, w) (x) q
        q2 = np.einsum("ni,ni->n", q, q)[:, None]
        zdot[self.i_pq] = quat_mul(2.0 * _pure(dpi) + quat_mul(Pi, _pure(w)), q) / q2
        zdot[self.i_phi] = u[m.col_hinge]
        zdot[self.i_pphi] = dpphi
        p = self.ode.spins(t)
        if p is not None:
            zdot[self.i_kappa] = dyn.torque_rotor_rates(m, d, p)  # (18)-(19)
        return zdot

    def project(self, z: np.ndarray) -> None:
        """Nothing: |q|^2 is a quadratic invariant of this field for every z (q . q' = 0), so a
        Gauss method keeps it to round-off, and H does not depend on |q|. (Scaling q to unit
        length after a step would not be a symplectic map of (q, p).)"""

    def angular_momentum(self, z: np.ndarray) -> np.ndarray:
        """sum_k pi^k (+ r0 x p_r for a free base): the world angular momentum about the base
        point (about the origin for a free base), bilinear in z, when every body on the base is
        spherical."""
        Pi = 0.5 * quat_mul(z[self.i_pq], quat_conj(z[self.i_quat]))
        L = Pi[:, 1:].sum(axis=0)
        if self.free:
            L = L + np.cross(z[self.i_r0], z[self.i_pr])
        return L


def _pure(v: np.ndarray) -> np.ndarray:
    """(0, v) quaternions of vectors v (n, 3)."""
    out = np.zeros(v.shape[:-1] + (4,), dtype=v.dtype)
    out[..., 1:] = v
    return out
