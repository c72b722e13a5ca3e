"""The work of the commanded moments closes the energy balance: E(t) - E(0) - W(t) = 0.

The commands are internal moments (hinge and rotor motors), so the energy changes by exactly
their work; the balance is a conservation law the integration must keep to its tolerance,
with or without commands. Without the work term the same numbers miss by the work itself,
which the test checks is large: the test can fail.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.paths import find_scene

HORIZON = 10.0
CHUNK = 0.01


def commands(t: float) -> list[float]:
    """A step and a sine on each axis of the hinge chain (wheel2, arm3, arm4), N m."""
    step = 1.0 if t >= 2.0 else 0.0
    return [0.004 * step + 0.002 * math.sin(3.0 * t),
            -0.05 * step + 0.03 * math.sin(1.7 * t + 0.3),
            0.03 * step + 0.02 * math.cos(2.3 * t)]


@pytest.mark.slow
def test_energy_balance_holds_under_commands():
    sim = Simulator(load_scene(find_scene("hinge_chain")), integrator="dop853", rtol=1e-10, atol=1e-12)
    assert len(sim.axis_names) == 3
    worst_balance = worst_drift = 0.0
    for i in range(int(round(HORIZON / CHUNK))):
        sim.set_axis_moments(commands(sim.time))
        sim.advance(CHUNK)
        if i % 10 == 9:
            snap = sim.snapshot(bodies=False, wrenches=False)
            worst_balance = max(worst_balance, abs(snap.energy_balance) / snap.energy_scale)
            worst_drift = max(worst_drift, abs(snap.drift["energy"]))
    assert worst_balance < 1e-9, worst_balance
    assert worst_drift > 1e-4, "the commands must do work for the balance to mean anything"
    # momenta are not touched by internal moments
    assert abs(snap.drift["vertical_momentum"]) < 1e-8


def test_without_commands_the_balance_is_the_energy_drift():
    sim = Simulator(load_scene(find_scene("hinge_chain")), integrator="dop853", rtol=1e-10, atol=1e-12)
    for _ in range(20):
        sim.advance(CHUNK)
    snap = sim.snapshot(bodies=False, wrenches=False)
    assert snap.work == 0.0
    ref = sim.reference_invariants()
    assert snap.energy_balance == snap.invariants["energy"] - ref["energy"]


def test_work_is_moment_times_angle_and_resets():
    """One held moment on one hinge: W = tau * (phi(t) - phi(0)), and reset() zeroes it."""
    sim = Simulator(load_scene(find_scene("hinge_chain")), integrator="rk4", step=1e-3)
    i = sim.axis_names.index("arm3")
    phi0 = sim.joint_states().position[sim.joint_states().name.index("arm3")]
    tau = np.zeros(3)
    tau[i] = 0.04
    sim.set_axis_moments(tau)
    for _ in range(30):
        sim.advance(CHUNK)
    phi1 = sim.joint_states().position[sim.joint_states().name.index("arm3")]
    assert sim.work == pytest.approx(0.04 * (phi1 - phi0), rel=1e-12, abs=1e-15)
    assert abs(sim.work) > 1e-6
    sim.reset()
    assert sim.work == 0.0 and sim.snapshot().work == 0.0


def test_scenes_without_a_balanced_integral_report_no_balance():
    """A moving base does work of its own: no balance is claimed there. With speed rotors the
    balance is the Jacobi integral's."""
    from gyro_sim.dynamics.invariants import balanced_energy

    has = {}
    for name in ("hinge_chain", "vibrating_base", "speed_rotor_top"):
        sim = Simulator(load_scene(find_scene(name)))
        snap = sim.snapshot()
        has[name] = snap.energy_balance is not None
        assert has[name] == (balanced_energy(sim.model) is not None)
    assert has == {"hinge_chain": True, "vibrating_base": False, "speed_rotor_top": True}


@pytest.mark.parametrize("factor", [1.0, 30.0])
def test_the_jacobi_integral_balances_the_commands_work(factor):
    """Speed rotors' motors do work the commands do not account for (the energy drifts by more
    than the commands' work), but the Jacobi integral changes by the commands' work alone: the
    Lagrangian of a constant relative spin does not depend on t. A free chain in space, its hinge
    and its torque rotor commanded."""
    from gyro_sim.bench.extreme import abrupt_commands

    scene, moments = abrupt_commands(factor, "free_chain_rotors")
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    e0 = sim.invariants()["energy"]
    sim.set_axis_moments(moments)
    for _ in range(30):
        sim.advance(CHUNK)
    snap = sim.snapshot(bodies=False, wrenches=False)
    assert abs(snap.work) > 1.0
    assert abs(snap.energy_balance) < 1e-10 * abs(snap.work), (snap.energy_balance, snap.work)
    # the energy alone misses the balance: the speed rotor's motor works too
    motor_work = snap.invariants["energy"] - e0 - snap.work
    assert abs(motor_work) > 1e3 * abs(snap.energy_balance) and abs(motor_work) > 1e-3, motor_work
