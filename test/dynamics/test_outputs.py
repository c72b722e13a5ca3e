"""The compiled snapshot (gyro_sim.dynamics.outputs, Simulator.snapshot on the numba backend)
against the numpy reference's snapshot of the same state: equal to round-off."""
import glob
import os

import numpy as np
import pytest

from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.backends import NumpyOutputs
from gyro_sim.simulator import Simulator

from test.dynamics.chains import random_chain

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

CONFIG = os.path.join(os.path.dirname(__file__), "..", "..", "config")
SHIPPED = sorted(os.path.basename(p)[:-5] for p in glob.glob(os.path.join(CONFIG, "*.yaml"))
                 if not p.endswith("params.yaml"))
#: agreement, relative to the scale of each quantity
RTOL = 1e-12


def close(a, b, scale=None):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    s = max(np.max(np.abs(b), initial=0.0), 1e-300) if scale is None else scale
    return np.max(np.abs(a - b), initial=0.0) <= RTOL * s


def reference(sim):
    """The snapshot and body states of the simulator's state from the numpy reference."""
    compiled = sim._outputs
    sim._outputs = NumpyOutputs(sim.model, sim.system, sim._joint_index, sim._inputs)
    sim._outputs.moved(sim.time, sim._y, sim._p, sim._moments)
    try:
        return sim.snapshot(), sim.body_states()
    finally:
        sim._outputs = compiled


def check(sim):
    fast_snap = sim.snapshot()
    ref, ref_bodies = reference(sim)  # the reference path of the same state
    assert fast_snap.joint_names == ref.joint_names
    for name in ("position", "velocity", "body_position", "body_quaternion", "wrench_force"):
        assert close(getattr(fast_snap, name), getattr(ref, name)), name
    # a speed rotor's motor torque A (w' . e) may be round-off: against A |w|^2, w' its scale
    spin = float(np.max(sim.model.speed_A, initial=0.0)) * np.max(np.abs(ref.velocity)) ** 2
    assert close(fast_snap.effort, ref.effort, np.max(np.abs(ref.effort)) + spin)
    # a spherical joint transmits no moment (eq 44): both are round-off there, so the moments
    # are compared against what a force can make of them over the chain
    reach = np.max(np.linalg.norm(ref.body_position - ref.body_position[0], axis=1)) + 1.0
    wscale = np.max(np.abs(ref.wrench_moment)) + reach * np.max(np.abs(ref.wrench_force))
    assert close(fast_snap.wrench_moment, ref.wrench_moment, wscale)
    assert fast_snap.invariants.keys() == ref.invariants.keys()
    escale = abs(ref.invariants["kinetic"]) + abs(ref.invariants["potential"])
    hscale = np.linalg.norm(ref.invariants["angular_momentum_O1"]) + 1e-300
    for key, v in ref.invariants.items():
        scale = escale if key in ("energy", "kinetic", "potential", "jacobi", "lagrange_85") else None
        if key in ("vertical_momentum", "angular_momentum_O1", "lagrange_82"):
            scale = hscale
        assert close(fast_snap.invariants[key], v, scale), key
    assert fast_snap.drift.keys() == ref.drift.keys()
    assert fast_snap.nonfinite() is None
    # the public outputs are the snapshot's numbers on this backend
    for b, r in zip(sim.body_states(), ref_bodies):
        for name in ("position", "rotation", "angular_velocity", "velocity"):
            assert close(getattr(b, name), getattr(r, name), 1.0 + np.max(np.abs(getattr(r, name)))), name
    np.testing.assert_array_equal(sim.joint_states().position, fast_snap.position)
    np.testing.assert_array_equal([w.force for w in sim.wrenches()], fast_snap.wrench_force)


def drive(sim, seed):
    rng = np.random.default_rng(seed)
    if sim.axis_names:
        sim.set_axis_moments(rng.normal(size=len(sim.axis_names)) * 0.2)
    sim.advance(0.03)


@pytest.mark.parametrize("scene", SHIPPED)
def test_compiled_snapshot_is_the_numpy_snapshot_on_shipped_scenes(scene):
    sim = Simulator(scene, integrator="rk4", backend="numba")
    assert sim.snapshot().invariants is not None  # at the reset state too
    check(sim)
    drive(sim, 1)
    check(sim)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_snapshot_is_the_numpy_snapshot_on_random_chains(seed, base):
    sim = Simulator(random_chain(seed, base=base), integrator="rk4", backend="numba")
    drive(sim, seed)
    check(sim)


def test_parts_switched_off_are_none():
    sim = Simulator("hinge_chain", integrator="rk4", backend="numba")
    snap = sim.snapshot(bodies=False, wrenches=False, invariants=False)
    assert snap.body_position is None and snap.wrench_force is None and snap.invariants is None


def stateful_chain() -> dict:
    """A stateful model with every actuator term: a hinge arm under Coulomb, Stribeck and viscous
    friction carrying a wheel with max_torque, max_speed and friction, a spherical tip, an IMU."""
    wheel = {"name": "wheel", "axis": [1.0, 0.0, 0.0], "position": [0.0, 0.0, 0.1], "mass": 0.2,
             "axial_inertia": 6e-4, "transverse_inertia": 3e-4, "mode": "torque", "spin": 30.0, "actuated": True,
             "max_torque": 0.1, "max_speed": 40.0,
             "friction": {"coulomb": 0.002, "viscous": 1e-4, "static": 0.004, "stribeck_speed": 0.5}}
    return {"name": "stateful", "gravity": [0.0, 0.0, -9.81], "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
            "bodies": [{"name": "arm", "mass": 0.5, "com": [0.0, 0.0, 0.07], "next_joint": [0.0, 0.0, 0.15],
                        "inertia": {"axial": 1e-3, "transverse": 4e-3}, "rotors": [wheel],
                        "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0],
                                  "friction": {"coulomb": 0.003, "viscous": 1e-3, "static": 0.005,
                                               "stribeck_speed": 0.2}},
                        "initial": {"angle": 0.4, "rate": 0.5}},
                       {"name": "tip", "joint": {"type": "spherical"}, "mass": 0.2, "com": [0.0, 0.0, 0.05],
                        "inertia": {"axial": 2e-4, "transverse": 1e-3},
                        "initial": {"euler": [0.1, 0.3, 0.0], "euler_rates": [0.5, 0.0, 0.2]}}],
            "imus": [{"name": "imu", "body": "arm", "position": [0.0, 0.02, 0.05]}]}


@pytest.mark.parametrize("scene", ["rw_pendulum", stateful_chain()], ids=["rw_pendulum", "every_term"])
def test_compiled_outputs_of_a_stateful_model_are_the_numpy_reference(scene):
    """Friction and the speed cut: the efforts published are the torques applied at the state
    (after the cut, with friction), the IMUs read the accelerations under them, the energy
    watchdog's energies take the spins from the state; all as the numpy reference."""
    sim = Simulator(scene, integrator="rk4", step=1e-3, backend="numba")
    assert sim.model.stateful
    for seed, moments in enumerate(([0.0, 0.3], [0.0, -0.05], [0.02, 0.0])):
        sim.set_axis_moments(moments)  # the first beyond max_torque; the wheel near max_speed
        sim.advance(0.2)
        check(sim)
        ref = NumpyOutputs(sim.model, sim.system, sim._joint_index, sim._inputs)
        ref.moved(sim.time, sim._y, sim._p, sim._moments)
        for a, b in zip(sim._outputs.accelerations(), ref.accelerations()):
            assert close(a, b, 1.0 + np.max(np.abs(b))), seed
        e_fast, e_ref = sim._outputs.energies(sim.time, sim._y), ref.energies(sim.time, sim._y)
        assert close(e_fast[:3], e_ref[:3], abs(e_ref[1]) + abs(e_ref[2]))
        # friction is in the wheel's effort: not its command (the check above compared the sums)
        js = sim.joint_states()
        wheel = js.effort[js.name.index("wheel")]
        assert abs(wheel - sim._inputs_moments()[sim.axis_names.index("wheel")]) > 1e-6
