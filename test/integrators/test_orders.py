"""Convergence order of each fixed-step integrator measured on a real chain (the hinge chain
of eq (52) with commands and a rotor): the global error at t = 0.5 s against a tight DOP853
reference falls as step^order."""
import numpy as np
import pytest

from gyro_sim import Simulator, load_scene

from test.dynamics.chains import random_chain

T = 0.5


def final_state(scene, integrator, **kw):
    sim = Simulator(scene, integrator=integrator, **kw)
    sim.set_axis_moments(0.05 * np.ones(len(sim.axis_names)))
    sim.advance(T)
    return np.concatenate([np.concatenate([b.rotation.ravel(), b.angular_velocity]) for b in sim.body_states()])


@pytest.mark.parametrize("method, order", [("rk4", 4), ("lie4", 4)])
def test_fixed_step_order_on_chain(method, order):
    scene = load_scene(random_chain(2, base="fixed", commands=True, speed_rotors=True))
    ref = final_state(scene, "dop853", rtol=1e-13, atol=1e-14)
    steps = np.array([0.02, 0.01, 0.005, 0.0025])
    err = np.array([np.abs(final_state(scene, method, step=h) - ref).max() for h in steps])
    slope = np.polyfit(np.log(steps), np.log(err), 1)[0]
    assert order - 0.4 < slope < order + 0.5, (slope, err)


@pytest.mark.parametrize("method", ["dop853", "radau"])
def test_adaptive_error_falls_with_tolerance(method):
    scene = load_scene(random_chain(2, base="fixed", commands=True, speed_rotors=True))
    ref = final_state(scene, "dop853", rtol=1e-13, atol=1e-14)
    errs = [np.abs(final_state(scene, method, rtol=r, atol=r * 1e-2) - ref).max() for r in (1e-5, 1e-7, 1e-9)]
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[2] < 1e-6, errs
