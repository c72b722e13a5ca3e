"""The tree oracles themselves (test/oracles/tree_closed_forms.py), before anything is compared with
them: each closed form against an independent numerical formulation of the same Lagrangian.

These tests sit next to the module they check rather than under a package folder: the oracle
is not part of gyro_sim (it imports nothing of it), and checking it is a precondition of every
test that will compare gyro_sim's trees with it.

- (a.1)-(a.3): the frequencies against the eigenvalues of (K, M) of a `PlanarTree`, whose
  mass matrix comes from the kinetic energy of positions written as sums of rotating segments
  and whose stiffness is the Hessian of the potential by differences;
- (b.1)-(b.5): the momenta and the energy of a solve_ivp integration of Lagrange's equations,
  and the closed-form hub angle, hub offset and panel rates along it;
- (c.1): the spacecraft's integrals in Basilisk's conventions against the planar ones, on
  states where the spacecraft moves in a plane.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the oracles package

from oracles.tree_closed_forms import (
    FreeHubPanels,
    HubPendulums,
    PlanarBody,
    PlanarTree,
    Segment,
    Spacecraft,
    Wheel,
    bar,
    flapping_hub_offset,
    flapping_rate_squared,
    free_hub_tree,
    hub_pendulum_frequencies,
    hub_pendulums_tree,
    mrp_dcm_BN,
    planar_spacecraft,
    pinwheel_hub_angle,
    pinwheel_rate_squared,
    point_mass,
    slider_frequencies,
    slider_pendulums_tree,
    spacecraft_integrals,
)

HUBS = {
    "point masses": dict(hub_mass=2.0, hub_com=0.3, hub_inertia=0.4, attach_down=0.5, attach_side=0.2),
    "bars": dict(hub_mass=5.0, hub_com=0.1, hub_inertia=0.2, attach_down=0.25, attach_side=0.4),
    "light hub": dict(hub_mass=0.1, hub_com=0.05, hub_inertia=0.01, attach_down=1.0, attach_side=0.0),
}


def hub(name: str) -> HubPendulums:
    l, J = point_mass(0.7, 0.6) if name != "bars" else bar(1.3, 0.9)
    mass = 0.7 if name != "bars" else 1.3
    return HubPendulums(**HUBS[name], mass=mass, com=l, inertia=J)


@pytest.mark.parametrize("name", sorted(HUBS))
def test_hub_pendulum_frequencies_are_the_linearised_lagrangians(name):
    p = hub(name)
    omega_a, (low, high) = hub_pendulum_frequencies(p)
    numeric = hub_pendulums_tree(p).frequencies(np.zeros(3))
    np.testing.assert_allclose(sorted([omega_a, low, high]), numeric, rtol=1e-8)


@pytest.mark.parametrize("name", sorted(HUBS))
def test_antisymmetric_mode_is_one_pendulum_on_a_fixed_hinge(name):
    """Its shape is (0, 1, -1), and its frequency that of one pendulum alone (a PlanarTree of one
    body): the hub stays still."""
    p = hub(name)
    omega_a, _ = hub_pendulum_frequencies(p)
    w2, shapes = hub_pendulums_tree(p).modes(np.zeros(3))
    k = int(np.argmin(abs(w2 - omega_a ** 2)))
    shape = shapes[:, k] / shapes[1, k]
    np.testing.assert_allclose(shape, [0.0, 1.0, -1.0], atol=1e-8)
    one = PlanarBody(p.mass, p.inertia - p.mass * p.com ** 2, (1,), (Segment(p.com, (1,), -np.pi / 2),))
    alone = PlanarTree((one,), g=p.g)
    np.testing.assert_allclose(omega_a, alone.frequencies(np.zeros(1))[0], rtol=1e-8)
    # the symmetric modes move the hub and both pendulums alike
    for j in set(range(3)) - {k}:
        assert abs(shapes[0, j]) > 1e-3 and abs(shapes[1, j] - shapes[2, j]) < 1e-8 * abs(shapes[1, j])


def test_antisymmetric_swing_of_any_amplitude_leaves_the_hub_still():
    p = hub("point masses")
    tree = hub_pendulums_tree(p)
    times = np.linspace(0.0, 3.0, 31)
    q, qd = tree.integrate(np.array([0.0, 0.6, -0.6]), np.zeros(3), times)
    assert np.max(abs(q[:, 0])) < 1e-10 and np.max(abs(q[:, 1] + q[:, 2])) < 1e-10
    energy = [tree.integrals(a, b)[2] for a, b in zip(q, qd)]
    assert np.ptp(energy) < 1e-10 * abs(energy[0])
    assert np.ptp(q[:, 1]) > 1.0  # it did swing


@pytest.mark.parametrize("J_of", [point_mass, bar])
def test_slider_frequencies_are_the_linearised_lagrangians(J_of):
    m, M, g = 0.8, 1.7, 9.81
    l, J = J_of(m, 0.5)
    omega_a, omega_s = slider_frequencies(M, m, l, J, g)
    numeric = slider_pendulums_tree(M, m, l, J, b=0.3, g=g).frequencies(np.zeros(3))
    assert numeric[0] < 1e-6  # the drift of the slider
    np.testing.assert_allclose(sorted([omega_a, omega_s]), numeric[1:], rtol=1e-8)


PANELS = FreeHubPanels(hub_mass=50.0, hub_inertia=8.0, hinge=0.8, mass=4.0, com=1.2, inertia=1.5, stiffness=3.0)


@pytest.mark.parametrize("mirror", [False, True], ids=["pinwheel", "flapping"])
def test_free_hub_with_panels_conserves_momenta_and_energy(mirror):
    """An unsymmetric motion: the integrals of Lagrange's equations."""
    tree = free_hub_tree(PANELS, mirror)
    times = np.linspace(0.0, 4.0, 21)
    q, qd = tree.integrate(np.array([0.1, -0.2, 0.3, 0.7, -0.4]), np.array([0.05, 0.02, 0.4, -0.3, 0.9]), times)
    P0, H0, E0 = tree.integrals(q[0], qd[0])
    for a, b in zip(q[1:], qd[1:]):
        P, H, E = tree.integrals(a, b)
        np.testing.assert_allclose(P, P0, rtol=0, atol=1e-11 * (1 + np.abs(P0).max()))
        assert abs(H - H0) < 1e-11 * abs(H0) and abs(E - E0) < 1e-11 * E0
    assert np.ptp(q[:, 3]) > 0.5 and np.ptp(q[:, 2]) > 0.5  # panels and hub did move


def test_pinwheel_deployment_follows_the_closed_form():
    """From rest with both panels at beta0: the hub turns by (b.2), the panels' rate is (b.3), the
    hub's centre stays put."""
    tree = free_hub_tree(PANELS, mirror=False)
    beta0 = 1.1
    times = np.linspace(0.0, 3.0, 31)
    q, qd = tree.integrate(np.array([0.0, 0.0, 0.0, beta0, beta0]), np.zeros(5), times)
    beta = q[:, 3]
    assert np.ptp(beta) > 1.5  # it swung through beta = 0
    np.testing.assert_allclose(q[:, 4], beta, atol=1e-10)
    np.testing.assert_allclose(q[:, :2], 0.0, atol=1e-10)
    np.testing.assert_allclose(q[:, 2], pinwheel_hub_angle(beta, beta0, PANELS), atol=1e-9)
    energy = PANELS.stiffness * beta0 ** 2
    np.testing.assert_allclose(qd[:, 3] ** 2, pinwheel_rate_squared(beta, energy, PANELS), atol=1e-9)
    assert np.ptp(q[:, 2]) > 0.1  # the hub turned


def test_flapping_deployment_follows_the_closed_form():
    tree = free_hub_tree(PANELS, mirror=True)
    beta0 = 1.1
    times = np.linspace(0.0, 3.0, 31)
    q, qd = tree.integrate(np.array([0.0, 0.0, 0.0, beta0, beta0]), np.zeros(5), times)
    beta = q[:, 3]
    np.testing.assert_allclose(q[:, [0, 2]], 0.0, atol=1e-10)  # no rotation, no sideways motion
    np.testing.assert_allclose(q[:, 1], flapping_hub_offset(beta, beta0, PANELS), atol=1e-10)
    energy = PANELS.stiffness * beta0 ** 2
    np.testing.assert_allclose(qd[:, 3] ** 2, flapping_rate_squared(beta, energy, PANELS), atol=1e-9)
    assert np.ptp(q[:, 1]) > 0.05


@pytest.mark.parametrize("mirror", [False, True], ids=["pinwheel", "flapping"])
def test_spacecraft_integrals_are_the_planar_ones(mirror):
    tree, sc = free_hub_tree(PANELS, mirror), planar_spacecraft(PANELS, mirror)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, qd = rng.normal(size=5), rng.normal(size=5)
        P, H, E = tree.integrals(q, qd)
        sigma = (0.0, 0.0, np.tan(q[2] / 4))
        P3, H3, E3 = spacecraft_integrals(sc, (q[0], q[1], 0.0), (qd[0], qd[1], 0.0), sigma, (0.0, 0.0, qd[2]),
                                          q[3:], qd[3:], ())
        np.testing.assert_allclose(P3, [*P, 0.0], rtol=0, atol=1e-12 * np.abs(P).max())
        np.testing.assert_allclose(H3, [0.0, 0.0, H], rtol=0, atol=1e-12 * abs(H))
        np.testing.assert_allclose(E3, E, rtol=1e-13)


def test_mrp_matrix_is_a_rotation_about_the_mrp_axis():
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    angle = 2.3
    BN = mrp_dcm_BN(np.tan(angle / 4) * axis)
    np.testing.assert_allclose(BN @ BN.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(BN @ axis, axis, atol=1e-15)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rodrigues_NB = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K  # rotates B's axes into N
    np.testing.assert_allclose(BN, rodrigues_NB.T, atol=1e-15)


def test_a_balanced_wheel_adds_its_relative_spin():
    """(c.1)'s wheel terms against the hub and the wheel as two rigid bodies: the carrier (the
    hub less the locked wheel) turning at omega, the wheel at omega + Omega g."""
    g, Js, Jt = np.array([0.0, 0.6, 0.8]), 0.05, 0.03
    hub_inertia = np.array([[10.0, 0.3, -0.2], [0.3, 12.0, 0.1], [-0.2, 0.1, 8.0]])
    sc = Spacecraft(100.0, tuple(map(tuple, hub_inertia)), (), (Wheel(tuple(g), Js),))
    w, speed, sigma = np.array([0.1, -0.3, 0.2]), 40.0, np.array([0.1, 0.2, -0.3])
    _, H, E = spacecraft_integrals(sc, np.zeros(3), np.zeros(3), sigma, w, (), (), (speed,))
    wheel = Jt * np.eye(3) + (Js - Jt) * np.outer(g, g)
    carrier, w_wheel = hub_inertia - wheel, w + speed * g
    NB = mrp_dcm_BN(sigma).T
    np.testing.assert_allclose(H, NB @ (carrier @ w + wheel @ w_wheel), rtol=1e-14)
    np.testing.assert_allclose(E, 0.5 * w @ carrier @ w + 0.5 * w_wheel @ wheel @ w_wheel, rtol=1e-14)
