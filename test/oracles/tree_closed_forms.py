"""Closed forms for trees of rigid bodies: the oracles a tree of gyrostats is checked against.

Nothing here shares code with gyro_sim. Three cases, each derived below from Lagrange's
equations d/dt (dL/dq') - dL/dq = Q with L = T - V (Landau & Lifshitz, *Mechanics*, 3rd ed.,
sections 5-7; Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., chapter 1), and an
independent numerical formulation (`PlanarTree`) the closed forms are tested against
(test/oracles/test_tree_closed_forms.py).

a. Two equal pendulums on a hub (`HubPendulums`, `hub_pendulum_frequencies`; the hub on a
   horizontal slider: `slider_frequencies`). Small oscillations about the hanging state split
   into a symmetric and an antisymmetric family; the antisymmetric mode has the frequency of
   one pendulum on a fixed hinge.

   The hub is a pendulum on a fixed horizontal hinge through O: mass M, its centre of mass at
   distance c below O, moment of inertia J0 about the hinge axis. Its angle theta is measured
   from the downward vertical. Two equal pendulums hang from it on hinges parallel to the
   hub's, at the points P+- = a (down) +- b (sideways) of the hub's frame. Each pendulum has
   mass m, its centre of mass at distance l from its hinge, moment of inertia J about its
   hinge (a point mass: J = m l^2; a uniform bar of length L hinged at an end: l = L/2,
   J = m L^2 / 3). Their angles phi_1, phi_2 are absolute, from the downward vertical.

   With x horizontal and y up, P+- = (a sin th +- b cos th, -a cos th +- b sin th) and the
   pendulum's centre of mass is P + l (sin phi, -cos phi). Its velocity is
   P' + l phi' (cos phi, sin phi), with P+-' = th' (a cos th -+ b sin th, a sin th +- b cos th).
   At the equilibrium th = phi = 0 (the +-b terms of V are odd and cancel between the two
   pendulums, so it is one), to second order:

       T = 1/2 J_H th'^2 + m l a th' (phi_1' + phi_2') + 1/2 J (phi_1'^2 + phi_2'^2),
       J_H = J0 + 2 m (a^2 + b^2)
       V = 1/2 k_H th^2 + 1/2 m g l (phi_1^2 + phi_2^2),    k_H = g (M c + 2 m a)

   (the pendulum's m |P'|^2 gives 2 m (a^2 + b^2) th'^2 / 2 summed, the cross term
   m l P' . (cos phi, sin phi) phi' gives m l a th' phi'). In the coordinates
   s = (phi_1 + phi_2)/2, d = (phi_1 - phi_2)/2 the coupling m l a th' (phi_1' + phi_2') =
   2 m l a th' s' involves s only: T and V separate into (th, s) and d.

   - Antisymmetric (d): T_d = J d'^2, V_d = m g l d^2, hence

         omega_a^2 = m g l / J                                                   (a.1)

     the single pendulum on a fixed hinge (g / l for a point mass, 3 g / (2 L) for a bar).
     The hub is not moved: the two pendulums' forces on it are mirror images about the hub's
     vertical axis and their moments about O cancel, even in the nonlinear motion.
   - Symmetric (th, s): M_s = [[J_H, 2 m l a], [2 m l a, 2 J]], K_s = diag(k_H, 2 m g l);
     det(K_s - w^2 M_s) = 0 gives, with W = w^2,

         (J_H J - 2 m^2 l^2 a^2) W^2 - (k_H J + m g l J_H) W + k_H m g l = 0      (a.2)

     two positive roots (the in-phase and the counter-phase swing of hub and pendulums).

   The hub on a horizontal slider instead (coordinate x, mass M, no rotation; the pendulums
   hinged at x +- b): T = 1/2 (M + 2 m) x'^2 + m l x' (phi_1' + phi_2') + 1/2 J (...),
   V = 1/2 m g l (phi_1^2 + phi_2^2). The antisymmetric mode is again (a.1); the symmetric one
   has M_s = [[M + 2 m, 2 m l], [2 m l, 2 J]], K_s = diag(0, 2 m g l): one zero frequency (the
   drift of x) and

         omega_s^2 = m g l (M + 2 m) / ((M + 2 m) J - 2 m^2 l^2)                 (a.3)

   (for a point mass, J = m l^2: g (M + 2 m) / (M l), the pendulum on a free cart,
   Goldstein's exercise; with M -> infinity both modes tend to (a.1)).

b. A free hub in the plane, no gravity, with two equal hinged panels (`FreeHubPanels`). The hub:
   mass M, centre of mass at its reference point, moment of inertia I_h about it. Each panel:
   mass m, moment of inertia I_p about its centre of mass, hinged at distance b from the hub's
   centre (at +-b along the hub's x axis, hinge axes normal to the plane), its centre of mass at
   distance l from the hinge, a torsional spring k about the hinge (potential 1/2 k beta^2).
   No external force or moment: the linear momentum P, the angular momentum H about any fixed
   point and the energy E = T + V are integrals (Landau & Lifshitz, sections 6-9). Let
   A = I_p + m l^2, a panel's moment of inertia about its hinge.

   - Pinwheel (`pinwheel_hub_angle`, `pinwheel_rate_squared`): the second panel is the first
     turned by pi about the hub's centre (both turn the same way about their hinges, angles
     beta_1 = beta_2 = beta). Point symmetry keeps the total centre of mass at the hub's centre
     (P = 0: the hub does not translate) and is kept by the motion. In the hub's frame the
     first panel's centre of mass is r = (b + l cos beta, l sin beta), its absolute angle
     theta + beta. Its angular momentum about the hub's centre is
     m r x (th' z x r + r_beta beta') + I_p (th' + beta') with |r|^2 = b^2 + l^2 + 2 b l cos beta
     and r x r_beta = l^2 + b l cos beta. Summed with the hub and the second panel:

         H = (C0 + D cos beta) th' + (2 A + D/2 cos beta) beta',
         C0 = I_h + 2 A + 2 m b^2,   D = 4 m b l                                     (b.1)

     With H = 0 (a deployment from rest), dth/dbeta = -(2 A + D/2 cos beta) / (C0 + D cos beta)
     = -1/2 + (I_h + 2 m b^2 - 2 A) / (2 (C0 + D cos beta)). C0 >= 2 m (b^2 + l^2) >= D, and
     (Gradshteyn & Ryzhik 2.553.3) for C0 > D and |beta| < pi,
     integral dbeta / (C0 + D cos beta) = 2 / sqrt(C0^2 - D^2) atan(sqrt((C0 - D) / (C0 + D))
     tan(beta / 2)) =: G(beta), so

         th(beta) = th0 - (beta - beta0) / 2 + (I_h + 2 m b^2 - 2 A) / 2 (G(beta) - G(beta0))   (b.2)

     The energy T = 1/2 [(C0 + D cos beta) th'^2 + 2 (2 A + D/2 cos beta) th' beta' + 2 A beta'^2]
     + k beta^2, with th' eliminated by H = 0, gives the panel's rate as a quadrature:

         beta'^2 = 2 (E - k beta^2) / (2 A - (2 A + D/2 cos beta)^2 / (C0 + D cos beta))       (b.3)

   - Flapping (`flapping_hub_offset`, `flapping_rate_squared`): the second panel is the mirror
     image of the first about the hub's y axis (panel 1 along (cos beta, sin beta), panel 2
     along (-cos beta, sin beta)). Mirror symmetry keeps th = 0 (H = 0) and x fixed; the centre
     of mass stays put, so the hub moves along y by

         y_hub(beta) - y_hub(beta0) = -2 m l (sin beta - sin beta0) / (M + 2 m)                (b.4)

     and with y_hub' = -mu l cos beta beta', mu = 2 m / (M + 2 m), T reduces to
     1/2 (2 A - 4 m^2 l^2 cos^2 beta / (M + 2 m)) beta'^2, so

         beta'^2 = 2 (E - k beta^2) / (2 A - 4 m^2 l^2 cos^2 beta / (M + 2 m))                  (b.5)

c. A spacecraft hub with hinged panels and balanced reaction wheels as Basilisk models them
   (`Spacecraft`, `spacecraft_integrals`): the linear momentum, the angular momentum about the
   inertial origin N and the energy, from the hub's state and each panel's and wheel's, for the
   check of a Basilisk run (test/dynamics/test_tree_basilisk.py) and, once trees simulate, of
   gyro_sim's. Basilisk's conventions, as its `hingedRigidBodyStateEffector` and
   `reactionWheelStateEffector` define them:

   - the hub's attitude is the MRP sigma_BN; [BN] = I + (8 S^2 - 4 (1 - s^2) S) / (1 + s^2)^2
     with S = [sigma x] and s = |sigma| (Schaub & Junkins, *Analytical Mechanics of Space
     Systems*, the MRP's direction cosine matrix); r_BN_N, v_BN_N are the hub's point B, here its
     centre of mass (r_BcB_B = 0), omega_BN_B the hub's rate in hub axes;
   - a panel hangs from its hinge point H (r_HB_B) in a hinge frame with rows [HB]; it turns by
     theta about h_2 (the hinge axis): [SH] = M2(theta) = [[c, 0, -s], [0, 1, 0], [s, 0, c]],
     so s_1 = c h_1 - s h_3. Its centre of mass is at r_SB = r_HB - d s_1, its rate
     omega_BN + theta' s_2, its inertia IPntS_S about its centre of mass in S axes, its spring
     potential 1/2 k theta^2 (Basilisk's spring has its rest angle at theta = 0);
   - a balanced wheel (spin axis g_B, axial inertia Js, relative speed Omega) is counted in the
     hub's mass and inertia as if locked; what it adds is its relative spin: Js Omega g to the
     angular momentum, Js Omega (g . omega) + 1/2 Js Omega^2 to the kinetic energy (the
     kinetic energy of an axisymmetric rotor with absolute axial rate g . omega + Omega, less
     the locked part the hub already holds).

   Then, with every vector of body k at its centre of mass, in N components,

       P = sum_k m_k v_k,    H_N = sum_k (m_k r_k x v_k + [NB] I_k omega_k) + sum_wheels [NB] Js Omega g,
       E = sum_k (1/2 m_k v_k^2 + 1/2 omega_k . I_k omega_k) + sum_panels 1/2 k theta^2
           + sum_wheels (Js Omega g . omega + 1/2 Js Omega^2)                              (c.1)

   With no command, no damping (c = 0) and no external force, P, H_N and E are constant.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import eigh

# --- a. two equal pendulums on a hub ------------------------------------------------------------------


@dataclass(frozen=True)
class HubPendulums:
    """The hub (a pendulum on a fixed hinge) and its two equal pendulums; symbols of part a."""

    hub_mass: float  # M
    hub_com: float  # c, below the hinge O
    hub_inertia: float  # J0, about the hinge axis
    attach_down: float  # a
    attach_side: float  # b
    mass: float  # m, each pendulum
    com: float  # l, hinge to centre of mass
    inertia: float  # J, about its hinge
    g: float = 9.81


def point_mass(m: float, l: float) -> tuple[float, float]:
    """(l, J) of a point mass m on a massless rod of length l."""
    return l, m * l * l


def bar(m: float, length: float) -> tuple[float, float]:
    """(l, J) of a uniform bar of mass m hinged at one end."""
    return length / 2, m * length * length / 3


def hub_pendulum_frequencies(p: HubPendulums) -> tuple[float, tuple[float, float]]:
    """(omega_a, (omega_s low, omega_s high)) in rad/s: eqs (a.1) and (a.2)."""
    m, l, J, g = p.mass, p.com, p.inertia, p.g
    J_H = p.hub_inertia + 2 * m * (p.attach_down ** 2 + p.attach_side ** 2)
    k_H = g * (p.hub_mass * p.hub_com + 2 * m * p.attach_down)
    qa = J_H * J - 2 * (m * l * p.attach_down) ** 2
    qb = -(k_H * J + m * g * l * J_H)
    qc = k_H * m * g * l
    disc = np.sqrt(qb * qb - 4 * qa * qc)
    low, high = (-qb - disc) / (2 * qa), (-qb + disc) / (2 * qa)
    return float(np.sqrt(m * g * l / J)), (float(np.sqrt(low)), float(np.sqrt(high)))


def slider_frequencies(hub_mass: float, m: float, l: float, J: float, g: float = 9.81) -> tuple[float, float]:
    """(omega_a, omega_s) in rad/s for the hub on a horizontal slider: eqs (a.1) and (a.3)."""
    total = hub_mass + 2 * m
    return float(np.sqrt(m * g * l / J)), float(np.sqrt(m * g * l * total / (total * J - 2 * (m * l) ** 2)))


# --- b. a free hub with two hinged panels -------------------------------------------------------------


@dataclass(frozen=True)
class FreeHubPanels:
    """The free hub and its two equal panels in the plane; symbols of part b."""

    hub_mass: float  # M
    hub_inertia: float  # I_h, about its centre of mass
    hinge: float  # b, hub centre to hinge
    mass: float  # m, each panel
    com: float  # l, hinge to the panel's centre of mass
    inertia: float  # I_p, about the panel's centre of mass
    stiffness: float = 0.0  # k, each hinge

    @property
    def about_hinge(self) -> float:
        """A = I_p + m l^2."""
        return self.inertia + self.mass * self.com ** 2


def _pinwheel_c0_d(p: FreeHubPanels) -> tuple[float, float]:
    return p.hub_inertia + 2 * p.about_hinge + 2 * p.mass * p.hinge ** 2, 4 * p.mass * p.hinge * p.com


def pinwheel_hub_angle(beta, beta0: float, p: FreeHubPanels, theta0: float = 0.0):
    """The hub's angle when both panels have turned from beta0 to beta, from rest (H = 0): (b.2)."""
    c0, d = _pinwheel_c0_d(p)
    root = np.sqrt(c0 * c0 - d * d)
    ratio = np.sqrt((c0 - d) / (c0 + d))

    def G(x):
        return 2 / root * np.arctan(ratio * np.tan(np.asarray(x) / 2))

    return theta0 - (np.asarray(beta) - beta0) / 2 + (p.hub_inertia + 2 * p.mass * p.hinge ** 2
                                                       - 2 * p.about_hinge) / 2 * (G(beta) - G(beta0))


def pinwheel_rate_squared(beta, energy: float, p: FreeHubPanels):
    """beta'^2 of the pinwheel deployment with H = 0 and total energy `energy`: (b.3)."""
    c0, d = _pinwheel_c0_d(p)
    beta = np.asarray(beta)
    A = p.about_hinge
    inertia = 2 * A - (2 * A + d / 2 * np.cos(beta)) ** 2 / (c0 + d * np.cos(beta))
    return 2 * (energy - p.stiffness * beta ** 2) / inertia


def flapping_hub_offset(beta, beta0: float, p: FreeHubPanels):
    """The hub's displacement along its y axis as both panels flap from beta0 to beta: (b.4)."""
    return -2 * p.mass * p.com * (np.sin(np.asarray(beta)) - np.sin(beta0)) / (p.hub_mass + 2 * p.mass)


def flapping_rate_squared(beta, energy: float, p: FreeHubPanels):
    """beta'^2 of the flapping motion with P = 0 and total energy `energy`: (b.5)."""
    beta = np.asarray(beta)
    inertia = 2 * p.about_hinge - 4 * (p.mass * p.com * np.cos(beta)) ** 2 / (p.hub_mass + 2 * p.mass)
    return 2 * (energy - p.stiffness * beta ** 2) / inertia


# --- an independent numerical formulation of planar trees -------------------------------------------


@dataclass(frozen=True)
class Segment:
    """A vector of fixed length whose direction angle is coef . q + offset."""

    length: float
    coef: tuple[float, ...]
    offset: float = 0.0


@dataclass(frozen=True)
class PlanarBody:
    """A rigid body of the plane: centre of mass = base . q + sum of segments, angle = angle . q."""

    mass: float
    inertia: float  # about its centre of mass
    angle: tuple[float, ...]
    segments: tuple[Segment, ...] = ()
    base_x: tuple[float, ...] | None = None
    base_y: tuple[float, ...] | None = None


@dataclass(frozen=True)
class PlanarTree:
    """Bodies whose centres of mass are sums of rotating segments, angles linear in q: the
    kinematics of any planar tree of hinges (and sliders). Everything is analytic in q, so
    derivatives in q are complex steps (exact to round-off); the mass matrix is read from T by
    polarisation. Lagrange's equations are integrated in Hamiltonian form: q' = M(q)^-1 p,
    p' = dT/dq(q, q') - dV/dq, with V = sum m g y + 1/2 sum k_i (q_i - q0_i)^2."""

    bodies: tuple[PlanarBody, ...]
    g: float = 0.0
    springs: tuple[tuple[int, float], ...] = ()  # (coordinate, stiffness)
    n: int = field(default=0)

    def __post_init__(self):
        object.__setattr__(self, "n", len(self.bodies[0].angle))

    def _com(self, body: PlanarBody, q, qd):
        q = np.asarray(q)
        x = np.dot(body.base_x, q) if body.base_x is not None else 0.0 * q[0]
        y = np.dot(body.base_y, q) if body.base_y is not None else 0.0 * q[0]
        vx = np.dot(body.base_x, qd) if body.base_x is not None else 0.0 * q[0]
        vy = np.dot(body.base_y, qd) if body.base_y is not None else 0.0 * q[0]
        for s in body.segments:
            a, ad = np.dot(s.coef, q) + s.offset, np.dot(s.coef, qd)
            x, y = x + s.length * np.cos(a), y + s.length * np.sin(a)
            vx, vy = vx - s.length * np.sin(a) * ad, vy + s.length * np.cos(a) * ad
        return x, y, vx, vy

    def kinetic(self, q, qd):
        out = 0.0
        for b in self.bodies:
            _, _, vx, vy = self._com(b, q, qd)
            w = np.dot(b.angle, qd)
            out = out + 0.5 * b.mass * (vx * vx + vy * vy) + 0.5 * b.inertia * w * w
        return out

    def potential(self, q):
        out = 0.0
        zero = np.zeros(self.n)
        for b in self.bodies:
            out = out + b.mass * self.g * self._com(b, q, zero)[1]
        for i, k in self.springs:
            out = out + 0.5 * k * q[i] ** 2
        return out

    def mass_matrix(self, q) -> np.ndarray:
        e = np.eye(self.n)
        diag = np.array([2 * self.kinetic(q, e[i]) for i in range(self.n)])
        M = np.diag(diag)
        for i in range(self.n):
            for j in range(i + 1, self.n):
                M[i, j] = M[j, i] = self.kinetic(q, e[i] + e[j]) - diag[i] / 2 - diag[j] / 2
        return M

    def _grad(self, f, q, h=1e-30):
        q = np.asarray(q, dtype=complex)
        return np.array([(f(q + 1j * h * np.eye(self.n)[i])).imag / h for i in range(self.n)])

    def potential_hessian(self, q, h=1e-5) -> np.ndarray:
        """By central differences of the complex-step gradient (error O(h^2))."""
        e = np.eye(self.n)
        H = np.array([(self._grad(self.potential, q + h * e[i]) - self._grad(self.potential, q - h * e[i])) / (2 * h)
                      for i in range(self.n)])
        return (H + H.T) / 2

    def frequencies(self, q0) -> np.ndarray:
        """sqrt of the generalized eigenvalues of (K, M) at the equilibrium q0, ascending."""
        w2 = eigh(self.potential_hessian(q0), self.mass_matrix(q0), eigvals_only=True)
        return np.sqrt(np.clip(w2, 0.0, None))

    def modes(self, q0) -> tuple[np.ndarray, np.ndarray]:
        """(omega^2, mode shapes as columns) at the equilibrium q0."""
        return eigh(self.potential_hessian(q0), self.mass_matrix(q0))

    def rhs(self, t, y):
        q, p = y[:self.n], y[self.n:]
        qd = np.linalg.solve(self.mass_matrix(q), p)
        dT = self._grad(lambda x: self.kinetic(x, qd), q)
        return np.concatenate([qd, dT - self._grad(self.potential, q)])

    def integrate(self, q0, qd0, times, rtol=1e-12, atol=1e-12) -> tuple[np.ndarray, np.ndarray]:
        """(q, q') at `times` (rows), by scipy's DOP853 on Lagrange's equations."""
        p0 = self.mass_matrix(q0) @ np.asarray(qd0, dtype=float)
        sol = solve_ivp(self.rhs, (0.0, times[-1]), np.concatenate([q0, p0]), method="DOP853", t_eval=times,
                        rtol=rtol, atol=atol)
        q = sol.y[:self.n].T
        qd = np.array([np.linalg.solve(self.mass_matrix(qi), pi) for qi, pi in zip(q, sol.y[self.n:].T)])
        return q, qd

    def integrals(self, q, qd) -> tuple[np.ndarray, float, float]:
        """(P, H_z about the origin, E) of the state."""
        P, H = np.zeros(2), 0.0
        for b in self.bodies:
            x, y, vx, vy = self._com(b, q, qd)
            P += b.mass * np.array([vx, vy])
            H += b.mass * (x * vy - y * vx) + b.inertia * np.dot(b.angle, qd)
        return P, float(H), float(self.kinetic(q, qd) + self.potential(q))


def hub_pendulums_tree(p: HubPendulums) -> PlanarTree:
    """Part a as a PlanarTree, q = (theta, phi_1, phi_2), angles from the downward vertical."""
    down = -np.pi / 2
    hub = PlanarBody(p.hub_mass, p.hub_inertia - p.hub_mass * p.hub_com ** 2, (1, 0, 0),
                     (Segment(p.hub_com, (1, 0, 0), down),))
    kids = []
    for i, side in ((1, 0.0), (2, np.pi)):
        coef = tuple(1.0 if j == i else 0.0 for j in range(3))
        kids.append(PlanarBody(p.mass, p.inertia - p.mass * p.com ** 2, coef,
                               (Segment(p.attach_down, (1, 0, 0), down), Segment(p.attach_side, (1, 0, 0), side),
                                Segment(p.com, coef, down))))
    return PlanarTree((hub, *kids), g=p.g)


def slider_pendulums_tree(hub_mass: float, m: float, l: float, J: float, b: float, g: float = 9.81) -> PlanarTree:
    """The hub on a horizontal slider, q = (x, phi_1, phi_2)."""
    down = -np.pi / 2
    hub = PlanarBody(hub_mass, 1.0, (0, 0, 0), (), base_x=(1, 0, 0))
    kids = [PlanarBody(m, J - m * l * l, coef, (Segment(b, (0, 0, 0), side), Segment(l, coef, down)), base_x=(1, 0, 0))
            for coef, side in (((0, 1, 0), 0.0), ((0, 0, 1), np.pi))]
    return PlanarTree((hub, *kids), g=g)


def free_hub_tree(p: FreeHubPanels, mirror: bool) -> PlanarTree:
    """Part b as a PlanarTree, q = (x, y, theta, beta_1, beta_2): pinwheel, or flapping if `mirror`."""
    sign = -1.0 if mirror else 1.0
    hub = PlanarBody(p.hub_mass, p.hub_inertia, (0, 0, 1, 0, 0), (), (1, 0, 0, 0, 0), (0, 1, 0, 0, 0))
    one = PlanarBody(p.mass, p.inertia, (0, 0, 1, 1, 0),
                     (Segment(p.hinge, (0, 0, 1, 0, 0)), Segment(p.com, (0, 0, 1, 1, 0))),
                     (1, 0, 0, 0, 0), (0, 1, 0, 0, 0))
    two = PlanarBody(p.mass, p.inertia, (0, 0, 1, 0, sign),
                     (Segment(p.hinge, (0, 0, 1, 0, 0), np.pi), Segment(p.com, (0, 0, 1, 0, sign), np.pi)),
                     (1, 0, 0, 0, 0), (0, 1, 0, 0, 0))
    return PlanarTree((hub, one, two), springs=((3, p.stiffness), (4, p.stiffness)))


# --- c. a spacecraft hub, hinged panels and balanced wheels, as Basilisk models them --------------------


@dataclass(frozen=True)
class Panel:
    """A hinged rigid panel in Basilisk's terms (hingedRigidBodyStateEffector). S must be a
    principal frame of the panel: Basilisk's hinge equation keeps IPntS_S's diagonal only, so
    with products of inertia its motion does not conserve (c.1)."""

    mass: float
    inertia: tuple  # IPntS_S, 3x3 about its centre of mass, S axes
    d: float  # hinge to centre of mass, along -s_1
    k: float  # torsional spring, N m / rad
    r_HB_B: tuple  # hinge point in hub axes
    dcm_HB: tuple  # rows: h_1, h_2 (the hinge axis), h_3 in hub axes
    theta: float = 0.0  # initial angle
    theta_dot: float = 0.0


@dataclass(frozen=True)
class Wheel:
    """A balanced reaction wheel in Basilisk's terms."""

    axis: tuple  # g_B, unit
    Js: float  # axial inertia
    speed: float = 0.0  # initial Omega relative to the hub, rad/s


@dataclass(frozen=True)
class Spacecraft:
    """The hub (its centre of mass at B; inertia about it, the wheels included as if locked),
    its panels and wheels, and the initial state: the hub's attitude and rate, and the position
    and velocity of the whole spacecraft's centre of mass C (Basilisk's r_CN_NInit, v_CN_NInit)."""

    hub_mass: float
    hub_inertia: tuple  # 3x3, about B, hub axes
    panels: tuple[Panel, ...]
    wheels: tuple[Wheel, ...]
    sigma_BN: tuple = (0.0, 0.0, 0.0)
    omega_BN_B: tuple = (0.0, 0.0, 0.0)
    r_CN_N: tuple = (0.0, 0.0, 0.0)  # the whole spacecraft's centre of mass, as Basilisk starts it
    v_CN_N: tuple = (0.0, 0.0, 0.0)


def mrp_dcm_BN(sigma) -> np.ndarray:
    """[BN] of the modified Rodrigues parameters sigma_BN."""
    s = np.asarray(sigma, dtype=float)
    S = np.array([[0.0, -s[2], s[1]], [s[2], 0.0, -s[0]], [-s[1], s[0], 0.0]])
    s2 = s @ s
    return np.eye(3) + (8 * S @ S - 4 * (1 - s2) * S) / (1 + s2) ** 2


def spacecraft_integrals(sc: Spacecraft, r_BN_N, v_BN_N, sigma_BN, omega_BN_B, theta, theta_dot, Omega
                         ) -> tuple[np.ndarray, np.ndarray, float]:
    """(P in N, H about the origin of N in N, E): eq (c.1), for one state."""
    NB = mrp_dcm_BN(sigma_BN).T
    r, v, w = np.asarray(r_BN_N, float), np.asarray(v_BN_N, float), np.asarray(omega_BN_B, float)
    I_hub = np.asarray(sc.hub_inertia, float)
    P = sc.hub_mass * v
    H = sc.hub_mass * np.cross(r, v) + NB @ (I_hub @ w)
    E = 0.5 * sc.hub_mass * v @ v + 0.5 * w @ I_hub @ w
    for panel, th, thd in zip(sc.panels, theta, theta_dot):
        HB = np.asarray(panel.dcm_HB, float)
        c, s = np.cos(th), np.sin(th)
        SB = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]) @ HB
        r_S = np.asarray(panel.r_HB_B, float) - panel.d * SB[0]  # r_SB in hub axes
        w_S = w + thd * SB[1]
        v_S = v + NB @ (np.cross(w, r_S) + panel.d * thd * SB[2])  # d/dt(-d s_1) = d theta' s_3
        I_S = SB.T @ np.asarray(panel.inertia, float) @ SB
        rN = r + NB @ r_S
        P = P + panel.mass * v_S
        H = H + panel.mass * np.cross(rN, v_S) + NB @ (I_S @ w_S)
        E += 0.5 * panel.mass * v_S @ v_S + 0.5 * w_S @ I_S @ w_S + 0.5 * panel.k * th * th
    for wheel, speed in zip(sc.wheels, Omega):
        g = np.asarray(wheel.axis, float)
        H = H + NB @ (wheel.Js * speed * g)
        E += wheel.Js * speed * (g @ w) + 0.5 * wheel.Js * speed * speed
    return P, H, float(E)


def planar_spacecraft(p: FreeHubPanels, mirror: bool, beta0: float = 0.0) -> Spacecraft:
    """Part b's hub and panels in Basilisk's terms (part c): the plane is B's x-y, the hinge axes
    along z (the second panel's along -z if `mirror`), the hub's angle theta about z.
    Panel i's Basilisk angle is beta_i; both start at rest at beta0."""
    inertia = ((p.inertia + 0.7, 0.0, 0.0), (0.0, p.inertia, 0.0), (0.0, 0.0, 2.1))  # only S's y axis counts
    one = Panel(p.mass, inertia, p.com, p.stiffness, (p.hinge, 0.0, 0.0), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)), beta0)
    two_frame = ((1, 0, 0), (0, 0, -1), (0, 1, 0)) if mirror else ((1, 0, 0), (0, 0, 1), (0, -1, 0))
    two = Panel(p.mass, inertia, p.com, p.stiffness, (-p.hinge, 0.0, 0.0), two_frame, beta0)
    hub_inertia = ((5.0, 0.0, 0.0), (0.0, 6.0, 0.0), (0.0, 0.0, p.hub_inertia))
    return Spacecraft(p.hub_mass, hub_inertia, (one, two), ())
