"""Rotors (docs/theory.md section 1): torque rotors integrate L_i / A_i (eq 29) and never couple
back into their own spin; a speed rotor at constant kappa_i' acts as a constant lambda."""
import copy

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene


def top_with_rotor(mode, spin, actuated=False):
    return {
        "name": "top with rotor",
        "gravity": [0.0, 0.0, -9.81],
        "base": {"type": "fixed"},
        "bodies": [
            {
                "name": "top",
                "joint": {"type": "spherical"},
                "mass": 1.0,
                "com": [0.0, 0.01, 0.1],
                "inertia": {"axial": 0.004, "transverse": 0.015},
                "rotors": [
                    {
                        "name": "wheel",
                        "axis": [0.0, 0.6, 0.8],
                        "position": [0.0, 0.0, 0.1],
                        "mass": 0.2,
                        "axial_inertia": 2.0e-4,
                        "transverse_inertia": 1.2e-4,
                        "mode": mode,
                        "spin": spin,
                        "actuated": actuated,
                    }
                ],
                "initial": {"euler": [0.0, 0.6, 0.0], "euler_rates": [3.0, 0.4, 25.0]},
            }
        ],
    }


def test_torque_rotor_spin_integrates_command():
    """p_i(t) = p_i0 + int L_i / A_i dt (eq 29), whatever the carrier does."""
    sim = Simulator(load_scene(top_with_rotor("torque", 300.0, actuated=True)), rtol=1e-11, atol=1e-12)
    A = 2.0e-4
    schedule = [(0.3, 0.002), (0.2, -0.005), (0.5, 0.0)]
    p_expected = 300.0
    for dt, L in schedule:
        sim.set_axis_moments([L])
        for _ in range(10):
            sim.advance(dt / 10)
        p_expected += L / A * dt
        js = sim.joint_states()
        i = js.name.index("wheel")
        body = sim.body_states()[0]
        e = body.rotation @ np.array([0.0, 0.6, 0.8])
        p = js.velocity[i] + body.angular_velocity @ e  # p = kappa' + w . e (eq 19)
        assert p == pytest.approx(p_expected, rel=1e-12, abs=1e-9)
        assert js.effort[i] == L


def test_speed_rotor_equals_constant_lambda():
    """A speed rotor (A_i, kappa_i') moves the carrier exactly as a carrier with A_i added to its
    inertia and a constant gyrostatic moment A_i kappa_i' e_i (here: a torque rotor whose
    absolute spin equals kappa_i', with the axial inertia moved into the carrier)."""
    speed = top_with_rotor("speed", 150.0)
    equiv = copy.deepcopy(speed)
    e = np.array([0.0, 0.6, 0.8])
    A = 2.0e-4
    body = equiv["bodies"][0]
    I_O = np.diag([0.015, 0.015, 0.004]) + A * np.outer(e, e)
    m, c = 1.0, np.array(body["com"])
    body.pop("inertia")
    body["inertia_com"] = (I_O - m * (c @ c * np.eye(3) - np.outer(c, c))).tolist()
    body["rotors"][0]["mode"] = "torque"
    sims = [Simulator(load_scene(s), rtol=1e-12, atol=1e-13) for s in (speed, equiv)]
    for sim in sims:
        sim.advance(1.0)
    a, b = (s.body_states()[0] for s in sims)
    assert np.allclose(a.rotation, b.rotation, atol=1e-10)
    assert np.allclose(a.angular_velocity, b.angular_velocity, atol=1e-9)
    # and the rotor really matters: without it the motion differs
    plain = copy.deepcopy(equiv)
    plain["bodies"][0]["rotors"][0]["spin"] = 0.0
    c = Simulator(load_scene(plain), rtol=1e-12, atol=1e-13)
    c.advance(1.0)
    assert np.abs(c.body_states()[0].rotation - a.rotation).max() > 1e-3


def test_rotor_spin_is_not_state():
    """Rotors add no mechanical state: the state size is the same with and without them."""
    with_rotor = Simulator(load_scene(top_with_rotor("speed", 150.0)))
    no_rotor = top_with_rotor("speed", 150.0)
    no_rotor["bodies"][0].pop("rotors")
    plain = Simulator(load_scene(no_rotor))
    assert with_rotor.model.N == plain.model.N
    torque = Simulator(load_scene(top_with_rotor("torque", 10.0)))
    # a torque rotor adds only its angle, an output quadrature after the velocities
    assert torque.model.N == plain.model.N and torque.model.size == plain.model.size + 1
