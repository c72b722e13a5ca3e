"""The node's fixed-step method (gyro_sim.core.integrators.choose): rk4 where it is stable at
the step, gauss4 where the scene is stiff, and the choice checked against a 1 s run."""
import numpy as np
import pytest

from gyro_sim.bench.extreme import load_dict
from gyro_sim.core.integrators.choose import spectral_radius_estimate, fixed_step_method
from gyro_sim.core.simulator import SimulationError, Simulator

STEP = 1e-3  # the node's physics step
CALL = 0.01  # the node's advance calls
FAST_SPIN = 1e4  # rad/s, the fast heavy top


def fast_heavy_top(spin=FAST_SPIN):
    """config/heavy_top.yaml spun about its axis at `spin` rad/s."""
    sd = load_dict("heavy_top")
    sd["bodies"][0]["initial"]["euler_rates"] = [0.0, 0.0, spin]
    return sd


def survives(scene, name, seconds=1.0):
    sim = Simulator(scene, integrator=name, step=STEP)
    try:
        for _ in range(round(seconds / CALL)):
            sim.advance(CALL)
    except SimulationError:
        return False
    return True


def test_spectral_radius_exact_on_a_small_matrix():
    J = np.array([[0.0, 50.0, 0.0], [-50.0, 0.0, 0.0], [0.0, 0.0, -3.0]])  # +-50 i, -3
    rho = spectral_radius_estimate(lambda t, y: J @ y, 0.0, np.array([1.0, 2.0, 3.0]))
    assert rho == pytest.approx(50.0, rel=1e-6)


@pytest.mark.parametrize("scene", ["hinge_chain", "stiff_fast_rotor"])
def test_rk4_where_stable_and_it_survives(scene):
    name, why = fixed_step_method(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert name == "rk4" and why.startswith("rk4: h |lambda| = "), why
    assert survives(scene, "rk4")


def test_gauss4_on_the_fast_heavy_top_where_rk4_fails():
    scene = fast_heavy_top()
    name, why = fixed_step_method(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert name == "gauss4" and "stiff for rk4" in why, why
    assert not survives(scene, "rk4")  # the choice matters: rk4 goes non-finite
