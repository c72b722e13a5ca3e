"""A free hub with four reaction wheels under Coulomb and viscous friction, torque saturation
and a speed limit, against Basilisk's reactionWheelStateEffector (balanced wheels) on the same
numbers. Runs where Basilisk (PyPI: bsk) is installed."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim.simulator import Simulator

pytest.importorskip("Basilisk.utilities.SimulationBaseClass", reason="Basilisk (PyPI: bsk) is not installed")

#: Basilisk's step (s): its RK4 and its control period (commands, the speed limit's cut)
DT = 0.01
HUB_INERTIA = np.array([[10.0, 0.3, -0.2], [0.3, 12.0, 0.1], [-0.2, 0.1, 8.0]])  # the whole spacecraft's
OMEGA0 = [0.01, -0.02, 0.03]  # rad/s, hub, body frame
COMMAND = [0.3, -0.05, 0.02, 0.08]  # N m: the first beyond u_max
JS = 0.05
# spin relative to the hub (rad/s), coulomb (N m), viscous (N m s/rad), u_max (N m), Omega_max (rad/s)
WHEELS = [(100.0, 0.005, 2e-4, 0.1, 150.0), (-50.0, 0.002, 1e-4, 0.1, 150.0), (5.0, 0.01, 0.0, 0.1, 150.0),
          (0.0, 0.0, 5e-4, 0.1, 120.0)]


def pyramid() -> list[np.ndarray]:
    beta = np.deg2rad(54.74)
    return [np.array([np.cos(beta) * np.cos(a), np.cos(beta) * np.sin(a), np.sin(beta)])
            for a in np.deg2rad([0.0, 90.0, 180.0, 270.0])]


def basilisk_run(duration: float, samples: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """Hub angular velocities (body frame) and wheel speeds at the sample times."""
    from Basilisk.architecture import messaging
    from Basilisk.simulation import reactionWheelStateEffector, spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros, simIncludeRW

    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", macros.sec2nano(DT)))
    sc = spacecraft.Spacecraft()
    sc.hub.mHub = 100.0
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = HUB_INERTIA.tolist()
    sc.hub.omega_BN_BInit = [[w] for w in OMEGA0]
    factory = simIncludeRW.rwFactory()
    for axis, (spin, coulomb, viscous, u_max, omega_max) in zip(pyramid(), WHEELS):
        factory.create("custom", axis.tolist(), Omega=spin / macros.RPM, Js=JS, useRWfriction=True,
                       fCoulomb=coulomb, cViscous=viscous, useMaxTorque=True, u_max=u_max,
                       Omega_max=omega_max / macros.RPM)
    wheels = reactionWheelStateEffector.ReactionWheelStateEffector()
    factory.addToSpacecraft("wheels", wheels, sc)
    sim.AddModelToTask("t", wheels, 2)
    sim.AddModelToTask("t", sc, 1)
    command = messaging.ArrayMotorTorqueMsgPayload()
    command.motorTorque = COMMAND + [0.0] * (messaging.MAX_EFF_CNT - len(COMMAND))
    message = messaging.ArrayMotorTorqueMsg().write(command)
    wheels.rwMotorCmdInMsg.subscribeTo(message)
    hub, speeds = sc.scStateOutMsg.recorder(), wheels.rwSpeedOutMsg.recorder()
    sim.AddModelToTask("t", hub)
    sim.AddModelToTask("t", speeds)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(duration))
    sim.ExecuteSimulation()
    t = hub.times() * 1e-9
    at = [int(np.argmin(np.abs(t - s))) for s in samples]
    return hub.omega_BN_B[at], speeds.wheelSpeeds[at, :len(WHEELS)]


def gyro_sim_run(samples: list[float]) -> tuple[np.ndarray, np.ndarray]:
    axes = pyramid()
    # Basilisk's balanced wheels leave the spacecraft's inertia as given, wheels included
    # (H = I w + sum Js Omega_i g_i): the carrier is that less each rotor's transverse
    # inertia Jt (1 - g g^T) and axial Js g g^T (Basilisk's custom wheel: Jt = Js / 2)
    carrier = HUB_INERTIA - sum(0.5 * JS * (np.eye(3) - np.outer(g, g)) + JS * np.outer(g, g) for g in axes)
    rotors = [{"name": f"rw{i}", "axis": g.tolist(), "mass": 1.0, "axial_inertia": JS, "transverse_inertia": 0.5 * JS,
               "mode": "torque", "spin": spin + float(np.dot(OMEGA0, g)), "actuated": True, "max_torque": u_max,
               "max_speed": omega_max, "friction": {"coulomb": coulomb, "viscous": viscous}}
              for i, (g, (spin, coulomb, viscous, u_max, omega_max)) in enumerate(zip(axes, WHEELS))]
    scene = {"name": "hub", "base": {"type": "free", "position": [0.0, 0.0, 0.0]},
             "bodies": [{"name": "hub", "joint": {"type": "spherical"}, "mass": 100.0, "com": [0.0, 0.0, 0.0],
                         "inertia_com": carrier.tolist(), "rotors": rotors,
                         "initial": {"quaternion": [1.0, 0.0, 0.0, 0.0], "angular_velocity": OMEGA0}}]}
    sim = Simulator(scene, integrator="dop853", rtol=1e-11, atol=1e-13)
    sim.set_axis_moments(COMMAND)
    hub, speeds = [], []
    for t in samples:
        sim.advance(t - sim.time)
        body = sim.body_states()[0]
        hub.append(body.rotation.T @ body.angular_velocity)
        js = sim.joint_states()
        speeds.append([js.velocity[js.name.index(f"rw{i}")] for i in range(len(WHEELS))])
    return np.array(hub), np.array(speeds)


def test_four_wheels_under_friction_and_limits_agree_with_basilisk():
    samples = [1.0, 5.0, 10.0, 20.0, 45.0]
    hub_b, speeds_b = basilisk_run(samples[-1], samples)
    hub, speeds = gyro_sim_run(samples)
    # friction and saturation are the same model: agreement to the integration error until
    # the first wheel reaches its speed limit (about t = 30 s)
    np.testing.assert_allclose(hub[:4], hub_b[:4], rtol=0, atol=1e-9)
    np.testing.assert_allclose(speeds[:4], speeds_b[:4], rtol=0, atol=1e-8)
    # at the limit Basilisk cuts the torque at control steps once at Omega_max and restores it
    # once friction has slowed the wheel below: it hovers within u_max DT / Js of the limit;
    # here the cut ramps down over the last 0.1 % below it, to where friction balances the
    # ramped torque: never past it
    limit, u_max = WHEELS[0][4], WHEELS[0][3]
    assert abs(speeds_b[-1, 0] - limit) <= u_max * DT / JS
    assert limit * (1 - 1e-3) <= speeds[-1, 0] <= limit
