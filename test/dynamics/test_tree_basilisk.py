"""A spacecraft hub with two hinged panels and three reaction wheels in Basilisk
(hingedRigidBodyStateEffector x 2, reactionWheelStateEffector), against the closed forms of
test/oracles/tree_closed_forms.py: the case a tree of gyrostats will be compared on.

- The 3D case (`SPACECRAFT`: a tumbling hub, panels on unsymmetric springs, wheels spinning):
  the linear momentum, the angular momentum about N's origin and the energy of (c.1), computed
  from Basilisk's states, stay constant to Basilisk's RK4 accuracy, the residual shrinks as
  the fourth power of the step, and they are Basilisk's own totals to round-off.
- The pinwheel deployment from rest (planar): the hub's angle follows (b.2) of the panels'
  angle, the panels' rate (b.3); the flapping one: the hub's offset follows (b.4), the
  panels' rate (b.5).
- gyro_sim's tree (a free hub, two hinged panels on springs, three wheels as torque rotors)
  moves as Basilisk's `SPACECRAFT` does: attitude, rates, position, velocity, panel angles and
  rates, wheel speeds within 1e-10 over 10 s (Basilisk's RK4 at 2.5 ms, whose own error is the
  residual: it shrinks as the step's fourth power), with Basilisk's energy and momentum.

Runs where Basilisk (PyPI: bsk) is installed.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("Basilisk.utilities.SimulationBaseClass", reason="Basilisk (PyPI: bsk) is not installed")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the oracles package

from oracles.basilisk_tree import Trajectory, run
from oracles.tree_closed_forms import (
    FreeHubPanels,
    mrp_dcm_BN,
    Panel,
    Spacecraft,
    Wheel,
    flapping_hub_offset,
    flapping_rate_squared,
    pinwheel_hub_angle,
    pinwheel_rate_squared,
    planar_spacecraft,
    spacecraft_integrals,
)

#: panels in IPntS_S about their centres of mass (S's y axis is the hinge's), a hinge axis
#: along the hub's y for one, tilted for the other. S must be a principal frame: Basilisk's hinge
#: equation keeps IPntS_S's diagonal only (with a product of inertia of 0.2 kg m^2 the energy
#: drifts by 1e-5 instead of 1.6e-12)
PANEL_INERTIA = ((8.0, 0.0, 0.0), (0.0, 6.0, 0.0), (0.0, 0.0, 2.5))
TILT = np.deg2rad(20.0)
SPACECRAFT = Spacecraft(
    hub_mass=400.0,
    hub_inertia=((150.0, 2.0, -1.0), (2.0, 120.0, 3.0), (-1.0, 3.0, 100.0)),  # about B, the wheels locked
    panels=(Panel(20.0, PANEL_INERTIA, 1.5, 40.0, (1.0, 0.0, 0.2), ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),
                  theta=0.3, theta_dot=0.2),
            Panel(20.0, PANEL_INERTIA, 1.5, 60.0, (-1.0, 0.1, 0.0),
                  ((1, 0, 0), (0, np.cos(TILT), np.sin(TILT)), (0, -np.sin(TILT), np.cos(TILT))),
                  theta=-0.2, theta_dot=-0.4)),
    wheels=(Wheel((1.0, 0.0, 0.0), 0.08, 300.0), Wheel((0.0, 1.0, 0.0), 0.08, -200.0),
            Wheel((0.0, 0.0, 1.0), 0.08, 100.0)),
    sigma_BN=(0.1, -0.2, 0.05), omega_BN_B=(0.15, -0.3, 0.25), r_CN_N=(10.0, -5.0, 2.0), v_CN_N=(0.3, 0.1, -0.2))
DURATION = 30.0


def integrals(sc: Spacecraft, tr: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    out = [spacecraft_integrals(sc, tr.r_BN_N[i], tr.v_BN_N[i], tr.sigma_BN[i], tr.omega_BN_B[i], tr.theta[i],
                                tr.theta_dot[i], tr.Omega[i]) for i in range(len(tr.t))]
    return np.array([o[0] for o in out]), np.array([o[1] for o in out]), np.array([o[2] for o in out])


def drifts(sc: Spacecraft, dt: float) -> tuple[float, float, float, Trajectory, np.ndarray, np.ndarray]:
    """Largest relative drifts of P, H, E over the run, the run, and (H, E) along it."""
    tr = run(sc, DURATION, dt)
    P, H, E = integrals(sc, tr)
    return (np.abs(P - P[0]).max() / np.linalg.norm(P[0]), np.abs(H - H[0]).max() / np.linalg.norm(H[0]),
            np.abs(E - E[0]).max() / E[0], tr, H, E)


def test_hub_panels_and_wheels_keep_momentum_and_energy():
    dP, dH, dE, tr, H, E = drifts(SPACECRAFT, 0.01)
    # it moves: the panels swing, the wheels exchange momentum with the hub
    assert np.ptp(tr.theta, axis=0).min() > 0.3 and np.ptp(tr.Omega, axis=0).min() > 0.1
    assert np.ptp(tr.omega_BN_B, axis=0).min() > 0.01
    # the integrals of (c.1) are Basilisk's own totals (the same model: springs, balanced wheels)
    np.testing.assert_allclose(E, tr.energy, rtol=1e-13)
    np.testing.assert_allclose(H, tr.momentum, rtol=0, atol=1e-13 * np.linalg.norm(H[0]))
    # and constant to Basilisk's RK4 accuracy at 10 ms (measured: 3.1e-11, 3.4e-11, 1.6e-12)
    assert dP < 1e-10 and dH < 1e-10 and dE < 1e-11, (dP, dH, dE)
    # the residual is the step's: halving it divides the drifts by about 2^4 (measured: 16, 16, 27)
    dP2, dH2, dE2, *_ = drifts(SPACECRAFT, 0.005)
    assert dP / dP2 > 10 and dH / dH2 > 10 and dE / dE2 > 10, (dP / dP2, dH / dH2, dE / dE2)


PLANAR = FreeHubPanels(hub_mass=50.0, hub_inertia=8.0, hinge=0.8, mass=4.0, com=1.2, inertia=1.5, stiffness=3.0)


def test_pinwheel_deployment_turns_the_hub_as_the_closed_form_says():
    beta0 = 1.1
    tr = run(planar_spacecraft(PLANAR, mirror=False, beta0=beta0), 6.0, 0.005)
    beta = tr.theta[:, 0]
    assert np.ptp(beta) > 2.0  # through beta = 0 and back
    np.testing.assert_allclose(tr.theta[:, 1], beta, atol=1e-12)
    np.testing.assert_allclose(tr.r_BN_N, 0.0, atol=1e-12)
    np.testing.assert_allclose(tr.omega_BN_B[:, :2], 0.0, atol=1e-12)
    hub_angle = 4 * np.arctan(tr.sigma_BN[:, 2])
    assert np.ptp(hub_angle) > 0.1
    # measured at 5 ms: 3e-13 rad on the angle, 1.1e-10 on the rate squared (at 10 ms: 4.8e-12, 1.8e-9)
    np.testing.assert_allclose(hub_angle, pinwheel_hub_angle(beta, beta0, PLANAR), atol=1e-11)
    rate2 = pinwheel_rate_squared(beta, PLANAR.stiffness * beta0 ** 2, PLANAR)
    np.testing.assert_allclose(tr.theta_dot[:, 0] ** 2, rate2, atol=1e-9)


def test_flapping_deployment_moves_the_hub_as_the_closed_form_says():
    beta0 = 1.1
    tr = run(planar_spacecraft(PLANAR, mirror=True, beta0=beta0), 6.0, 0.005)
    beta = tr.theta[:, 0]
    assert np.ptp(beta) > 2.0
    np.testing.assert_allclose(tr.theta[:, 1], beta, atol=1e-12)
    np.testing.assert_allclose(tr.sigma_BN, 0.0, atol=1e-12)  # mirror images: no rotation
    np.testing.assert_allclose(tr.r_BN_N[:, [0, 2]], 0.0, atol=1e-12)
    assert np.ptp(tr.r_BN_N[:, 1]) > 0.1
    # Basilisk starts the centre of mass at the origin, where the hub is with the panels at 0: (b.4)
    np.testing.assert_allclose(tr.r_BN_N[0, 1], flapping_hub_offset(beta0, 0.0, PLANAR), rtol=1e-14)
    # measured at 5 ms: 1.7e-13 m, 2.4e-13 on the rate squared
    np.testing.assert_allclose(tr.r_BN_N[:, 1] - tr.r_BN_N[0, 1], flapping_hub_offset(beta, beta0, PLANAR), atol=1e-11)
    rate2 = flapping_rate_squared(beta, PLANAR.stiffness * beta0 ** 2, PLANAR)
    np.testing.assert_allclose(tr.theta_dot[:, 0] ** 2, rate2, atol=1e-11)


# --- gyro_sim's tree against Basilisk -------------------------------------------------------------------


def gyro_sim_scene(sc: Spacecraft, r0, v0) -> dict:
    """`sc` as a gyro_sim scene: a free hub (its joint point at B, its centre of mass) with the
    wheels as torque rotors (a disc's transverse moment Js/2, taken out of the hub's locked
    inertia with the axial one), the panels as hinges on springs about h_2 at r_HB_B, their
    frames the hub's at theta = 0; O^1 starts at r0 with velocity v0 (Basilisk's B)."""
    from gyro_sim.dynamics.rotations import matrix_to_quat

    I_hub = np.array(sc.hub_inertia, float)
    rotors = []
    for i, wheel in enumerate(sc.wheels):
        g = np.array(wheel.axis, float)
        Jt = wheel.Js / 2
        I_hub = I_hub - wheel.Js * np.outer(g, g) - Jt * (np.eye(3) - np.outer(g, g))
        rotors.append({"name": f"wheel{i}", "axis": g.tolist(), "mass": 0.0, "axial_inertia": wheel.Js,
                       "transverse_inertia": Jt, "mode": "torque",
                       "spin": float(wheel.speed + g @ np.array(sc.omega_BN_B, float))})  # absolute spin
    hub = {"name": "hub", "joint": {"type": "spherical"}, "mass": sc.hub_mass, "inertia_com": I_hub.tolist(),
           "rotors": rotors, "initial": {"quaternion": matrix_to_quat(mrp_dcm_BN(sc.sigma_BN).T).tolist(),
                                         "angular_velocity": list(sc.omega_BN_B)}}
    bodies = [hub]
    for i, panel in enumerate(sc.panels):
        HB = np.array(panel.dcm_HB, float)
        bodies.append({"name": f"panel{i}", "parent": "hub", "mass": panel.mass,
                       "joint": {"type": "hinge", "axis": HB[1].tolist(), "at": list(panel.r_HB_B),
                                 "spring": {"stiffness": panel.k}},
                       "com": (-panel.d * HB[0]).tolist(),
                       "inertia_com": (HB.T @ np.array(panel.inertia, float) @ HB).tolist(),
                       "initial": {"angle": panel.theta, "rate": panel.theta_dot}})
    return {"name": "spacecraft", "base": {"type": "free", "position": list(r0), "velocity": list(v0)},
            "bodies": bodies}


def test_gyro_sim_moves_the_hub_panels_and_wheels_as_basilisk():
    from gyro_sim import Simulator
    from gyro_sim.dynamics.rotations import quat_to_matrix

    dt = 0.0025
    tr = run(SPACECRAFT, 10.0, dt)
    sim = Simulator(gyro_sim_scene(SPACECRAFT, tr.r_BN_N[0], tr.v_BN_N[0]), integrator="dop853",
                    rtol=1e-13, atol=1e-15)
    m = sim.model
    assert not m.chain and list(m.parent) == [-1, 0, 0]
    axes = np.array([w.axis for w in SPACECRAFT.wheels], float)
    spins = m.torque_p0  # no wheel torque: the absolute spins stay
    worst = np.zeros(7)
    for i in range(40, len(tr.t), 40):  # every 0.1 s
        sim.advance(tr.t[i] - sim.time)
        y, hub = sim.state, sim.body_states()[0]
        R = quat_to_matrix(y[m.i_quat[0]])
        w_body = R.T @ hub.angular_velocity
        worst = np.maximum(worst, [
            np.abs(R - mrp_dcm_BN(tr.sigma_BN[i]).T).max(), np.abs(w_body - tr.omega_BN_B[i]).max(),
            np.abs(y[m.i_r0] - tr.r_BN_N[i]).max(), np.abs(hub.velocity - tr.v_BN_N[i]).max(),
            np.abs(y[m.i_phi] - tr.theta[i]).max(), np.abs(y[m.i_vel][m.col_hinge] - tr.theta_dot[i]).max(),
            np.abs(spins - axes @ w_body - tr.Omega[i]).max()])
        inv = sim.invariants()
        assert abs(inv["energy"] - tr.energy[i]) < 1e-12 * tr.energy[i]
        about_origin = inv["angular_momentum_O1"] + np.cross(y[m.i_r0], inv["linear_momentum"])
        np.testing.assert_allclose(about_origin, tr.momentum[i], rtol=0, atol=1e-12 * np.linalg.norm(tr.momentum[0]))
    # measured: 6.4e-12 (attitude), 1.2e-11 rad/s, 4.8e-13 m, 7.9e-13 m/s, 2.2e-11 rad, 3.4e-11 rad/s
    # (at 5 ms Basilisk's step makes them 16 times larger: its RK4's error)
    assert np.all(worst < 1e-10), worst
    assert np.ptp(tr.theta, axis=0).min() > 0.3  # it moved
