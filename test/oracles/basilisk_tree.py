"""A spacecraft hub with hinged panels and balanced reaction wheels, run in Basilisk (PyPI: bsk):
the peer engine a tree of gyrostats is checked against.

The scenario is described by `tree_closed_forms.Spacecraft` (Basilisk's own parameters:
a `hingedRigidBodyStateEffector` per panel, one `reactionWheelStateEffector` for the wheels,
the hub's mass properties about its centre of mass B) and run with Basilisk's default RK4 at a
fixed step, no gravity, no command, no damping. `run` returns the hub's, panels' and wheels'
states at every step, and Basilisk's own energy and momentum totals, so that the closed-form
integrals of tree_closed_forms (c.1) and, once trees simulate, gyro_sim can be compared with it.

Basilisk imports only here, inside `run`: the module loads where Basilisk is not installed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tree_closed_forms import Spacecraft


@dataclass(frozen=True)
class Trajectory:
    """Basilisk's states at the times t (s), one row per time."""

    t: np.ndarray
    r_BN_N: np.ndarray  # (k, 3) hub's point B (its centre of mass), inertial
    v_BN_N: np.ndarray
    sigma_BN: np.ndarray  # (k, 3) MRP
    omega_BN_B: np.ndarray  # (k, 3) hub axes
    theta: np.ndarray  # (k, panels)
    theta_dot: np.ndarray
    Omega: np.ndarray  # (k, wheels) relative to the hub
    energy: np.ndarray  # (k,) Basilisk's totOrbEnergy + totRotEnergy
    momentum: np.ndarray  # (k, 3) Basilisk's totOrbAngMomPntN_N + totRotAngMomPntC_N, inertial


def run(sc: Spacecraft, duration: float, dt: float) -> Trajectory:
    """Basilisk's run of `sc` from its initial state for `duration` seconds at the step dt."""
    from Basilisk.simulation import hingedRigidBodyStateEffector, reactionWheelStateEffector, spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros, simIncludeRW

    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", macros.sec2nano(dt)))
    hub = spacecraft.Spacecraft()
    hub.ModelTag = "hub"
    hub.hub.mHub = sc.hub_mass
    hub.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    hub.hub.IHubPntBc_B = [list(row) for row in sc.hub_inertia]
    hub.hub.r_CN_NInit = [[x] for x in sc.r_CN_N]
    hub.hub.v_CN_NInit = [[x] for x in sc.v_CN_N]
    hub.hub.sigma_BNInit = [[x] for x in sc.sigma_BN]
    hub.hub.omega_BN_BInit = [[x] for x in sc.omega_BN_B]
    panels = []
    for i, p in enumerate(sc.panels):
        panel = hingedRigidBodyStateEffector.HingedRigidBodyStateEffector()
        panel.ModelTag = f"panel{i}"
        panel.mass, panel.d, panel.k, panel.c = p.mass, p.d, p.k, 0.0
        panel.IPntS_S = [list(row) for row in p.inertia]
        panel.r_HB_B = [[x] for x in p.r_HB_B]
        panel.dcm_HB = [list(row) for row in p.dcm_HB]
        panel.thetaInit, panel.thetaDotInit = p.theta, p.theta_dot
        hub.addStateEffector(panel)
        sim.AddModelToTask("t", panel)
        panels.append(panel)
    wheels = None
    if sc.wheels:
        factory = simIncludeRW.rwFactory()
        for w in sc.wheels:
            factory.create("custom", list(w.axis), Omega=w.speed / macros.RPM, Js=w.Js, useRWfriction=False,
                           useMaxTorque=False, Omega_max=0.0)
        wheels = reactionWheelStateEffector.ReactionWheelStateEffector()
        factory.addToSpacecraft("wheels", wheels, hub)
        sim.AddModelToTask("t", wheels, 2)
    sim.AddModelToTask("t", hub, 1)
    states = hub.scStateOutMsg.recorder()
    totals = hub.logger(["totOrbEnergy", "totRotEnergy", "totOrbAngMomPntN_N", "totRotAngMomPntC_N"])
    angles = [p.hingedRigidBodyOutMsg.recorder() for p in panels]
    speeds = wheels.rwSpeedOutMsg.recorder() if wheels is not None else None
    for recorder in [states, totals, *angles] + ([speeds] if speeds is not None else []):
        sim.AddModelToTask("t", recorder)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(duration))
    sim.ExecuteSimulation()
    k = len(states.times())
    rot = np.array(totals.totRotAngMomPntC_N)
    # the rotational momentum is about the centre of mass C; about N's origin it gains r_C x P,
    # which Basilisk's orbital term (about N) holds: their sum is the total about N's origin
    return Trajectory(
        t=states.times() * 1e-9, r_BN_N=np.array(states.r_BN_N), v_BN_N=np.array(states.v_BN_N),
        sigma_BN=np.array(states.sigma_BN), omega_BN_B=np.array(states.omega_BN_B),
        theta=np.array([a.theta for a in angles]).T.reshape(k, len(panels)),
        theta_dot=np.array([a.thetaDot for a in angles]).T.reshape(k, len(panels)),
        Omega=np.array(speeds.wheelSpeeds)[:, :len(sc.wheels)] if speeds is not None else np.zeros((k, 0)),
        energy=np.array(totals.totOrbEnergy) + np.array(totals.totRotEnergy),
        momentum=np.array(totals.totOrbAngMomPntN_N) + rot)
